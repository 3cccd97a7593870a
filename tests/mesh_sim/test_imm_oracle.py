"""The oracle's IMM (``Tracker`` with ``[tracking] motion = "imm"``, associated by label): exact reprocessing of
late bearings, deletion, bad input, and — slow — the oracle's consistency on the shipped camera scenario (per
target, ANEES inside its 95 % chi-square interval, with independent samples counted as ``skymesh bench rumor``
counts them, rumor_stats)."""

import tempfile
from pathlib import Path

import numpy as np
import pytest

from agent.beliefs.tracking import Tracker
from agent.beliefs.tracking_config import ImmConfig, TrackerConfig
from agent.sensors.bearing import Bearing
from fusion.measurement import los_to_azel
from mesh_sim.bench.rumor_stats import anees_interval, independent_samples
from perception.terrain import FlatTerrain

STEP = 0.2
R = np.diag([1e-4, 1e-4])
TARGET = np.array([10.0, 5.0, 0.0])
SENSORS = [np.array([0.0, 0.0, -80.0]), np.array([30.0, -20.0, -80.0])]
IMM = TrackerConfig(motion="imm", policy="flood")


def _bearings(t: float, truth_id="parked", sensors=SENSORS) -> list[Bearing]:
    return [Bearing(t, s, los_to_azel(TARGET - s), R, truth_id) for s in sensors]


def _run(order: str) -> np.ndarray:
    """Bearings of epochs 0..9, delivered in time order or with epochs 3 and 5 arriving at epoch 7."""
    tracker = Tracker(IMM, STEP, FlatTerrain())
    late = {3, 5}
    for k in range(10):
        tracker.advance(k)
        if order == "in_order" or k not in late:
            tracker.update(_bearings(k * STEP), by_label=True)
        if order == "late" and k == 7:
            tracker.update([b for e in sorted(late) for b in _bearings(e * STEP)], by_label=True)
    (_, estimate), = tracker.estimates()
    return np.concatenate([estimate.mean, estimate.cov.ravel()])


def test_late_bearings_are_reprocessed_exactly():
    np.testing.assert_allclose(_run("late"), _run("in_order"), rtol=1e-9, atol=1e-12)


def test_unmeasured_tracks_are_deleted_and_unlabelled_bearings_unused():
    tracker = Tracker(IMM, STEP, FlatTerrain())
    assert tracker.update(_bearings(0.0, sensors=SENSORS[:1]), by_label=True)["initiated"] == 1
    assert tracker.update(_bearings(0.0, truth_id=None), by_label=True) == {"updated": 0, "initiated": 0, "unused": 2}
    for k in range(1, IMM.confirm_hits):
        tracker.advance(k)
        assert tracker.update(_bearings(k * STEP, sensors=SENSORS[:1]), by_label=True)["updated"] == 1
    last = IMM.confirm_hits - 1
    assert len(tracker.estimates()) == 1
    tracker.advance(last + int(IMM.stale_after / STEP))
    assert tracker.tracks
    tracker.advance(last + int(IMM.stale_after / STEP) + 2)
    assert not tracker.tracks


def test_bad_input_is_rejected():
    tracker = Tracker(IMM, STEP, FlatTerrain())
    tracker.update(_bearings(0.0), by_label=True)
    tracker.advance(20)
    with pytest.raises(ValueError, match="outside the window"):
        tracker.update(_bearings(0.0), by_label=True)  # a bearing older than the window
    for kwargs in ({"manoeuvre_q": -1.0}, {"stay": 0.0}, {"quiet_prior": 1.0}, {"vertical_q": float("nan")}):
        with pytest.raises(ValueError, match="tracking.imm"):
            ImmConfig(**kwargs)
    with pytest.raises(ValueError, match="unknown tracking.imm settings"):
        TrackerConfig(motion="imm", policy="flood", imm={"stay": 0.9, "switch": 0.1})
    for policy in ("hybrid", "exact", "ci", "naive"):  # a mixture cannot go through channel filters
        with pytest.raises(ValueError, match="needs policy"):
            TrackerConfig(motion="imm", policy=policy)


PLACEHOLDER = {"planner": "placeholder", "search": "lawnmower", "spacing": 80.0, "orbit_radius": 40.0}


@pytest.mark.slow
def test_the_imm_oracle_is_consistent_on_every_shipped_target():
    """4 agents on the camera scenario, 2 seeds x 90 s: per target, the oracle's ANEES (pooled by samples) lies
    inside the 95 % chi-square interval of its independent samples (``mesh_sim.bench.rumor_stats``: one per
    ``DECORRELATION_S`` block). Measured with the ROI camera drawing its random numbers as the whole frame does:
    car 0.77 in [0.74, 1.30], parked 0.83 in [0.72, 1.32], walker 1.12 in [0.74, 1.30] (before that draw
    order parked was 1.51 and the test was marked xfail).

    The agents fly the placeholder planner here (lanes, then 40 m orbits shared by several agents), the geometry
    these figures were measured on. Under the assignment planner the car has an agent of its own on a 15 m
    circle and many more bearings: its IMM ANEES falls to 0.62 (K = 16), below the interval — conservative, not
    overconfident: the manoeuvre mode's process noise is sized for the car's peak acceleration (issue 13's
    note)."""
    from mesh_sim.lockstep import run_lockstep
    from mesh_sim.scenario import load

    pooled: dict[str, list] = {}
    for seed in (1, 2):
        scenario = load("default", seed=seed, duration=90.0, agents=4, tasking=PLACEHOLDER)
        with tempfile.TemporaryDirectory() as tmp:
            metrics = run_lockstep(scenario, Path(tmp))
        for t in metrics["oracle"]["imm_targets"]:
            nees, samples, k = pooled.setdefault(t["target"], [0.0, 0, 0])
            pooled[t["target"]] = [nees + t["anees"] * t["samples"], samples + t["samples"],
                                   k + independent_samples({t["target"]: t["samples"]}, scenario.agent.step)]
    assert set(pooled) == {"parked", "walker", "car"}
    for target, (nees, samples, k) in pooled.items():
        lo, hi = anees_interval(k)
        assert lo <= nees / samples <= hi, f"{target}: ANEES {nees / samples:.2f} outside [{lo:.2f}, {hi:.2f}] (K={k})"


def test_a_scenario_selects_the_imm_for_its_agents_and_rejects_bad_modes():
    from mesh_sim.scenario import load

    scenario = load("default", tracking={"policy": "flood", "motion": "imm", "imm": {"stay": 0.99}})
    assert scenario.agent.tracking.imm == ImmConfig(stay=0.99)
    with pytest.raises(ValueError, match="tracking.imm.stay"):
        load("default", tracking={"policy": "flood", "motion": "imm", "imm": {"stay": 1.5}})
    with pytest.raises(ValueError, match="needs policy"):
        load("default", tracking={"policy": "hybrid", "motion": "imm"})


@pytest.mark.slow
def test_agents_with_the_imm_under_flood_track_every_target_like_their_in_flight_reference():
    """4 agents, default scenario, 40 s, ``motion = "imm"``: every agent tracks every target, the fleet's RMSE is
    within 10 % of the in-flight oracle's (the same IMM, fed what could have arrived) and its ANEES inside
    [0.5, 1.5] (measured, seed 1: 1.01 and 0.96; the damped-velocity agents of the same run: RMSE 2.1 times
    theirs, ANEES 0.71)."""
    from mesh_sim.lockstep import run_lockstep
    from mesh_sim.scenario import load

    scenario = load("default", agents=4, duration=40.0, seed=1, tracking={"policy": "flood", "motion": "imm"})
    with tempfile.TemporaryDirectory() as tmp:
        fleet = run_lockstep(scenario, Path(tmp))["fleet"]
    assert fleet["targets_tracked_by_every_agent"]
    assert fleet["rmse_ratio_to_in_flight"] <= 1.1
    assert 0.5 <= fleet["anees"] <= 1.5
