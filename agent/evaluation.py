"""Scoring estimates against the truth: position RMSE, ANEES and time to first track, per target.

At each evaluation the target is matched to the estimate nearest to it in Mahalanobis distance over
position, accepted if ``d^2`` is inside ``gate`` (chi-square(3) 99.9 % by default). NEES is the full
6-D ``(x - mu)^T P^-1 (x - mu)``; ``anees`` is its average divided by the state dimension, so 1.0 is
perfectly consistent (Bar-Shalom et al., *Estimation with Applications to Tracking and Navigation*, 2001, §5.4).

Each target's summary also has a ``tail``: the same figures over the last ``tail_s`` seconds before the
newest evaluation only, e.g. to see estimates re-converge after a partition heals, which the whole-run
figures dilute. And a ``bins`` list, ``[start_s, squared_errors, nees, samples, position_variance]`` per
:data:`BIN_S` time bin (simulation time; a bin starts at ``k BIN_S``) that has samples: the sums behind the
figures, so that any interval of whole bins can be pooled afterwards (:mod:`mesh_sim.phases`) without keeping
every sample, and the sum of ``trace(P_pos)`` — the squared error the estimator expects, ``E|e|^2 = trace(P_pos)``
for a consistent one — so that the error over time can be drawn against the estimator's own ``sigma``
(:mod:`mesh_sim.plots.errors`).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from fusion.gaussian import Gaussian
from fusion.trajectory import grid_epoch

MATCH_GATE = 16.27  # chi-square(3) 99.9 %; chosen here
TAIL_S = 10.0  # s: the final part of a run that is also summarised on its own; chosen here
BIN_S = 1.0  # s: the width of the time bins the sums are also kept in; chosen here


@dataclass
class _TargetScore:
    squared_errors: float = 0.0
    nees: float = 0.0
    count: int = 0
    first_track_t: float | None = None
    bins: dict[int, list] = field(default_factory=dict)  # bin index -> [squared errors, nees, count, trace(P_pos)]


class TrackEvaluator:
    """Accumulates per-target scores over a run."""

    def __init__(self, gate: float = MATCH_GATE, tail_s: float = TAIL_S):
        self.gate = gate
        self.tail_s = tail_s
        self.scores: dict[str, _TargetScore] = {}
        self.t0: float | None = None
        self._recent: deque = deque()  # (t, target, squared error, nees) of the last tail_s seconds

    def record(self, t: float, truth: list[dict], estimates: list[tuple[int, Gaussian]]) -> None:
        """Score the estimates at time ``t`` against the true targets (``{"id", "position", "velocity"}``)."""
        self.t0 = t if self.t0 is None else self.t0
        while self._recent and self._recent[0][0] < t - self.tail_s - 1e-9:
            self._recent.popleft()
        for target in truth:
            score = self.scores.setdefault(target["id"], _TargetScore())
            state = np.concatenate([target["position"], target["velocity"]])
            best = _nearest(state, estimates, self.gate)
            if best is None:
                continue
            err = best.mean[:3] - state[:3]
            squared_error, nees = float(err @ err), best.nees(state)
            score.squared_errors += squared_error
            score.nees += nees
            score.count += 1
            sums = score.bins.setdefault(grid_epoch(t, BIN_S), [0.0, 0.0, 0, 0.0])
            sums[0] += squared_error
            sums[1] += nees
            sums[2] += 1
            sums[3] += float(np.trace(best.cov[:3, :3]))
            self._recent.append((t, target["id"], squared_error, nees))
            if score.first_track_t is None:
                score.first_track_t = t - self.t0

    def summary(self) -> list[dict]:
        """``[{"target", "rmse", "anees", "time_to_first_track", "samples", "tail", "bins"}]`` (None where
        never tracked); ``tail`` is ``{"window_s", "rmse", "anees", "samples"}`` over the last ``tail_s`` seconds,
        ``bins`` the ``[start_s, squared_errors, nees, samples, position_variance]`` of each :data:`BIN_S` bin
        with samples (``position_variance``: the sum of ``trace(P_pos)``)."""
        tails: dict[str, _TargetScore] = {}
        for _, target, squared_error, nees in self._recent:  # record() keeps only the last tail_s seconds
            tail = tails.setdefault(target, _TargetScore())
            tail.squared_errors += squared_error
            tail.nees += nees
            tail.count += 1
        out = []
        for target, s in sorted(self.scores.items()):
            out.append({
                "target": target, **_figures(s),
                "time_to_first_track": s.first_track_t,
                "tail": {"window_s": self.tail_s, **_figures(tails.get(target, _TargetScore()))},
                "bins": [[k * BIN_S, *sums] for k, sums in sorted(s.bins.items())],
            })
        return out


def _figures(s: _TargetScore) -> dict:
    return {
        "rmse": float(np.sqrt(s.squared_errors / s.count)) if s.count else None,
        "anees": s.nees / (s.count * 6) if s.count else None,
        "samples": s.count,
    }


def _nearest(state: np.ndarray, estimates: list[tuple[int, Gaussian]], gate: float) -> Gaussian | None:
    best, best_d2 = None, gate
    for _, est in estimates:
        d = est.mean[:3] - state[:3]
        d2 = float(d @ np.linalg.solve(est.cov[:3, :3], d))
        if d2 <= best_d2:
            best, best_d2 = est, d2
    return best
