"""``skymesh router --parent-pid``: a router outlives no launcher (mesh_sim.router, mesh_sim.testbed)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from mesh_sim.launcher import free_port


def _gone(pid: int) -> bool:
    """No such process, or a zombie nobody has reaped yet (it has exited)."""
    try:
        return Path(f"/proc/{pid}/status").read_text().split("State:")[1].split()[0] == "Z"
    except (FileNotFoundError, IndexError):
        return True


def _wait(condition, seconds: float, what: str) -> None:
    deadline = time.time() + seconds
    while not condition():
        assert time.time() < deadline, what
        time.sleep(0.1)


def test_a_router_stops_when_the_process_that_started_it_is_killed(tmp_path):
    """A launcher (here a small Python parent) starts a router with ``--parent-pid`` of itself and is SIGKILLed —
    as ``skymesh testbed``'s launcher could be, its routers in namespaces it can no longer stop: the router sees
    its parent gone and exits by itself, saying why."""
    config = tmp_path / "router.json5"
    config.write_text(json.dumps({"mode": "router", "listen": {"endpoints": [f"tcp/127.0.0.1:{free_port()}"]},
                                  "scouting": {"multicast": {"enabled": False}}}))
    log = tmp_path / "router.log"
    parent_code = textwrap.dedent(f"""
        import os, subprocess, sys, time
        with open({str(log)!r}, "wb") as log:
            router = subprocess.Popen([sys.executable, "-m", "mesh_sim", "router", "--config", {str(config)!r},
                                       "--parent-pid", str(os.getpid())], stdout=log, stderr=subprocess.STDOUT)
        print(router.pid, flush=True)
        time.sleep(120)
    """)
    parent = subprocess.Popen([sys.executable, "-c", parent_code], stdout=subprocess.PIPE, text=True,
                              cwd=Path(__file__).resolve().parents[2])
    router_pid = int(parent.stdout.readline())
    try:
        _wait(lambda: "listening on" in log.read_text(), 60, f"the router did not listen: {log.read_text()}")
        assert not _gone(router_pid)
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        _wait(lambda: _gone(router_pid), 15, "the router outlived the process that started it")
        assert "parent process" in log.read_text() and "is gone; stopping" in log.read_text()
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()
        if not _gone(router_pid):
            os.kill(router_pid, signal.SIGKILL)
