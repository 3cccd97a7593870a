"""Grid beliefs as the arrays that travel: ``(L, rows, cols)`` float layers <-> a grid belief of one type.

A log-odds grid (Merino Alg. 4.2/4.3) is one layer, its evidence relative to the prior; a Beta grid
(Alg. 4.4/4.5) is two, its counts ``α``, ``β``. The codec (:mod:`agent.net.grid_codec`) moves layers; this
class turns them back into beliefs with the algebra of :mod:`fusion.belief`. With ``forgetting``
(:mod:`fusion.grid_forgetting`) the beliefs live at a tick of the common clock: layers are read at the tick
given, or else at :attr:`GridLayers.epoch`, the tick its owner is at now. Beta grids read their fire
probability against ``boundary`` (:class:`fusion.grid.BetaGrid`).
"""

from __future__ import annotations

import numpy as np

from fusion.grid import BetaGrid, LogOddsGrid
from fusion.grid_forgetting import Forgetting
from fusion.grid_geometry import GridGeometry

BELIEFS = ("logodds", "beta")


class GridLayers:
    """Layers <-> grid beliefs of one type (``"logodds"`` or ``"beta"``) on one geometry."""

    def __init__(self, belief: str, geometry: GridGeometry, forgetting: Forgetting | None = None,
                 boundary: float | None = None):
        if belief not in BELIEFS:
            raise ValueError(f"grid belief must be one of {BELIEFS}, got {belief!r}")
        self.belief = belief
        self.geometry = geometry
        self.forgetting = forgetting
        self.boundary = boundary
        self.layers = 1 if belief == "logodds" else 2
        self.epoch = None if forgetting is None else 0  # the owner's tick now (set by the owner)

    def epoch_of(self, t: float) -> int | None:
        """The tick of time ``t`` (``None`` for static grids)."""
        return None if self.forgetting is None else self.forgetting.epoch_of(t)

    def uniform(self):
        if self.belief == "logodds":
            return LogOddsGrid.uniform(self.geometry, forgetting=self.forgetting, epoch=self.epoch)
        return BetaGrid.uniform(self.geometry, forgetting=self.forgetting, epoch=self.epoch, boundary=self.boundary)

    def to_layers(self, grid) -> np.ndarray:
        return grid.evidence[None] if self.belief == "logodds" else np.stack([grid.alpha, grid.beta])

    def from_layers(self, layers: np.ndarray, epoch: int | None = None):
        """The belief of these layers, at tick ``epoch`` (default: :attr:`epoch`)."""
        epoch = self.epoch if epoch is None else epoch
        if self.belief == "logodds":
            return LogOddsGrid(self.geometry, layers[0], forgetting=self.forgetting, epoch=epoch)
        return BetaGrid(self.geometry, layers[0], layers[1], forgetting=self.forgetting, epoch=epoch,
                        boundary=self.boundary)
