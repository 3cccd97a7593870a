"""Pixels, world rays and ground points for a posed camera.

``world_to_pixel`` is Merino (3.57) ``s m = A (R_t  -t_t) p`` (plus lens distortion); ``pixel_to_ray_world``
is its inverse up to scale, the bearing of thesis 000 §2.5 (``R_body->world R_cam->body R_pixel->cam``);
``pixel_to_ground`` casts that ray on the terrain (Merino §3.6, Ross Eq. 1); ``footprint`` georeferences
the four image corners (Ross Fig. 3).

Ray casting (:func:`cast_ray`; :func:`cast_rays` for many rays at once) picks the exact method each terrain
allows: a closed form on :class:`~perception.terrain.FlatTerrain` (``λ = (-h0 - o_z) / d_z``), the terrain's
own ``intersect`` when it has one (:class:`perception.dem.GridTerrain`: exact per-cell intersection), and
otherwise the generic root search :func:`perception.terrain.intersect_ray`.
"""

from __future__ import annotations

import numpy as np

from perception.camera import Intrinsics
from perception.pose import CameraPose
from perception.terrain import FlatTerrain, Terrain, intersect_ray, unit_rays

__all__ = [
    "pixel_to_ray_world", "world_to_pixel", "cast_ray", "cast_rays", "cast_rays_on_raised", "pixel_to_ground",
    "footprint",
]

#: Default longest ray considered when georeferencing (m, chosen here, as in perception.geolocation).
DEFAULT_MAX_RANGE = 5000.0
#: Default bracket tolerance of the generic root search (m). The final secant step makes the error far
#: smaller than this on smooth terrain. Chosen here.
DEFAULT_TOL = 1e-6


def pixel_to_ray_world(pose: CameraPose, intrinsics: Intrinsics, pixels) -> np.ndarray:
    """Unit viewing direction(s) in the world frame (NED) through pixel(s) (..., 2) -> (..., 3)."""
    return intrinsics.ray(pixels) @ pose.R_world_from_cam.T


def world_to_pixel(pose: CameraPose, intrinsics: Intrinsics, points):
    """Pixel(s) of world point(s). A single point (3,) gives a (2,) array, or ``None`` when it is on or
    behind the plane through the optical centre (``Z_cam <= 0``); an array (N, 3) gives (N, 2) with NaN
    rows for such points. Points in front but outside the image still get (out-of-range) pixels: test
    with :meth:`Intrinsics.contains`."""
    p = np.asarray(points, dtype=float)
    if p.shape[-1:] != (3,):
        raise ValueError(f"world points must have shape (3,) or (N, 3), got {p.shape}")
    uv = intrinsics.project(pose.world_to_camera(p))
    if p.ndim == 1:
        return None if not np.all(np.isfinite(uv)) else uv
    return uv


def cast_ray(
    terrain: Terrain,
    origin,
    direction,
    max_range: float = DEFAULT_MAX_RANGE,
    tol: float = DEFAULT_TOL,
) -> np.ndarray | None:
    """First point where the ray ``origin + λ d̂`` (``0 <= λ <= max_range``) meets the terrain, or ``None``
    (pointing at or above the horizon over flat ground, leaving the range, missing a grid)."""
    o = np.asarray(origin, dtype=float)
    d = np.asarray(direction, dtype=float)
    if o.shape != (3,) or d.shape != (3,) or not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))):
        raise ValueError(f"ray origin and direction must be finite 3-vectors, got {origin!r} and {direction!r}")
    norm = float(np.linalg.norm(d))
    if norm == 0.0:
        raise ValueError("ray direction must be non-zero")
    d = d / norm
    if isinstance(terrain, FlatTerrain):
        hit = _flat_hits(terrain.level, o[None], d[None], max_range)[0]
        return None if np.isnan(hit[0]) else hit
    own = getattr(terrain, "intersect", None)
    if callable(own):
        return own(o, d, max_range=max_range)
    return intersect_ray(terrain, o, d, max_range=max_range, tol=tol)


def cast_rays(
    terrain: Terrain,
    origins,
    directions,
    max_range: float = DEFAULT_MAX_RANGE,
    tol: float = DEFAULT_TOL,
) -> np.ndarray:
    """:func:`cast_ray` for ``k`` rays at once: origins and directions ``(k, 3)`` -> hits ``(k, 3)``, a row of
    NaN where a ray misses. Vectorised in closed form on :class:`~perception.terrain.FlatTerrain`; a loop over
    :func:`cast_ray` otherwise."""
    o, d = unit_rays(origins, directions)
    if isinstance(terrain, FlatTerrain):
        return _flat_hits(terrain.level, o, d, max_range)
    out = np.full(o.shape, np.nan)
    for k, (origin, direction) in enumerate(zip(o, d, strict=True)):
        hit = cast_ray(terrain, origin, direction, max_range, tol)
        if hit is not None:
            out[k] = hit
    return out


def cast_rays_on_raised(
    terrain: Terrain,
    origins,
    directions,
    raised,
    max_range: float = DEFAULT_MAX_RANGE,
) -> np.ndarray:
    """:func:`cast_rays` on the terrain raised by ``raised[i]`` metres for ray ``i`` (a DEM error, Merino §3.7.1):
    the same geometry as the ray's origin lowered by that much, with the hit raised back."""
    lowered = np.array(origins, dtype=float)
    lowered[:, 2] += raised
    hits = cast_rays(terrain, lowered, directions, max_range)
    hits[:, 2] -= raised
    return hits


def _flat_hits(level: float, o: np.ndarray, d: np.ndarray, max_range: float) -> np.ndarray:
    """Rays ``o + λ d`` (unit ``d``, rows) on the plane at height ``level``: ``λ = c / d_z`` with the clearance
    ``c = -level - o_z`` of the origin above the plane; a ray starting on the plane hits at its origin; one that
    starts below it (``c < 0``), points level or up (``d_z <= 0``) or would go beyond ``max_range`` misses (NaN)."""
    clearance = -level - o[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.where(clearance == 0.0, 0.0, clearance / d[:, 2])
        hit = o + lam[:, None] * d
    hit[:, 2] = -level  # exactly on the plane
    missed = (clearance != 0.0) & ((clearance < 0.0) | (d[:, 2] <= 0.0) | (lam > max_range))
    hit[missed] = np.nan
    return hit


def pixel_to_ground(
    pose: CameraPose,
    intrinsics: Intrinsics,
    terrain: Terrain,
    pixel,
    max_range: float = DEFAULT_MAX_RANGE,
    tol: float = DEFAULT_TOL,
) -> np.ndarray | None:
    """Ground point (NED) seen at ``pixel`` (2,), or ``None`` when its ray misses the terrain."""
    pixel = np.asarray(pixel, dtype=float)
    if pixel.shape != (2,) or not np.all(np.isfinite(pixel)):
        raise ValueError(f"pixel must be a finite (u, v) pair, got {pixel!r}")
    return cast_ray(terrain, pose.centre, pixel_to_ray_world(pose, intrinsics, pixel), max_range, tol)


def footprint(
    pose: CameraPose,
    intrinsics: Intrinsics,
    terrain: Terrain,
    max_range: float = DEFAULT_MAX_RANGE,
    tol: float = DEFAULT_TOL,
) -> list[np.ndarray | None]:
    """Ground points of the four outer image corners, clockwise from top-left (Ross Fig. 3); a corner
    whose ray is at or above the horizon, or misses the terrain within ``max_range``, is ``None``."""
    return [pixel_to_ground(pose, intrinsics, terrain, c, max_range, tol) for c in intrinsics.corners]
