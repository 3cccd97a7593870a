"""The launcher's side of the agents' fork server (mesh_sim/forked.py), over a real ``python -m agent.forkserver``.
Every process started here is stopped and checked gone."""

from __future__ import annotations

import json
import os
import signal
import time

import pytest

from mesh_sim.forked import ForkServer, ForkServerError
from mesh_sim.launcher import free_port, open_router
from mesh_sim.scenario import load
from tests.processes import assert_all_gone

ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}


def test_a_server_that_cannot_preload_is_a_one_line_error_and_leaves_nothing(tmp_path):
    """Bad input: the scenario file is missing."""
    with pytest.raises(ForkServerError, match=r"did not start: agent forkserver: cannot preload .*none\.json"):
        ForkServer(tmp_path / "none.json", ENV, tmp_path / "forkserver.log", timeout=60)


def test_forked_agents_answer_as_popen_does(tmp_path):
    scenario = tmp_path / "scenario.json"
    scenario.write_text(json.dumps(load("default", agents=2, sensor={"kind": "bearing"}).raw))
    server = ForkServer(scenario, ENV, tmp_path / "forkserver.log", timeout=60)
    common = ["--fleet", "t", "--scenario", str(scenario), "--connect", f"tcp/127.0.0.1:{free_port()}"]
    try:
        # no router there: the agent exits with 2 and says so in its own log
        failed = server.spawn(["--id", "uav0", "--index", "0", *common], tmp_path / "uav0.log")
        assert failed.wait(timeout=30) == 2 and failed.poll() == 2
        assert "the Zenoh router could not be reached" in (tmp_path / "uav0.log").read_text()
        # bad input: an index outside the team
        assert server.spawn(["--id", "uav1", "--index", "9", *common], tmp_path / "uav1.log").wait(timeout=30) == 2
        # over a real router, waiting for an epoch that never comes: killed by PID, it reports -SIGKILL
        # (subprocess's negative code for a signal)
        router, endpoint = open_router()
        try:
            waiting = server.spawn(["--id", "uav1", "--index", "1", "--epoch-file", str(tmp_path / "never"),
                                    "--ready-file", str(tmp_path / "ready"), *common[:4], "--connect", endpoint],
                                   tmp_path / "uav1b.log")
            deadline = time.time() + 60
            while not (tmp_path / "ready").exists() and time.time() < deadline:
                time.sleep(0.05)
            assert waiting.poll() is None and (tmp_path / "ready").exists()
            waiting.kill()
            assert waiting.wait(timeout=30) == -signal.SIGKILL
        finally:
            router.close()
        pids = [failed.pid, waiting.pid]
    finally:
        server.close(10.0)
    assert server.process.returncode == 0
    assert_all_gone([server.process.pid, *pids], timeout=10)
    with pytest.raises(ForkServerError, match="is gone"):
        server.spawn(["--id", "uav0"], tmp_path / "late.log")
