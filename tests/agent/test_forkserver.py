"""The agents' fork server (agent/forkserver.py): its protocol over real pipes, what it imports, and exit codes.

The server is started as the launcher starts it (``python -m agent.forkserver --scenario FILE``); the children it
forks run the real ``python -m agent`` entry point. Every process started here is stopped and checked gone.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from agent.forkserver import with_parent
from mesh_sim.launcher import free_port
from mesh_sim.scenario import load
from tests.processes import assert_all_gone


def _scenario_file(tmp_path, sensor: str):
    path = tmp_path / f"scenario-{sensor}.json"
    path.write_text(json.dumps(load("default", agents=2, sensor={"kind": sensor}).raw))
    return path


def test_a_forked_agent_runs_the_real_entry_point_and_bad_requests_change_nothing(tmp_path):
    server = subprocess.Popen([sys.executable, "-m", "agent.forkserver", "--scenario",
                               str(_scenario_file(tmp_path, "bearing"))],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    pids = []
    try:
        def ask(line: str) -> dict:
            server.stdin.write(line + "\n")
            server.stdin.flush()
            return json.loads(server.stdout.readline())

        assert json.loads(server.stdout.readline()) == {"ready": server.pid}
        # bad input: a line that is not JSON, and a request whose argv is not a list of strings
        assert "bad request" in ask("fork me")["error"]
        assert "argv must be a list of strings" in ask(json.dumps({"argv": "--id uav0", "log": "x"}))["error"]
        # an agent whose router is not there: the real main() reports it in its log and exits with 2
        log = tmp_path / "uav0.log"
        argv = ["--id", "uav0", "--index", "0", "--fleet", "t", "--scenario", str(_scenario_file(tmp_path, "bearing")),
                "--connect", f"tcp/127.0.0.1:{free_port()}", "--parent-pid", "1"]
        pid = ask(json.dumps({"argv": argv, "log": str(log)}))["pid"]
        pids.append(pid)
        assert json.loads(server.stdout.readline()) == {"exit": pid, "code": 2}
        assert "agent uav0: the Zenoh router could not be reached" in log.read_text()
        server.stdin.close()  # end of input: the server exits
        assert server.wait(timeout=30) == 0
    finally:
        if server.poll() is None:
            server.kill()
            server.wait()
    assert_all_gone([server.pid, *pids], timeout=10)


@pytest.mark.parametrize(("sensor", "opencv"), [("bearing", False), ("camera", True)])
def test_the_server_imports_what_the_scenario_needs_and_no_more(tmp_path, sensor, opencv):
    """Its children share what it imported: OpenCV only for a camera, never matplotlib or Rerun (issue 12), nor the
    simulator (DESIGN.md §1: agents hold no simulated truth but what the transport brings)."""
    code = ("import sys; from agent.forkserver import preload; preload(sys.argv[1]); "
            "print(sorted(m for m in ('cv2', 'matplotlib', 'rerun', 'mesh_sim', 'zenoh', 'scipy.optimize') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code, str(_scenario_file(tmp_path, sensor))], capture_output=True,
                         text=True, timeout=120, check=True).stdout
    assert out.strip() == str(sorted(["scipy.optimize", "zenoh", *(["cv2"] if opencv else [])]))


def test_a_missing_scenario_is_a_one_line_error(tmp_path):
    """Bad input: the scenario file does not exist; exit code 2 before anything is forked."""
    out = subprocess.run([sys.executable, "-m", "agent.forkserver", "--scenario", str(tmp_path / "none.json")],
                         capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.startswith("agent forkserver: cannot preload") and "cannot read" in out.stderr


def test_parent_pid_is_the_server():
    """(Exit codes, a signal's negative included, are checked over a real server in tests/mesh_sim/test_forked.py.)"""
    assert with_parent(["--id", "uav0", "--parent-pid", "41", "--x"], 7) == ["--id", "uav0", "--parent-pid", "7", "--x"]
    assert with_parent(["--id", "uav0"], 7) == ["--id", "uav0"]
