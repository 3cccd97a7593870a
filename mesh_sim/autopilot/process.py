"""Start and stop simulator processes on free ports (for tests and benchmarks; by PID, never by name).

The simulator prints one JSON line when its sockets are bound (``{"event": "ready", ...}``) and one when it
stops (``{"event": "stopped", "counters": ...}``); :class:`AutopilotProcess` waits for the first and
returns the second's counters from :meth:`AutopilotProcess.stop`.
"""

from __future__ import annotations

import json
import os
import selectors
import signal
import socket
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def free_udp_ports(count: int) -> list[int]:
    """``count`` distinct UDP ports on loopback that were free a moment ago (the OS picks them)."""
    sockets = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(count)]
    try:
        for s in sockets:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in sockets]
    finally:
        for s in sockets:
            s.close()


@dataclass
class AutopilotProcess:
    """A running ``python -m mesh_sim.autopilot`` and its four ports."""

    popen: subprocess.Popen
    offboard_port: int  # the simulator's offboard port (send commands here)
    offboard_remote_port: int  # where it sends the offboard link (a client listens here)
    gcs_port: int
    gcs_remote_port: int
    ready: dict = field(default_factory=dict)

    @property
    def pid(self) -> int:
        return self.popen.pid

    @classmethod
    def start(cls, *args: str, timeout: float = 20.0, quiet: bool = False) -> AutopilotProcess:
        """Start a simulator with ``args`` (more options) on four free ports; wait for its ready line.
        ``quiet`` discards its log (stderr), which is otherwise this process's stderr."""
        ports = free_udp_ports(4)
        command = [sys.executable, "-m", "mesh_sim.autopilot", "--offboard-port", str(ports[0]),
                   "--offboard-remote-port", str(ports[1]), "--gcs-port", str(ports[2]),
                   "--gcs-remote-port", str(ports[3]), "--parent-pid", str(os.getpid()), *args]
        stderr = subprocess.DEVNULL if quiet else None
        popen = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=stderr, text=True)
        process = cls(popen, *ports)
        try:
            process.ready = process._read_line(timeout)
        except BaseException:
            process.stop()
            raise
        if process.ready.get("event") != "ready":
            process.stop()
            raise RuntimeError(f"the autopilot simulator did not start: {process.ready}")
        return process

    def _read_line(self, timeout: float) -> dict:
        with selectors.DefaultSelector() as selector:
            selector.register(self.popen.stdout, selectors.EVENT_READ)
            if not selector.select(timeout):
                raise TimeoutError(f"no ready line from the autopilot simulator within {timeout} s")
        line = self.popen.stdout.readline()
        try:
            return json.loads(line)
        except json.JSONDecodeError:
            return {"event": "error", "output": line.strip(), "returncode": self.popen.poll()}

    def stop(self, timeout: float = 10.0) -> dict | None:
        """SIGTERM, wait, SIGKILL if needed; the counters of the stopped line (``None`` if there was none)."""
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGTERM)
        try:
            out, _ = self.popen.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            out, _ = self.popen.communicate()
        for line in reversed((out or "").splitlines()):
            try:
                report = json.loads(line)
            except json.JSONDecodeError:
                continue
            if report.get("event") == "stopped":
                return report["counters"]
        return None

    def __enter__(self) -> AutopilotProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

