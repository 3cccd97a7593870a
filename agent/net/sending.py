"""What to broadcast, and when, within the link budget.

* **Information trigger.** A confirmed track is sent when its current estimate has gained at least
  ``info_gain`` nats since it was last sent — ``1/2 log det Y_now - 1/2 log det Y_sent``, the entropy
  reduction of the current state (Merino (2.30)-(2.33)) — or when it has not been sent for
  ``max_silence`` seconds (so that peers' copies and acknowledgements stay fresh), or was never sent.
* **Budget.** A sender never exceeds its link budget (the tightest rate of its outgoing links, from the
  radio plan): a token bucket at the sender admits each message; tracks are offered by priority
  (never sent first, then largest gain) and the ones that do not fit are left for a later round —
  thinned, never queued without bound. Telemetry passes the same bucket first (it is small and
  carries the topology reports).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent.net.link_emulator import TokenBucket
from agent.net.link_plan import default_burst


@dataclass(frozen=True)
class SendConfig:
    period: float = 1.0  # s between track broadcasts; chosen here
    info_gain: float = 0.1  # nats of new information that make a track worth sending; chosen here
    max_silence: float = 3.0  # s: every confirmed track is re-sent at least this often; chosen here
    ack_timeout: float = 0.4  # s: flood policy, re-send an increment unacknowledged after a round trip (2 steps)

    def __post_init__(self):
        for name in ("period", "max_silence", "ack_timeout"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"sending.{name} must be positive, got {getattr(self, name)!r}")
        if not (np.isfinite(self.info_gain) and self.info_gain >= 0):
            raise ValueError(f"sending.info_gain must be non-negative, got {self.info_gain!r}")


class Every:
    """A periodic trigger on simulation time: due at the first call, then once ``period`` has passed since
    it last fired (a step late rather than early: times within 1e-9 s count as reached)."""

    def __init__(self, period: float):
        self.period = period
        self._next = 0.0

    def due(self, t: float) -> bool:
        if t + 1e-9 < self._next:
            return False
        self._next = t + self.period
        return True


def information(track) -> float:
    """``1/2 log det Y`` of the track's current state (its negative entropy, up to a constant)."""
    sign, logdet = np.linalg.slogdet(track.estimate().Y)
    return 0.5 * float(logdet) if sign > 0 else -np.inf


class SendScheduler:
    def __init__(self, config: SendConfig, budget: float | None, burst: float | None = None):
        self.config = config
        self.bucket = None if budget is None else TokenBucket(budget, burst or default_burst(budget))
        self.timer = Every(config.period)
        self._sent: dict[int, tuple[float, float]] = {}  # track id -> (time, information) when last sent
        self.thinned = 0  # tracks that were due but did not fit the budget

    def admit(self, size: int, t: float) -> bool:
        """May a message of ``size`` bytes leave now? (Consumes budget when it may.)"""
        return self.bucket is None or self.bucket.admit(size, t)

    def due(self, t: float) -> bool:
        return self.timer.due(t)

    def choose(self, t: float, tracks: list, entry_bytes: int) -> list:
        """The tracks to send now, by priority, within the budget."""
        ranked = []
        for track in tracks:
            now = information(track)
            if track.id not in self._sent:
                ranked.append((np.inf, track, now))
                continue
            when, then = self._sent[track.id]
            gain = now - then
            if gain >= self.config.info_gain or t - when >= self.config.max_silence - 1e-9:
                ranked.append((max(gain, 0.0) + (t - when) / self.config.max_silence, track, now))
        ranked.sort(key=lambda r: -r[0])
        chosen = []
        for _, track, now in ranked:
            if not self.admit(entry_bytes, t):
                self.thinned += 1
                continue
            chosen.append(track)
            self._sent[track.id] = (t, now)
        return chosen
