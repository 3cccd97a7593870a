"""The standoff scenario in lockstep: fixed wings on collocation plans track both moving targets, the plans are
adopted on simulation time (two runs are identical whatever the worker thread's timing), and the benchmark
compares them with the circle on the same seed."""

from __future__ import annotations

import random
import time

import pytest

from mesh_sim.launcher import new_run_dir
from mesh_sim.lockstep import run_lockstep
from mesh_sim.scenario import load
from tasking.collocation import RecedingHorizonPlanner

DURATION = 30.0


def _run(tmp_path, name: str, **tasking) -> dict:
    scenario = load("standoff", duration=DURATION, tasking=tasking)
    return run_lockstep(scenario, new_run_dir(tmp_path, name))


@pytest.fixture(scope="module")
def collocation(tmp_path_factory):
    return _run(tmp_path_factory.mktemp("standoff"), "a")


def _fleet_rmse(metrics: dict) -> list:
    return [(a["id"], t["target"], t["rmse"]) for a in metrics["agents"] for t in a.get("targets", [])]


def test_the_fixed_wings_track_both_targets_on_adopted_plans(collocation):
    assert {t["target"] for t in collocation["oracle"]["targets"]} == {"car", "walker"}
    assert {target for _, target, _ in _fleet_rmse(collocation)} == {"car", "walker"}
    assert all(rmse < 5.0 for _, _, rmse in _fleet_rmse(collocation))
    pilots = [a["standoff"] for a in collocation["agents"]]
    assert all(p["adopted"] >= 2 and p["late"] == 0 for p in pilots)
    assert all(p["requested"] >= p["adopted"] + p["failed"] for p in pilots)


@pytest.mark.slow
def test_two_lockstep_runs_are_identical_however_slow_the_worker(collocation, tmp_path, monkeypatch):
    """The second run's solves are delayed by random sleeps (0-0.3 s): the adopted plans, hence the paths and the
    errors, must not change — they would if a plan were taken when its solve happened to finish."""
    solve, rng = RecedingHorizonPlanner.solve, random.Random(7)

    def slow(self, *args):
        time.sleep(rng.uniform(0.0, 0.3))
        return solve(self, *args)

    monkeypatch.setattr(RecedingHorizonPlanner, "solve", slow)
    again = _run(tmp_path, "b")
    assert _fleet_rmse(again) == _fleet_rmse(collocation)  # exact: adoption does not depend on thread timing
    assert [a["standoff"]["adopted"] for a in again["agents"]] == [a["standoff"]["adopted"]
                                                                   for a in collocation["agents"]]


def test_the_circle_runs_no_pilot(tmp_path):
    circle = _run(tmp_path, "circle", standoff="circle")
    assert all("standoff" not in a for a in circle["agents"])
    assert {t["target"] for t in circle["oracle"]["targets"]} == {"car", "walker"}


@pytest.mark.slow
def test_the_benchmark_compares_both_modes_on_one_seed():
    from mesh_sim.bench import tasking_standoff

    result = tasking_standoff.run(quick=True, repeats=1, duration=30.0)
    assert {r["mode"] for r in result["rows"]} == {"circle", "collocation"}
    assert {r["target"] for r in result["rows"]} == {"car", "walker"}
    cost = {c["mode"]: c for c in result["cost"]}
    assert cost["circle"]["requested"] == 0 and cost["collocation"]["adopted"] > 0
    assert cost["collocation"]["solve_cpu_p95_s"] > 0
    assert len(result["goals"]) == 4
