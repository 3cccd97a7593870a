"""The geometry of a certainty grid: a rectangle of square cells on flat ground (NED, metres).

Rows run along north, columns along east; cell ``(i, j)`` spans north ``[n0 + i c, n0 + (i+1) c)`` and east
``[e0 + j c, e0 + (j+1) c)`` (the far edges belong to the last row and column), its centre ``r_k`` at depth
``height``. Flat indices are row-major. Grids of different geometries never combine.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

#: Largest grid accepted, guarding memory against a corrupt geometry off the wire (chosen here: 4096^2).
MAX_CELLS = 4096 * 4096
#: Relative slack in :meth:`GridGeometry.covering` so a span of exactly n cells does not get n + 1 (chosen here).
COVER_RTOL = 1e-9


class GridGeometryError(ValueError):
    """A grid geometry is invalid, two grids do not share a geometry, or a point lies off the grid."""


def real_number(value, name: str, error: type[ValueError] = ValueError) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise error(f"{name} must be a real number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise error(f"{name} must be finite, got {value}")
    return value


def _pair(value, name: str) -> tuple[float, float]:
    if not isinstance(value, list | tuple | np.ndarray) or len(value) != 2:
        raise GridGeometryError(f"{name} must be a pair of numbers, got {value!r}")
    return tuple(real_number(v, f"{name}[{k}]", GridGeometryError) for k, v in enumerate(value))


@dataclass(frozen=True)
class GridGeometry:
    """A rectangular grid on flat ground: rows along north, columns along east (NED)."""

    origin: tuple[float, float]  # (north, east) of the grid's corner with the smallest coordinates [m]
    cell: float  # cell side [m], > 0
    shape: tuple[int, int]  # (rows, cols), each >= 1
    height: float = 0.0  # NED down coordinate of the cell centres [m]

    def __post_init__(self):
        origin = _pair(self.origin, "origin")
        cell = real_number(self.cell, "cell size", GridGeometryError)
        if cell <= 0.0:
            raise GridGeometryError(f"cell size must be positive, got {cell}")
        shape = self.shape
        if not isinstance(shape, list | tuple | np.ndarray) or len(shape) != 2:
            raise GridGeometryError(f"shape must be a pair (rows, cols), got {shape!r}")
        for name, n in zip(("rows", "cols"), shape, strict=True):
            if isinstance(n, bool) or not isinstance(n, int | np.integer):
                raise GridGeometryError(f"shape {name} must be an integer, got {n!r}")
            if n < 1:
                raise GridGeometryError(f"shape {name} must be at least 1, got {n}")
        shape = (int(shape[0]), int(shape[1]))
        if shape[0] * shape[1] > MAX_CELLS:
            raise GridGeometryError(f"grid of {shape[0]}x{shape[1]} cells exceeds MAX_CELLS = {MAX_CELLS}")
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "cell", cell)
        object.__setattr__(self, "shape", shape)
        object.__setattr__(self, "height", real_number(self.height, "height", GridGeometryError))

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1]

    def centres(self) -> np.ndarray:
        """``(rows, cols, 2)``: north, east of every cell centre, ``origin + (index + 1/2) cell``."""
        north = self.origin[0] + (np.arange(self.shape[0]) + 0.5) * self.cell
        east = self.origin[1] + (np.arange(self.shape[1]) + 0.5) * self.cell
        return np.stack(np.meshgrid(north, east, indexing="ij"), axis=-1)

    def centres_ned(self) -> np.ndarray:
        """``(rows*cols, 3)``: the 3-D cell centres ``r_k`` (north, east, height), row-major."""
        flat = self.centres().reshape(-1, 2)
        return np.column_stack([flat, np.full(self.size, self.height)])

    def cell_of(self, north: float, east: float) -> tuple[int, int]:
        """The (row, col) holding a point. Cells are half-open except on the far edges, which belong to
        the last row/column, so every point of ``[origin, origin + shape * cell]`` has a cell."""
        index = []
        for name, value, start, n in zip(("north", "east"), (north, east), self.origin, self.shape, strict=True):
            value = real_number(value, name, GridGeometryError)
            if not start <= value <= start + n * self.cell:
                raise GridGeometryError(
                    f"{name} = {value} lies outside the grid [{start}, {start + n * self.cell}]"
                )
            index.append(min(max(int(math.floor((value - start) / self.cell)), 0), n - 1))
        return index[0], index[1]

    def check_same(self, other: GridGeometry) -> None:
        """Raise :class:`GridGeometryError` naming the first field in which ``other`` differs."""
        if not isinstance(other, GridGeometry):
            raise GridGeometryError(f"expected a GridGeometry, got {type(other).__name__}")
        for name in ("shape", "cell", "origin", "height"):
            mine, theirs = getattr(self, name), getattr(other, name)
            if mine != theirs:
                raise GridGeometryError(f"grid geometry mismatch: {name} {mine} vs {theirs}")

    def to_dict(self) -> dict:
        """Plain JSON/msgpack types."""
        return {"origin": list(self.origin), "cell": self.cell, "shape": list(self.shape), "height": self.height}

    @classmethod
    def from_dict(cls, d) -> GridGeometry:
        """Inverse of :meth:`to_dict`; rejects missing or unknown keys and bad values."""
        if not isinstance(d, Mapping):
            raise GridGeometryError(f"grid geometry must be a mapping, got {type(d).__name__}")
        missing = {"origin", "cell", "shape"} - set(d)
        unknown = set(d) - {"origin", "cell", "shape", "height"}
        if missing or unknown:
            raise GridGeometryError(
                f"grid geometry keys: missing {sorted(missing)}, unknown {sorted(map(str, unknown))}"
            )
        return cls(d["origin"], d["cell"], d["shape"], d.get("height", 0.0))

    @classmethod
    def covering(
        cls, north: tuple[float, float], east: tuple[float, float], cell: float, height: float = 0.0
    ) -> GridGeometry:
        """The smallest grid with corner ``(north[0], east[0])`` that covers both closed ranges."""
        cell = real_number(cell, "cell size", GridGeometryError)
        if cell <= 0.0:
            raise GridGeometryError(f"cell size must be positive, got {cell}")
        shape = []
        for name, bounds in (("north", north), ("east", east)):
            lo, hi = _pair(bounds, f"{name} range")
            if hi < lo:
                raise GridGeometryError(f"{name} range is reversed: {lo} > {hi}")
            shape.append(max(1, math.ceil((hi - lo) / cell * (1.0 - COVER_RTOL))))
        return cls((_pair(north, "north range")[0], _pair(east, "east range")[0]), cell, tuple(shape), height)
