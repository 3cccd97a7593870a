"""One UAV: the loop of DESIGN.md §4, stepped by simulation time — a host for plug-ins.

``Agent.step(t)`` reads the vehicle; every sensor measures (:class:`agent.plugins.Sensor`; simulated ones see the
step's truth first); every belief exchange absorbs the observations it uses (:class:`agent.plugins.BeliefExchange`);
received messages are decoded, validated and dispatched to the exchange of their kind; telemetry goes out to the
ground station and topology reports to the peers (when due); every exchange offers its message, sealed and charged to
the link budget here; the planner turns the exchanges' views into a goal for the vehicle and the sensors
(``look_at``). The loop names no implementation: sensors, exchanges, planners and vehicles come from their registries.

It knows nothing of clocks or processes: the live harness (``agent.runtime``) calls it on the wall clock over Zenoh,
the lockstep harness over an in-memory bus (with a radio plan wrapped in :class:`agent.net.radio.RadioTransport`).

Every received message is decoded and validated (``agent.net.wire``) before it touches a belief, from fleet members
only (``unknown_origin`` first: per-peer state is bounded by the fleet); a rejected message is counted by reason and
logged once per (peer, reason). Duplicates, replays and stale stamps are dropped by ``(origin, kind, seq)`` and time;
a peer's new incarnation (:mod:`agent.net.incarnation`) resets what the exchanges assumed they shared with it.
"""

from __future__ import annotations

import logging
from collections import Counter

from agent.beliefs import EXCHANGES, ExchangeContext
from agent.config import AgentScenario
from agent.fusion_log import FusionLog
from agent.net import wire
from agent.net.incarnation import ReceiveWindow, first_number
from agent.net.keys import Incoming, Keys
from agent.net.link_emulator import LinkEmulator
from agent.net.radio import RadioTransport
from agent.net.sending import SendScheduler
from agent.net.topology import Topology
from agent.plugins import Views, merge_observations
from agent.sensors.registry import sensor_from_config
from agent.sensors.truth import WorldTruth
from agent.traffic import TrafficLog
from agent.vehicles import vehicle_from_config
from agent.vehicles.base import goal_to_setpoint
from perception.terrain import terrain_from_config
from tasking.registry import PlanningContext, planner_from_config

log = logging.getLogger("skymesh.agent")

class Agent:
    """One agent of a fleet over ``transport`` (:class:`agent.plugins.Transport`). ``camera``: an open external video
    source replacing the synthetic camera. ``lockstep``: no wall-clock deadline (the planner may await its solves)."""

    def __init__(self, agent_id: str, index: int, scenario: AgentScenario, transport, keys: Keys,
                 seed: int, fleet_key: bytes | None = None, camera=None, lockstep: bool = False, incarnation: int = 0):
        self.id, self.index, self.scenario, self.keys, self.fleet_key = agent_id, index, scenario, keys, fleet_key
        self.fleet = scenario.fleet_of(agent_id)
        self.terrain = terrain_from_config(scenario.terrain)
        self.vehicle = vehicle_from_config(scenario.vehicle, scenario.start_position(index), 0.0, scenario.origin)
        self.sensor = sensor_from_config(scenario.sensor, seed, self.terrain, camera)
        self.world = WorldTruth(self.terrain, agent_id)
        self.unused: Counter = Counter()  # reason -> observations the agent could not use
        plan = scenario.radio_plan
        self.sender = SendScheduler(scenario.sending, scenario.sending.budget(plan and plan.sender_budget(agent_id)))
        self.topology = Topology(agent_id)
        self.fusions = FusionLog(silence_s=2 * scenario.sending.max_silence)
        self.exchanges: dict = {}
        self.views = Views(self.exchanges)  # filled below; exchanges and planner read each other's views through it
        context = ExchangeContext(agent_id, scenario, self.terrain, seed, self.sender, self, self.unused,
                                  self.topology, self.views, self.vehicle, incarnation, fusions=self.fusions)
        built = {kind: build(context) for kind, build in EXCHANGES.items()}
        self.exchanges.update((kind, exchange) for kind, exchange in built.items() if exchange is not None)
        self.extra_sensors = [s for exchange in self.exchanges.values() for s in exchange.sensors()]
        hints = {k: v for exchange in self.exchanges.values() for k, v in exchange.planning_hints().items()}
        top_speed = getattr(self.vehicle, "max_speed", getattr(self.vehicle, "airspeed", None))
        self.planner = planner_from_config(scenario.tasking, PlanningContext(
            index, scenario.agents, scenario.area.as_tuple(), scenario.altitude, seed, frozenset(self.exchanges),
            hints, scenario.step, top_speed, scenario.vehicle, lockstep))
        self.kinds = wire.KINDS | frozenset(EXCHANGES)  # the wire's kinds and every registered belief kind
        self._now = 0.0
        self.radio = None if plan is None else RadioTransport(
            transport, LinkEmulator(agent_id, plan), lambda: self._now,
            lambda: {**self.world.uav_positions, self.id: self.vehicle.state().position})
        self.transport = transport if self.radio is None else self.radio
        self.traffic = TrafficLog()  # bytes sent by kind and over time
        self.sim_bytes_tx: Counter = Counter()  # kind -> bytes of simulation-only data (for the oracles)
        self.bytes_rx: Counter = Counter()  # (peer, kind) -> bytes
        self.rejected: Counter = Counter()  # reason -> messages
        self.telemetry_thinned = self.steps = 0
        self._seq = first_number(incarnation)  # agent.net.incarnation: a restarted agent's numbers are all newer
        self.window = ReceiveWindow()
        self._logged: set[tuple[str, str]] = set()

    @property
    def sensors(self) -> list:
        """The ``[sensor]`` section's sensor, then the ones the beliefs bring (e.g. a thermal camera)."""
        return [self.sensor, *self.extra_sensors]

    # -- the loop -------------------------------------------------------------------------------
    def step(self, t: float) -> None:
        self._now = t
        state = self.vehicle.state()
        truth = self.world.at(t)
        observations: dict = {}
        for sensor in self.sensors if state.fresh else ():  # a stale pose (autopilot lost) georeferences nothing
            sensor.on_truth(truth)
            merge_observations(observations, sensor.measure(t, state))
        for exchange in self.exchanges.values():
            exchange.absorb(t, observations)
        for item in self.transport.drain():
            self.receive(item, t)
        for exchange in self.exchanges.values():
            exchange.settle(t)
        self._publish_telemetry(t, state)
        self._publish_topology(t)
        neighbours = self.topology.neighbours(t)
        for exchange in self.exchanges.values():
            self._offer(exchange, t, neighbours)
        goal = self.planner.plan(state, self.views)
        self.vehicle.set_setpoint(goal_to_setpoint(goal))
        for part in (*self.sensors, self.vehicle):
            part.point(goal.look_at)  # the gimbal command, for the next step's measurements (a real one's too)
        self.vehicle.step(self.scenario.step)
        for exchange in self.exchanges.values():
            exchange.evaluate(t, truth)
        self.steps += 1

    def close(self) -> None:
        """Release the sensors (an external camera), the vehicle (a MAVLink link) and the planner (its threads)."""
        for part in (*self.sensors, self.vehicle, self.planner):  # a planner's close() is optional
            getattr(part, "close", lambda: None)()

    # -- receiving ------------------------------------------------------------------------------
    def receive(self, item: Incoming, t: float) -> None:
        """Validate one incoming sample and apply it. Never raises on bad input."""
        try:
            parts = self.keys.parse(item.key)
        except ValueError:
            return self._reject("?", "bad_key")
        origin = parts[-1]
        if origin == self.id:
            return
        if parts[:2] == ("sim", "truth"):
            origin = None  # the world publishes truth under its own name, not under the key
        elif origin not in self.fleet:  # before any per-peer state: a made-up name costs the agent nothing
            return self._reject("?", "unknown_origin")
        try:
            wire.check_encoding(item.encoding)
            env = wire.decode(item.data, expected_origin=origin, key=self.fleet_key, kinds=self.kinds, fleet=self.fleet)
        except wire.DecodeError as err:
            return self._reject(origin or "world", err.reason)
        verdict = self.window.admit(env.origin, env.kind, env.seq, t, env.stamp)
        if verdict in ("duplicate", "stale"):  # a replay (agent.net.incarnation), or a copy the mesh delivered twice
            return self._reject(env.origin, verdict, log_it=False)
        for exchange in self.exchanges.values() if verdict == "restarted" else ():  # it holds nothing of ours now
            getattr(exchange, "peer_restarted", lambda peer: None)(env.origin)
        try:
            self._use(env, len(item.data), t)
        except wire.DecodeError as err:
            return self._reject(env.origin, err.reason)
        self.window.used(env.origin, env.kind, env.seq)

    def _use(self, env: wire.Envelope, size: int, t: float) -> None:
        """Apply a decoded message: truth to the intake, beliefs to the exchange of their kind."""
        if env.kind == "truth":
            return self.world.accept(env)
        self.bytes_rx[(env.origin, env.kind)] += size
        if env.kind == "topology" or env.kind in EXCHANGES:
            self.topology.heard(env.origin, t)
        if env.kind == "topology":
            self.topology.receive(env.origin, env.payload["reports"], t)
        exchange = self.exchanges.get(env.kind)
        if exchange is not None:
            edge = self.topology.edge(env.origin, t) if exchange.needs_edge else None
            self.fusions.record(env.origin, t, exchange.receive(env.origin, env.seq, env.stamp, env.payload, edge, t))

    def _reject(self, peer: str, reason: str, log_it: bool = True) -> None:
        self.rejected[reason] += 1
        if log_it and (peer, reason) not in self._logged:
            self._logged.add((peer, reason))
            log.warning("%s: rejected a message from %s (%s); further ones are only counted", self.id, peer, reason)

    # -- sending --------------------------------------------------------------------------------
    def _seal(self, kind: str, t: float, payload: dict) -> tuple[int, bytes]:
        self._seq += 1
        env = wire.Envelope(kind=kind, origin=self.id, seq=self._seq, stamp=t, payload=payload)
        return self._seq, wire.encode(env, self.fleet_key, kinds=self.kinds)

    def _send(self, key: str, kind: str, data: bytes) -> None:
        self.transport.publish(key, data)
        self.traffic.sent(self._now, kind, len(data))

    def to_simulator(self, kind: str, t: float, payload: dict) -> None:
        """Simulation-only data for the centralized references (:class:`agent.plugins.Outbox`): not radio traffic."""
        _, data = self._seal(kind, t, payload)
        self.transport.publish(self.keys.sim(f"{kind}/{self.id}"), data)
        self.sim_bytes_tx[kind] += len(data)

    def _offer(self, exchange, t: float, neighbours: list[str]) -> None:
        message = exchange.outgoing(t, neighbours)
        if message is None:
            return
        seq, data = self._seal(exchange.kind, t, message.payload)
        if not message.prepaid and not self.sender.admit(len(data), t):
            return exchange.thinned(message)
        exchange.sent(seq, message)
        self._send(self.keys.belief(exchange.kind, self.id), exchange.kind, data)
        self.topology.spoke(t)  # the peers heard us: no beacon needed yet

    def _publish_topology(self, t: float) -> None:
        """Who this agent hears, to its peers on a change, a beacon or a refresh (:mod:`agent.net.topology`)."""
        if (payload := self.topology.outgoing(t)) is not None:
            self._publish("topology", self.keys.topology(self.id), t, payload)

    def _publish_telemetry(self, t: float, state) -> None:
        """For the ground station (``telemetry/<agent>``): the agents do not subscribe to it."""
        payload = {"position": state.position, "velocity": state.velocity, "yaw": float(state.yaw),
                   "neighbours": self.topology.neighbours(t)}
        for part in (*self.sensors, *self.exchanges.values()):
            payload.update(part.telemetry())
        if not self._publish("telemetry", self.keys.telemetry(self.id), t, payload):
            self.telemetry_thinned += 1

    def _publish(self, kind: str, key: str, t: float, payload: dict) -> bool:
        """Seal and send a message charged to the link budget; ``False`` if the budget refused it."""
        _, data = self._seal(kind, t, payload)
        if not self.sender.admit(len(data), t):
            return False
        self._send(key, kind, data)
        return True

    # -- results --------------------------------------------------------------------------------
    def metrics(self) -> dict:
        sensor, drops = self.sensor.metrics(), Counter() if self.radio is None else self.radio.drops
        out = {
            "id": self.id, "steps": self.steps,
            "bytes_rx": int(sum(self.bytes_rx.values())), "sim_bytes_tx_by_kind": dict(self.sim_bytes_tx),
            "bytes_rx_by_peer": _by_peer(self.bytes_rx),
            "msgs_rejected": int(sum(v for k, v in self.rejected.items() if k != "duplicate")),
            "rejected_by_reason": dict(self.rejected), **self.fusions.metrics(),
            "radio_drops": _by_peer(drops),
            "radio_drops_by_cause": dict(Counter(cause for (_, cause) in drops.elements())),
            "telemetry_thinned": self.telemetry_thinned,
            "sensor": sensor, "sensor_outcomes": dict(Counter(sensor["outcomes"]) + self.unused),
        }
        for part in (*self.exchanges.values(), self.planner, self.vehicle, self.topology, self.window, self.traffic):
            out.update(getattr(part, "metrics", dict)())  # metrics() is optional for a plug-in
        return out


def _by_peer(counter: Counter) -> dict:
    out: dict[str, dict[str, int]] = {}
    for (peer, kind), n in counter.items():
        out.setdefault(peer, {})[kind] = int(n)
    return out
