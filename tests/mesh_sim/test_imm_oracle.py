"""The oracle's IMM tracker (mesh_sim.imm_oracle): exact reprocessing of late bearings, deletion, bad input,
and — slow — the oracle's consistency on the shipped camera scenario (per target, ANEES inside its 95 %
chi-square interval, with independent samples counted as ``skymesh bench rumor`` counts them, rumor_stats)."""

import tempfile
from pathlib import Path

import numpy as np
import pytest

from agent.beliefs.tracking_config import TrackerConfig
from agent.sensors.bearing import Bearing
from fusion.measurement import los_to_azel
from mesh_sim.bench.rumor_stats import anees_interval, independent_samples
from mesh_sim.imm_oracle import ImmTracker, OracleConfig
from perception.terrain import FlatTerrain

STEP = 0.2
R = np.diag([1e-4, 1e-4])
TARGET = np.array([10.0, 5.0, 0.0])


def _bearings(t: float, truth_id="parked") -> list[Bearing]:
    sensors = [np.array([0.0, 0.0, -80.0]), np.array([30.0, -20.0, -80.0])]
    return [Bearing(t, s, los_to_azel(TARGET - s), R, truth_id) for s in sensors]


def _run(order: str) -> np.ndarray:
    """Bearings of epochs 0..9, delivered in time order or with epochs 3 and 5 arriving at epoch 7."""
    tracker = ImmTracker(TrackerConfig(), STEP, FlatTerrain())
    late = {3, 5}
    for k in range(10):
        tracker.advance(k)
        if order == "in_order" or k not in late:
            tracker.update(_bearings(k * STEP))
        if order == "late" and k == 7:
            tracker.update([b for e in sorted(late) for b in _bearings(e * STEP)])
    (_, estimate), = tracker.estimates()
    return np.concatenate([estimate.mean, estimate.cov.ravel()])


def test_late_bearings_are_reprocessed_exactly():
    np.testing.assert_allclose(_run("late"), _run("in_order"), rtol=1e-9, atol=1e-12)


def test_unmeasured_tracks_are_deleted_and_unlabelled_bearings_unused():
    config = TrackerConfig()
    tracker = ImmTracker(config, STEP, FlatTerrain())
    assert tracker.update(_bearings(0.0))["initiated"] == 1
    assert tracker.update(_bearings(0.0, truth_id=None)) == {"updated": 0, "initiated": 0, "unused": 2}
    tracker.advance(int(config.stale_after / STEP))
    assert tracker.tracks
    tracker.advance(int(config.stale_after / STEP) + 2)
    assert not tracker.tracks


def test_bad_input_is_rejected():
    tracker = ImmTracker(TrackerConfig(), STEP, FlatTerrain())
    with pytest.raises(ValueError, match="true labels"):
        tracker.update(_bearings(0.0), by_label=False)
    tracker.advance(20)
    with pytest.raises(ValueError, match="outside the window"):
        tracker.update(_bearings(0.0))
    for kwargs in ({"manoeuvre_q": -1.0}, {"stay": 0.0}, {"quiet_prior": 1.0}, {"vertical_q": float("nan")}):
        with pytest.raises(ValueError, match="oracle"):
            OracleConfig(**kwargs)


@pytest.mark.slow
def test_the_imm_oracle_is_consistent_on_every_shipped_target():
    """4 agents on the camera scenario, 2 seeds x 90 s: per target, the oracle's ANEES (pooled by samples) lies
    inside the 95 % chi-square interval of its independent samples (``mesh_sim.bench.rumor_stats``: one per
    ``DECORRELATION_S`` block)."""
    from mesh_sim.lockstep import run_lockstep
    from mesh_sim.scenario import load

    pooled: dict[str, list] = {}
    for seed in (1, 2):
        scenario = load("camera", seed=seed, duration=90.0, agents=4)
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
