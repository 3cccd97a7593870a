"""A run's phases (:mod:`mesh_sim.phases`): the evaluator's time bins pool back to its whole-run figures, a
hand-built two-phase run gives its per-phase figures and chi-square verdicts, re-convergence is found (or not)
on synthetic ratios, and a lockstep partition run reports its three phases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from agent.evaluation import BIN_S, TrackEvaluator
from fusion.gaussian import Gaussian
from mesh_sim import phases
from mesh_sim.lockstep import run_lockstep
from mesh_sim.results import pooled
from mesh_sim.scenario import load


def _scored_run(seed: int) -> list[dict]:
    """A real evaluator fed 0.2 s evaluations of two targets for 7.3 s with noisy estimates (none outside the
    match gate)."""
    rng = np.random.default_rng(seed)
    evaluator = TrackEvaluator()
    cov = np.diag([4.0, 4.0, 9.0, 1.0, 1.0, 1.0])
    for k in range(37):
        t = 0.1 + 0.2 * k
        truth = [{"id": name, "position": np.array([10.0 * i, t, 0.0]), "velocity": np.array([0.0, 1.0, 0.0])}
                 for i, name in enumerate(("car", "walker"))]
        noise = [rng.multivariate_normal(np.zeros(6), cov * rng.uniform(0.1, 0.5)) for _ in truth]
        estimates = [(i, Gaussian.from_moments(np.concatenate([x["position"], x["velocity"]]) + e, cov))
                     for i, (x, e) in enumerate(zip(truth, noise, strict=True))]
        evaluator.record(t, truth, estimates)
    return evaluator.summary()


def test_the_bins_sum_to_the_whole_run_figures():
    targets = _scored_run(1)
    for t in targets:
        starts = [b[0] for b in t["bins"]]
        assert starts == [k * BIN_S for k in range(8)]  # 0.1 ... 7.3 s: bins 0 ... 7
        sums = np.sum([b[1:] for b in t["bins"]], axis=0)
        assert sums[2] == t["samples"] == 37
        assert np.sqrt(sums[0] / sums[2]) == pytest.approx(t["rmse"], rel=1e-12)
        assert sums[1] / (6 * sums[2]) == pytest.approx(t["anees"], rel=1e-12)
    other = _scored_run(2)
    whole = phases.phase_figures([targets, other], targets, 0.0, 100.0)
    rmse, anees = pooled(targets + other)
    assert (whole["fleet_rmse"], whole["anees"]) == pytest.approx((rmse, anees), rel=1e-12)
    assert whole["oracle_rmse"] == pytest.approx(pooled(targets)[0], rel=1e-12) and whole["samples"] == 4 * 37
    split = [phases.phase_figures([targets, other], targets, a, b)["samples"] for a, b in ((0, 3), (3, 100))]
    assert split == [4 * 15, 4 * 22]  # 0.1 ... 2.9 s in the first; a bin is in the phase its start is in


def _target(name: str, bins: list[list[float]]) -> dict:
    return {"target": name, "bins": bins}


def test_a_two_phase_run_gives_each_phase_its_own_figures_and_verdict():
    """Phase 1 (0-10 s): the fleet's squared error 4 m^2 per sample, NEES 6 (ANEES 1); phase 2 (10-20 s): 16 m^2,
    NEES 0.6 (ANEES 0.1). The oracle: 1 m^2 throughout. One target tracked 10 s per phase: one independent
    sample (DECORRELATION_S), whatever the 100 evaluations."""
    def agent(se2, nees2):
        return [_target("car", [[float(k), 4.0 * 5, 6.0 * 5, 5] for k in range(10)]
                        + [[float(k), se2 * 5, nees2 * 5, 5] for k in range(10, 20)])]

    oracle = [_target("car", [[float(k), 1.0 * 5, 6.0 * 5, 5] for k in range(20)])]
    in_flight = [_target("car", [[float(k), 4.0 * 5, 3.0 * 5, 5] for k in range(20)])]  # 4 m^2: what could arrive
    raw = {"radio": {"events": [{"t": 10.0, "kind": "partition", "groups": [["uav0"], ["uav1"]]}]},
           "radio_plan": {"phases": [{"t": 0.0, "edges": "all"}, {"t": 10.0, "edges": []}]}}
    metrics = {"agents": [{"id": "uav0", "targets": agent(16.0, 0.6)}, {"id": "uav1", "targets": agent(16.0, 0.6)},
                          {"id": "uav2", "status": "died: no metrics written"}],
               "oracle": {"targets": oracle, "in_flight": {"uav0": in_flight, "uav1": in_flight}},
               "config": raw, "losses": []}
    first, second = phases.run_phases(metrics, 20.0)
    assert (first["name"], first["start_s"], first["end_s"]) == ("start", 0.0, 10.0)
    assert (second["name"], second["start_s"], second["end_s"]) == ("partition", 10.0, 20.0)
    assert first["samples"] == second["samples"] == 100
    assert (first["fleet_rmse"], first["oracle_rmse"], first["rmse_ratio_to_oracle"]) == pytest.approx((2, 1, 2))
    assert (second["fleet_rmse"], second["rmse_ratio_to_oracle"], second["anees"]) == pytest.approx((4, 4, 0.1))
    assert first["independent_samples"] == second["independent_samples"] == 1
    lo, hi = chi2.ppf([0.025, 0.975], 6) / 6
    assert first["anees_interval"] == pytest.approx([lo, hi]) and lo < 1 < hi and lo > 0.1
    assert first["anees_inside"] and not second["anees_inside"]
    assert (first["rmse_ratio_to_in_flight"], second["rmse_ratio_to_in_flight"]) == pytest.approx((1, 2))
    assert first["oracle_anees"] == second["oracle_anees"] == pytest.approx(1.0)
    assert "reconverged_after_s" not in first and "reconverged_after_s" not in second


def test_independent_samples_count_one_per_target_per_decorrelation_time():
    """Per target its longest tracked time over the agents (1 s bins with samples), one sample per 10 s of it, at
    least one; a target nobody tracked in the window counts for nothing."""
    a = [_target("car", [[float(k), 1.0, 1.0, 5] for k in range(25)]), _target("walker", [[3.0, 1.0, 1.0, 5]])]
    b = [_target("car", [[float(k), 1.0, 1.0, 5] for k in range(12)]), _target("dog", [[40.0, 1.0, 1.0, 5]])]
    assert phases.independent_samples([a, b], 0.0, 30.0) == 2 + 1  # car 25 s -> 2, walker 1 s -> 1, dog outside
    assert phases.independent_samples([a, b], 0.0, 100.0) == 2 + 1 + 1
    assert phases.independent_samples([b], 0.0, 9.0) == 1  # 9 s of the car: still one
    assert phases.independent_samples([], 0.0, 9.0) == 0


def test_phases_start_at_radio_events_losses_and_rejoins():
    raw = {"radio": {"events": [{"t": 15.0, "kind": "partition"}, {"t": 30.0, "kind": "merge"},
                                {"t": 50.0, "kind": "link_up"}]},
           "radio_plan": {"phases": [{"t": 0.0}, {"t": 15.0}, {"t": 30.0}, {"t": 50.0}]}}
    losses = [{"agent": "uav2", "t": 20.0, "restarted_as": 1,
               "rejoined_after": {"uav0": 2.5, "uav1": 4.0, "uav3": None}},
              {"agent": "uav3", "t": 40.0, "detected_after": {"uav0": 3.0}}]
    got = [(p["name"], p["start_s"], p["end_s"], p["heals"]) for p in phases.boundaries(raw, losses, 45.0)]
    assert got == [("start", 0.0, 15.0, False), ("partition", 15.0, 20.0, False), ("uav2 lost", 20.0, 24.0, False),
                   ("uav2 rejoined", 24.0, 30.0, True), ("merge", 30.0, 40.0, True), ("uav3 lost", 40.0, 45.0, False)]


def test_settled_after_finds_the_start_of_the_last_run_within_the_limit():
    series = [(1.0, 3.0), (2.0, 1.1), (3.0, 1.4), (4.0, None), (5.0, 1.2), (6.0, 1.0), (7.0, 1.25)]
    assert phases.settled_after(series, 1.25) == 5.0
    assert phases.settled_after(series + [(8.0, 1.3)], 1.25) is None
    assert phases.settled_after([], 1.25) is None


def test_reconvergence_after_a_merge_uses_the_window_after_the_event():
    """After a merge at 10 s the fleet's error is 3x the oracle's for 3 s (bins 10-12), then equal. The windows
    ``[max(10, tau - 5), tau)`` give sqrt(29 / 5) = 2.41 at tau = 15, sqrt(13 / 5) = 1.61 at 17 and 1 from 18 on,
    when the last bad bin has left: re-converged 8 s after the merge."""
    fleet = [_target("car", [[float(k), 9.0 if 10 <= k < 13 else 1.0, 6.0, 1] for k in range(25)])]
    oracle = [_target("car", [[float(k), 1.0, 6.0, 1] for k in range(25)])]
    after = phases.reconvergence([fleet], [oracle], 10.0, 25.0)
    assert after == 8.0
    assert phases.reconvergence([fleet], [[_target("car", [[float(k), 0.5, 6.0, 1] for k in range(25)])]],
                                10.0, 25.0) is None  # sqrt(1 / 0.5) = 1.41 for good


def test_reconvergence_to_the_in_flight_oracles_pools_them_like_the_fleet():
    """Two agents whose errors (squared 4 and 1 per bin) equal their own in-flight oracles' from the merge on:
    re-converged to them at the first bin (pooled 2.5 ÷ 2.5), though the fleet stays sqrt(2.5 / 1) = 1.58x the
    oracle (squared error 1) for good."""
    bins = lambda err: [_target("car", [[float(k), err, 6.0, 1] for k in range(25)])]  # noqa: E731
    agents, in_flight = [bins(4.0), bins(1.0)], [bins(4.0), bins(1.0)]
    assert phases.reconvergence(agents, in_flight, 10.0, 25.0) == 1.0
    assert phases.reconvergence(agents, [bins(1.0)], 10.0, 25.0) is None
    assert phases.worst_ratio(agents, [bins(1.0)], 10.0, 15.0) == pytest.approx(np.sqrt(2.5))


@pytest.mark.slow
def test_a_lockstep_partition_run_reports_three_phases(tmp_path):
    metrics = run_lockstep(load("partition"), tmp_path)  # the whole merge phase: its first seconds are the catch-up
    got = [(p["name"], p["start_s"], p["end_s"]) for p in metrics["phases"]]
    assert got == [("start", 0.0, 15.0), ("partition", 15.0, 30.0), ("merge", 30.0, 45.0)]
    assert all(p["samples"] > 0 and p["fleet_rmse"] > 0 and p["oracle_rmse"] > 0 for p in metrics["phases"])
    assert {"reconverged_after_s", "reconverged_to_in_flight_after_s"} <= metrics["phases"][2].keys()
    # hybrid on a tree is exact up to what is still in flight, in every phase (with the old entropy trigger the
    # tracks waited max_silence in steady state: 1.3-1.5x in every phase)
    assert all(p["rmse_ratio_to_in_flight"] < 1.15 for p in metrics["phases"]), metrics["phases"]
    # and its channels never fall back: at the merge a message waits for the healed link's place in the graph
    # (agent/beliefs/tracks.py EDGE_WAIT_S) instead of being intersected (97 % exact before)
    assert all(a["exact_share"] == 1.0 for a in metrics["agents"]), [a["fusions_by_cause"] for a in metrics["agents"]]
    assert sum(p["samples"] for p in metrics["phases"]) == sum(t["samples"] for a in metrics["agents"]
                                                               for t in a["targets"])
