"""Track start-up from two detections: the first one outside every gate is held as a *candidate* — a ground point,
no trajectory — and a tentative track starts only when a detection of another scan falls in its gate.

This is initiation from two detections (S. Blackman and R. Popoli, *Design and Analysis of Modern Tracking Systems*,
Artech House, 1999, on track initiation): a false alarm seldom has a partner, so it never costs a trajectory window.
Under ``flood`` every agent runs the tracker on every agent's detections, so each false alarm of the fleet started a
tentative track in every agent, predicted, gated and deleted there: with 24 bearing agents 8.5 of the 11.5 tracks an
agent held were such, and a lockstep step cost 8.5 ms against 5.1 ms without false alarms.

A candidate's gate is the tentative track's own, in closed form. The track would start from the position
measurement ``N(p, C)`` at the detection's epoch, under the motion model's prior on the velocity ``N(0, S_v)`` —
the stationary velocity of ``damped``, the pseudo-prior of ``constant_velocity`` — which the position tells
nothing about (its own prior is flat). So its position ``k`` steps later, or earlier, is ``N(p, C + G_|k|)`` with

    G_k = [F^k diag(0, S_v) F^kT + sum_{j<k} F^j Q F^jT]_pos

(the process ``x_{k+1} = F x_k + w``, ``w ~ N(0, Q)``, Merino (3.27); the position rows of ``F^k`` are
``[I, .]``, so ``C`` passes unchanged; both models are reversible, so a peer's older detection is gated with
``G`` of the same lag). ``tests/agent/beliefs/test_track_candidates.py`` checks it against the tentative track's
own marginals. A candidate expires as the track would have been deleted: ``confirm_within`` steps after it was
made, or when its position's largest standard deviation exceeds ``max_position_std``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion.measurement import bearing_gate_distances


@dataclass(frozen=True, eq=False)  # compared by identity: it holds arrays
class Candidate:
    bearing: object  # the detection (agent.beliefs.tracking.Bearing)
    position: np.ndarray  # its ground point (3,) and the point's covariance (3, 3)
    cov: np.ndarray
    epoch: int  # the detection's epoch
    created: int  # the tracker's epoch when it was held (the tentative track's created_epoch)
    scan: int  # the scan it came in: a detection of the same scan is another object, never its partner


def position_spread(F: np.ndarray, Q: np.ndarray, velocity_cov: np.ndarray, steps: int) -> np.ndarray:
    """``G_k`` of the module docstring for ``k = 0 .. steps``: ``(steps + 1, 3, 3)``."""
    n, d = F.shape[0], velocity_cov.shape[0]
    P = np.zeros((n, n))
    P[n - d :, n - d :] = velocity_cov
    out = [np.zeros((d, d))]
    for _ in range(steps):
        P = F @ P @ F.T + Q  # the prediction of the state's covariance, one step
        out.append(P[:d, :d].copy())
    return np.array(out)


class Candidates:
    """The held first detections of one tracker."""

    def __init__(self, spread: np.ndarray, confirm_within: int, max_position_std: float):
        self.spread = spread  # position_spread(...) up to the longest lag a candidate can live
        self.confirm_within = confirm_within
        self.max_var = max_position_std**2
        self.held: list[Candidate] = []

    def __len__(self) -> int:
        return len(self.held)

    def hold(self, candidate: Candidate) -> None:
        self.held.append(candidate)

    def expire(self, epoch: int, oldest: int) -> None:
        """Drop the candidates whose track would have been deleted by ``epoch`` (tentative for ``confirm_within``
        steps, or its position too uncertain), or whose detection left the window (``oldest``)."""
        keep = [c for c in self.held if epoch - c.created < self.confirm_within and c.epoch >= oldest]
        if keep:
            lags = np.minimum([epoch - c.epoch for c in keep], len(self.spread) - 1)
            covs = np.array([c.cov for c in keep]) + self.spread[lags]
            certain = np.linalg.eigvalsh(covs).max(axis=1) <= self.max_var
            keep = [c for c, ok in zip(keep, certain, strict=True) if ok]
        self.held = keep

    def take(self, bearing, epoch: int, scan: int, gate: float) -> Candidate | None:
        """The candidate of another scan nearest to ``bearing`` (at grid index ``epoch``) within ``gate`` in
        Merino (3.64)'s ``d^2``, removed from the held ones; None if there is none."""
        others = [c for c in self.held if c.scan != scan]
        if not others:
            return None
        lags = np.minimum([abs(epoch - c.epoch) for c in others], len(self.spread) - 1)
        covs = np.array([c.cov for c in others]) + self.spread[lags]
        d2 = bearing_gate_distances(np.asarray(bearing.sensor, float)[None], np.asarray(bearing.azel, float)[None],
                                    np.asarray(bearing.R, float)[None], np.array([c.position for c in others]),
                                    covs)[0]
        d2 = np.where(np.isfinite(d2), d2, np.inf)
        best = int(np.argmin(d2))
        if d2[best] > gate:
            return None
        self.held.remove(others[best])
        return others[best]
