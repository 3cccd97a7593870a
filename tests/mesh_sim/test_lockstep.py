"""The lockstep harness: exactness on trees, consistency on loops and under loss, determinism, and
statistical equivalence with a live run of the same scenario.

The lockstep harness runs the same :class:`~agent.agent.Agent` as a live run over an in-memory bus, so
what is checked here holds for the agents themselves, not for a model of them. The exactness test steps
the agents itself (the loop of :func:`mesh_sim.lockstep.run_lockstep`) so that it can blind the sensors.
"""

from __future__ import annotations

import functools
import uuid
from collections import Counter, deque
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from agent.agent import Agent
from agent.net.bus import InMemoryBus
from agent.net.keys import Keys
from agent.sensors.bearing import GeometricBearingSensor
from mesh_sim.launcher import Launcher, new_run_dir
from mesh_sim.lockstep import run_lockstep
from mesh_sim.scenario import load
from mesh_sim.world import World
from tests.processes import assert_all_gone

STATE_DIM = 6


def anees_upper_bound(runs: int, level: float = 0.95) -> float:
    """Upper end of the two-sided ``level`` chi-square interval for an ANEES averaged over ``runs`` runs.

    Each run counts as ONE ``chi2(6)`` sample, not one per step: a run's NEES series is strongly
    correlated in time (the same track, the same errors carried from step to step) and across agents and
    targets (shared information), and the variance of an average of correlated samples is at most the
    variance of one sample, so ``runs`` samples is the conservative (widest) count. The sum of ``runs``
    independent ``chi2(6)`` variables is ``chi2(6 runs)`` (Bar-Shalom et al. §5.4)."""
    dof = STATE_DIM * runs
    return float(chi2.ppf(0.5 + level / 2, dof) / dof)




# ------------------------------------------------------------------------------------------------------
# 1. Exactness on a tree


class SteppedFleet:
    """``run_lockstep``'s loop one step at a time, with the agents and the world (and its oracle) exposed."""

    def __init__(self, scenario):
        self.scenario = scenario
        sc = scenario.agent
        keys = Keys(f"{scenario.name}-{uuid.uuid4().hex[:8]}")
        bus = InMemoryBus()
        self.agents = [
            Agent(f"uav{i}", i, sc, bus.endpoint(f"uav{i}", keys.agent_subscriptions()), keys, seed=sc.seed * 1000 + i)
            for i in range(sc.agents)
        ]
        self.world = World(scenario, bus.endpoint("world", World.subscriptions(keys)), keys)
        self.sensors = [agent.sensor for agent in self.agents]
        self.detections = Counter()  # agent id -> detections over the run
        self.k = 0

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            t = self.k * self.scenario.agent.step
            self.world.publish_truth(t)
            for agent in self.agents:
                agent.step(t)
                self.detections[agent.id] += len(agent.exchanges["track"].last_bearings)
            self.world.absorb_measurements()
            self.k += 1

    def blind(self) -> None:
        """The world becomes invisible: no detections, no false alarms."""
        for agent in self.agents:
            agent.sensor = GeometricBearingSensor(replace(agent.sensor.config, p_detect=0.0, false_alarms=0.0), 0)

    def see(self) -> None:
        for agent, sensor in zip(self.agents, self.sensors, strict=True):
            agent.sensor = sensor


def diameter(scenario) -> int:
    """Hop diameter of the scenario's (first-phase) radio graph."""
    names = [f"uav{i}" for i in range(scenario.agent.agents)]
    edges = scenario.raw["radio_plan"]["phases"][0]["edges"]
    if edges == "all":
        return 1
    adjacent = {n: set() for n in names}
    for a, b in edges:
        adjacent[a].add(b)
        adjacent[b].add(a)
    longest = 0
    for start in names:
        hops, queue = {start: 0}, deque([start])
        while queue:
            node = queue.popleft()
            for nxt in adjacent[node] - set(hops):
                hops[nxt] = hops[node] + 1
                queue.append(nxt)
        assert len(hops) == len(names), "the radio graph must be connected"
        longest = max(longest, *hops.values())
    return longest


WARM_STEPS = 5  # blind steps first: topology reports spread (hybrid is exact only on links known to be bridges)
SENSE_STEPS = 20


def exactness_run(policy: str, topology: str) -> SteppedFleet:
    """4 agents on a tree, ideal links, geolocated positions (linear, so fusion is exactly additive), one static
    target that two of the agents see every step and two never see (their estimates are relayed), every track
    sent every step. Sense for ``SENSE_STEPS`` steps, then go blind for diameter + 2 steps so that everything
    measured reaches everyone."""
    scenario = load(
        "default", agents=4, duration=60.0, seed=1,
        radio={"topology": topology, "preset": "ideal"},
        tracking={"policy": policy, "measurement": "position", "speed_std": 5.0},  # naive's double counting stays
        sensor={"kind": "bearing", "p_detect": 1.0, "false_alarms": 0.0, "range": 110.0},  # in one gate: one track
        sending={"period": 0.2, "max_silence": 0.2, "info_gain": 0.0},
        targets=[{"id": "parked", "kind": "static", "position": [-120.0, -60.0]}],  # between uav0 and uav1
    )
    fleet = SteppedFleet(scenario)
    fleet.blind()
    fleet.step(WARM_STEPS)
    fleet.see()
    fleet.step(SENSE_STEPS)
    fleet.blind()
    fleet.step(diameter(scenario) + 2)
    return fleet


def only_track(tracker):
    assert len(tracker.tracks) == 1, f"expected one track, got {len(tracker.tracks)}"
    track = next(iter(tracker.tracks.values()))
    assert track.confirmed
    return track


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def exactness_errors(agent_track, oracle_track) -> dict:
    est, ref = agent_track.estimate(), oracle_track.estimate()
    return {
        "Y": relative(agent_track.belief.Y, oracle_track.belief.Y),
        "y": relative(agent_track.belief.y, oracle_track.belief.y),
        "cov": relative(est.cov, ref.cov),
        "mean": float(np.linalg.norm(est.mean - ref.mean) / np.linalg.norm(ref.mean)),
    }


@pytest.mark.parametrize("topology", ["line", "tree"])
@pytest.mark.parametrize("policy", ["exact", "hybrid"])
def test_decentralized_fusion_equals_the_oracle_on_a_tree(policy, topology):
    """On a tree, with linear measurements and no loss, every agent ends up with the centralized belief: the
    whole trajectory (information vector and matrix) and its newest-state marginal, to rounding."""
    fleet = exactness_run(policy, topology)
    observers = [a for a in fleet.agents if fleet.detections[a.id] > 0]
    assert len(observers) >= 2, fleet.detections  # independent evidence is fused ...
    assert len(observers) < len(fleet.agents), fleet.detections  # ... and relayed to agents that never saw it
    oracle = only_track(fleet.world.oracle.tracker)
    for agent in fleet.agents:
        track = only_track(agent.exchanges["track"].tracker)
        assert track.belief.epoch == oracle.belief.epoch == fleet.k - 1
        errors = exactness_errors(track, oracle)
        assert max(errors.values()) < 1e-9, (agent.id, errors)
        assert set(agent.fusions.by_method) == {"exact"}, (agent.id, agent.fusions.metrics())


def test_naive_fusion_on_a_tree_is_overconfident():
    """The same run with the naive policy double-counts: its covariance is much smaller than the oracle's."""
    fleet = exactness_run("naive", "line")
    oracle = only_track(fleet.world.oracle.tracker)
    oracle_trace = np.trace(oracle.estimate().cov[:3, :3])
    for agent in fleet.agents:
        track = only_track(agent.exchanges["track"].tracker)
        assert max(exactness_errors(track, oracle).values()) > 1e-2
        assert np.trace(track.estimate().cov[:3, :3]) < 0.8 * oracle_trace, agent.id


# ------------------------------------------------------------------------------------------------------
# 2. Consistency on loops and under loss (Monte Carlo), 3. determinism

MC_RUNS = 3  # seeds per case: independent runs, each one chi2(6) sample (see anees_upper_bound)
MC_TARGETS = [
    {"id": "parked", "kind": "static", "position": [-70.0, -60.0]},
    {"id": "walker", "kind": "constant_velocity", "position": [-70.0, 60.0], "velocity": [0.8, -0.4]},
]
MC_CASES = {
    "ci-ring": ("ci", {"topology": "ring"}),
    "hybrid-random": ("hybrid", {"topology": "random", "mean_degree": 2.0}),  # loops and bridges, by seed
    "exact-tree-30%-loss": ("exact", {"topology": "tree", "loss": 0.3}),
    "naive-ring": ("naive", {"topology": "ring"}),
}


def mc_scenario(case: str, seed: int):
    """4 agents, 20 s, a static and a constant-velocity target both in view from the start. The velocity prior
    (``speed_std`` 2 m/s) is above the targets' real speeds (0 and 0.9 m/s), so even the oracle is conservative;
    tracks are sent every 0.4 s so that naive double counting accumulates fast."""
    policy, radio = MC_CASES[case]
    return load(
        "default", agents=4, duration=15.0, seed=seed, targets=MC_TARGETS,
        radio={"preset": "ideal", **radio},
        tracking={"policy": policy, "speed_std": 2.0},
        sending={"period": 0.4, "max_silence": 1.0},
    )


@functools.cache
def mc_run(case: str, seed: int, run_dir: Path) -> dict:
    run_dir.mkdir(parents=True)
    return run_lockstep(mc_scenario(case, seed), run_dir)


@pytest.fixture(scope="module")
def mc_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("mc")


def mc_results(case: str, base: Path) -> list[dict]:
    return [mc_run(case, seed, base / f"{case}-{seed}") for seed in range(1, MC_RUNS + 1)]


@pytest.mark.parametrize("case", ["ci-ring", "hybrid-random", "exact-tree-30%-loss"])
def test_consistent_policies_are_not_overconfident(case, mc_dir):
    """Fleet ANEES averaged over ``MC_RUNS`` seeds stays below the upper end of the 95 % interval.

    Only the upper end is tested: the oracle itself is conservative here (ANEES ~0.4; its damped-velocity
    prior assumes faster targets than these), so "consistent" means "not overconfident". The fleet is also
    held to the same bound relative to the oracle's ANEES: with the same models and a subset of the same
    measurements, a fleet that is not overconfident should not look more confident than the oracle does."""
    runs = mc_results(case, mc_dir)
    bound = anees_upper_bound(len(runs))
    fleet = float(np.mean([m["fleet"]["anees"] for m in runs]))
    oracle = float(np.mean([m["oracle"]["anees"] for m in runs]))
    print(f"{case}: fleet ANEES {fleet:.3f}, oracle {oracle:.3f}, bound {bound:.3f}")
    for m in runs:
        assert m["fleet"]["targets_tracked_by_every_agent"]
    assert fleet <= bound
    assert fleet / oracle <= bound
    fusions = Counter()
    for m in runs:
        for agent in m["agents"]:
            fusions.update(agent["fusions"])
    policy = MC_CASES[case][0]
    if policy == "exact":  # the loss case tests exact fusion under loss, not its fallback
        drops = sum(a["radio_drops_by_cause"].get("loss", 0) for m in runs for a in m["agents"])
        assert drops > 100
        assert fusions["exact"] > 4 * fusions["ci"], fusions
    if policy == "hybrid":  # both branches of hybrid ran
        assert fusions["exact"] > 0 and fusions["ci"] > 0, fusions


def test_naive_fusion_is_overconfident_on_a_ring(mc_dir):
    runs = mc_results("naive-ring", mc_dir)
    fleet = float(np.mean([m["fleet"]["anees"] for m in runs]))
    print(f"naive-ring: fleet ANEES {fleet:.3f}, bound {anees_upper_bound(len(runs)):.3f}")
    assert fleet > anees_upper_bound(len(runs))


WALL_CLOCK_KEYS = {"pid", "cpu_per_step_ms", "wall_s", "speed"}


def without_wall_clock(value):
    """Metrics minus what depends on the wall clock (PIDs, CPU time, speed)."""
    if isinstance(value, dict):
        return {k: without_wall_clock(v) for k, v in value.items() if k not in WALL_CLOCK_KEYS}
    if isinstance(value, list):
        return [without_wall_clock(v) for v in value]
    return value


def test_an_agent_is_handed_only_the_beliefs_its_radio_can_carry(monkeypatch, tmp_path):
    """On partition's line (uav0 - uav1 - uav2 - uav3) an agent subscribes to the beliefs of its neighbours only: a
    far peer's would be decoded only to be dropped as "down" (on a 40-agent random graph of mean degree 4, 35 of
    every 39 messages). Topology reports still come from everyone (the known graph is the fleet's)."""
    handed = Counter()  # (receiver, kind, origin) -> messages put in its inbox
    deliver = InMemoryBus.deliver

    def counting(bus, sender, key, data):
        deliver(bus, sender, key, data)
        for ep in bus._routes[key]:
            chunks = key.split("/")
            handed[(ep.name, chunks[2], chunks[-1])] += 1

    monkeypatch.setattr(InMemoryBus, "deliver", counting)
    run_lockstep(load("partition", duration=3.0), tmp_path)
    line = {"uav0": {"uav1"}, "uav1": {"uav0", "uav2"}, "uav2": {"uav1", "uav3"}, "uav3": {"uav2"}}
    for me, neighbours in line.items():
        beliefs = {origin for (to, kind, origin) in handed if to == me and kind == "belief"}
        assert beliefs == neighbours, (me, beliefs)
        assert {origin for (to, kind, origin) in handed if to == me and kind == "topology"} >= set(line) - {me}


def test_lockstep_is_deterministic(mc_dir, tmp_path):
    """The same scenario and seed (here with 30 % loss, so the loss draws are covered) give identical metrics:
    every per-agent figure (bytes per peer and kind, drops, fusions, per-target RMSE and ANEES) and the fleet's."""
    first = mc_run("exact-tree-30%-loss", 1, mc_dir / "exact-tree-30%-loss-1")
    second = run_lockstep(mc_scenario("exact-tree-30%-loss", 1), tmp_path)
    for key in ("rmse", "anees", "bytes_per_agent_per_s", "tail_rmse", "tail_anees"):
        assert first["fleet"][key] == second["fleet"][key], key
    assert without_wall_clock(first) == without_wall_clock(second)


# ------------------------------------------------------------------------------------------------------
# 4. Lockstep vs live

LIVE_DURATION = 30.0
# Tolerances. Live and lockstep runs of one seed are two different realizations: message timing differs, so the
# assignment planner's choices flip at different instants, the UAVs fly different paths and see the targets
# from different geometry. The absolute fleet RMSE therefore follows the flight paths, not the estimator: six
# live runs at 2x (default, 30 s, seed of the scenario, 2026-11-27) gave 1.11, 1.47, 1.11, 1.14, 1.11 and
# 1.22 m against lockstep's 1.10 m — and the centralized oracle's own RMSE moved with them. What the runtime
# must keep is the estimation quality on whatever geometry it flew: the fleet's RMSE over the oracle's on the
# same measurements (lockstep 1.086; live 1.036-1.064, spread 3 %) and ANEES (0.547; live 0.526-0.582, 5 %).
# ~4 sigma of that spread, plus the first seconds a late-starting live agent skips, gives these; the bytes
# (12.9-13.6 k across seeds, 2 %) keep their earlier bound.
RMSE_RATIO_TOLERANCE = 0.15
ANEES_TOLERANCE = 0.40
BYTES_TOLERANCE = 0.25


@pytest.fixture(scope="module")
def live_and_lockstep(tmp_path_factory):
    scenario = load("default", duration=LIVE_DURATION)
    lock = run_lockstep(scenario, new_run_dir(tmp_path_factory.mktemp("lockstep"), scenario.name))
    outcome = Launcher(scenario, new_run_dir(tmp_path_factory.mktemp("live"), scenario.name), speed=2.0,
                       rerun="off").run()
    return scenario, lock, outcome


def bytes_per_second_run(agent: dict, step: float) -> float:
    """Bytes sent per second of simulation the agent actually stepped through: a live agent whose process starts
    late skips its first steps (``skipped_steps``) and sends nothing for them, which the fleet figure
    (bytes over the whole duration) would count as a lower rate."""
    return agent["bytes_tx"] / (agent["steps"] * step)


@pytest.mark.slow
def test_lockstep_and_live_runs_agree(live_and_lockstep):
    scenario, lock, outcome = live_and_lockstep
    live = outcome.metrics
    assert outcome.status == "completed", outcome.status
    for m in (lock, live):
        assert m["fleet"]["targets_tracked_by_every_agent"]
        for agent in m["agents"]:
            assert all(t["rmse"] is not None for t in agent["targets"]), agent["id"]
    step = scenario.agent.step
    figures = {
        "rmse / oracle": (lock["fleet"]["rmse_ratio_to_oracle"], live["fleet"]["rmse_ratio_to_oracle"],
                          RMSE_RATIO_TOLERANCE),
        "anees": (lock["fleet"]["anees"], live["fleet"]["anees"], ANEES_TOLERANCE),
        "bytes/agent/s": (
            np.mean([bytes_per_second_run(a, step) for a in lock["agents"]]),
            np.mean([bytes_per_second_run(a, step) for a in live["agents"]]),
            BYTES_TOLERANCE,
        ),
    }
    print({k: (round(float(a), 3), round(float(b), 3)) for k, (a, b, _) in figures.items()},
          "fleet bytes/agent/s:", (lock["fleet"]["bytes_per_agent_per_s"], live["fleet"]["bytes_per_agent_per_s"]),
          "skipped steps (live):", [a.get("skipped_steps") for a in live["agents"]])
    for name, (lockstep_value, live_value, tolerance) in figures.items():
        assert abs(live_value - lockstep_value) <= tolerance * lockstep_value, (name, lockstep_value, live_value)


@pytest.mark.slow
def test_live_comparison_run_leaves_no_process(live_and_lockstep):
    assert_all_gone(live_and_lockstep[2].pids.values())
