"""The shipped ``orbit`` and ``rendezvous`` scenarios (spec 004's experiments in the running fleet, lockstep):
the fleet meets on one circle around the target, stays on it and spaces itself equally."""

import pytest

from mesh_sim.launcher import new_run_dir
from mesh_sim.lockstep import run_lockstep
from mesh_sim.scenario import load

pytestmark = pytest.mark.slow


def _run(name, tmp_path, **overrides):
    scenario = load(name, **overrides)
    return run_lockstep(scenario, new_run_dir(tmp_path, name))


def test_five_uavs_share_the_figure8_targets_circle(tmp_path):
    metrics = _run("orbit", tmp_path, duration=40.0)
    orbits = metrics["oracle"]["orbits"]
    assert orbits["rendezvous_s"] is not None and orbits["rendezvous_s"] < 15.0  # 7.4 s measured
    assert orbits["on_circle_share"] >= 0.9  # 0.97
    assert orbits["steady_spacing_error_deg"]["median"] < 20.0  # equal gaps of 72 degrees, within 20
    assert metrics["oracle"]["separation"]["violations"] == 0
    assert metrics["fleet"]["targets_tracked_by_every_agent"]


def test_four_uavs_find_the_walker_then_all_orbit_it(tmp_path):
    metrics = _run("rendezvous", tmp_path)
    orbits = metrics["oracle"]["orbits"]
    first_track = min(t["time_to_first_track"] for a in metrics["agents"] for t in a["targets"])
    assert first_track > 5.0  # it had to be searched for
    assert orbits["rendezvous_s"] is not None and orbits["rendezvous_s"] > first_track
    assert orbits["on_circle_share"] >= 0.95
    assert orbits["steady_spacing_error_deg"]["p95"] < 20.0
