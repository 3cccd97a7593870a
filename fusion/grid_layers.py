"""Grid beliefs as the arrays that travel: ``(L, rows, cols)`` float layers <-> a grid belief of one type.

A log-odds grid (Merino Alg. 4.2/4.3) is one layer, its evidence relative to the prior; a Beta grid
(Alg. 4.4/4.5) is two, its counts ``α``, ``β``. The codec (:mod:`agent.net.grid_codec`) moves layers; this
class turns them back into beliefs with the algebra of :mod:`fusion.belief`.
"""

from __future__ import annotations

import numpy as np

from fusion.grid import BetaGrid, LogOddsGrid
from fusion.grid_geometry import GridGeometry

BELIEFS = ("logodds", "beta")


class GridLayers:
    """Layers <-> grid beliefs of one type (``"logodds"`` or ``"beta"``) on one geometry."""

    def __init__(self, belief: str, geometry: GridGeometry):
        if belief not in BELIEFS:
            raise ValueError(f"grid belief must be one of {BELIEFS}, got {belief!r}")
        self.belief = belief
        self.geometry = geometry
        self.layers = 1 if belief == "logodds" else 2

    def uniform(self):
        return LogOddsGrid.uniform(self.geometry) if self.belief == "logodds" else BetaGrid.uniform(self.geometry)

    def to_layers(self, grid) -> np.ndarray:
        return grid.evidence[None] if self.belief == "logodds" else np.stack([grid.alpha, grid.beta])

    def from_layers(self, layers: np.ndarray):
        if self.belief == "logodds":
            return LogOddsGrid(self.geometry, layers[0])
        return BetaGrid(self.geometry, layers[0], layers[1])
