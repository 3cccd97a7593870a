"""The §4.4 mission simulation (thesis 000, spec 000 §4.3): hand-built scenarios with known outcomes, the
nominal vs extended contrast, and the benchmark smoke test."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from rich.console import Console

from mesh_sim.bench import common
from mesh_sim.bench import tasking_health as bench
from mesh_sim.tasking_mission import MissionConfig, loiter_tasks, monte_carlo, random_arrivals, run_mission
from tasking.health import HealthModel
from tasking.tasks import Task

SMALL = MissionConfig(vehicles=4, area=300.0, duration=150.0, arrival_rate=0.1)


def _one_task(north: float, east: float = 0.0):
    return [(0.0, Task("far", (north, east), 1.0))]


def test_service_time_is_flight_time_to_the_task():
    config = replace(SMALL, vehicles=1, health=HealthModel(failure_rate=0.0))
    result = run_mission(config, "nominal", seed=0, arrivals=_one_task(100.0))
    # planned at t = 0, 100 m at 5 m/s: served at the end of the step that reaches it
    assert result.service_times.tolist() == pytest.approx([100.0 / config.speed], abs=config.dt + 1e-9)
    assert result.unserved == 0 and result.lost == 0


def test_failed_vehicle_far_out_crashes_under_nominal_and_is_recalled_under_extended():
    """One vehicle, one task 600 m out (1200 m out and back, range 1500 m on a full tank at the nominal
    burn). A failure (p_f = 1/20 s: almost surely on the way out) quadruples the burn: the nominal RHTA,
    which plans with the nominal burn, flies on and turns back only when the fuel left looks short at the
    nominal burn — too late, it runs dry before base; the extended one sees at once that the task is out
    of reach, recalls the vehicle, and it lands (grounded for the rest of the run)."""
    model = HealthModel(burn=1 / 300.0, burn_failed=4 / 300.0, failure_rate=1 / 20.0, refuel_time=1e4)
    config = replace(SMALL, vehicles=1, duration=400.0, area=700.0, health=model)
    nominal = run_mission(config, "nominal", seed=1, arrivals=_one_task(600.0))
    extended = run_mission(config, "extended", seed=1, arrivals=_one_task(600.0))
    (t_fail, _, distance), = nominal.failure_log
    assert extended.failure_log == nominal.failure_log  # same failure clock, same outbound flight
    fuel = 1.0 - distance / (config.speed * 300.0)
    failed_range = config.speed * fuel / model.burn_failed
    assert distance < failed_range < (600.0 - distance) + 600.0  # home is in reach, the task and home not
    assert nominal.lost == 1 and nominal.losses[0][0] > t_fail
    assert extended.lost == 0 and extended.unserved == 1


def test_healthy_vehicles_are_never_lost():
    config = replace(SMALL, duration=400.0, arrival_rate=0.3, health=HealthModel(failure_rate=0.0, burn=1 / 120.0,
                                                                               burn_failed=2 / 120.0))
    for mode in ("nominal", "extended"):
        result = run_mission(config, mode, seed=3)
        assert result.lost == 0 and result.failures == 0
        assert result.service_times.size > 0 and np.all(result.service_times > 0)


def test_loiter_tasks_keep_the_extended_fleet_out_and_the_nominal_fleet_home():
    config = replace(SMALL, health=HealthModel(failure_rate=0.0))
    nominal = run_mission(config, "nominal", seed=0, arrivals=[])
    extended = run_mission(config, "extended", seed=0, arrivals=[])
    assert nominal.airborne == 0.0  # no task: every vehicle stays at base
    assert extended.airborne > 0.5 * config.vehicles * config.duration  # out to the loiter points
    cells = [task.position for task in loiter_tasks(config)]
    assert len(cells) == config.loiter_grid**2
    assert all(0 < c[0] < config.area and abs(c[1]) < config.area / 2 for c in cells)


def test_both_modes_see_the_same_tasks_and_runs_repeat():
    results = monte_carlo(SMALL, runs=2, seed=5)
    for nominal, extended in zip(results["nominal"], results["extended"], strict=True):
        assert nominal.arrived == extended.arrived
    again = run_mission(SMALL, "extended", seed=5)
    assert again.service_times.tolist() == results["extended"][0].service_times.tolist()


def test_arrivals_are_a_poisson_process_over_the_area():
    config = replace(SMALL, duration=20000.0, arrival_rate=0.1)
    arrivals = random_arrivals(config, np.random.default_rng(0))
    mean = config.arrival_rate * config.duration
    assert abs(len(arrivals) - mean) < 3 * math.sqrt(mean)
    where = np.array([task.position for _, task in arrivals])
    assert where[:, 0].min() >= 0 and where[:, 0].max() <= config.area and np.abs(where[:, 1]).max() <= 150.0
    values = [task.value for _, task in arrivals]
    assert config.value_range[0] <= min(values) and max(values) <= config.value_range[1]


@pytest.mark.parametrize("bad, match", [
    (lambda: run_mission(SMALL, "optimistic", 0), "mode"),        # an unknown mode
    (lambda: monte_carlo(SMALL, runs=0), "runs"),                 # no run
    (lambda: MissionConfig(vehicles=0), "vehicles"),
    (lambda: MissionConfig(speed=-1.0), "speed"),                 # flying backwards
    (lambda: MissionConfig(arrival_rate=-0.1), "arrival_rate"),
    (lambda: MissionConfig(value_range=(2.0, 1.0)), "value_range"),
    (lambda: MissionConfig(horizon=0), "n_c"),                    # n_c < 1
    (lambda: MissionConfig(discount=1.5), "λ"),                   # λ outside (0, 1]
])
def test_bad_input_is_refused(bad, match):
    with pytest.raises(ValueError, match=match):
        bad()


@pytest.mark.slow  # a benchmark run
def test_bench_quick_run_reports_finite_numbers(tmp_path):
    result = bench.run(quick=True, repeats=1)
    assert result["benchmark"] == "tasking-health"
    rows = {row["mode"]: row for row in result["rows"]}
    assert set(rows) == {"nominal", "extended", "thesis nominal", "thesis extended"}
    for mode in ("nominal", "extended"):
        for key in ("median_service_s", "mean_service_s", "lost_per_run", "lost_total", "runs"):
            assert math.isfinite(rows[mode][key])
    assert {goal["name"] for goal in result["goals"]} >= {"mean service time", "vehicles lost"}
    assert all(isinstance(goal["met"], bool) for goal in result["goals"])
    console = Console(record=True, width=200)
    bench.report(result, console)
    assert "extended / nominal" in console.export_text()
    assert json.loads(common.write_json(tmp_path / "health.json", result).read_text())["rows"]
