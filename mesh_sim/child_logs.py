"""Why a child process failed, from its log: the line a user needs, not the whole log.

A Python process that fails ends its log either with a one-line usage error (``agent uav0: the Zenoh router could
not be reached (…)``, :func:`agent.runtime.usage_error`) or with a traceback, whose exception line is the first
line after the last ``Traceback`` header that is not an indented frame (an exception's message may go on over
more lines, e.g. rerun-sdk's install advice: the first is the one that says what went wrong). Terminal colour codes
are removed.
"""

from __future__ import annotations

import re
from pathlib import Path

TAIL_BYTES = 64 * 1024  # read at most this much of the end of a log (chosen here: tracebacks are a few kB)
TRACEBACK = "Traceback (most recent call last):"
_ANSI = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")


def last_meaningful_line(log_path: Path) -> str | None:
    """The exception line of the log's last traceback, else its last non-blank line; ``None`` for a log that is
    empty or cannot be read."""
    try:
        with open(log_path, "rb") as f:
            f.seek(max(0, f.seek(0, 2) - TAIL_BYTES))
            text = f.read().decode("utf-8", "replace")
    except OSError:
        return None
    lines = [line.rstrip() for line in _ANSI.sub("", text).splitlines() if line.strip()]
    if not lines:
        return None
    if TRACEBACK in lines:
        after = lines[len(lines) - 1 - lines[::-1].index(TRACEBACK) + 1:]
        exception = next((line for line in after if not line[0].isspace()), None)
        if exception is not None:
            return exception
    return lines[-1]


def failure_text(name: str, pid: int, what: str, log_path: Path) -> str:
    """``observer (pid 123) exited with code 1: RuntimeError: … (log: run/logs/observer.log)``: what happened
    to the process, why (:func:`last_meaningful_line`) and where the whole story is."""
    line = last_meaningful_line(log_path)
    return f"{name} (pid {pid}) {what}" + (f": {line}" if line else "") + f" (log: {log_path})"
