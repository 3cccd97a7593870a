"""Checks that tests which start processes leave none behind (by PID, never by name)."""

from __future__ import annotations

import time

import psutil


def assert_all_gone(pids, timeout: float = 15.0) -> None:
    """Every process in ``pids`` has exited within ``timeout`` seconds (zombies count as gone)."""
    deadline = time.time() + timeout
    alive = set(pids)
    while alive and time.time() < deadline:
        alive = {p for p in alive if psutil.pid_exists(p) and psutil.Process(p).status() != psutil.STATUS_ZOMBIE}
        time.sleep(0.1)
    assert not alive, f"processes left running: {sorted(alive)}"
