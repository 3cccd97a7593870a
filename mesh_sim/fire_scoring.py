"""Scoring a fire map against the truth: alarms, detection, false-alarm rejection, localisation, KL.

Merino's field figures (001b §4.4, COMETS) are a detection rate above 95 %, false-alarm rejection
above 80 % and a localisation error below 1 m. Here, for one probability grid and one threshold:

* the alarms are the grid's connected regions above the threshold (Merino (4.20));
* a true fire region is **detected** when an alarm's mean lies within its match radius,
  ``sqrt(area / pi) + MATCH_CELLS * cell`` (its equivalent-disc radius plus a margin, chosen here);
  the **localisation error** is the distance from that alarm's mean to the region's centroid;
* a **decoy** (a transient hot spot) is **rejected** when no alarm lies within ``MATCH_CELLS * cell`` of
  it; alarms that match neither a fire nor a decoy are counted as other false alarms.

Sweeping the threshold gives the operating curve (ROC) of Merino Fig. 4.10/4.21.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fusion.grid_alarms import extract_alarms
from fusion.grid_geometry import GridGeometry

MATCH_CELLS = 2.0  # margin of a match, in cells (chosen here)
THRESHOLDS = (0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.99)  # the ROC sweep (chosen here)


def score_alarms(probability: np.ndarray, geometry: GridGeometry, regions: Sequence[dict],
                 decoys: Sequence[Sequence[float]], threshold: float) -> dict:
    """Detection, decoy rejection and localisation of the alarms of one grid at one threshold.

    ``regions``: true fire regions ``{"centroid": (n, e), "area_m2": a}``; ``decoys``: ``(n, e, ...)``."""
    alarms = extract_alarms(probability, geometry, threshold)
    means = np.array([a.mean for a in alarms], float).reshape(-1, 2)
    return {"threshold": threshold, **score_positions(means, geometry.cell, regions, decoys)}


def score_positions(means: np.ndarray, cell: float, regions: Sequence[dict], decoys: Sequence[Sequence[float]]) -> dict:
    """Detection, decoy rejection and localisation of alarms at ``means`` (k, 2) north, east [m]: the grid's own
    (:func:`score_alarms`) or where the agents report them (:mod:`agent.beliefs.alarm_handoff`)."""
    means = np.asarray(means, float).reshape(-1, 2)
    used = np.zeros(len(means), bool)
    errors = []
    for region in regions:
        centroid = np.asarray(region["centroid"], float)
        radius = math.sqrt(region["area_m2"] / math.pi) + MATCH_CELLS * cell
        d = np.linalg.norm(means - centroid, axis=1) if len(means) else np.empty(0)
        if d.size and d.min() <= radius:
            best = int(np.argmin(d))
            used[best] = True
            errors.append(float(d[best]))
    rejected = 0
    for decoy in decoys:
        d = np.linalg.norm(means - np.asarray(decoy[:2], float), axis=1) if len(means) else np.empty(0)
        near = d <= MATCH_CELLS * cell
        if not near.any():
            rejected += 1
        used |= near
    return {
        "alarms": len(means),
        "fires": len(regions),
        "detected": len(errors),
        "detection_rate": len(errors) / len(regions) if regions else None,
        "decoys": len(decoys),
        "decoys_rejected": rejected,
        "false_alarm_rejection": rejected / len(decoys) if decoys else None,
        "other_false_alarms": int((~used).sum()),
        "localisation_error_m": float(np.mean(errors)) if errors else None,
    }


def roc(probability: np.ndarray, geometry: GridGeometry, regions, decoys, thresholds=THRESHOLDS) -> list[dict]:
    return [score_alarms(probability, geometry, regions, decoys, th) for th in thresholds]

