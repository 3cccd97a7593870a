"""``python -m agent.forkserver``: start a run's agent processes by forking one that has imported them already.

An agent process spends most of its private memory on the modules it imports (numpy, SciPy's linear algebra and
optimisation, Zenoh, OpenCV with a camera: about 45 MB of 70) and a second or more of CPU importing them; with
N processes each pays both. This server imports them once — it builds a throwaway :class:`agent.agent.Agent` of
the scenario over an in-memory bus and steps it, so that exactly the modules an agent of *this* scenario imports
are loaded (OpenCV only with a camera, never matplotlib or Rerun: issue 12's lean processes) and its one-time work
is done (:mod:`agent.warmup`) — freezes the garbage collector's view of them (``gc.freeze``: a collection then
never writes to those pages) and forks one child per agent. A child shares the server's pages until it writes to
them (copy-on-write), so what it imported costs it nothing until used. Measured (16 camera agents of ``default``,
each stepping 60 times over its own bus): proportional set size 70.4 MB per spawned process against 27.7 MB per
forked one (plus 44 MB for the server, shared by all); 16 ready in 3 s instead of 14.

Each child is then exactly ``python -m agent ARGS`` (:func:`agent.__main__.main`), with its output in its own
log. The server opens no Zenoh session and starts no thread before it forks (a fork copies only the calling
thread: a runtime's worker threads would be lost in the child); every child opens its own session.

**Protocol** (one JSON object per line; the launcher's side is :class:`mesh_sim.forked.ForkServer`):

* the launcher writes ``{"argv": [...], "log": PATH}``; the server forks, and answers ``{"pid": N}``;
* when a child ends, the server (its parent) reaps it and writes ``{"exit": N, "code": C}``, ``C`` negative when a
  signal killed it (``subprocess``'s convention);
* a request it cannot read is answered ``{"error": "..."}`` and changes nothing;
* end of input (the launcher closed the pipe after stopping them, or died): the server stops the children still
  running — SIGTERM, SIGKILL after :data:`GRACE_S` — reaps them and exits. An agent started with ``--parent-pid``
  watches the server, its parent, instead (the value is replaced), so children also stop by themselves should the
  server be killed, as they do when a launcher that spawned them is.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import json
import os
import selectors
import signal
import sys
import time
import traceback

POLL_S = 0.1  # seconds between reaping rounds while no request arrives (chosen here)
GRACE_S = 10.0  # seconds between SIGTERM and SIGKILL for the children left at the end (the launcher's GRACE_S)


def preload(scenario_file: str) -> None:
    """Import what an agent of this scenario imports, and do its one-time work: the agent's entry point, and a
    throwaway agent stepped and dropped (:func:`agent.warmup.warm_up`: its sensor, planner and beliefs import their
    modules as they are built, and its first steps fill the per-process caches). A MAVLink vehicle is not built
    (it would connect to an autopilot): its agents import the rest themselves."""
    import agent.__main__  # noqa: F401  (the entry point and its imports: the agent, Zenoh, the runtime)
    from agent.config import AgentScenario, read_scenario_file
    from agent.warmup import warm_up

    warm_up(AgentScenario.from_dict(read_scenario_file(scenario_file)))


def with_parent(argv: list[str], parent: int) -> list[str]:
    """``argv`` with the value of every ``--parent-pid`` replaced by ``parent`` (the forked agent's parent)."""
    out = list(argv)
    for i, arg in enumerate(out[:-1]):
        if arg == "--parent-pid":
            out[i + 1] = str(parent)
    return out


def _child(argv: list[str], log: str) -> None:
    """In the forked child: its output to ``log``, no input, default signal handling, then the agent. Never
    returns."""
    code = 1
    try:
        for sig in (signal.SIGCHLD, signal.SIGTERM, signal.SIGINT, signal.SIGPIPE):
            signal.signal(sig, signal.SIG_DFL)
        fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.close(null)
        from agent.__main__ import main

        sys.argv = ["python -m agent", *argv]
        code = main(argv)
    except SystemExit as done:  # argparse's usage errors
        code = done.code if isinstance(done.code, int) else 2
    except BaseException:  # noqa: BLE001 - whatever happened is in the child's log, not the server's
        traceback.print_exc()
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code or 0)


class Server:
    """Forks children on request and reports their ends (the protocol of the module docstring)."""

    def __init__(self, out=None):
        self.out = out or sys.stdout
        self.children: set[int] = set()

    def say(self, message: dict) -> None:
        self.out.write(json.dumps(message) + "\n")
        self.out.flush()

    def handle(self, line: str) -> None:
        try:
            request = json.loads(line)
            argv, log = request["argv"], request["log"]
            if not (isinstance(argv, list) and all(isinstance(a, str) for a in argv) and isinstance(log, str)):
                raise ValueError("argv must be a list of strings and log a path")
        except (ValueError, KeyError, TypeError) as err:
            self.say({"error": f"bad request {line.strip()[:200]!r}: {err}"})
            return
        pid = os.fork()
        if pid == 0:
            _child(with_parent(argv, os.getppid()), log)
        self.children.add(pid)
        self.say({"pid": pid})

    def reap(self) -> None:
        while self.children:
            try:
                pid, status = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                self.children.clear()
                return
            if pid == 0:
                return
            self.children.discard(pid)
            self.say({"exit": pid, "code": os.waitstatus_to_exitcode(status)})  # subprocess's convention

    def serve(self, fd: int) -> None:
        """Requests from file descriptor ``fd`` until it ends, then the children's ends."""
        pending = b""
        with selectors.DefaultSelector() as selector:
            selector.register(fd, selectors.EVENT_READ)
            while True:
                if selector.select(timeout=POLL_S):
                    chunk = os.read(fd, 1 << 16)
                    if not chunk:
                        break
                    *lines, pending = (pending + chunk).split(b"\n")
                    for line in lines:
                        self.handle(line.decode("utf-8", "replace"))
                self.reap()
        self.stop()

    def stop(self) -> None:
        """SIGTERM the children still running (by PID), SIGKILL them after :data:`GRACE_S`, and reap them all."""
        self.reap()
        self._signal(signal.SIGTERM)
        deadline = time.monotonic() + GRACE_S
        while self.children:
            if time.monotonic() > deadline:
                self._signal(signal.SIGKILL)
                deadline = float("inf")
            time.sleep(POLL_S)
            self.reap()

    def _signal(self, sig: int) -> None:
        for pid in self.children:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, sig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m agent.forkserver", description=__doc__.splitlines()[0])
    p.add_argument("--scenario", required=True, help="the run's scenario.json (what the agents will import)")
    args = p.parse_args(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the launcher's to handle; it closes our input
    try:
        preload(args.scenario)
    except (OSError, ValueError) as err:
        print(f"agent forkserver: cannot preload {args.scenario}: {err}", file=sys.stderr)
        return 2
    gc.freeze()  # what is imported stays untouched by collections: shared with every child until it writes
    server = Server()
    server.say({"ready": os.getpid()})
    server.serve(sys.stdin.fileno())
    return 0


if __name__ == "__main__":
    sys.exit(main())
