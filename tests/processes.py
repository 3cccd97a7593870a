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


def assert_no_children_left(timeout: float = 10.0) -> None:
    """No child process of this test process is still running after ``timeout`` seconds."""
    deadline = time.time() + timeout
    children = psutil.Process().children(recursive=True)
    while children and time.time() < deadline:
        children = [c for c in children if c.is_running() and c.status() != psutil.STATUS_ZOMBIE]
        time.sleep(0.1)
    assert children == [], f"processes left running: {[(c.pid, c.cmdline()) for c in children]}"
