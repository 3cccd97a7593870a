"""A fire mission scored window by window: every map at the alarm threshold against the truth of its time.

A final map says little about a mission whose fires spread: an alarm placed early may be metres off later,
and a decoy may be an alarm for a minute and then rejected. At the end of every window of
:data:`WINDOW_S` seconds (and at the end of the run, for a last partial window), :class:`FireWindows`
scores the centralized map and each agent's map with :func:`mesh_sim.fire_scoring.score_alarms` at the
scenario's alarm threshold against the fire regions and decoys *at that time*.

A window is **before the first detection** while no agent's map has detected a fire at the end of this or
an earlier window (fires are small at first: the issue's goals apply to the windows after it).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from fusion.grid_geometry import GridGeometry
from mesh_sim.fire_scoring import score_alarms, score_positions

__all__ = ["FireWindows", "WINDOW_S"]

WINDOW_S = 30.0  # s per scoring window (issue 15: "per 30 s window")
_EPS = 1e-9  # s: a lockstep time this close to a window's end is its end


class FireWindows:
    """The per-window series of one run: ``{"start", "end", "before_first_detection", "fires", "central",
    "agents": {agent: score}}`` per window, each score as :func:`~mesh_sim.fire_scoring.score_alarms`."""

    def __init__(self, geometry: GridGeometry, threshold: float, length: float = WINDOW_S):
        if not length > 0.0:
            raise ValueError(f"window length must be positive, got {length!r} s")
        self.geometry = geometry
        self.threshold = threshold
        self.length = length
        self.series: list[dict] = []
        self.start = 0.0
        self.detected = False  # has an agent's map detected a fire at a window's end yet

    def due(self, t: float) -> bool:
        """Whether ``t`` ends the current window."""
        return t + _EPS >= self.start + self.length

    def record(self, t: float, central: np.ndarray, agents: Mapping[str, np.ndarray], regions: Sequence[dict],
               decoys: Sequence, located: Mapping[str, np.ndarray] | None = None) -> dict:
        """Close the current window at ``t``: score the maps (cell probabilities) against the truth at ``t``."""
        window = self.score(t, central, agents, regions, decoys, located)
        self.series.append(window)
        self.detected = not window["before_first_detection"]
        self.start = t
        return window

    def score(self, t: float, central: np.ndarray, agents: Mapping[str, np.ndarray], regions: Sequence[dict],
              decoys: Sequence, located: Mapping[str, np.ndarray] | None = None) -> dict:
        """The current window ending at ``t``, without closing it (the last partial window of a run).
        ``located``: each agent's alarm positions as it reports them (the hand-off of Merino Ch. 8), scored
        under ``"located"``."""
        def scored(probability):
            return score_alarms(probability, self.geometry, regions, decoys, self.threshold)

        by_agent = {agent: scored(p) for agent, p in sorted(agents.items())}
        detected = self.detected or any(s["detected"] for s in by_agent.values())
        window = {"start": self.start, "end": t, "before_first_detection": not detected, "fires": len(regions),
                  "central": scored(central), "agents": by_agent}
        if located:
            window["located"] = {agent: score_positions(means, self.geometry.cell, regions, decoys)
                                 for agent, means in sorted(located.items())}
        return window

    def pending(self, t: float) -> bool:
        """Whether time has passed since the last closed window (a run ending between window ends)."""
        return t > self.start + _EPS
