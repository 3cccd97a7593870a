"""The live harness: run an :class:`~agent.agent.Agent` on the wall clock, one process per agent.

Simulation time is ``t = (wall - epoch) * speed``, with ``epoch`` and ``speed`` given by the launcher,
so every process of a run shares one clock without exchanging it. Step ``k`` runs at ``t = k * dt``;
a step that ends after the next one was due is a deadline miss, and when the agent is late by more
than a step it skips ahead to the current time (tracks then advance over several grid epochs) rather
than falling further behind.

The process stops at the end of the scenario, on SIGTERM or SIGINT, or when its parent dies (the
launcher never leaves orphans, and a child never outlives a launcher that was killed).
"""

from __future__ import annotations

import json
import logging
import math
import os
import resource
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import numpy as np

log = logging.getLogger("skymesh.runtime")

EXIT_USAGE = 2  # a bad setting or a bad environment (unwritable folder, full disk, no router): nothing was done


def usage_error(prog: str, err: Exception | str) -> int:
    """Say ``prog: what went wrong`` as one line on stderr (no traceback) and return :data:`EXIT_USAGE`: the one
    way every skymesh command and process reports a bad setting or a bad environment. An ``OSError`` reads
    ``FILE: reason`` (Python's ``[Errno N]`` prefix is noise to a user)."""
    if isinstance(err, OSError) and err.strerror:
        text = f"{err.filename}: {err.strerror}" if err.filename else err.strerror
    else:
        text = str(err)
    print(f"{prog}: {text}", file=sys.stderr)
    return EXIT_USAGE


@dataclass(frozen=True)
class SimClock:
    epoch: float  # wall-clock time [s since the Unix epoch] of simulation time 0
    speed: float = 1.0  # simulation seconds per wall second

    def __post_init__(self):
        if not self.speed > 0:
            raise ValueError(f"clock speed must be positive, got {self.speed}")

    def now(self) -> float:
        return (time.time() - self.epoch) * self.speed

    def wall(self, t: float) -> float:
        return self.epoch + t / self.speed


def wait_for_epoch(epoch_file: Path, ready_file: Path, stop: threading.Event, parent_pid: int | None,
                   timeout: float = 120.0) -> float | None:
    """Say "ready" (create ``ready_file``) and wait for the launcher to publish the start time in
    ``epoch_file`` once every process is ready — so a slow start on a busy machine costs no steps.
    Returns ``None`` if stopped, orphaned or timed out first."""
    Path(ready_file).touch()
    deadline = time.time() + timeout
    while not stop.is_set() and time.time() < deadline:
        if parent_pid is not None and not parent_alive(parent_pid):
            return None
        try:
            return float(Path(epoch_file).read_text())
        except (OSError, ValueError):
            stop.wait(0.02)
    return None


def install_stop_handlers(stop: threading.Event) -> None:
    """SIGTERM and SIGINT set ``stop`` instead of killing the process mid-write."""
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())


def parent_alive(parent_pid: int) -> bool:
    return os.getppid() == parent_pid


@dataclass
class LoopStats:
    steps: int = 0
    deadline_misses: int = 0
    skipped_steps: int = 0
    cpu_s: float = 0.0
    step_wall_s: list[float] = field(default_factory=list)  # wall time of each step (a thread's work included)

    def as_dict(self) -> dict:
        walls = [1e3 * w for w in self.step_wall_s]
        return {
            "step_wall_ms_median": float(np.median(walls)) if walls else None,
            "step_wall_ms_p95": float(np.percentile(walls, 95)) if walls else None,
            "deadline_misses": self.deadline_misses,
            "skipped_steps": self.skipped_steps,
            "cpu_per_step_ms": 1e3 * self.cpu_s / self.steps if self.steps else None,
            "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        }


def staggered_phase(index: int, count: int, dt: float) -> float:
    """``dt * index / count``: the phase at which agent ``index`` of ``count`` runs its steps, so that the agents
    of one machine wake one after another over the step instead of all at once (real UAVs' loops are not in
    phase either). With N processes on fewer cores, waking together queues N steps behind each other at every
    grid time; spread out, each finds the cores that the previous one left."""
    if count < 1 or not 0 <= index:
        raise ValueError(f"need 0 <= index and count >= 1, got index {index}, count {count}")
    return dt * (index % count) / count


def run_steps(step_fn, clock: SimClock, dt: float, duration: float, stop: threading.Event,
              parent_pid: int | None = None, phase: float = 0.0) -> LoopStats:
    """Call ``step_fn(t)`` at ``t = k dt`` on ``clock`` until ``duration``, ``stop`` or orphaning, from the first
    grid time not yet past (0 at a normal start, the present for a process restarted mid-run); each call is
    made ``phase`` simulation seconds after its grid time (``0 <= phase < dt``, :func:`staggered_phase`), and
    its deadline is the next call's time.

    ``parent_pid`` is the launcher's PID as the launcher gave it: checking against ``os.getppid()`` taken
    here would miss a launcher that died while this process was still importing."""
    if not 0 <= phase < dt:
        raise ValueError(f"phase must be in [0, dt = {dt}), got {phase}")
    stats = LoopStats()
    parent = os.getppid() if parent_pid is None else parent_pid
    k = max(0, math.floor((clock.now() - phase) / dt))  # a process started mid-run (a restart) joins the present
    while not stop.is_set() and k * dt <= duration + 1e-9:
        t = k * dt
        delay = clock.wall(t + phase) - time.time()
        if delay > 0 and stop.wait(delay):
            break
        if not parent_alive(parent):
            log.error("parent process is gone; stopping")
            break
        cpu, wall = time.process_time(), time.perf_counter()
        step_fn(t)
        stats.cpu_s += time.process_time() - cpu
        stats.step_wall_s.append(time.perf_counter() - wall)
        stats.steps += 1
        if time.time() > clock.wall(t + dt + phase):
            stats.deadline_misses += 1
        k_next = max(k + 1, int((clock.now() - phase) / dt))
        stats.skipped_steps += k_next - k - 1
        k = k_next
    return stats


@contextmanager
def atomic_file(path: str | Path, mode: str = "w") -> Iterator[IO]:
    """Open a temporary file beside ``path`` for writing; when the block ends cleanly it replaces ``path``
    (``os.replace``, atomic on one file system), and when it raises (a full disk, a write that failed) the
    temporary file is removed and ``path`` is left as it was. So a reader never sees half a file, and a failed
    write leaves nothing half-written behind. An ``OSError`` of the writing names ``path`` (a failed ``write`` alone
    would name nothing, a failed ``open`` the temporary file)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, mode) as f:
            yield f
        os.replace(tmp, path)
    except BaseException as err:
        with suppress(OSError):  # never created (a read-only folder), or gone already
            tmp.unlink()
        if isinstance(err, OSError) and err.errno is not None and err.filename in (None, str(tmp)):
            raise OSError(err.errno, err.strerror, str(path)) from err
        raise


def write_json(path: str | Path, data: dict) -> None:
    """Write ``data`` as JSON atomically (:func:`atomic_file`), so a reader never sees half a file."""
    with atomic_file(path) as f:
        f.write(json.dumps(data, indent=2, default=_plain))


def _plain(value):
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")
