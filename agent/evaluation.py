"""Scoring estimates against the truth: position RMSE, ANEES and time to first track, per target.

At each evaluation the target is matched to the estimate nearest to it in Mahalanobis distance over
position, accepted if ``d^2`` is inside ``gate`` (chi-square(3) 99.9 % by default). NEES is the full
6-D ``(x - mu)^T P^-1 (x - mu)``; ``anees`` is its average divided by the state dimension, so 1.0 is
perfectly consistent (Bar-Shalom et al., *Estimation with Applications to Tracking*, §5.4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion.gaussian import Gaussian

MATCH_GATE = 16.27  # chi-square(3) 99.9 %; chosen here


@dataclass
class _TargetScore:
    squared_errors: float = 0.0
    nees: float = 0.0
    count: int = 0
    first_track_t: float | None = None


class TrackEvaluator:
    """Accumulates per-target scores over a run."""

    def __init__(self, gate: float = MATCH_GATE):
        self.gate = gate
        self.scores: dict[str, _TargetScore] = {}
        self.t0: float | None = None

    def record(self, t: float, truth: list[dict], estimates: list[tuple[int, Gaussian]]) -> None:
        """Score the estimates at time ``t`` against the true targets (``{"id", "position", "velocity"}``)."""
        self.t0 = t if self.t0 is None else self.t0
        for target in truth:
            score = self.scores.setdefault(target["id"], _TargetScore())
            state = np.concatenate([target["position"], target["velocity"]])
            best = _nearest(state, estimates, self.gate)
            if best is None:
                continue
            err = best.mean[:3] - state[:3]
            score.squared_errors += float(err @ err)
            score.nees += best.nees(state)
            score.count += 1
            if score.first_track_t is None:
                score.first_track_t = t - self.t0

    def summary(self) -> list[dict]:
        """``[{"target", "rmse", "anees", "time_to_first_track", "samples"}]`` (None where never tracked)."""
        out = []
        for target, s in sorted(self.scores.items()):
            out.append({
                "target": target,
                "rmse": float(np.sqrt(s.squared_errors / s.count)) if s.count else None,
                "anees": s.nees / (s.count * 6) if s.count else None,
                "time_to_first_track": s.first_track_t,
                "samples": s.count,
            })
        return out


def _nearest(state: np.ndarray, estimates: list[tuple[int, Gaussian]], gate: float) -> Gaussian | None:
    best, best_d2 = None, gate
    for _, est in estimates:
        d = est.mean[:3] - state[:3]
        d2 = float(d @ np.linalg.solve(est.cov[:3, :3], d))
        if d2 <= best_d2:
            best, best_d2 = est, d2
    return best
