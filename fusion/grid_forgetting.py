"""Forgetting: grid evidence that fades on a common clock, so a certainty grid can follow a spreading fire.

A static grid (Merino Alg. 4.2/4.4) adds every frame's evidence for ever. On a fire that spreads (Merino
§6.3) that is wrong: a cell seen unburnt many times piles up negative evidence that a later ignition must
first cancel, so the map lags the front, and a cell mapped once is never worth a second look. Merino's
answer is the prediction (6.2)-(6.6), which makes old evidence count less. That prediction is nonlinear in
the log-odds, so it does not commute with decentralized fusion: ``predict(a + b - c)`` is not
``predict(a) + predict(b) - predict(c)``, and channel filters (Merino (2.26)-(2.28), Alg. 4.3/4.5) would
no longer reproduce the centralized map.

Here, per tick of ``tick`` seconds on the clock every node shares (simulation time ``t``; tick
``k = floor(t / tick)``), every cell's evidence is multiplied by the same factor

    lambda = 2^(-tick / half_life),      e_k <- lambda e_k   (log-odds evidence l - l0, Alg. 4.2)
                                         a_k <- lambda a_k,  b_k <- lambda b_k   (Beta counts, Alg. 4.4)

— exponential forgetting, the linear surrogate (chosen here) of the transition of a cell that may change
state: the symmetric two-state chain ``p' = (1 - eps) p + eps (1 - p)`` moves the log-odds by the factor
``1 - 2 eps`` near ``p = 1/2`` (its first-order term). It is linear in the evidence, so the own grid, every
received grid and every channel filter's common grid decay alike, and ``lambda (a + b - c) = lambda a +
lambda b - lambda c``: fusion stays exact on a tree (equal to a centralized map that forgets the same way)
and conservative on loops. Grids carry the tick they are at (their ``epoch``); the channel filter advances
two grids to the newer tick before combining them (:mod:`fusion.channel_filter`).

Two effects follow: evidence is bounded (a cell seen ``r`` times a second with mean log-likelihood ratio
``m`` settles at ``r m half_life / ln 2``), so a flickering decoy's small positive drift cannot grow into an
alarm for ever; and a cell not seen for a while regains entropy, so the explorer comes back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The clock's tick [s] (chosen here): one factor per second keeps the decay smooth against 2 s messages.
DEFAULT_TICK = 1.0
#: Slack on the tick index for times that land on a tick boundary up to rounding.
_EDGE = 1e-9


@dataclass(frozen=True)
class Forgetting:
    """Evidence halves every ``half_life`` seconds, in steps of ``tick`` seconds on a common clock."""

    half_life: float
    tick: float = DEFAULT_TICK

    def __post_init__(self):
        for name in ("half_life", "tick"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"forgetting {name} must be a positive number of seconds, got {value!r}")
            object.__setattr__(self, name, float(value))

    def epoch_of(self, t: float) -> int:
        """The tick ``floor(t / tick)`` that time ``t`` [s] falls in."""
        if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t):
            raise ValueError(f"time must be a finite number of seconds, got {t!r}")
        return math.floor(t / self.tick + _EDGE)

    def factor(self, ticks: int) -> float:
        """``lambda^ticks = 2^(-ticks tick / half_life)``: what ``ticks`` ticks leave of the evidence."""
        if isinstance(ticks, bool) or not isinstance(ticks, int) or ticks < 0:
            raise ValueError(f"ticks must be a non-negative integer, got {ticks!r}")
        return 2.0 ** (-ticks * self.tick / self.half_life)
