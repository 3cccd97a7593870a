"""The time series behind a run's plots and Rerun scalars, from the per-process metrics alone.

* :func:`error_series` — per bin, one estimator's position RMSE on one target, ``sqrt(sum |e|^2 / n)``, beside its
  own predicted RMS error ``sigma = sqrt(sum trace(P_pos) / n)``: for a consistent estimator ``E|e|^2 =
  trace(P_pos)``, so the error stays mostly under ``2 sigma``. Pooled over the run (weights ``n``), the error
  series gives back the reported RMSE.
* :func:`nees_series` — per bin, the ANEES ``sum NEES / (6 n)`` of some estimators over every target, with the
  95 % χ² interval of a consistent estimator for that bin's independent samples (one per tracked target in a
  bin shorter than :data:`mesh_sim.phases.DECORRELATION_S`; :func:`mesh_sim.phases.independent_samples`,
  :func:`mesh_sim.phases.anees_interval`).
* :func:`traffic_series` — per bin, the bytes and messages an agent sent, per second (``agent.traffic``).
* :func:`link_intervals` — from the agents' neighbour changes (:mod:`mesh_sim.run_traces`), each pair's intervals
  of being reported by both ends or by one.
"""

from __future__ import annotations

import numpy as np

from agent.evaluation import BIN_S
from mesh_sim.phases import DIM, anees_interval, independent_count


def scored(metrics: dict) -> dict[str, dict[str, dict]]:
    """``{who: {target: score}}``: each agent's per-target scores, then the oracle's (``"oracle"``, last)."""
    out = {a["id"]: {t["target"]: t for t in a.get("targets", [])} for a in metrics["agents"]}
    out["oracle"] = {t["target"]: t for t in metrics["oracle"].get("targets", [])}
    return out


def error_series(target: dict) -> np.ndarray:
    """``[[t, rmse, sigma], ...]`` of one per-target score (``bins`` of :class:`agent.evaluation.TrackEvaluator`)
    at each bin's middle; ``sigma`` is NaN for bins written before the evaluator kept ``trace(P_pos)``."""
    rows = [[start + BIN_S / 2, np.sqrt(sums[0] / sums[2]), np.sqrt(sums[3] / sums[2]) if len(sums) > 3 else np.nan]
            for start, *sums in target.get("bins", []) if sums[2]]
    return np.array(rows, float).reshape(-1, 3)


def nees_series(target_lists: list[list[dict]]) -> np.ndarray:
    """``[[t, anees, low, high], ...]`` per bin with samples, pooled over every list of per-target scores. A bin is
    shorter than the decorrelation time, so its independent samples are its tracked targets, one each
    (:func:`mesh_sim.phases.independent_samples` over one bin, counted in the same pass)."""
    sums: dict[float, np.ndarray] = {}
    tracked: dict[float, set[str]] = {}
    for targets in target_lists:
        for target in targets:
            for start, *bin_sums in target.get("bins", []):
                sums[start] = sums.get(start, np.zeros(2)) + (bin_sums[1], bin_sums[2])
                if bin_sums[2]:
                    tracked.setdefault(start, set()).add(target["target"])
    rows = []
    for start, (nees, n) in sorted(sums.items()):
        if n:
            lo, hi = anees_interval(independent_count([BIN_S] * len(tracked[start])))
            rows.append([start + BIN_S / 2, nees / (DIM * n), lo, hi])
    return np.array(rows, float).reshape(-1, 4)


def traffic_series(agent: dict) -> np.ndarray:
    """``[[t, bytes/s, messages/s], ...]`` of one agent's ``traffic_bins`` at each bin's middle."""
    rows = [[start + BIN_S / 2, sent / BIN_S, messages / BIN_S]
            for start, sent, messages in agent.get("traffic_bins", [])]
    return np.array(rows, float).reshape(-1, 3)


def pair_states(reported: dict[str, set[str]]) -> dict[tuple[str, str], bool]:
    """``{(a, b): both_ends}`` (``a < b``) of every pair some agent reports as neighbours, from each agent's
    reported neighbours: the link rule of the live 3D view and of ``plots/links.png`` (green both, orange one)."""
    links: dict[tuple[str, str], bool] = {}
    for a, peers in reported.items():
        for b in peers:
            links[(a, b) if a < b else (b, a)] = a in reported.get(b, ())
    return links


def link_intervals(neighbours: dict[str, list], end: float) -> dict[tuple[str, str], list[tuple[float, float, bool]]]:
    """``{(a, b): [(t0, t1, both_ends), ...]}`` (``a < b``): when ``a`` or ``b`` reported the other as a
    neighbour, and whether both did, from each agent's ``[[t, [peer, ...]], ...]`` changes up to ``end``."""
    times = sorted({t for history in neighbours.values() for t, _ in history} | {end})
    out: dict[tuple[str, str], list[tuple[float, float, bool]]] = {}
    for t0, t1 in zip(times, times[1:], strict=False):
        reported = {a: _at(history, t0) for a, history in neighbours.items()}
        for (a, b), both in sorted(pair_states(reported).items()):
            spans = out.setdefault((a, b), [])
            if spans and spans[-1][1] == t0 and spans[-1][2] == both:
                spans[-1] = (spans[-1][0], t1, both)
            else:
                spans.append((t0, t1, both))
    return out


def _at(history: list, t: float) -> set[str]:
    """The peers of the last change at or before ``t`` (none before the first)."""
    peers: list[str] = []
    for when, reported in history:
        if when > t:
            break
        peers = reported
    return set(peers)
