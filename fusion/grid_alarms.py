"""Alarms from a certainty grid: the grid-to-Gaussian hand-off (Merino §4.2.2, (4.20); Ch. 8).

Cells whose probability is above a threshold are grouped into connected regions ``R`` (4- or
8-connectivity; the thesis does not say which). Each region becomes an alarm with the probability-weighted
mean and covariance of its cell centres, Merino (4.20):

    mu_R    = sum_{k in R} r_k p_k / sum_{k in R} p_k
    Sigma_R = sum_{k in R} (r_k - mu_R)(r_k - mu_R)^T p_k / sum_{k in R} p_k  +  (cell^2 / 12) I

The ``cell^2 / 12`` term (chosen here) is the variance of a position uniform over one cell: the fire may
be anywhere inside its cell, and without it a one-cell region would have a zero (singular) covariance.

In Merino's hybrid scheme (Ch. 8, Marvin's DACLE) each region is entered into the information filter as
a Gaussian alarm, and the region's *mean cell probability* initialises the class prior ``p(theta = fire)``
(:attr:`Alarm.probability`). Alarms are sorted by that probability, highest first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from fusion.gaussian import Gaussian
from fusion.grid_geometry import GridGeometry, GridGeometryError

#: Alarm threshold on the cell probability: Merino's example value (§4.1.3: "alarm threshold 0.8").
DEFAULT_THRESHOLD = 0.8
#: Vertical variance [m^2] of a 3-D alarm on flat ground: unmodelled terrain relief (chosen here).
VERTICAL_VARIANCE = 1.0
#: Within-cell variance factor: a uniform position over a side ``c`` has variance ``c^2 / 12``.
WITHIN_CELL_FACTOR = 1.0 / 12.0


@dataclass(frozen=True, eq=False)
class Alarm:
    """One connected high-probability region of a grid, summarised as a Gaussian (4.20)."""

    mean: np.ndarray  # (2,) north, east [m]
    cov: np.ndarray  # (2, 2): (4.20) plus the within-cell variance cell^2/12 on the diagonal
    probability: float  # mean cell probability over the region: the class prior p(theta = fire) (Ch. 8)
    cells: int  # number of cells in the region
    peak: float  # max cell probability

    def __post_init__(self):
        mean = np.array(self.mean, dtype=float)
        cov = np.array(self.cov, dtype=float)
        if mean.shape != (2,) or not np.isfinite(mean).all():
            raise ValueError(f"alarm mean must be a finite (north, east) pair, got {mean}")
        if cov.shape != (2, 2) or not np.isfinite(cov).all() or not np.allclose(cov, cov.T):
            raise ValueError(f"alarm covariance must be a finite symmetric 2x2 matrix, got {cov}")
        if np.linalg.eigvalsh(cov)[0] <= 0.0:
            raise ValueError("alarm covariance must be positive definite")
        for name in ("probability", "peak"):
            value = getattr(self, name)
            if not (isinstance(value, float | int | np.floating) and 0.0 <= value <= 1.0):
                raise ValueError(f"alarm {name} must be a probability in [0, 1], got {value!r}")
        if isinstance(self.cells, bool) or not isinstance(self.cells, int | np.integer) or self.cells < 1:
            raise ValueError(f"alarm cells must be a positive integer, got {self.cells!r}")
        mean.setflags(write=False)
        cov.setflags(write=False)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)
        object.__setattr__(self, "probability", float(self.probability))
        object.__setattr__(self, "peak", float(self.peak))
        object.__setattr__(self, "cells", int(self.cells))

    def to_gaussian(self, height: float | None = None, vertical_variance: float = VERTICAL_VARIANCE) -> Gaussian:
        """The alarm as a :class:`~fusion.gaussian.Gaussian`: 2-D (north, east), or, given the ground
        ``height`` (NED down), 3-D with ``vertical_variance`` [m^2] on the down axis."""
        if height is None:
            return Gaussian.from_moments(self.mean, self.cov)
        if isinstance(height, bool) or not isinstance(height, int | float | np.number) or not math.isfinite(height):
            raise ValueError(f"height must be a finite number, got {height!r}")
        if not (isinstance(vertical_variance, int | float | np.number) and 0.0 < vertical_variance < math.inf):
            raise ValueError(f"vertical variance must be positive and finite, got {vertical_variance!r}")
        cov = np.zeros((3, 3))
        cov[:2, :2] = self.cov
        cov[2, 2] = vertical_variance
        return Gaussian.from_moments(np.append(self.mean, float(height)), cov)


def extract_alarms(
    probability: np.ndarray,
    geometry: GridGeometry,
    threshold: float = DEFAULT_THRESHOLD,
    connectivity: int = 8,
    min_cells: int = 1,
) -> list[Alarm]:
    """Connected regions of cells with probability strictly above ``threshold``, as alarms (4.20), sorted
    by mean cell probability (highest first). Regions smaller than ``min_cells`` are dropped."""
    if not isinstance(geometry, GridGeometry):
        raise GridGeometryError(f"geometry must be a GridGeometry, got {type(geometry).__name__}")
    p = np.asarray(probability, dtype=float)
    if p.shape != geometry.shape:
        raise ValueError(f"probability must have the grid's shape {geometry.shape}, got {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError("probability contains non-finite values (NaN or inf)")
    if p.min() < 0.0 or p.max() > 1.0:
        raise ValueError(f"probability values must lie in [0, 1], got range [{p.min()}, {p.max()}]")
    if isinstance(threshold, bool) or not isinstance(threshold, int | float | np.number) or not 0 < threshold < 1:
        raise ValueError(f"threshold must lie in (0, 1), got {threshold!r}")
    if isinstance(connectivity, bool) or connectivity not in (4, 8):
        raise ValueError(f"connectivity must be 4 or 8, got {connectivity!r}")
    if isinstance(min_cells, bool) or not isinstance(min_cells, int | np.integer) or min_cells < 1:
        raise ValueError(f"min_cells must be a positive integer, got {min_cells!r}")

    structure = ndimage.generate_binary_structure(2, 1 if connectivity == 4 else 2)
    labels, count = ndimage.label(p > threshold, structure=structure)
    if count == 0:
        return []
    label = labels.ravel()
    inside = label > 0
    label, w = label[inside], p.ravel()[inside]
    r = geometry.centres().reshape(-1, 2)[inside]

    def per_region(values: np.ndarray) -> np.ndarray:
        return np.bincount(label, weights=values, minlength=count + 1)[1:]

    cells = np.bincount(label, minlength=count + 1)[1:]
    total = per_region(w)  # > 0: every cell in a region is above a positive threshold
    mean = np.column_stack([per_region(w * r[:, 0]), per_region(w * r[:, 1])]) / total[:, None]
    d = r - mean[label - 1]
    second = np.stack([per_region(w * d[:, i] * d[:, j]) for i in range(2) for j in range(2)], axis=1)
    cov = second.reshape(count, 2, 2) / total[:, None, None]
    cov += WITHIN_CELL_FACTOR * geometry.cell**2 * np.eye(2)
    peak = ndimage.maximum(p, labels, index=np.arange(1, count + 1))
    mean_p = per_region(w) / cells

    alarms = [
        Alarm(mean[k], 0.5 * (cov[k] + cov[k].T), min(float(mean_p[k]), 1.0), int(cells[k]), float(peak[k]))
        for k in range(count)
        if cells[k] >= min_cells
    ]
    return sorted(alarms, key=lambda a: (-a.probability, -a.peak, -a.cells))
