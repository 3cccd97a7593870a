"""Valid seed messages for ``skymesh bench fuzz``, and the agent that receives the fuzzed inputs.

A seed is a real message, not a hand-made one: a short lockstep run (the world and two agents over an
in-memory bus, as :mod:`mesh_sim.lockstep` runs them) is tapped, and for every message kind the richest
message ``uav1`` (or the world) published is kept. The receiving agent is that run's ``uav0``, with every
belief it built from the run, so a fuzzed input meets a receive path in a realistic state (tracks held,
grid baselines known, bids exchanged).

Which scenario yields which kind (:data:`CASES`): the default scenario (flooded detections, the fleet's
assignment, topology, truth, telemetry, measurements), the same with channel-filter tracks
(``policy = "hybrid"``), the fire scenario (grids and their evidence) and the ambiguous scenario
(particle candidates). Nothing publishes ``clock`` in a simulated run (:mod:`agent.net.schemas`): its seed
is the clock report a MAVLink vehicle puts in its telemetry.
"""

from __future__ import annotations

import copy
import uuid
from dataclasses import dataclass

from agent.agent import Agent
from agent.config import member_name
from agent.net import wire
from agent.net.bus import InMemoryBus
from agent.net.keys import Keys
from mesh_sim import scenario as scenarios
from mesh_sim.world import World

SENDER = "uav1"  # whose messages seed the inputs
RECEIVER = "uav0"  # the agent under test
MIN_STEPS = 25  # lockstep steps of a capture run at least (chosen here: tracks, grids and bids exist by then) ...
MAX_STEPS = 200  # ... and at most, until every kind asked for was published (particle candidates take longest)
#: The receiver's fleet in the fuzzed cases (uav0 .. uav255, the wire's MAX_PEERS): the capture run flies two agents,
#: but the fuzzer's sender takes the name of another member each time it spent one's sequence numbers.
FLEET = 256
CLOCK_PAYLOAD = {"source": "mavlink", "offset": 0.0021, "round_trip": 0.0134}


@dataclass(frozen=True)
class CaseSpec:
    """One fuzzed kind: the scenario that produces it, its overrides, and the wire kind of its seed."""

    name: str  # as reported (``track`` and ``track-flood`` are both wire kind ``track``)
    kind: str
    scenario: str
    overrides: tuple[tuple[str, object], ...] = ()


BEARING = (("sensor", {"kind": "bearing"}),)  # geometric bearings: the camera's rendering is not under test
FLOOD = ("default", BEARING)  # the default scenario: flooded detections, the fleet's assignment
HYBRID = ("default", (*BEARING, ("tracking", {"policy": "hybrid"})))  # channel-filter tracks
CASES = [
    CaseSpec("track", "track", *HYBRID),
    CaseSpec("track-flood", "track", *FLOOD),
    CaseSpec("topology", "topology", *FLOOD),
    CaseSpec("tasks", "tasks", *FLOOD),
    CaseSpec("truth", "truth", *FLOOD),
    CaseSpec("telemetry", "telemetry", *FLOOD),
    CaseSpec("measurement", "measurement", *FLOOD),
    CaseSpec("clock", "clock", *FLOOD),
    CaseSpec("grid", "grid", "fire"),
    CaseSpec("grid_evidence", "grid_evidence", "fire"),
    CaseSpec("particles", "particles", "ambiguous", BEARING),
]


@dataclass
class Case:
    """A seed and its receiver: ``seed`` is a valid envelope from ``seed.origin`` that ``agent`` would use;
    ``now`` is the agent's time; ``next_seq`` the first sequence number the agent has not seen from it."""

    spec: CaseSpec
    seed: wire.Envelope
    agent: Agent
    keys: Keys
    fleet_key: bytes | None
    now: float
    next_seq: int

    def senders(self):
        """The names the fuzzer's sender takes in turn: the seed's origin, then the other members of the fleet."""
        yield self.seed.origin
        yield from sorted(self.agent.fleet - {self.seed.origin, self.agent.id}, key=lambda name: int(name[3:]))

    def key_for(self, origin: str) -> str:
        """Where a message of this kind from ``origin`` reaches an agent (peers may publish any kind as a belief)."""
        if self.spec.kind == "truth":
            return self.keys.sim("truth")
        if self.spec.kind == "topology":
            return self.keys.topology(origin)
        return self.keys.belief(self.spec.kind, origin)


@dataclass
class Capture:
    """What a capture run left: its receiving agent, the richest message of each kind, the time and the first
    sequence number not yet used by any sender."""

    agent: Agent
    keys: Keys
    seeds: dict[str, wire.Envelope]
    now: float
    next_seq: int


def capture(scenario: str, overrides: tuple, kinds: set[str]) -> Capture:
    """Run ``scenario`` with two agents, tapping every message, until each of ``kinds`` was published (at least
    :data:`MIN_STEPS` steps, at most :data:`MAX_STEPS`)."""
    sc = scenarios.load(scenario, agents=2, **dict(overrides))
    keys = Keys(f"fuzz-{uuid.uuid4().hex[:8]}")
    bus = InMemoryBus()
    agents = [Agent(f"uav{i}", i, sc.agent, bus.endpoint(f"uav{i}", keys.agent_subscriptions()), keys,
                    seed=sc.agent.seed * 1000 + i, lockstep=True) for i in range(2)]
    world = World(sc, bus.endpoint("world", World.subscriptions(keys)), keys)
    tap = bus.endpoint("tap", [f"{keys.root}/**"])
    best: dict[str, tuple[int, wire.Envelope]] = {}
    last_seq, t = 0, 0.0
    for k in range(MAX_STEPS):
        if k >= MIN_STEPS and kinds - {"clock"} <= set(best):
            break
        t = k * sc.agent.step
        world.publish_truth(t)
        for agent in agents:
            agent.step(t)
        world.absorb_measurements()
        for item in tap.drain():
            env = wire.decode(item.data, kinds=agents[0].kinds)
            if env.origin in (SENDER, "world") and len(item.data) >= best.get(env.kind, (-1,))[0] \
                    and env.kind in kinds:
                best[env.kind] = (len(item.data), env)
            last_seq = max(last_seq, env.seq)
    agents[1].close()
    seeds = {kind: env for kind, (_, env) in best.items()}
    seeds["clock"] = wire.Envelope(kind="clock", origin=SENDER, seq=last_seq, stamp=t, payload=dict(CLOCK_PAYLOAD))
    return Capture(agents[0], keys, seeds, t, last_seq + 1)


def cases(specs: list[CaseSpec], fleet_keys: tuple[bytes | None, ...]) -> list[Case]:
    """A case per fleet key and spec, one capture run per scenario; every case receives with its own copy of the
    agent (given a fleet key: it then checks every message's MAC; the inputs are signed with it)."""
    captures: dict = {}
    out = []
    for spec in specs:
        where = (spec.scenario, repr(spec.overrides))
        if where not in captures:
            kinds = {s.kind for s in specs if (s.scenario, s.overrides) == (spec.scenario, spec.overrides)}
            captures[where] = capture(spec.scenario, spec.overrides, kinds)
        cap = captures[where]
        if spec.kind not in cap.seeds:
            raise RuntimeError(f"the {spec.scenario} scenario published no {spec.kind} in {MAX_STEPS} steps")
        for fleet_key in fleet_keys:
            # not the radio nor the bus (hash state, no copy): inputs go to receive() directly
            agent = copy.deepcopy(cap.agent, {id(cap.agent.radio): None, id(cap.agent.transport): None})
            agent.fleet_key = fleet_key
            agent.fleet = frozenset(member_name(i) for i in range(FLEET))
            out.append(Case(spec, cap.seeds[spec.kind], agent, cap.keys, fleet_key, cap.now, cap.next_seq))
    return out
