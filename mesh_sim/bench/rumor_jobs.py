"""The runs of ``skymesh bench rumor``: one lockstep run per job, in a pool of worker processes, each stopped
early when its tracks explode.

A job is plain JSON: ``{"label", "scenario", "overrides", "edges_at"}`` — a scenario name and the
:func:`mesh_sim.scenario.load` overrides of the run, plus an optional time at which to report the radio
plan's edges (the partition row asks for the tree after the merge). :func:`run_job` returns what the
statistics (:mod:`mesh_sim.bench.rumor_stats`) need: per agent its per-target scores and its channel
timelines (:class:`agent.fusion_log.FusionLog`), the oracle's per-target scores, fusion counts and bytes.

**Diverged runs.** Double counting (``naive`` anywhere, ``exact`` on loops) makes tracks overconfident
until they fail their own association gates; new tracks start beside them, are exchanged in turn, and the
number of tracks explodes (measured: ~100 tracks per agent for 3 targets after 40 s, with a step cost
growing accordingly). A run in which an agent holds more than ``DIVERGED_TRACKS`` tracks is stopped there
(:func:`stop_on_divergence`) and scored up to that time. Likewise a run in which an agent raises (a defect:
an agent must never crash on input) is stopped at that step and the exception is reported.
"""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import traceback
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from mesh_sim.bench import common

_REPO = Path(__file__).resolve().parents[2]
DIVERGED_TRACKS = 20  # tracks held by one agent (3 targets + a few tentative) beyond which a run has diverged


def run_job(job: dict) -> dict:
    """One lockstep run (in a worker process); returns what the row statistics need."""
    from mesh_sim.lockstep import run_lockstep
    from mesh_sim.scenario import load

    scenario = load(job["scenario"], **job["overrides"])
    with tempfile.TemporaryDirectory(prefix="skymesh-bench-rumor-run-") as tmp, stop_on_divergence() as guard:
        metrics = run_lockstep(scenario, Path(tmp))
    agents = metrics["agents"]
    fusions, kinds = Counter(), Counter()
    for a in agents:
        fusions.update(a.get("fusions", {}))
        kinds.update(a.get("bytes_tx_by_kind", {}))
    out = {
        "job": job,
        "step": scenario.agent.step,
        "agents_n": scenario.agent.agents,
        "t_end": scenario.agent.duration if guard.stopped_at is None else guard.stopped_at,
        "diverged_at": guard.stopped_at if guard.error is None else None, "max_tracks": guard.max_tracks,
        "crashed_at": guard.stopped_at if guard.error is not None else None, "error": guard.error,
        "agents": [{"id": a["id"], "targets": a.get("targets", []), "channels": a.get("channels", {})}
                   for a in agents],
        "oracle_targets": metrics["oracle"].get("targets", []),
        "imm_targets": metrics["oracle"].get("imm_targets", []),
        "in_flight_targets": [t for a in agents for t in metrics["oracle"].get("in_flight", {}).get(a["id"], [])],
        "fusions": dict(fusions),
        "radio_bytes": int(sum(kinds.values())),
    }
    if job.get("edges_at") is not None:
        plan = scenario.agent.radio_plan
        out["edges"] = sorted(sorted(e) for e in plan.edges_at(job["edges_at"]))
    return out


class _Guard:
    stopped_at: float | None = None
    max_tracks: int = 0
    error: str | None = None  # set when an agent raised (a defect of the agent: it must not crash on input)


@contextmanager
def stop_on_divergence(limit: int | None = None) -> Iterator[_Guard]:
    """Stop a lockstep run whose tracks explode, keeping its metrics up to that point.

    Once an agent holds more than ``limit`` tracks (default ``DIVERGED_TRACKS``) every agent and the oracle
    stop at that step — the run's scores cover [0, stop] for everybody — and the remaining steps cost
    nothing. Done by substituting subclasses of :class:`~agent.agent.Agent` and :class:`~mesh_sim.world.World`
    into :mod:`mesh_sim.lockstep` for the duration of the block (restored afterwards)."""
    from mesh_sim import lockstep

    guard = _Guard()
    limit = DIVERGED_TRACKS if limit is None else limit
    base_agent, base_world = lockstep.Agent, lockstep.World

    class GuardedAgent(base_agent):
        def step(self, t: float) -> None:
            if guard.stopped_at is not None:
                for _ in self.transport.drain():  # a radio transport drains lazily
                    pass
                return
            try:
                super().step(t)
            except Exception as err:  # noqa: BLE001 - reported per run, the run's scores up to here are kept
                guard.stopped_at, guard.error = t, f"{self.id}: {_where(err)}"
                return
            tracks = len(self.exchanges["track"].tracker.tracks)
            guard.max_tracks = max(guard.max_tracks, tracks)
            if tracks > limit:
                guard.stopped_at = t

    class GuardedWorld(base_world):
        def absorb_measurements(self) -> None:
            if guard.stopped_at is not None:
                self.transport.drain()
                return
            super().absorb_measurements()

    lockstep.Agent, lockstep.World = GuardedAgent, GuardedWorld
    try:
        yield guard
    finally:
        lockstep.Agent, lockstep.World = base_agent, base_world


def _where(err: BaseException) -> str:
    """``Type: message (agent frame -> innermost frame)``, frames inside this repository."""
    frames = [f for f in traceback.extract_tb(err.__traceback__) if _REPO in Path(f.filename).parents]
    name = [f"{Path(f.filename).relative_to(_REPO)}:{f.lineno} {f.name}" for f in frames]
    agent = [n for n in name if n.startswith("agent/")]
    chain = list(dict.fromkeys(agent[-1:] + name[-1:]))
    return f"{type(err).__name__}: {str(err)[:120]}" + (f" ({' -> '.join(chain)})" if chain else "")


# ==================================================================================================
# the worker pool
# ==================================================================================================
def run_jobs(jobs: list[dict], workers: int, title: str) -> list[dict]:
    """Run the jobs in this process (``workers`` <= 1) or in ``workers`` worker processes, each started as
    ``python -m mesh_sim.bench.rumor_jobs --worker`` (DESIGN §1: processes start fresh, never by forking),
    fed one job at a time so that the slow runs spread over all of them. Workers are stopped by PID before
    returning. Results come back in completion order."""
    out: list[dict] = []
    with common.progress(len(jobs), title) as advance:
        if workers <= 1:
            for job in jobs:
                out.append(run_job(job))
                advance(job["label"])
            return out
        todo: queue.SimpleQueue = queue.SimpleQueue()
        for job in jobs:
            todo.put(job)
        done: queue.SimpleQueue = queue.SimpleQueue()
        pool = [_Worker() for _ in range(min(workers, len(jobs)))]
        threads = [threading.Thread(target=w.serve, args=(todo, done), daemon=True) for w in pool]
        ok = False
        try:
            for thread in threads:
                thread.start()
            for _ in jobs:
                item = done.get()
                if isinstance(item, Exception):
                    raise item
                out.append(item)
                advance(item["job"]["label"])
            ok = True
        finally:
            while not todo.empty():
                todo.get_nowait()
            for w in pool:
                w.stop(kill=not ok)
            for thread in threads:
                thread.join(timeout=10)
    return out


class _Worker:
    """One worker process: a job as a JSON line on its stdin, its result as a JSON line on its stdout."""

    def __init__(self):
        self.log = tempfile.TemporaryFile()
        self.process = subprocess.Popen(
            [sys.executable, "-m", "mesh_sim.bench.rumor_jobs", "--worker"], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, stderr=self.log, text=True, bufsize=1,
        )

    def serve(self, todo: queue.SimpleQueue, done: queue.SimpleQueue) -> None:
        while True:
            try:
                job = todo.get_nowait()
            except queue.Empty:
                return
            try:
                self.process.stdin.write(json.dumps(job) + "\n")
                self.process.stdin.flush()
                line = self.process.stdout.readline()
            except (OSError, ValueError):
                line = ""
            if not line:
                done.put(RuntimeError(f"rumor worker (pid {self.process.pid}) failed on {job['label']}:\n"
                                      f"{self._log_tail()}"))
                return
            done.put(json.loads(line))

    def _log_tail(self) -> str:
        try:
            self.log.seek(0)
            return self.log.read().decode(errors="replace")[-2000:]
        except (OSError, ValueError):
            return ""

    def stop(self, kill: bool) -> None:
        """End of input makes an idle worker exit; a busy one (on error or Ctrl-C) gets SIGTERM (it removes its
        run folder and exits), then SIGKILL after a grace period, by PID."""
        try:
            if kill:
                self.process.terminate()
            else:
                self.process.stdin.close()
            self.process.wait(timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            self.process.kill()
            self.process.wait()
        finally:
            self.log.close()


def _worker_main() -> int:
    """``python -m mesh_sim.bench.rumor_jobs --worker``: run jobs from stdin until it closes."""
    out = os.fdopen(os.dup(sys.stdout.fileno()), "w")
    sys.stdout = sys.stderr  # nothing but results goes to the result pipe
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the parent decides
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # unwinds, so the run folder is removed
    for line in sys.stdin:
        if line.strip():
            out.write(json.dumps(run_job(json.loads(line))) + "\n")
            out.flush()
    return 0


if __name__ == "__main__" and sys.argv[1:] == ["--worker"]:
    sys.exit(_worker_main())
