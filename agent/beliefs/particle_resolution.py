"""When a belief about each target became *resolved*: unimodal and close to the truth (skymesh issue 15).

The metric of the ambiguous scenario, for an agent (:mod:`agent.beliefs.particles`) and for the centralized
particle filter (:mod:`mesh_sim.particle_oracle`) alike: a target is resolved at time ``t`` if some belief
held then is one compact cloud (a Gaussian track, or a particle set for which
:meth:`fusion.particles.ParticleSet.is_unimodal` holds) whose mean lies within ``RESOLVED_M`` of the target's
true position. The clock keeps the first such time per target (``None`` while there is none).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

RESOLVED_M = 2.0  # m: the "within 2 m of the truth"


class ResolutionClock:
    """First time each target was resolved."""

    def __init__(self, radius: float = RESOLVED_M):
        if not (np.isfinite(radius) and radius > 0):
            raise ValueError(f"resolution radius must be a positive number of metres, got {radius!r}")
        self.radius = float(radius)
        self.first: dict[str, float | None] = {}

    def record(self, t: float, targets: Iterable[dict], means: Iterable[np.ndarray]) -> None:
        """``targets``: the truth (``{"id", "position"}``); ``means``: the mean positions (3,) of the beliefs
        held at ``t`` that are unimodal."""
        means = [np.asarray(m, float)[:3] for m in means]
        for target in targets:
            tid, truth = target["id"], np.asarray(target["position"], float)
            if self.first.get(tid) is None and any(np.linalg.norm(m - truth) <= self.radius for m in means):
                self.first[tid] = float(t)
            self.first.setdefault(tid, None)

    def summary(self) -> dict[str, float | None]:
        return dict(sorted(self.first.items()))
