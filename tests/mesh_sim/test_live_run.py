"""Live runs: real agent processes over a real Zenoh router, started and stopped by the launcher.

Every test checks that no process it caused is left running (by PID, never by name).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import pytest
from rerun.chunk import RrdReader

from mesh_sim.launcher import Launcher, new_run_dir
from mesh_sim.scenario import load
from tests.processes import assert_all_gone


@pytest.fixture(scope="module")
def completed_run(tmp_path_factory):
    """One 4-agent run of the default scenario at twice real time (shared by the checks below)."""
    scenario = load("default", duration=30.0, agents=4)
    run_dir = new_run_dir(tmp_path_factory.mktemp("runs"), scenario.name)
    outcome = Launcher(scenario, run_dir, speed=2.0, rerun="save").run()
    return outcome


@pytest.mark.slow
def test_live_run_completes_and_every_agent_tracks_every_target(completed_run):
    metrics = completed_run.metrics
    assert completed_run.status == "completed", completed_run.status
    assert len(metrics["agents"]) == 4
    for agent in metrics["agents"]:
        assert agent["steps"] > 100
        assert {t["target"] for t in agent["targets"]} == {"parked", "walker", "car"}
        for target in agent["targets"]:
            assert target["rmse"] is not None and target["rmse"] < 10.0, (agent["id"], target)
            assert target["anees"] < 3.0, (agent["id"], target)
    assert metrics["oracle"]["rmse"] is not None
    assert metrics["fleet"]["rmse_ratio_to_oracle"] < 3.0


@pytest.mark.slow
def test_live_run_bytes_flow_between_every_pair(completed_run):
    agents = completed_run.metrics["agents"]
    names = {a["id"] for a in agents}
    for agent in agents:
        heard = agent["bytes_rx_by_peer"]
        for peer in names - {agent["id"]}:
            assert heard.get(peer, {}).get("track", 0) > 0, f"{agent['id']} never heard {peer}'s tracks"
            assert heard[peer].get("topology", 0) > 0  # its beacons (agents do not receive telemetry)


@pytest.mark.slow
def test_live_run_writes_the_run_folder(completed_run):
    run_dir = completed_run.run_dir
    on_disk = json.loads((run_dir / "metrics.json").read_text())
    assert on_disk["status"] == "completed"
    assert (run_dir / "recording.rrd").stat().st_size > 10_000
    for plot in ("rmse", "errors", "nees", "map", "traffic", "links"):
        assert (run_dir / "plots" / f"{plot}.png").stat().st_size > 1000
    reader = RrdReader(run_dir / "recording.rrd")  # the observer process's file, finished after the run
    assert len(reader.recordings()) == len(reader.blueprints()) == 1
    assert "/series/anees/fleet" in {chunk.entity_path for chunk in reader.stream()}
    for key in ("id", "pid", "steps", "deadline_misses", "bytes_tx", "bytes_rx", "msgs_rejected", "targets"):
        assert key in on_disk["agents"][0]
    for key in ("rmse", "anees", "rmse_ratio_to_oracle", "bytes_per_agent_per_s"):
        assert key in on_disk["fleet"]


@pytest.mark.slow
def test_live_run_leaves_no_process(completed_run):
    assert_all_gone(completed_run.pids.values())


@pytest.mark.slow
def test_killing_an_agent_loses_only_that_agent(tmp_path):
    """Bad event: an agent dies (SIGKILL) mid-run. The launcher records the death and the run goes on: the
    survivors finish the scenario and write their metrics, which say when they noticed; nothing is left running."""
    scenario = load("default", duration=20.0, agents=4)
    launcher = Launcher(scenario, new_run_dir(tmp_path, "kill"), speed=1.0, rerun="off")

    def kill_one():
        deadline = time.time() + 60
        while time.time() < deadline and not launcher._epoch_file.exists():
            time.sleep(0.1)
        time.sleep(6.0)
        victim = next(c for c in launcher.children if c.name == "uav1")
        os.kill(victim.process.pid, signal.SIGKILL)

    killer = threading.Thread(target=kill_one, daemon=True)
    killer.start()
    outcome = launcher.run()
    killer.join(timeout=5)
    assert outcome.status == "completed", outcome.status
    assert_all_gone(outcome.pids.values())
    (death,) = outcome.deaths
    assert (death.name, death.exit_code, death.cause) == ("uav1", -9, "killed by SIGKILL")
    by_id = {a["id"]: a for a in outcome.metrics["agents"]}
    assert by_id["uav1"]["status"].startswith("died")
    for survivor in ("uav0", "uav2", "uav3"):
        assert by_id[survivor]["steps"] >= 0.9 * 20.0 * 5, by_id[survivor]["steps"]  # it flew the whole run
    (loss,) = json.loads((outcome.run_dir / "metrics.json").read_text())["losses"]
    assert loss["agent"] == "uav1" and loss["cause"] == "killed by SIGKILL" and 4.0 < loss["t"] < 10.0
    assert set(loss["detected_after"]) == {"uav0", "uav2", "uav3"}
    assert all(0.0 <= s <= 4.0 for s in loss["detected_after"].values()), loss


@pytest.mark.slow
def test_a_killed_agent_restarted_rejoins_as_its_next_incarnation(tmp_path):
    """``--restart``: uav1 is SIGKILLed mid-run and started again as incarnation 1. Every survivor hears the new
    life within a few seconds and takes it for a restart (not for replays of old numbers), the new life tracks
    the targets and writes its metrics, and nothing is left running."""
    scenario = load("default", duration=24.0, agents=3)
    launcher = Launcher(scenario, new_run_dir(tmp_path, "restart"), speed=1.0, rerun="off", restart=True)

    def kill_one():
        deadline = time.time() + 60
        while time.time() < deadline and not launcher._epoch_file.exists():
            time.sleep(0.1)
        time.sleep(6.0)
        os.kill(next(c for c in launcher.children if c.name == "uav1").process.pid, signal.SIGKILL)

    killer = threading.Thread(target=kill_one, daemon=True)
    killer.start()
    outcome = launcher.run()
    killer.join(timeout=5)
    assert outcome.status == "completed", outcome.status
    assert_all_gone(outcome.pids.values())
    (death,) = outcome.deaths
    assert (death.name, death.restarted_as) == ("uav1", 1)
    by_id = {a["id"]: a for a in outcome.metrics["agents"]}
    reborn = by_id["uav1"]
    assert reborn["incarnation"] == 1 and reborn["steps"] > 0
    assert sum(t["rmse"] is not None for t in reborn["targets"]) >= 1, reborn["targets"]
    for survivor in ("uav0", "uav2"):
        assert [r[:2] for r in by_id[survivor]["peer_restarts"]] == [["uav1", 1]]
        assert by_id[survivor]["rejected_by_reason"].get("duplicate", 0) < 5
    (loss,) = outcome.metrics["losses"]
    # start-up of a new agent process: ~2 s on an idle machine, 8-9 s measured with the two cores shared 4 ways
    assert loss["restarted_as"] == 1 and all(s is not None and s < 15.0 for s in loss["rejoined_after"].values()), loss
    names = [p["name"] for p in outcome.metrics["phases"]]  # mesh_sim.phases: cut at the death and the rejoin
    assert names == ["start", "uav1 lost", "uav1 rejoined"], outcome.metrics["phases"]
    assert "reconverged_after_s" in outcome.metrics["phases"][2]


@pytest.mark.slow
def test_sigterm_stops_the_run_and_keeps_its_results(tmp_path):
    """Bad event (reliability audit: "SIGTERM: results lost"): `skymesh run` gets SIGTERM mid-run. It stops its
    children, writes the metrics of what ran with the status "terminated" and exits with 143 (128 + 15)."""
    cmd = [sys.executable, "-m", "mesh_sim.cli", "run", "--agents", "2", "--duration", "60", "--rerun", "off",
           "--out", str(tmp_path)]
    launcher = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    children = []
    try:
        deadline = time.time() + 60
        while time.time() < deadline and not list(tmp_path.glob("*/epoch")):
            time.sleep(0.2)
        children = psutil.Process(launcher.pid).children()
        time.sleep(3.0)
        launcher.send_signal(signal.SIGTERM)
        assert launcher.wait(timeout=30) == 143
        (metrics,) = tmp_path.glob("*/metrics.json")
        data = json.loads(metrics.read_text())
        assert data["status"] == "terminated"
        assert all(a.get("steps", 0) > 0 for a in data["agents"]), data["agents"]
        assert_all_gone([c.pid for c in children], timeout=20)
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait()
        for child in children:
            if child.is_running():
                child.kill()


@pytest.mark.slow
def test_children_exit_when_the_launcher_is_killed(tmp_path):
    """Bad event: the launcher itself is SIGKILLed. Its children must not become orphans: the world, and the agents
    with the fork server that forked them (the launcher's grandchildren)."""
    cmd = [sys.executable, "-m", "mesh_sim.cli", "run", "--agents", "3", "--duration", "60", "--rerun", "off",
           "--out", str(tmp_path)]
    launcher = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.time() + 30
        children = []
        while time.time() < deadline and len(children) < 5:
            children = psutil.Process(launcher.pid).children(recursive=True)
            time.sleep(0.2)
        assert len(children) >= 5, "the launcher did not start its children"
        time.sleep(3.0)
        launcher.kill()
        launcher.wait()
        assert_all_gone([c.pid for c in children], timeout=20)
    finally:
        if launcher.poll() is None:
            launcher.kill()
        for child in psutil.Process().children(recursive=True):
            child.kill()


def test_unknown_scenario_is_a_clear_error(tmp_path):
    """Bad input: a scenario name that does not exist."""
    out = subprocess.run([sys.executable, "-m", "mesh_sim.cli", "run", "--scenario", "no-such-scenario",
                          "--out", str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert "no scenario 'no-such-scenario'" in out.stderr
    assert "default" in out.stderr  # it lists the shipped ones


def test_scenario_with_a_typo_is_a_clear_error(tmp_path):
    """Bad input: a scenario file with an unknown setting (a typo must not be silently ignored)."""
    bad = tmp_path / "typo.toml"
    bad.write_text(Path(load("default").path).read_text().replace("rate_hz", "rate_hertz"))
    out = subprocess.run([sys.executable, "-m", "mesh_sim.cli", "run", "--scenario", str(bad),
                          "--out", str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert "rate_hertz" in out.stderr
