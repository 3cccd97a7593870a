"""``python -m agent --mavlink URL``: a real agent process over a Zenoh router opened here flies the scripted
autopilot; a URL that cannot be opened or an autopilot that never heartbeats is exit code 2 before the loop.
A process that hangs is killed by PID when its timeout runs out."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import uuid
from pathlib import Path

import pytest
import zenoh

from agent.net.zenoh_transport import router_config
from mesh_sim.scenario import load
from tests.agent.mavlink_peer import SCENARIO_ORIGIN, ScriptedAutopilot, free_port

pytestmark = pytest.mark.slow  # live agent processes over a Zenoh router

REPO = Path(__file__).resolve().parents[2]


def run_agent(tmp_path: Path, url: str, duration: float = 2.0, **vehicle) -> tuple[int, str]:
    """Run ``python -m agent --mavlink url`` on the default scenario (origin :data:`SCENARIO_ORIGIN`, its
    ``[vehicle]`` a MAVLink one with ``vehicle``'s keys); its exit code and stderr."""
    scenario = load("default", agents=1, duration=duration)
    raw = {**scenario.raw, "origin": dict(zip(("lat", "lon", "alt"), SCENARIO_ORIGIN, strict=True)),
           "vehicle": {"kind": "mavlink", "url": "udpin:127.0.0.1:1", **vehicle}}
    scenario_file = tmp_path / "scenario.json"
    scenario_file.write_text(json.dumps(raw))
    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    router = zenoh.open(router_config([endpoint]))
    try:  # subprocess.run kills the process (by its PID) if it outlives the timeout
        done = subprocess.run(
            [sys.executable, "-m", "agent", "--id", "uav0", "--index", "0", "--fleet", f"mav-{uuid.uuid4().hex[:8]}",
             "--scenario", str(scenario_file), "--connect", endpoint, "--out", str(tmp_path), "--mavlink", url,
             "--parent-pid", str(os.getpid())],
            cwd=REPO, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
            timeout=90)
    finally:
        router.close()
    return done.returncode, done.stderr


def test_the_agent_process_flies_the_autopilot(tmp_path):
    peer = ScriptedAutopilot(free_port())
    try:
        code, err = run_agent(tmp_path, f"udpin:127.0.0.1:{peer.address[1]}", takeoff_altitude=3.0)
    finally:
        peer.close()
    assert code == 0, err[-3000:]
    metrics = json.loads((tmp_path / "agent-uav0.json").read_text())
    vehicle = metrics["vehicle"]
    assert vehicle["kind"] == "mavlink" and vehicle["setpoints_sent"] >= 20 and vehicle["stale_steps"] == 0
    assert metrics["steps"] >= 10
    assert peer.armed and len(peer.messages("SET_POSITION_TARGET_LOCAL_NED")) >= 20


def test_an_autopilot_that_never_heartbeats_is_exit_code_2(tmp_path):
    url = f"udpin:127.0.0.1:{free_port()}"  # bad input: nobody sends on this port
    code, err = run_agent(tmp_path, url, connect_timeout=1.0)
    assert code == 2
    assert f"no autopilot HEARTBEAT on '{url}' within 1 s" in err
    assert not (tmp_path / "agent-uav0.json").exists()  # the agent never ran


def test_a_url_that_is_no_connection_string_is_exit_code_2(tmp_path):
    code, err = run_agent(tmp_path, "ftp://autopilot")  # bad input: not a pymavlink connection string
    assert code == 2 and "url: expected a pymavlink connection string" in err
