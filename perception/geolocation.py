"""Geolocation of one bearing on the terrain, with an honest covariance.

A camera gives a direction only; a target known to be on the ground is where the ray meets the
terrain (Merino §3.6: DEM plus ray tracing). Its uncertainty comes from the bearing noise, the
camera position error and the DEM error, propagated through the (non-linear) ray casting with the
unscented transform (Merino Alg. 3.5, §3.7.1). The result is elongated along the ray at low grazing
angles, as it should be.
"""

from __future__ import annotations

import numpy as np

from fusion.measurement import azel_to_los_array
from fusion.unscented import unscented_transform
from perception.projection import cast_rays_on_raised


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
    the terrain within ``max_range``: such a bearing cannot start a track on its own.

    All 13 sigma points are cast together, each on the terrain raised by its ``dh``
    (:func:`perception.projection.cast_rays_on_raised`: in closed form on flat terrain)."""
    sensor = np.asarray(sensor, float)
    mean = np.concatenate([np.asarray(azel, float), np.zeros(4)])
    cov = np.zeros((6, 6))
    cov[:2, :2] = R_azel
    cov[2, 2] = terrain_sigma**2
    cov[3:, 3:] = sensor_sigma**2 * np.eye(3)

    def cast(points: np.ndarray) -> np.ndarray:
        return cast_rays_on_raised(terrain, sensor + points[:, 3:], azel_to_los_array(points[:, :2]), points[:, 2],
                                   max_range)

    try:
        return unscented_transform(cast, mean, cov, vectorized=True)
    except ValueError:  # a sigma point missed the terrain
        return None
