"""The launcher's side of :mod:`agent.forkserver`: agent processes forked from one that has imported them.

:class:`ForkServer` starts ``python -m agent.forkserver`` for a run's scenario and asks it for one child per agent;
each comes back as a :class:`ForkedProcess`, which answers what the launcher asks of a ``subprocess.Popen`` —
``pid``, ``poll()``, ``wait(timeout)``, ``send_signal``, ``terminate``, ``kill`` — so that deaths, restarts and the
stop by PID work as for any other child. The server is the children's parent: it reaps them and reports their exit
codes on its output, which a reader thread here collects.
"""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

UNKNOWN_EXIT = 255  # the code of a child whose end no one reported (its server died first); chosen here


class ForkServerError(OSError):
    """The fork server could not start or stopped answering; the message says why, on one line."""


class ForkedProcess:
    """One forked agent, as the launcher sees a ``subprocess.Popen``."""

    def __init__(self, pid: int, server: ForkServer):
        self.pid = pid
        self._server = server
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            self.returncode = self._server.exit_code(self.pid)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.poll() is None:
            if deadline is not None and time.monotonic() > deadline:
                raise subprocess.TimeoutExpired(f"forked agent {self.pid}", timeout)
            time.sleep(0.02)
        return self.returncode

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:
            os.kill(self.pid, sig)  # by PID; the server reaps an ended child within POLL_S and tells us

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


class ForkServer:
    """``python -m agent.forkserver --scenario SCENARIO_FILE`` with ``env``, its own errors in ``log_path``; ready
    within ``timeout`` seconds or :class:`ForkServerError`."""

    def __init__(self, scenario_file: Path, env: dict, log_path: Path, timeout: float):
        self.log_path = log_path
        self.timeout = timeout
        with open(log_path, "wb") as log:
            command = [sys.executable, "-m", "agent.forkserver", "--scenario", str(scenario_file)]
            self.process = subprocess.Popen(command,
                                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, env=env)
        self._codes: dict[int, int] = {}
        self._lock = threading.Lock()
        self._replies: queue.Queue = queue.Queue()
        self._reader = threading.Thread(target=self._read, name="forkserver-reader", daemon=True)
        self._reader.start()
        try:
            if "ready" not in self._reply("start"):
                raise ForkServerError(f"the agents' fork server did not start: {self._why()}")
        except ForkServerError:
            self.close(0.0)  # nothing of it is left running
            raise

    def _read(self) -> None:
        for line in self.process.stdout:
            try:
                message = json.loads(line)
            except ValueError:
                continue  # not ours (nothing else writes there); its log has the rest
            if "exit" in message:
                with self._lock:
                    self._codes[int(message["exit"])] = int(message["code"])
            else:
                self._replies.put(message)
        self._replies.put({})  # the server's output ended

    def _reply(self, what: str) -> dict:
        try:
            return self._replies.get(timeout=self.timeout)
        except queue.Empty:
            raise ForkServerError(f"the agents' fork server did not answer ({what}) within {self.timeout:g} s; "
                                  f"see {self.log_path}") from None

    def _why(self) -> str:
        code = self.process.poll()
        text = self.log_path.read_text(errors="replace").strip().splitlines()
        last = text[-1] if text else "no output"
        return f"{last} (exit code {code}; log {self.log_path})" if code is not None else f"{last} ({self.log_path})"

    def spawn(self, argv: list[str], log_path: Path) -> ForkedProcess:
        """``python -m agent ARGV`` as a child of the server, its output appended to ``log_path``."""
        try:
            self.process.stdin.write((json.dumps({"argv": list(argv), "log": str(log_path)}) + "\n").encode())
            self.process.stdin.flush()
        except (BrokenPipeError, ValueError):
            raise ForkServerError(f"the agents' fork server is gone: {self._why()}") from None
        answer = self._reply("fork")
        if "pid" not in answer:
            raise ForkServerError(f"the agents' fork server did not fork: {answer.get('error') or self._why()}")
        return ForkedProcess(int(answer["pid"]), self)

    def exit_code(self, pid: int) -> int | None:
        """How child ``pid`` ended, or None while it runs. Should the server die first, its orphans stop by
        themselves (their parent is gone) and end with :data:`UNKNOWN_EXIT`."""
        with self._lock:
            code = self._codes.get(pid)
        if code is not None or self.process.poll() is None:
            return code
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return UNKNOWN_EXIT
        return None

    def close(self, grace: float) -> None:
        """End the server's input: it stops the children still running, reaps them and exits; killed after
        ``grace``."""
        if self.process.stdin and not self.process.stdin.closed:
            try:
                self.process.stdin.close()
            except BrokenPipeError:
                pass
        try:
            self.process.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self._reader.join(timeout=grace)
