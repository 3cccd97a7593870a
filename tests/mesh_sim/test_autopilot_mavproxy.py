"""MAVProxy (headless: ``--non-interactive``, no map, no console) as the ground station of the simulator: it
detects the vehicle, decodes the PX4 mode, and downloads the parameters over the parameter protocol.

MAVProxy runs in a temporary folder (it writes ``mav.tlog`` and ``mav_SYS_COMP.parm`` where it runs),
unbuffered (``python -u``, so that its lines arrive as it prints them), and is stopped by PID. Its ``--cmd``
commands run before a vehicle is detected and it reads no stdin when non-interactive, so this test drives
nothing; it checks what an unmodified MAVProxy makes of the simulator."""

from __future__ import annotations

import selectors
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mesh_sim.autopilot.params import SPECS
from mesh_sim.autopilot.process import AutopilotProcess

pytestmark = pytest.mark.slow
MAVPROXY = shutil.which("mavproxy.py", path=str(Path(sys.executable).parent))


def read_until(popen: subprocess.Popen, wanted: list[str], timeout: float) -> str:
    """MAVProxy's output until every string of ``wanted`` has appeared (or ``timeout``)."""
    out = []
    deadline = time.monotonic() + timeout
    with selectors.DefaultSelector() as selector:
        selector.register(popen.stdout, selectors.EVENT_READ)
        while time.monotonic() < deadline and not all(w in "".join(out) for w in wanted):
            if selector.select(0.2):
                line = popen.stdout.readline()
                if not line:
                    break
                out.append(line)
    return "".join(out)


@pytest.mark.skipif(MAVPROXY is None, reason="mavproxy.py is not installed (make installs it, without its GUI)")
def test_mavproxy_detects_the_vehicle_its_px4_mode_and_its_parameters(tmp_path):
    with AutopilotProcess.start("--instance", "4") as ap:
        popen = subprocess.Popen(
            [sys.executable, "-u", MAVPROXY, f"--master=udpin:127.0.0.1:{ap.gcs_remote_port}", "--non-interactive",
             "--nowait"],
            cwd=tmp_path, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            out = read_until(popen, ["Detected vehicle", "Mode LOITER", f"Saved {len(SPECS)} parameters"], 40.0)
        finally:
            popen.kill()
            popen.wait(timeout=10)
    assert "Detected vehicle 5:1" in out, out  # MAV_SYS_ID 1 + instance, component 1
    assert "Mode LOITER" in out, out  # PX4 AUTO_LOITER (Hold), as pymavlink names PX4 modes
    assert f"Received {len(SPECS)} parameters" in out, out
    saved = (tmp_path / "mav_5_1.parm").read_text()  # MAVProxy names the file after system and component
    assert "MIS_TAKEOFF_ALT" in saved and "COM_OF_LOSS_T" in saved
