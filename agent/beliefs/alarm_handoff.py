"""The grid-to-information-filter hand-off of an alarm (Merino Ch. 8, (8.1)): where each alarm is.

An alarm's state is ``x = (P, theta)``, estimated by separate filters (spec 001b §2.8): the class ``theta`` by
the certainty grid (the region's mean cell probability, (4.20)), the position ``P`` by the decentralized
information filter. Here the filter is the agent's tracker: the thermal camera's hot spots inside an alarm's
gate are its measurements (:mod:`agent.sensors.hot_spots`), and its tracks are fused with the peers' through
channel filters like target tracks. :func:`located_alarms` reports every grid alarm at the position of the
confirmed track inside its gate (at each of its tracks that are cells apart: two fires one grid region merged),
or at the grid's (4.20) mean while no track holds it (before the first look, or once its track went stale).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from agent.sensors.hot_spots import GATE, gate_distance
from fusion.gaussian import Gaussian
from fusion.grid_alarms import Alarm

SEPARATE_CELLS = 2.0  # tracks of one alarm farther apart than this many cells are separate fires (chosen here)


def located_alarms(alarms: Sequence[Alarm], tracks: Sequence[tuple[int, Gaussian]], cell: float) -> list[dict]:
    """Each alarm as ``{"mean", "cov", "probability", "track", "alarm"}`` entries (``"alarm"`` its index): the
    (north, east) marginal of a confirmed track, ``"track"`` its id, or the alarm's own Gaussian (``"track"``
    ``None``) while no track holds it. A track locates only the alarm whose gate it is deepest in (smallest
    ``d^2``: a small fire's track inside the wide gate of a large neighbour stays with its own alarm), and an alarm
    takes the most certain of its tracks (smallest ``det``: a stale duplicate has grown) — and, as separate fires,
    every other track farther than :data:`SEPARATE_CELLS` cells from those it took (a grid region that merged a
    fire and a spot fire beside it is two fires to the camera)."""
    held: dict[int, list[tuple[float, int, Gaussian]]] = {}  # alarm index -> (det, track id, estimate)
    for track_id, est in tracks:
        distances = [gate_distance(est.mean[:2], alarm, cell) for alarm in alarms]
        if not distances or min(distances) > GATE:
            continue
        held.setdefault(int(np.argmin(distances)), []).append((float(np.linalg.det(est.cov[:2, :2])), track_id, est))
    out = []
    for k, alarm in enumerate(alarms):
        taken: list[tuple[int, Gaussian]] = []
        for _, track_id, est in sorted(held.get(k, []), key=lambda held_track: held_track[:2]):
            if all(np.hypot(*(est.mean[:2] - other.mean[:2])) > SEPARATE_CELLS * cell for _, other in taken):
                taken.append((track_id, est))
        if not taken:
            out.append({"mean": alarm.mean, "cov": alarm.cov, "probability": alarm.probability, "track": None,
                        "alarm": k})
        out.extend({"mean": est.mean[:2].copy(), "cov": est.cov[:2, :2].copy(), "probability": alarm.probability,
                    "track": int(track_id), "alarm": k} for track_id, est in taken)
    return out
