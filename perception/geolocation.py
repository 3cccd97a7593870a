"""Geolocation of one bearing on the terrain, with an honest covariance.

A camera gives a direction only; a target known to be on the ground is where the ray meets the
terrain (Merino §3.6: DEM plus ray tracing). Its uncertainty comes from the bearing noise, the
camera position error and the DEM error, propagated through the (non-linear) ray casting with the
unscented transform (Merino Alg. 3.5, §3.7.1). The result is elongated along the ray at low grazing
angles, as it should be.
"""

from __future__ import annotations

import numpy as np

from fusion.measurement import azel_to_los
from fusion.unscented import unscented_transform
from perception.terrain import intersect_ray


class _RaisedTerrain:
    """The terrain shifted up by ``dh`` metres (one sigma point of the DEM error)."""

    def __init__(self, base, dh: float):
        self.base, self.dh = base, dh
        # Forward the hints that let ray casting take long safe steps (see perception.terrain.intersect_ray).
        self.max_slope = getattr(base, "max_slope", None)
        bounds = getattr(base, "height_bounds", None)
        self.height_bounds = None if bounds is None else (bounds[0] + dh, bounds[1] + dh)

    def height(self, north, east):
        return self.base.height(north, east) + self.dh


def geolocate(
    sensor,
    azel,
    R_azel,
    terrain,
    sensor_sigma: float = 0.5,
    terrain_sigma: float = 2.0,
    max_range: float = 2000.0,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Ground point hit by the ray from ``sensor`` along ``azel`` and its 3x3 covariance (NED).

    The uncertain inputs are ``(az, el, dh, dn, de, dd)``: the bearing with covariance ``R_azel``,
    the DEM error ``dh ~ N(0, terrain_sigma^2)`` and the camera position error
    ``~ N(0, sensor_sigma^2 I)``. Returns ``None`` when the ray (or one of its sigma points) misses
    the terrain within ``max_range``: such a bearing cannot start a track on its own."""
    sensor = np.asarray(sensor, float)
    mean = np.concatenate([np.asarray(azel, float), np.zeros(4)])
    cov = np.zeros((6, 6))
    cov[:2, :2] = R_azel
    cov[2, 2] = terrain_sigma**2
    cov[3:, 3:] = sensor_sigma**2 * np.eye(3)

    def cast(p):
        hit = intersect_ray(_RaisedTerrain(terrain, p[2]), sensor + p[3:], azel_to_los(p[:2]), max_range=max_range)
        return np.full(3, np.nan) if hit is None else hit

    try:
        return unscented_transform(cast, mean, cov)
    except ValueError:  # a sigma point missed the terrain
        return None
