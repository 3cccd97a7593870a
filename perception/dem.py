"""Gridded digital elevation models: :class:`GridTerrain` and the ArcInfo ASCII grid format.

Ross et al. georeference on a USGS DEM exported as an ArcInfo ASCII grid (spec 002 §2.3). The file is

    ncols         4
    nrows         3
    xllcorner     500000.0      (or xllcenter)
    yllcorner     4400000.0     (or yllcenter)
    cellsize      30.0
    NODATA_value  -9999         (optional)
    <nrows lines of ncols heights, the first line is the NORTHERNMOST row>

The file's ``x`` is easting and ``y`` northing (a projected, metric grid such as UTM; geodetic
conversion is not done here — DESIGN.md §3 keeps it in one place). The values are node heights at
cell centres: with ``xllcorner`` the westernmost column is at ``x = xllcorner + cellsize/2``, with
``xllcenter`` at ``x = xllcenter`` (likewise for ``y`` and the southernmost row). The local NED frame
has its origin at file coordinates ``(origin_easting, origin_northing, origin_height)``:

    north = y - origin_northing,   east = x - origin_easting,   height (up) = z - origin_height.

:class:`GridTerrain` stores ``heights[i, j]`` with ``i`` increasing to the NORTH (the file's rows
reversed) and ``j`` to the EAST. The surface covers the nodes' hull (outside it ``height`` is NaN) and
is either ``"bilinear"`` in each cell or ``"triangles"`` (each cell split along its SW-NE diagonal into
the triangles SW-SE-NE and SW-NW-NE, the piecewise-planar surface of Ross Eq. 1).
"""

from __future__ import annotations

import math
import os
from numbers import Real

import numpy as np

from perception.raycast import grid_intersect

__all__ = ["GridTerrain", "parse_ascii_grid", "read_ascii_grid", "format_ascii_grid"]

INTERPOLATIONS = ("bilinear", "triangles")
_HEADER_KEYS = ("ncols", "nrows", "xllcorner", "xllcenter", "yllcorner", "yllcenter", "cellsize", "nodata_value")


def _finite(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


class GridTerrain:
    """Heights (m, up) on a square grid of nodes; implements the :class:`perception.terrain.Terrain`
    protocol with ``height``, ``height_bounds``, ``max_slope`` and an exact ``intersect``.

    ``heights[i, j]`` is the node at north ``north0 + i·cellsize``, east ``east0 + j·cellsize``; NaN
    marks a NODATA hole (``height`` is NaN in the four cells around it and rays that reach it give
    ``None``)."""

    def __init__(
        self, heights, cellsize: float, north0: float = 0.0, east0: float = 0.0, interpolation: str = "bilinear"
    ):
        H = np.array(heights, dtype=float)
        if H.ndim != 2 or H.shape[0] < 2 or H.shape[1] < 2:
            raise ValueError(f"grid heights must be a 2-D array with at least 2x2 nodes, got shape {H.shape}")
        if np.any(np.isinf(H)):
            raise ValueError("grid heights must be finite (NaN marks a NODATA hole, inf is not allowed)")
        if np.all(np.isnan(H)):
            raise ValueError("grid heights are all NODATA")
        self.cellsize = _finite(cellsize, "grid cellsize")
        if self.cellsize <= 0:
            raise ValueError(f"grid cellsize must be > 0, got {self.cellsize}")
        self.north0 = _finite(north0, "grid north0")
        self.east0 = _finite(east0, "grid east0")
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"grid interpolation must be one of {INTERPOLATIONS}, got {interpolation!r}")
        self.interpolation = interpolation
        H.setflags(write=False)
        self.heights = H
        z00, z01, z10, z11 = H[:-1, :-1], H[:-1, 1:], H[1:, :-1], H[1:, 1:]
        dn = np.fmax(np.abs(z10 - z00), np.abs(z11 - z01))  # per-cell bound on |dh/dn| * cellsize
        de = np.fmax(np.abs(z01 - z00), np.abs(z11 - z10))
        slope = np.hypot(dn, de) / self.cellsize
        self._max_slope = float(np.nanmax(slope)) if np.any(np.isfinite(slope)) else 0.0
        self._bounds = (float(np.nanmin(H)), float(np.nanmax(H)))

    def __repr__(self) -> str:
        rows, cols = self.heights.shape
        return (
            f"GridTerrain({rows}x{cols} nodes, cellsize={self.cellsize}, north0={self.north0}, "
            f"east0={self.east0}, interpolation={self.interpolation!r})"
        )

    @classmethod
    def sample(
        cls,
        terrain,
        north0: float,
        east0: float,
        cellsize: float,
        shape: tuple[int, int],
        interpolation: str = "bilinear",
    ) -> GridTerrain:
        """A grid of another terrain's heights at the nodes (e.g. a DEM of :class:`HillsTerrain`)."""
        rows, cols = shape
        n = north0 + cellsize * np.arange(rows)
        e = east0 + cellsize * np.arange(cols)
        N, E = np.meshgrid(n, e, indexing="ij")
        return cls(np.asarray(terrain.height(N, E), dtype=float), cellsize, north0, east0, interpolation)

    # ---------------------------------------------------------------------------- Terrain protocol
    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(north_min, north_max, east_min, east_max)`` of the nodes."""
        rows, cols = self.heights.shape
        return (
            self.north0,
            self.north0 + (rows - 1) * self.cellsize,
            self.east0,
            self.east0 + (cols - 1) * self.cellsize,
        )

    @property
    def height_bounds(self) -> tuple[float, float]:
        """``(min, max)`` of the valid nodes; both interpolations stay within them."""
        return self._bounds

    @property
    def max_slope(self) -> float:
        """Conservative bound on ``|∇h|`` for either interpolation: per cell
        ``hypot(max(|z_NW - z_SW|, |z_NE - z_SE|), max(|z_SE - z_SW|, |z_NE - z_NW|)) / cellsize``."""
        return self._max_slope

    def _locate(self, north, east):
        n, e = np.broadcast_arrays(np.asarray(north, dtype=float), np.asarray(east, dtype=float))
        rows, cols = self.heights.shape
        fn = (n - self.north0) / self.cellsize
        fe = (e - self.east0) / self.cellsize
        with np.errstate(invalid="ignore"):
            inside = (fn >= 0) & (fn <= rows - 1) & (fe >= 0) & (fe <= cols - 1)
        i = np.clip(np.floor(np.where(inside, fn, 0.0)), 0, rows - 2).astype(int)
        j = np.clip(np.floor(np.where(inside, fe, 0.0)), 0, cols - 2).astype(int)
        return i, j, fn - i, fe - j, inside

    def height(self, north, east):
        """Height (m, up) at NED ``(north, east)``; NaN outside the grid or next to a hole."""
        i, j, s, t, inside = self._locate(north, east)
        H = self.heights
        z00, z01, z10, z11 = H[i, j], H[i, j + 1], H[i + 1, j], H[i + 1, j + 1]
        if self.interpolation == "bilinear":
            h = z00 * (1 - s) * (1 - t) + z01 * (1 - s) * t + z10 * s * (1 - t) + z11 * s * t
        else:  # east of the SW-NE diagonal (t >= s): SW-SE-NE; else SW-NW-NE
            h = np.where(t >= s, z00 + t * (z01 - z00) + s * (z11 - z01), z00 + s * (z10 - z00) + t * (z11 - z10))
        h = np.where(inside, h, np.nan)
        return float(h) if h.ndim == 0 else h

    # ------------------------------------------------------------------------------- triangles
    def triangle_at(self, north: float, east: float) -> tuple[int, int, int] | None:
        """``(i, j, half)`` of the triangle containing a point, ``half`` 0 for SW-SE-NE (east of the
        diagonal, ties included) and 1 for SW-NW-NE; ``None`` outside the grid."""
        i, j, s, t, inside = self._locate(float(north), float(east))
        if not inside:
            return None
        return int(i), int(j), 0 if t >= s else 1

    def triangle(self, i: int, j: int, half: int) -> np.ndarray:
        """NED vertices (3, 3) of triangle ``half`` of cell ``(i, j)`` (rows SW, SE or NW, NE)."""
        rows, cols = self.heights.shape
        if not (0 <= i < rows - 1 and 0 <= j < cols - 1 and half in (0, 1)):
            raise ValueError(f"no triangle ({i}, {j}, {half}) in a {rows}x{cols} grid")
        cs = self.cellsize
        n, e = self.north0 + i * cs, self.east0 + j * cs
        H = self.heights
        middle = [n, e + cs, -H[i, j + 1]] if half == 0 else [n + cs, e, -H[i + 1, j]]
        return np.array([[n, e, -H[i, j]], middle, [n + cs, e + cs, -H[i + 1, j + 1]]])

    def intersect(self, origin, direction, max_range: float = 5000.0) -> np.ndarray | None:
        """Exact first hit of the ray on this surface (:func:`perception.raycast.grid_intersect`)."""
        return grid_intersect(self, origin, direction, max_range, self.interpolation)


# --------------------------------------------------------------------------------- ASCII grid I/O
def _number(token: str, what: str) -> float:
    try:
        value = float(token)
    except ValueError:
        raise ValueError(f"ASCII grid: {what}: {token!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"ASCII grid: {what}: {token!r} is not finite")
    return value


def parse_ascii_grid(
    text: str,
    *,
    origin_easting: float = 0.0,
    origin_northing: float = 0.0,
    origin_height: float = 0.0,
    nodata: str | float = "error",
    interpolation: str = "bilinear",
    source: str = "<text>",
) -> GridTerrain:
    """Parse an ArcInfo ASCII grid (see module docstring) into a :class:`GridTerrain`.

    ``nodata``: ``"error"`` (default) rejects a grid with NODATA cells, ``"hole"`` keeps them as NaN
    holes, a number fills them with that height (file units). Malformed files — missing, unknown,
    duplicate or conflicting header keys, non-integer sizes, a non-positive cell size, a row count or
    row length that differs from the header, non-numeric values — raise :class:`ValueError` naming
    ``source`` and the line."""
    lines = [(k + 1, line.split()) for k, line in enumerate(text.splitlines())]
    lines = [(k, tokens) for k, tokens in lines if tokens]
    header: dict[str, str] = {}
    body_start = len(lines)  # the header is the leading run of lines that start with a key
    for k, (lineno, tokens) in enumerate(lines):
        if not tokens[0][0].isalpha():
            body_start = k
            break
        key = tokens[0].lower()
        if key not in _HEADER_KEYS:
            expected = ", ".join(_HEADER_KEYS)
            raise ValueError(f"{source}:{lineno}: unknown header key {tokens[0]!r} (expected {expected})")
        if key in header:
            raise ValueError(f"{source}:{lineno}: duplicate header key {tokens[0]!r}")
        if len(tokens) != 2:
            raise ValueError(f"{source}:{lineno}: header line must be 'key value', got {' '.join(tokens)!r}")
        header[key] = tokens[1]

    for key in ("ncols", "nrows", "cellsize"):
        if key not in header:
            raise ValueError(f"{source}: missing header key {key!r}")
    for axis in ("x", "y"):
        corner, centre = f"{axis}llcorner", f"{axis}llcenter"
        if (corner in header) == (centre in header):
            raise ValueError(f"{source}: the header needs exactly one of {corner!r} and {centre!r}")
    sizes = {}
    for key in ("ncols", "nrows"):
        try:
            sizes[key] = int(header[key])
        except ValueError:
            raise ValueError(f"{source}: {key} must be an integer, got {header[key]!r}") from None
        if sizes[key] < 2:
            raise ValueError(f"{source}: {key} must be >= 2 (one cell needs 2x2 nodes), got {sizes[key]}")
    ncols, nrows = sizes["ncols"], sizes["nrows"]
    cellsize = _number(header["cellsize"], f"{source}: cellsize")
    if cellsize <= 0:
        raise ValueError(f"{source}: cellsize must be > 0, got {cellsize}")
    x0 = (
        _number(header["xllcenter"], "xllcenter")
        if "xllcenter" in header
        else (_number(header["xllcorner"], "xllcorner") + 0.5 * cellsize)
    )
    y0 = (
        _number(header["yllcenter"], "yllcenter")
        if "yllcenter" in header
        else (_number(header["yllcorner"], "yllcorner") + 0.5 * cellsize)
    )
    nodata_value = _number(header["nodata_value"], f"{source}: NODATA_value") if "nodata_value" in header else None

    body = lines[body_start:]
    if len(body) != nrows:
        raise ValueError(f"{source}: expected {nrows} data rows (nrows), found {len(body)}")
    values = np.empty((nrows, ncols))
    for r, (lineno, tokens) in enumerate(body):
        if len(tokens) != ncols:
            raise ValueError(f"{source}:{lineno}: data row {r + 1} has {len(tokens)} values, expected {ncols} (ncols)")
        values[r] = [_number(tok, f"{source}:{lineno}") for tok in tokens]

    missing = np.zeros(values.shape, dtype=bool)
    if nodata_value is not None:
        missing = np.isclose(values, nodata_value, rtol=1e-7, atol=0.0)
    if np.any(missing):
        if isinstance(nodata, str):
            if nodata == "error":
                r, c = np.argwhere(missing)[0]
                raise ValueError(
                    f"{source}: {int(missing.sum())} NODATA value(s), first at data row {r + 1}, "
                    f"column {c + 1}; pass nodata='hole' or a fill height"
                )
            if nodata != "hole":
                raise ValueError(f"nodata must be 'error', 'hole' or a number, got {nodata!r}")
            values[missing] = np.nan
        else:
            values[missing] = _finite(nodata, "nodata fill height")
        if np.all(missing):
            raise ValueError(f"{source}: every value is NODATA")

    heights = values[::-1] - _finite(origin_height, "origin_height")  # row 0 = southernmost
    return GridTerrain(
        heights,
        cellsize,
        north0=y0 - _finite(origin_northing, "origin_northing"),
        east0=x0 - _finite(origin_easting, "origin_easting"),
        interpolation=interpolation,
    )


def read_ascii_grid(path: str | os.PathLike, **kwargs) -> GridTerrain:
    """Load an ArcInfo ASCII grid file (``.asc``); keyword arguments as :func:`parse_ascii_grid`."""
    with open(path, encoding="ascii", errors="strict") as f:
        try:
            text = f.read()
        except UnicodeDecodeError:
            raise ValueError(f"{path}: not an ASCII grid (non-ASCII bytes)") from None
    return parse_ascii_grid(text, source=str(path), **kwargs)


def format_ascii_grid(
    grid: GridTerrain,
    *,
    origin_easting: float = 0.0,
    origin_northing: float = 0.0,
    origin_height: float = 0.0,
    nodata_value: float = -9999.0,
) -> str:
    """The grid as ArcInfo ASCII text with ``xllcenter``/``yllcenter`` (inverse of :func:`parse_ascii_grid`)."""
    rows, cols = grid.heights.shape
    z = grid.heights[::-1] + origin_height
    lines = [
        f"ncols {cols}",
        f"nrows {rows}",
        f"xllcenter {grid.east0 + origin_easting!r}",
        f"yllcenter {grid.north0 + origin_northing!r}",
        f"cellsize {grid.cellsize!r}",
        f"NODATA_value {nodata_value!r}",
    ]
    lines += [" ".join(repr(float(v)) if np.isfinite(v) else repr(nodata_value) for v in row) for row in z]
    return "\n".join(lines) + "\n"
