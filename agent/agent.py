"""One UAV: the loop of DESIGN.md §4, stepped by simulation time.

``Agent.step(t)`` reads the vehicle, senses, updates its tracks, receives and fuses what peers sent,
broadcasts its beliefs, plans and moves. It knows nothing of clocks or processes: the live harness
(``agent.runtime``) calls it on the wall clock over Zenoh; a lockstep harness can call it over an
in-memory bus. Only the transport and the clock differ.

Every received message is decoded and validated (``agent.net.wire``) before it touches a belief; a
rejected message is counted by reason and logged once per (peer, reason). Duplicates and messages
older than the last one from the same origin are dropped by ``(origin, seq)``.
"""

from __future__ import annotations

import heapq
import logging
from collections import Counter
from dataclasses import dataclass

import numpy as np

from agent.beliefs.grids import FireMapper
from agent.beliefs.tracking import RemoteTrack, Tracker
from agent.config import AgentScenario
from agent.evaluation import TrackEvaluator
from agent.net import wire
from agent.net.fire_truth import decode_fire, decoy
from agent.net.keys import Keys
from agent.net.netem import LinkEmulator
from agent.net.sending import SendScheduler
from agent.net.topology import Topology
from agent.sensors.bearing import Bearing
from agent.sensors.camera import sensor_from_config
from agent.vehicles.kinematic import goal_to_setpoint, vehicle_from_config
from perception.terrain import terrain_from_config
from tasking.entropy import EntropyPlanner, EntropyPlannerConfig
from tasking.planner import PlaceholderPlanner

log = logging.getLogger("skymesh.agent")

TRUTH_MAX_AGE = 2.0  # s of simulation time; older truth is not extrapolated (chosen here)
FUTURE_EPOCHS = 50  # a peer's belief this many steps ahead of ours is rejected as a clock fault (chosen here)
TRACK_ENTRY_BYTES = 5000  # budget charged per track sent: an 8-state trajectory encodes to ~4.8 kB


@dataclass
class Counters:
    bytes_tx: Counter  # kind -> bytes
    sim_bytes_tx: Counter  # kind -> bytes of simulation-only data (raw measurements for the oracles)
    bytes_rx: Counter  # (peer, kind) -> bytes
    rejected: Counter  # reason -> messages
    fusions: Counter  # method -> remote tracks fused
    radio_drops: Counter  # (peer, cause) -> messages the emulated radio dropped
    latencies: list  # stamp-to-fusion delays of received beliefs [s of simulation time]


class Agent:
    """One agent of a fleet. ``transport`` needs ``publish(key, bytes)`` and ``drain() -> [Incoming]``.

    ``camera``: an open external video source (:class:`agent.sensors.camera.VideoSource`) that replaces
    the synthetic camera; ``None`` uses the scenario's ``[sensor]`` (geometric bearings or the camera)."""

    def __init__(self, agent_id: str, index: int, scenario: AgentScenario, transport, keys: Keys,
                 seed: int, fleet_key: bytes | None = None, camera=None):
        self.id = agent_id
        self.index = index
        self.scenario = scenario
        self.transport = transport
        self.keys = keys
        self.fleet_key = fleet_key
        self.terrain = terrain_from_config(scenario.terrain)
        self.vehicle = vehicle_from_config(scenario.vehicle, scenario.start_position(index), 0.0)
        self.sensor = sensor_from_config(scenario.sensor, seed, self.terrain, camera)
        self.sensor_outcomes: Counter = Counter()  # reason -> bearings the agent could not use
        self.tracker = Tracker(scenario.tracking, scenario.step, self.terrain, seed=seed + 104729)
        self.mapper = None if scenario.grid is None else FireMapper(
            agent_id, scenario.grid, scenario.area.as_tuple(), self.terrain, seed + 7919)
        self.planner = _planner(scenario, index, seed, self.mapper)
        self.evaluator = TrackEvaluator()
        self.topology = Topology(agent_id)
        self.counters = Counters(Counter(), Counter(), Counter(), Counter(), Counter(), Counter(), [])
        plan = scenario.radio_plan
        self.link = None if plan is None else LinkEmulator(agent_id, plan)
        self.sender = SendScheduler(scenario.sending, None if plan is None else plan.sender_budget(agent_id))
        self._pending: list = []  # (deliver_at, order, envelope, size): messages the radio delays
        self._order = 0
        self._uav_positions: dict[str, np.ndarray] = {}
        self.telemetry_thinned = 0
        self.grids_thinned = 0
        self.steps = 0
        self._seq = 0
        self._last_seq: dict[tuple[str, str], int] = {}  # (origin, kind) -> last seq accepted
        self._logged: set[tuple[str, str]] = set()
        self._truth: tuple[float, list[dict]] | None = None
        self._fire: tuple[list, list] = ([], [])  # burning cells and decoys (hot spot, probability), as scene fires
        self._fire_payload = None  # the (fire, decoys) truth self._fire was decoded from
        self.last_bearings: list[Bearing] = []

    # -- the loop -------------------------------------------------------------------------------
    def step(self, t: float) -> None:
        state = self.vehicle.state()
        truth = self.truth_at(t)
        bearings = self.sensor.measure(t, state, truth or [])
        self.tracker.advance(self.tracker.model.epoch_of(t))
        bearings = self._usable(bearings)
        self.tracker.update(bearings)
        self.last_bearings = bearings
        self._publish_measurements(t, bearings)
        if self.mapper is not None:
            self._publish_grid_evidence(t, self.mapper.sense(state, *self._fire))
        for item in self.transport.drain():
            self.receive(item, t)
        self._release_delayed(t)
        self._publish_telemetry(t, state, bearings)
        if self.sender.due(t):
            self._publish_tracks(t)
        if self.mapper is not None:
            self.mapper.update_alarms(t)
            if self.mapper.due(t):
                self._publish_grid(t)
        estimates = self.tracker.estimates()
        if isinstance(self.planner, EntropyPlanner):
            beta = self.mapper.grid.shape_parameters() if self.mapper.config.belief == "beta" else None
            goal = self.planner.plan(state.position, self.mapper.planning_probability(), self.mapper.geometry.centres(),
                                     beta)
        else:
            goal = self.planner.plan(state.position, [(tid, est.mean[:2]) for tid, est in estimates])
        self.vehicle.set_setpoint(goal_to_setpoint(goal))
        self.vehicle.step(self.scenario.step)
        if truth is not None:
            self.evaluator.record(t, truth, estimates)
        self.steps += 1

    def _usable(self, bearings: list[Bearing]) -> list[Bearing]:
        """Bearings the trajectory window can still take (a camera that waited for a late pose may hand
        over some from before it); the others are counted, never applied."""
        oldest = self.tracker.epoch - self.tracker.model.window + 1
        keep = []
        for b in bearings:
            epoch = self.tracker.model.epoch_of(b.t)
            if oldest <= epoch <= self.tracker.epoch:
                keep.append(b)
            else:
                self.sensor_outcomes["bearing_outside_window"] += 1
        return keep

    def close(self) -> None:
        """Release the sensor (an external camera)."""
        self.sensor.close()

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
        if env.kind == "truth":
            return self._accept_truth(env)
        if self.link is not None and env.origin in self.link.plan.agents:
            verdict = self.link.admit(env.origin, env.seq, len(item.data), env.stamp, self._radio_positions())
            if verdict.cause is not None:
                self.counters.radio_drops[(env.origin, verdict.cause)] += 1
                return None
            if verdict.deliver_at > t:
                heapq.heappush(self._pending, (verdict.deliver_at, self._order, env, len(item.data)))
                self._order += 1
                return None
        self._deliver(env, len(item.data), t)

    def _radio_positions(self) -> dict:
        return {**self._uav_positions, self.id: self.vehicle.state().position}

    def _release_delayed(self, t: float) -> None:
        while self._pending and self._pending[0][0] <= t:
            _, _, env, size = heapq.heappop(self._pending)
            self._deliver(env, size, t)

    def _deliver(self, env: wire.Envelope, size: int, t: float) -> None:
        """A message that made it through the radio: count it and use it."""
        self.counters.bytes_rx[(env.origin, env.kind)] += size
        if env.kind in ("track", "telemetry", "grid"):
            self.topology.heard(env.origin, t)
        if env.kind == "telemetry":
            self.topology.learn(env.payload.get("topology"))
        if env.kind == "track":
            self._fuse_tracks(env, t)
        if env.kind == "grid" and self.mapper is not None:
            self._fuse_grid(env, t)

    def _fuse_grid(self, env: wire.Envelope, t: float) -> None:
        try:
            method = self.mapper.receive(env.origin, env.seq, env.payload, self.topology.is_tree_edge(env.origin, t))
        except wire.DecodeError as err:
            return self._reject(env.origin, err.reason)
        self.counters.fusions[f"grid_{method}"] += 1

    def _fuse_tracks(self, env: wire.Envelope, t: float) -> None:
        try:
            remote = self._decode_tracks(env.payload)
        except wire.DecodeError as err:
            return self._reject(env.origin, err.reason)
        if any(r.belief.epoch > self.tracker.epoch + FUTURE_EPOCHS for r in remote):
            return self._reject(env.origin, "future_epoch")
        tree_edge = self.topology.is_tree_edge(env.origin, t)
        for out in self.tracker.fuse_remote(env.origin, remote, env.seq, tree_edge):
            self.counters.fusions[out.method] += 1
        self.counters.latencies.append(t - env.stamp)

    def _decode_tracks(self, payload: dict) -> list:
        tracks = payload.get("tracks")
        if not isinstance(tracks, list):
            raise wire.DecodeError("bad_field", "payload.tracks must be a list")
        out = []
        for entry in tracks:
            if not isinstance(entry, dict) or not isinstance(entry.get("id"), int) or "belief" not in entry:
                raise wire.DecodeError("bad_field", "each track needs an integer id and a belief")
            last, acks = entry.get("last_measured"), entry.get("acks", {})
            if isinstance(last, bool) or not isinstance(last, int | float) or not np.isfinite(last):
                raise wire.DecodeError("bad_field", "each track needs a finite last_measured time")
            if not isinstance(acks, dict) or not all(isinstance(v, int) and v >= 0 for v in acks.values()):
                raise wire.DecodeError("bad_field", "track acks must map peers to sequence numbers")
            belief = wire.decode_trajectory(entry["belief"], self.tracker.model)
            out.append(RemoteTrack(entry["id"], belief, float(last), acks.get(self.id)))
        return out

    def _accept_truth(self, env: wire.Envelope) -> None:
        targets = env.payload.get("targets")
        if isinstance(targets, list):
            self._truth = (env.stamp, targets)
        fire_truth = (env.payload.get("fire"), env.payload.get("decoys", []))
        if self.mapper is not None and fire_truth[0] is not None and fire_truth != self._fire_payload:
            try:  # the fire changes once per world step, the truth arrives at every agent step
                fire = decode_fire(fire_truth[0], self.terrain)
                self._fire = (fire.scene_fires(self.terrain), _decoys(fire_truth[1]))
                self._fire_payload = fire_truth
            except wire.DecodeError as err:
                self._reject("world", err.reason)
        uavs = env.payload.get("uavs")
        if isinstance(uavs, dict):  # the simulator's knowledge of where everyone is: the radio's range check
            self._uav_positions = {k: np.asarray(v, float) for k, v in uavs.items() if k != self.id}

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
        env = wire.Envelope(kind=kind, origin=self.id, seq=self._seq, stamp=t, payload=payload)
        return wire.encode(env, self.fleet_key)

    def _send(self, key: str, kind: str, data: bytes) -> None:
        self.transport.publish(key, data)
        self.counters.bytes_tx[kind] += len(data)

    def _send_to_simulator(self, key: str, kind: str, data: bytes) -> None:
        """Simulation-only data for the centralized references: not radio traffic, counted apart."""
        self.transport.publish(key, data)
        self.counters.sim_bytes_tx[kind] += len(data)

    def _publish_tracks(self, t: float) -> None:
        chosen = self.sender.choose(t, self.tracker.confirmed(), TRACK_ENTRY_BYTES)
        if not chosen:
            return
        seq = self._seq + 1  # the sequence number the envelope below will carry
        self.tracker.record_sent(chosen, seq)
        tracks = [
            {"id": tr.id, "belief": wire.encode_trajectory(tr.belief), "last_measured": tr.last_measured,
             "acks": dict(tr.acks)}
            for tr in chosen
        ]
        self._send(self.keys.belief("track", self.id), "track", self._envelope("track", t, {"tracks": tracks}))

    def _publish_telemetry(self, t: float, state, bearings: list[Bearing]) -> None:
        payload = {
            "position": state.position, "velocity": state.velocity, "yaw": float(state.yaw),
            "bearings": np.array([b.azel for b in bearings]).reshape(-1, 2),
            "video_quality": self.sensor.video_quality,  # D(t), thesis 000 §2.4 (None: no video)
            "neighbours": self.topology.neighbours(t),
            "topology": self.topology.gossip(t),
            "tracks": [{"id": tid, "mean": est.mean, "cov": est.cov} for tid, est in self.tracker.estimates()],
        }
        if self.tracker.initiator is not None:
            payload["particles"] = self.tracker.initiator.points()
        if self.mapper is not None:
            payload["alarms"] = [{"mean": a.mean, "cov": a.cov, "probability": a.probability}
                                 for a in self.mapper.alarms]
        data = self._envelope("telemetry", t, payload)
        if self.sender.admit(len(data), t):
            self._send(self.keys.telemetry(self.id), "telemetry", data)
        else:
            self.telemetry_thinned += 1

    def _publish_grid(self, t: float) -> None:
        payload, quantized = self.mapper.outgoing(self.topology.neighbours(t))
        data = self._envelope("grid", t, payload)
        if not self.sender.admit(len(data), t):
            self.grids_thinned += 1
            return
        self.mapper.sent(self._seq, payload, quantized)
        self._send(self.keys.belief("grid", self.id), "grid", data)

    def _publish_grid_evidence(self, t: float, evidence) -> None:
        """This frame's cell evidence for the centralized map (simulation only, like the raw bearings)."""
        payload = {"index": evidence.index.astype(np.int32), "llr": evidence.llr, "m": evidence.m, "n": evidence.n}
        self._send_to_simulator(self.keys.sim(f"grid_evidence/{self.id}"), "grid_evidence",
                                self._envelope("grid_evidence", t, payload))

    def _publish_measurements(self, t: float, bearings: list[Bearing]) -> None:
        """Raw bearings for the centralized oracle (simulation only; a real fleet does not send these)."""
        payload = {
            "bearings": [
                {"t": b.t, "sensor": b.sensor, "azel": b.azel, "R": b.R, "truth": b.truth_id} for b in bearings
            ]
        }
        self._send_to_simulator(self.keys.sim(f"measurement/{self.id}"), "measurement",
                                self._envelope("measurement", t, payload))

    # -- results --------------------------------------------------------------------------------
    def metrics(self) -> dict:
        lat = np.asarray(self.counters.latencies, float)
        return {
            "id": self.id,
            "steps": self.steps,
            "bytes_tx": int(sum(self.counters.bytes_tx.values())),
            "bytes_rx": int(sum(self.counters.bytes_rx.values())),
            "bytes_tx_by_kind": dict(self.counters.bytes_tx),
            "sim_bytes_tx_by_kind": dict(self.counters.sim_bytes_tx),
            "bytes_rx_by_peer": _by_peer(self.counters.bytes_rx),
            "msgs_rejected": int(sum(v for k, v in self.counters.rejected.items() if k != "duplicate")),
            "rejected_by_reason": dict(self.counters.rejected),
            "fusions": dict(self.counters.fusions),
            "radio_drops": _by_peer(self.counters.radio_drops),
            "radio_drops_by_cause": dict(Counter(cause for (_, cause) in self.counters.radio_drops.elements())),
            "tracks_thinned": self.sender.thinned,
            "telemetry_thinned": self.telemetry_thinned,
            "belief_latency_s": {
                "mean": float(lat.mean()) if lat.size else None,
                "p95": float(np.percentile(lat, 95)) if lat.size else None,
                "count": int(lat.size),
            },
            "targets": self.evaluator.summary(),
            "sensor": self.sensor.metrics(),
            "sensor_outcomes": dict(Counter(self.sensor.metrics()["outcomes"]) + self.sensor_outcomes),
            **({} if self.tracker.initiator is None else {"particle_init": self.tracker.initiator.metrics()}),
            **({} if self.mapper is None else {"grid": {**self.mapper.metrics(), "thinned": self.grids_thinned}}),
        }


def _planner(scenario: AgentScenario, index: int, seed: int, mapper):
    """``[tasking] planner``: ``"placeholder"`` (search, then orbit a target) or ``"entropy"`` (the
    information-gain explorer of Merino (4.21)-(4.24) over the agent's fire map; needs ``[grid]``)."""
    tasking = dict(scenario.tasking)
    kind = tasking.pop("planner", "placeholder")
    if kind == "entropy":
        if mapper is None:
            raise ValueError("tasking.planner = entropy needs a [grid] section (it explores the fire map)")
        config = EntropyPlannerConfig(pd=mapper.config.detection.pd, pf=mapper.config.detection.pf, **tasking)
        return EntropyPlanner(config, scenario.area.as_tuple(), scenario.altitude)
    if kind != "placeholder":
        raise ValueError(f"tasking.planner must be placeholder or entropy, got {kind!r}")
    tasking = {"search": "lawnmower", "spacing": 60.0, "orbit_radius": 40.0, **tasking}
    return PlaceholderPlanner(index, scenario.agents, scenario.area.as_tuple(), scenario.altitude, seed=seed, **tasking)


def _decoys(entries) -> list[tuple[float, float, float]]:
    """``[[north, east, probability], ...]`` from the truth: hot spots that show in a frame with that
    probability (malformed entries are ignored: advisory simulation data)."""
    parsed = [decoy(entry) for entry in (entries if isinstance(entries, list) else [])]
    return [d for d in parsed if d is not None]


def _by_peer(counter: Counter) -> dict:
    out: dict[str, dict[str, int]] = {}
    for (peer, kind), n in counter.items():
        out.setdefault(peer, {})[kind] = int(n)
    return out
