"""One UAV: the loop of DESIGN.md §4, stepped by simulation time.

``Agent.step(t)`` reads the vehicle, senses, updates its tracks, receives and fuses what peers sent,
broadcasts its beliefs, plans and moves. It knows nothing of clocks or processes: the live harness
(``agent.runtime``) calls it on the wall clock over Zenoh; a lockstep harness can call it over an
in-memory bus. Only the transport and the clock differ.

Every received message is decoded and validated (``agent.wire``) before it touches a belief; a
rejected message is counted by reason and logged once per (peer, reason). Duplicates and messages
older than the last one from the same origin are dropped by ``(origin, seq)``.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass

import numpy as np

from agent import wire
from agent.config import AgentScenario
from agent.evaluation import TrackEvaluator
from agent.sensing import Bearing, GeometricBearingSensor
from agent.topology import Topology
from agent.tracking import Tracker
from agent.transport import Keys
from agent.vehicle import goal_to_setpoint, vehicle_from_config
from perception.terrain import terrain_from_config
from tasking.planner import PlaceholderPlanner

log = logging.getLogger("skymesh.agent")

TRUTH_MAX_AGE = 2.0  # s of simulation time; older truth is not extrapolated (chosen here)
FUTURE_EPOCHS = 50  # a peer's belief this many steps ahead of ours is rejected as a clock fault (chosen here)


@dataclass
class Counters:
    bytes_tx: Counter  # kind -> bytes
    bytes_rx: Counter  # (peer, kind) -> bytes
    rejected: Counter  # reason -> messages
    fusions: Counter  # method -> remote tracks fused
    latencies: list  # stamp-to-fusion delays of received beliefs [s of simulation time]


class Agent:
    """One agent of a fleet. ``transport`` needs ``publish(key, bytes)`` and ``drain() -> [Incoming]``."""

    def __init__(self, agent_id: str, index: int, scenario: AgentScenario, transport, keys: Keys,
                 seed: int, fleet_key: bytes | None = None):
        self.id = agent_id
        self.index = index
        self.scenario = scenario
        self.transport = transport
        self.keys = keys
        self.fleet_key = fleet_key
        self.terrain = terrain_from_config(scenario.terrain)
        self.vehicle = vehicle_from_config(scenario.vehicle, scenario.start_position(index), 0.0)
        self.sensor = GeometricBearingSensor(scenario.sensor, seed)
        self.tracker = Tracker(scenario.tracking, scenario.step, self.terrain)
        tasking = {"search": "lawnmower", "spacing": 60.0, "orbit_radius": 40.0, **scenario.tasking}
        self.planner = PlaceholderPlanner(
            index, scenario.agents, scenario.area.as_tuple(), scenario.altitude, seed=seed, **tasking
        )
        self.evaluator = TrackEvaluator()
        self.topology = Topology(agent_id)
        self.counters = Counters(Counter(), Counter(), Counter(), Counter(), [])
        self.steps = 0
        self._seq = 0
        self._last_seq: dict[tuple[str, str], int] = {}  # (origin, kind) -> last seq accepted
        self._acks: dict[str, int] = {}  # peer -> last track message seq received from it
        self._logged: set[tuple[str, str]] = set()
        self._truth: tuple[float, list[dict]] | None = None
        self._next_send = 0.0
        self.last_bearings: list[Bearing] = []

    # -- the loop -------------------------------------------------------------------------------
    def step(self, t: float) -> None:
        state = self.vehicle.state()
        truth = self.truth_at(t)
        bearings = self.sensor.measure(t, state.position, truth or [])
        self.tracker.advance(self.tracker.model.epoch_of(t))
        self.tracker.update(bearings)
        self.last_bearings = bearings
        self._publish_measurements(t, bearings)
        for item in self.transport.drain():
            self.receive(item, t)
        if t + 1e-9 >= self._next_send:
            self._publish_tracks(t)
            self._next_send = t + self.scenario.send_period
        self._publish_telemetry(t, state, bearings)
        estimates = self.tracker.estimates()
        goal = self.planner.plan(state.position, [(tid, est.mean[:2]) for tid, est in estimates])
        self.vehicle.set_setpoint(goal_to_setpoint(goal))
        self.vehicle.step(self.scenario.step)
        if truth is not None:
            self.evaluator.record(t, truth, estimates)
        self.steps += 1

    # -- receiving ------------------------------------------------------------------------------
    def receive(self, item, t: float) -> None:
        """Validate one incoming sample and apply it. Never raises on bad input."""
        try:
            parts = self.keys.parse(item.key)
        except ValueError:
            return self._reject("?", "bad_key")
        origin = parts[-1]
        if origin == self.id:
            return
        if parts[0] == "sim" and parts[1] == "truth":
            origin = None  # the world publishes truth under its own name, not under the key
        try:
            env = wire.decode(item.data, expected_origin=origin, key=self.fleet_key)
        except wire.DecodeError as err:
            return self._reject(origin or "world", err.reason)
        seen = self._last_seq.get((env.origin, env.kind))
        if seen is not None and env.seq <= seen:
            return self._reject(env.origin, "duplicate", log_it=False)
        self._last_seq[(env.origin, env.kind)] = env.seq
        self.counters.bytes_rx[(env.origin, env.kind)] += len(item.data)
        if env.kind in ("track", "telemetry"):
            self.topology.heard(env.origin, t)
        if env.kind == "telemetry" and isinstance(env.payload.get("neighbours"), list):
            self.topology.report(env.origin, t, env.payload["neighbours"])
        if env.kind == "track":
            self._fuse_tracks(env, t)
        elif env.kind == "truth":
            self._accept_truth(env)

    def _fuse_tracks(self, env: wire.Envelope, t: float) -> None:
        try:
            remote = self._decode_tracks(env.payload)
        except wire.DecodeError as err:
            return self._reject(env.origin, err.reason)
        if any(b.epoch > self.tracker.epoch + FUTURE_EPOCHS for _, b, _ in remote):
            return self._reject(env.origin, "future_epoch")
        tree_edge = self.topology.is_tree_edge(env.origin, t, self.transport.alive())
        for out in self.tracker.fuse_remote(env.origin, remote, env.acks.get(self.id), env.seq, tree_edge):
            self.counters.fusions[out.method] += 1
        self._acks[env.origin] = env.seq
        self.counters.latencies.append(t - env.stamp)

    def _decode_tracks(self, payload: dict) -> list:
        tracks = payload.get("tracks")
        if not isinstance(tracks, list):
            raise wire.DecodeError("bad_field", "payload.tracks must be a list")
        out = []
        for entry in tracks:
            if not isinstance(entry, dict) or not isinstance(entry.get("id"), int) or "belief" not in entry:
                raise wire.DecodeError("bad_field", "each track needs an integer id and a belief")
            last = entry.get("last_measured")
            if isinstance(last, bool) or not isinstance(last, int | float) or not np.isfinite(last):
                raise wire.DecodeError("bad_field", "each track needs a finite last_measured time")
            out.append((entry["id"], wire.decode_trajectory(entry["belief"], self.tracker.model), float(last)))
        return out

    def _accept_truth(self, env: wire.Envelope) -> None:
        targets = env.payload.get("targets")
        if isinstance(targets, list):
            self._truth = (env.stamp, targets)

    def truth_at(self, t: float) -> list[dict] | None:
        """The world's latest truth, extrapolated at constant velocity to ``t``."""
        if self._truth is None or abs(t - self._truth[0]) > TRUTH_MAX_AGE:
            return None
        stamp, targets = self._truth
        dt = t - stamp
        return [
            {"id": tg["id"], "position": np.asarray(tg["position"], float) + dt * np.asarray(tg["velocity"], float),
             "velocity": np.asarray(tg["velocity"], float)}
            for tg in targets
        ]

    def _reject(self, peer: str, reason: str, log_it: bool = True) -> None:
        self.counters.rejected[reason] += 1
        if log_it and (peer, reason) not in self._logged:
            self._logged.add((peer, reason))
            log.warning("%s: rejected a message from %s (%s); further ones are only counted", self.id, peer, reason)

    # -- sending --------------------------------------------------------------------------------
    def _envelope(self, kind: str, t: float, payload: dict) -> bytes:
        self._seq += 1
        env = wire.Envelope(kind=kind, origin=self.id, seq=self._seq, stamp=t, acks=dict(self._acks), payload=payload)
        return wire.encode(env, self.fleet_key)

    def _send(self, key: str, kind: str, data: bytes) -> None:
        self.transport.publish(key, data)
        self.counters.bytes_tx[kind] += len(data)

    def _publish_tracks(self, t: float) -> None:
        seq = self._seq + 1  # the sequence number the envelope below will carry
        tracks = [
            {"id": tr.id, "belief": wire.encode_trajectory(tr.belief), "last_measured": tr.last_measured}
            for tr in self.tracker.outgoing(seq)
        ]
        self._send(self.keys.belief("track", self.id), "track", self._envelope("track", t, {"tracks": tracks}))

    def _publish_telemetry(self, t: float, state, bearings: list[Bearing]) -> None:
        payload = {
            "position": state.position, "velocity": state.velocity, "yaw": float(state.yaw),
            "bearings": np.array([b.azel for b in bearings]).reshape(-1, 2),
            "neighbours": self.topology.neighbours(t),
            "tracks": [{"id": tid, "mean": est.mean, "cov": est.cov} for tid, est in self.tracker.estimates()],
        }
        self._send(self.keys.telemetry(self.id), "telemetry", self._envelope("telemetry", t, payload))

    def _publish_measurements(self, t: float, bearings: list[Bearing]) -> None:
        """Raw bearings for the centralized oracle (simulation only; a real fleet does not send these)."""
        payload = {
            "bearings": [
                {"sensor": b.sensor, "azel": b.azel, "R": b.R, "truth": b.truth_id} for b in bearings
            ]
        }
        self._send(self.keys.sim(f"measurement/{self.id}"), "measurement", self._envelope("measurement", t, payload))

    # -- results --------------------------------------------------------------------------------
    def metrics(self) -> dict:
        lat = np.asarray(self.counters.latencies, float)
        return {
            "id": self.id,
            "steps": self.steps,
            "bytes_tx": int(sum(self.counters.bytes_tx.values())),
            "bytes_rx": int(sum(self.counters.bytes_rx.values())),
            "bytes_tx_by_kind": dict(self.counters.bytes_tx),
            "bytes_rx_by_peer": _by_peer(self.counters.bytes_rx),
            "msgs_rejected": int(sum(v for k, v in self.counters.rejected.items() if k != "duplicate")),
            "rejected_by_reason": dict(self.counters.rejected),
            "fusions": dict(self.counters.fusions),
            "belief_latency_s": {
                "mean": float(lat.mean()) if lat.size else None,
                "p95": float(np.percentile(lat, 95)) if lat.size else None,
                "count": int(lat.size),
            },
            "targets": self.evaluator.summary(),
        }


def _by_peer(counter: Counter) -> dict:
    out: dict[str, dict[str, int]] = {}
    for (peer, kind), n in counter.items():
        out.setdefault(peer, {})[kind] = int(n)
    return out
