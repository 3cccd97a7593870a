"""An agent process imports only what it uses (issue 12, item 4).

Each test starts a real ``python -X importtime -m agent`` over a Zenoh router opened here, exactly as the
launcher starts one (scenario file, readiness handshake through the ready and epoch files), lets it run a
second of steps and reads every module the interpreter imported from its ``-X importtime`` report — so
imports made lazily while stepping (a renderer loaded at the first frame) count too. The process is
stopped by PID if it is still running, and checked gone.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest
import zenoh

from agent.net.zenoh_transport import router_config
from mesh_sim.launcher import free_port
from mesh_sim.scenario import load
from tests.processes import assert_all_gone

pytestmark = pytest.mark.slow  # a live agent process over a Zenoh router

REPO = Path(__file__).resolve().parents[2]
NEVER = ("matplotlib", "rerun")  # plots and recordings belong to the launcher and the observer, never to an agent


def _run_agent(tmp_path: Path, sensor: str) -> tuple[set[str], dict]:
    """Run one agent of the default scenario with ``sensor`` for 1 s; its imported modules and its metrics."""
    scenario = load("default", agents=1, duration=1.0, sensor={"kind": sensor})
    scenario_file = tmp_path / "scenario.json"
    scenario_file.write_text(json.dumps(scenario.raw))
    epoch_file, ready_file, report = tmp_path / "epoch", tmp_path / "uav0.ready", tmp_path / "stderr.txt"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(router_config([endpoint]))
    try:
        with open(report, "wb") as err:
            proc = subprocess.Popen(
                [sys.executable, "-X", "importtime", "-m", "agent", "--id", "uav0", "--index", "0",
                 "--fleet", f"lean-{uuid.uuid4().hex[:8]}", "--scenario", str(scenario_file), "--connect", endpoint,
                 "--out", str(tmp_path), "--epoch-file", str(epoch_file), "--ready-file", str(ready_file),
                 "--parent-pid", str(os.getpid())],
                cwd=REPO, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err)
        try:
            deadline = time.time() + 60.0
            while not ready_file.exists():
                assert proc.poll() is None, f"the agent exited before it was ready:\n{report.read_text()[-3000:]}"
                assert time.time() < deadline, "the agent was not ready within 60 s"
                time.sleep(0.02)
            epoch_file.write_text(repr(time.time()))
            assert proc.wait(timeout=60) == 0, report.read_text()[-3000:]
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    finally:
        router.close()
    assert_all_gone([proc.pid])
    imported = {line.rsplit("|", 1)[1].strip() for line in report.read_text().splitlines()
                if line.startswith("import time:") and "|" in line}
    imported.discard("imported package")  # the report's header line
    return imported, json.loads((tmp_path / "agent-uav0.json").read_text())


def _loaded(imported: set[str], package: str) -> list[str]:
    return sorted(m for m in imported if m == package or m.startswith(package + "."))


def test_bearing_agent_process_loads_neither_opencv_nor_matplotlib_nor_rerun(tmp_path):
    imported, metrics = _run_agent(tmp_path, "bearing")
    assert metrics["steps"] > 0
    assert {"agent.agent", "agent.sensors.bearing", "zenoh"} <= imported, "the -X importtime report was not read"
    # If cv2 shows up, a module on the geometric sensor's path (agent.config and the *_config modules it reads,
    # agent.sensors.registry, agent.beliefs, perception.scene/degradation, ...) imports image code at top level:
    # every agent would pay OpenCV's start-up and memory although only a camera uses it. Move the cv2 code into a
    # module that only the camera (its factory in agent.sensors.registry, the grid builder) imports.
    assert _loaded(imported, "cv2") == [], "the geometric bearing agent imported OpenCV"
    assert "agent.sensors.camera" not in imported, "the camera pipeline was imported without a camera"
    for package in NEVER:
        assert _loaded(imported, package) == [], f"an agent process imported {package}"


def test_camera_agent_process_loads_opencv_but_neither_matplotlib_nor_rerun(tmp_path):
    imported, metrics = _run_agent(tmp_path, "camera")
    assert metrics["steps"] > 0 and metrics["sensor"]["frames"] > 0  # it did render and detect
    assert "cv2" in imported, "the camera agent ran without OpenCV: the -X importtime report was not read"
    # matplotlib or rerun here means an agent module imports plotting or logging code that belongs to the
    # launcher (plots) or the observer (the Rerun recording): ~40 MB and a second of start-up per agent.
    for package in NEVER:
        assert _loaded(imported, package) == [], f"an agent process imported {package}"
