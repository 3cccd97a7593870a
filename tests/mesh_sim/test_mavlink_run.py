"""``skymesh run --vehicle mavlink``: every agent flies a ``skymesh autopilot`` over MAVLink UDP; one autopilot
frozen mid-run is detected by its agent and its tasks go to the others. Plus the usage errors, and the
failover analysis on hand-made timelines."""

from __future__ import annotations

import pytest

from mesh_sim.bench.mavlink_fleet import detection_s, fly, reassignment_s
from mesh_sim.cli import main
from tests.processes import assert_all_gone


@pytest.fixture(scope="module")
def frozen_run(tmp_path_factory):
    return fly(tmp_path_factory.mktemp("runs"), "test", 1, 20.0, "mavlink", (8.0, 16.0))


@pytest.mark.slow
def test_a_fleet_of_autopilots_flies_the_default_scenario(frozen_run):
    metrics, times = frozen_run
    assert metrics["status"] == "completed", metrics["status"]
    tracked = [{t["target"] for t in a["targets"] if t["rmse"] is not None} for a in metrics["agents"]]
    assert set.intersection(*tracked), f"no target tracked by every agent: {tracked}"
    assert any(name.startswith("autopilot") for name in times["pids"])
    assert_all_gone(times["pids"].values())
    for agent in metrics["agents"]:
        vehicle = agent["vehicle"]
        assert vehicle["kind"] == "mavlink" and vehicle["setpoints_sent"] > 100
        assert not set(vehicle["rejected_by_reason"]) - {"before_heartbeat"}  # nothing malformed on the wire


@pytest.mark.slow
def test_a_frozen_autopilot_is_detected_within_2_s_and_its_tasks_reassigned(frozen_run):
    metrics, times = frozen_run
    detected = detection_s(metrics, "uav1", times["frozen_wall"])
    assert detected is not None and detected <= 2.0 + 0.25  # heartbeat timeout, plus one 0.2 s agent step
    reassigned, served = reassignment_s(metrics, "uav1", 8.0)
    assert served, "uav1 served nothing when it was frozen"
    assert reassigned is not None and reassigned <= detected + 3.0  # released, then agreed within a few rounds


def test_usage_errors_before_anything_starts(tmp_path, capsys):
    assert main(["run", "--vehicle", "mavlink", "--speed", "2", "--out", str(tmp_path)]) == 2
    assert "--speed 1" in capsys.readouterr().err
    assert main(["run", "--vehicle", "mavlink", "--lockstep", "--rerun", "off", "--out", str(tmp_path)]) == 2
    assert "kinematic" in capsys.readouterr().err


def _agent(name, timeline, changes=()):
    return {"id": name, "assignment": {"timeline": timeline}, "vehicle": {"health_changes": list(changes)}}


def test_failover_times_from_timelines():
    """uav1 serves the car and a cell; frozen at t = 10 (wall 1000). Its vehicle says so at wall 1001.5; the peers
    drop it from the cell at 11 and give the car to uav2 at 12."""
    before = {"car": "uav1", "search:0:0": "uav1", "walker": "uav0"}
    metrics = {"agents": [
        _agent("uav0", [[0.0, before], [11.0, {**before, "search:0:0": None}],
                        [12.0, {"car": "uav2", "search:0:0": None, "walker": "uav0"}]]),
        _agent("uav1", [[0.0, before]], [[990.0, ""], [1001.5, "autopilot heartbeat lost"]]),
        _agent("uav2", [[0.0, before], [12.0, {"car": "uav2", "walker": "uav0"}]]),
    ]}
    assert detection_s(metrics, "uav1", 1000.0) == pytest.approx(1.5)
    assert reassignment_s(metrics, "uav1", 10.0) == (pytest.approx(2.0), ["car", "search:0:0"])
    never = {"agents": [_agent("uav0", [[0.0, before]]), _agent("uav1", [[0.0, before]])]}
    assert reassignment_s(never, "uav1", 10.0) == (None, ["car", "search:0:0"])
    # a map that flickered just before the fault (the car's track re-matched) still counts what uav1 served
    flicker = {"agents": [_agent("uav0", [[0.0, before], [9.9, {"walker": "uav0"}], [12.0, {"car": "uav2"}]]),
                          _agent("uav1", [[0.0, before]])]}
    assert reassignment_s(flicker, "uav1", 10.0) == (pytest.approx(2.0), ["car", "search:0:0"])
    idle = {"agents": [_agent("uav0", [[0.0, {"car": "uav0"}], [11.0, {}]]), _agent("uav1", [[0.0, {}]])]}
    assert reassignment_s(idle, "uav1", 10.0) == (None, [])  # it served nothing: nothing to reassign
