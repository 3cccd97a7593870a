"""Ray intersection with DEM triangles and grid cells (Ross et al. Eq. 1, spec 002 §2.3).

* :func:`ross_eq1` — the paper's line/plane solve: with ``l_a`` the camera position, ``l_b`` a second
  point on the ray and ``p0, p1, p2`` three DEM nodes,

      [t, u, v]^T = [l_a - l_b, p1 - p0, p2 - p0]^{-1} (l_a - p0),   hit = l_a + t (l_b - l_a).   (Eq. 1)

* :func:`moller_trumbore` — the same system solved by Cramer's rule with cross products
  (Möller & Trumbore 1997), vectorised over many triangles; ``(t, u, v)`` agree with Eq. 1.
* :func:`ross_intersect` — the paper's iteration: start with the DEM triangle directly below the
  camera, intersect the ray with its plane, move to the triangle under the new point, repeat until the
  triangle (hence the point) stops changing. Ross et al. take "the 3 closest grid points"; here the
  triangle of a fixed triangulation that contains the point is used, so that the surface is continuous
  (a deviation, chosen here). Like the paper's method it can converge to a far-side hit on rugged
  terrain; it is kept for fidelity and as a cross-check.
* :func:`grid_intersect` — the exact first hit on a grid surface: the ray's horizontal track is cut at
  every grid line it crosses (a 2-D cell walk), cells the ray passes above are skipped with the cell's
  highest node, and the remaining cells are intersected exactly, in order, with their two triangles
  (Möller–Trumbore) or with the bilinear patch (a quadratic in λ).

Grids are duck-typed (see :class:`perception.dem.GridTerrain`): ``heights[i, j]`` is the height (up) of
the node at north ``north0 + i·cellsize``, east ``east0 + j·cellsize``; NaN marks a NODATA hole. Points
are NED (z = -height).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["moller_trumbore", "ross_eq1", "ross_intersect", "grid_intersect"]

#: Barycentric slack accepted on a triangle's edges (chosen here: rays through shared edges and nodes
#: must not fall between two triangles).
BARYCENTRIC_EPS = 1e-12


def moller_trumbore(origin, direction, v0, v1, v2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, u, v)`` with ``origin + t·direction = v0 + u (v1 - v0) + v (v2 - v0)`` for triangles
    ``v0, v1, v2`` (..., 3). ``t`` is in units of ``|direction|``; NaN where the ray is parallel to the
    triangle's plane. The ray hits the triangle where ``u, v >= 0``, ``u + v <= 1`` and ``t >= 0``."""
    o = np.asarray(origin, dtype=float)
    d = np.asarray(direction, dtype=float)
    v0 = np.asarray(v0, dtype=float)
    e1 = np.asarray(v1, dtype=float) - v0
    e2 = np.asarray(v2, dtype=float) - v0
    pvec = np.cross(d, e2)
    det = np.sum(e1 * pvec, axis=-1)
    scale = np.linalg.norm(e1, axis=-1) * np.linalg.norm(e2, axis=-1) * np.linalg.norm(d)
    parallel = np.abs(det) <= 1e-14 * scale
    inv = 1.0 / np.where(parallel, 1.0, det)
    tvec = o - v0
    u = np.sum(tvec * pvec, axis=-1) * inv
    qvec = np.cross(tvec, e1)
    v = np.sum(d * qvec, axis=-1) * inv
    t = np.sum(e2 * qvec, axis=-1) * inv
    nan = np.where(parallel, np.nan, 1.0)
    return t * nan, u * nan, v * nan


def ross_eq1(l_a, l_b, p0, p1, p2) -> tuple[float, float, float] | None:
    """Ross et al. Eq. 1: ``(t, u, v)`` of the line through ``l_a``, ``l_b`` and the plane of
    ``p0, p1, p2``; ``None`` when the line is parallel to the plane (singular matrix)."""
    l_a, l_b, p0, p1, p2 = (np.asarray(p, dtype=float) for p in (l_a, l_b, p0, p1, p2))
    M = np.column_stack([l_a - l_b, p1 - p0, p2 - p0])
    scale = np.linalg.norm(l_a - l_b) * np.linalg.norm(p1 - p0) * np.linalg.norm(p2 - p0)
    if scale == 0.0 or abs(np.linalg.det(M)) <= 1e-14 * scale:
        return None
    t, u, v = np.linalg.solve(M, l_a - p0)
    return float(t), float(u), float(v)


def _cell_nodes(grid, i, j):
    H = grid.heights
    return H[i, j], H[i, j + 1], H[i + 1, j], H[i + 1, j + 1]  # SW, SE, NW, NE


def _triangle_vertices(grid, i, j, half):
    """NED vertices (..., 3, 3) of triangle ``half`` (0: SW-SE-NE, east of the diagonal; 1: SW-NW-NE)."""
    i, j, half = np.broadcast_arrays(np.asarray(i), np.asarray(j), np.asarray(half))
    cs = grid.cellsize
    n0 = grid.north0 + i * cs
    e0 = grid.east0 + j * cs
    z00, z01, z10, z11 = _cell_nodes(grid, i, j)
    sw = np.stack([n0, e0, -z00], axis=-1)
    ne = np.stack([n0 + cs, e0 + cs, -z11], axis=-1)
    se = np.stack([n0, e0 + cs, -z01], axis=-1)
    nw = np.stack([n0 + cs, e0, -z10], axis=-1)
    middle = np.where((half == 0)[..., None], se, nw)
    return np.stack([sw, middle, ne], axis=-2)


def ross_intersect(grid, origin, direction, max_iter: int = 10) -> tuple[np.ndarray, int] | None:
    """Ross et al.'s iterative georeferencing on a grid's triangles (see module docstring).

    Returns ``(hit, iterations)`` or ``None`` when the point under the camera or an iterate leaves the
    grid or falls in a NODATA hole, the ray is parallel to a triangle or points away from it
    (``t <= 0``), or the triangle has not settled after ``max_iter`` solves."""
    o = np.asarray(origin, dtype=float)
    d = np.asarray(direction, dtype=float)
    if o.shape != (3,) or d.shape != (3,) or not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))) or not d.any():
        raise ValueError("ray origin and direction must be finite 3-vectors, direction non-zero")
    if max_iter < 1:
        raise ValueError(f"max_iter must be >= 1, got {max_iter}")
    cell = grid.triangle_at(o[0], o[1])
    for iteration in range(1, max_iter + 1):
        if cell is None:
            return None
        p0, p1, p2 = _triangle_vertices(grid, *cell)
        if not np.all(np.isfinite(p0 + p1 + p2)):
            return None
        solved = ross_eq1(o, o + d, p0, p1, p2)
        if solved is None or solved[0] <= 0.0:
            return None
        hit = o + solved[0] * d
        new = grid.triangle_at(hit[0], hit[1])
        if new == cell:
            return hit, iteration
        cell = new
    return None


def _bilinear_roots(grid, i, j, o, d, lam_lo, lam_hi):
    """Smallest λ in [lam_lo, lam_hi] (per cell) where the ray meets the bilinear patch, else NaN."""
    cs = grid.cellsize
    z00, z01, z10, z11 = _cell_nodes(grid, i, j)
    a, b, c = z10 - z00, z01 - z00, z00 - z01 - z10 + z11
    s0 = (o[0] - (grid.north0 + i * cs)) / cs
    t0 = (o[1] - (grid.east0 + j * cs)) / cs
    sd, td = d[0] / cs, d[1] / cs
    # clearance g(λ) = -(o_z + λ d_z) - h(s0 + λ sd, t0 + λ td) = A λ² + B λ + C
    A = -c * sd * td
    B = -d[2] - (a * sd + b * td + c * (s0 * td + t0 * sd))
    C = -o[2] - (z00 + a * s0 + b * t0 + c * s0 * t0)
    width = np.maximum(lam_hi - lam_lo, 0.0)
    slack = 1e-9 * (1.0 + np.abs(lam_hi))
    roots = np.full((2,) + np.shape(A), np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = B * B - 4.0 * A * C
        sq = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
        qq = -0.5 * (B + np.copysign(sq, B))  # stable quadratic roots q/A and C/q
        quadratic = np.abs(A) * width * width > 1e-15 * (np.abs(B) * width + np.abs(C) + 1e-300)
        roots[0] = np.where(quadratic, qq / A, -C / B)
        roots[1] = np.where(quadratic, C / qq, np.nan)
    ok = (roots >= lam_lo - slack) & (roots <= lam_hi + slack)
    roots = np.where(ok, np.clip(roots, lam_lo, lam_hi), np.nan)
    return np.fmin(roots[0], roots[1])


def grid_intersect(grid, origin, direction, max_range: float, interpolation: str) -> np.ndarray | None:
    """Exact first intersection of ``origin + λ d̂`` (``0 <= λ <= max_range``) with the grid surface.

    ``None`` when the ray misses the grid within ``max_range``, starts below the surface, enters the
    grid's footprint below the surface (it would hit the unknown terrain outside the grid), or reaches
    a cell with a NODATA node before any hit while below the highest valid node (the terrain there is
    unknown; a hole is assumed no higher than the rest of the grid)."""
    o = np.asarray(origin, dtype=float)
    d = np.asarray(direction, dtype=float)
    norm = float(np.linalg.norm(d))
    if o.shape != (3,) or d.shape != (3,) or not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))) or norm == 0:
        raise ValueError("ray origin and direction must be finite 3-vectors, direction non-zero")
    if not (math.isfinite(max_range) and max_range > 0):
        raise ValueError(f"max_range must be positive and finite, got {max_range}")
    d = d / norm
    rows, cols = grid.heights.shape
    cs = grid.cellsize
    lo_n, hi_n = grid.north0, grid.north0 + (rows - 1) * cs
    lo_e, hi_e = grid.east0, grid.east0 + (cols - 1) * cs

    lam0, lam1 = 0.0, float(max_range)
    for o_k, d_k, lo_k, hi_k in ((o[0], d[0], lo_n, hi_n), (o[1], d[1], lo_e, hi_e)):  # horizontal slabs
        if d_k == 0.0:
            if not lo_k <= o_k <= hi_k:
                return None
        else:
            a, b = sorted(((lo_k - o_k) / d_k, (hi_k - o_k) / d_k))
            lam0, lam1 = max(lam0, a), min(lam1, b)
    h_min, h_max = grid.height_bounds
    alt0 = -o[2]
    if d[2] == 0.0:  # level ray: only at a height the terrain reaches
        if not h_min <= alt0 <= h_max:
            return None
    else:  # altitude(λ) = alt0 - λ d_z must lie in [h_min, h_max]
        a, b = sorted(((alt0 - h_max) / d[2], (alt0 - h_min) / d[2]))
        pad = 1e-9 * (1.0 + abs(a) + abs(b))
        lam0, lam1 = max(lam0, a - pad), min(lam1, b + pad)
    if lam0 > lam1:
        return None
    lam0 = max(lam0, 0.0)

    entry = o + lam0 * d
    h_entry = grid.height(entry[0], entry[1])
    if np.isfinite(h_entry) and -entry[2] < h_entry - 1e-9 * (1.0 + abs(h_entry)):
        return None  # starts below the surface, or enters the grid underground
    if np.isfinite(h_entry) and -entry[2] <= h_entry:
        return entry

    # Cut [lam0, lam1] at every grid line crossed.
    cuts = [np.array([lam0, lam1])]
    for o_k, d_k, base in ((o[0], d[0], grid.north0), (o[1], d[1], grid.east0)):
        if d_k != 0.0:
            k_a, k_b = sorted(((o_k + lam0 * d_k - base) / cs, (o_k + lam1 * d_k - base) / cs))
            k = np.arange(math.ceil(k_a), math.floor(k_b) + 1)
            cuts.append((base + k * cs - o_k) / d_k)
    lam = np.unique(np.clip(np.concatenate(cuts), lam0, lam1))
    if lam.size == 1:
        lam = np.array([lam0, lam1])
    lam_lo, lam_hi = lam[:-1], lam[1:]
    mid = 0.5 * (lam_lo + lam_hi)
    i = np.clip(np.floor((o[0] + mid * d[0] - grid.north0) / cs).astype(int), 0, rows - 2)
    j = np.clip(np.floor((o[1] + mid * d[1] - grid.east0) / cs).astype(int), 0, cols - 2)

    nodes = np.stack(_cell_nodes(grid, i, j))
    hole = np.any(np.isnan(nodes), axis=0)
    cell_top = np.where(hole, np.inf, np.max(np.where(np.isnan(nodes), 0.0, nodes), axis=0))
    ray_low = alt0 - np.maximum(lam_lo * d[2], lam_hi * d[2])
    candidate = hole | (ray_low <= cell_top + 1e-9 * (1.0 + np.abs(cell_top)))
    idx = np.flatnonzero(candidate)
    if idx.size == 0:
        return None
    i, j, lam_lo, lam_hi, hole = i[idx], j[idx], lam_lo[idx], lam_hi[idx], hole[idx]

    if interpolation == "bilinear":
        hit_lam = _bilinear_roots(grid, i, j, o, d, lam_lo, lam_hi)
    else:
        tri = _triangle_vertices(grid, np.repeat(i[:, None], 2, 1), np.repeat(j[:, None], 2, 1), np.array([0, 1]))
        t, u, v = moller_trumbore(o, d, tri[..., 0, :], tri[..., 1, :], tri[..., 2, :])
        eps = BARYCENTRIC_EPS
        with np.errstate(invalid="ignore"):
            slack = 1e-9 * (1.0 + np.abs(lam_hi))[:, None]
            inside = (u >= -eps) & (v >= -eps) & (u + v <= 1.0 + eps)
            inside &= (t >= (lam_lo[:, None] - slack)) & (t <= (lam_hi[:, None] + slack)) & (t >= 0.0)
        hit_lam = np.min(np.where(inside, t, np.inf), axis=1)
        hit_lam[~np.isfinite(hit_lam)] = np.nan
    event = hole | np.isfinite(hit_lam)
    first = np.flatnonzero(event)
    if first.size == 0:
        return None
    k = first[0]
    if hole[k]:
        return None
    return o + float(hit_lam[k]) * d
