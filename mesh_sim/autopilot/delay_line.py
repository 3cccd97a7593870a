"""A constant one-way delay: items come out ``delay`` seconds after they went in, in order.

The simulator delays every datagram in both directions of a link by the configured latency, so an
offboard computer sees telemetry that is ``delay`` old and its setpoints act ``delay`` late — what the
agent's latency compensation must cope with on a real radio link (Ross et al., spec 002: 430 ms).
"""

from __future__ import annotations

from collections import deque


class DelayLine:
    def __init__(self, delay: float = 0.0):
        if not delay >= 0:
            raise ValueError(f"delay must be a non-negative number of seconds, got {delay!r}")
        self.delay = float(delay)
        self._queue: deque = deque()

    def __len__(self) -> int:
        return len(self._queue)

    def push(self, now: float, item) -> None:
        self._queue.append((now + self.delay, item))

    def pop_due(self, now: float) -> list:
        out = []
        while self._queue and self._queue[0][0] <= now:
            out.append(self._queue.popleft()[1])
        return out

    def next_due(self) -> float | None:
        return self._queue[0][0] if self._queue else None
