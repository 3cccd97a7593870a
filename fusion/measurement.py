"""Measurement models ``z = h(x) + v``, ``v ~ N(0, R)``, for the (extended) information filter.

Every model exposes ``h(x)``, ``jacobian(x)``, ``R``, ``R_inv`` and ``residual(z, z_hat)`` (which wraps
angles). Target positions are the first ``spatial_dims`` entries of the state (Merino (3.60)-(3.61)).
Frames follow DESIGN.md §3: local NED, so azimuth is measured from north (x) towards east (y), and
elevation is the angle of the line of sight above the horizontal plane (negative when looking down).
"""

from __future__ import annotations

import math

import numpy as np

from fusion import lapack, validation

#: Smallest squared horizontal distance [m^2] from the sensor at which an azimuth is defined.
MIN_RHO2 = 1e-12


def wrap_angle(angle):
    """Wrap an angle (or an array of angles) to ``[-pi, pi)``."""
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


class _Model:
    """Shared plumbing: the noise matrix, its inverse, and the selection of position components."""

    def __init__(self, state_dim: int, spatial_dims: int, R):
        if state_dim < spatial_dims:
            raise ValueError(f"state dimension {state_dim} is smaller than the {spatial_dims} position axes")
        self.state_dim = state_dim
        self.spatial_dims = spatial_dims
        self.R = validation.as_pd(R, "measurement noise R", self.dim)
        self.R_inv = lapack.spd_inverse(self.R)

    dim: int

    def residual(self, z, z_hat) -> np.ndarray:
        return np.asarray(z, dtype=float) - z_hat

    def linearize(self, x) -> tuple[np.ndarray, np.ndarray]:
        """``(h(x), dh/dx)`` in one call (models whose geometry is shared override it)."""
        return self.h(x), self.jacobian(x)

    def _pad(self, J_position: np.ndarray) -> np.ndarray:
        H = np.zeros((J_position.shape[0], self.state_dim))
        H[:, : self.spatial_dims] = J_position
        return H


class PositionMeasurement(_Model):
    """A direct (geolocated) position measurement: ``H = [I 0]`` (Merino (3.60)-(3.61))."""

    def __init__(self, state_dim: int, R, spatial_dims: int = 3):
        self.dim = spatial_dims
        super().__init__(state_dim, spatial_dims, R)
        self.H = self._pad(np.eye(spatial_dims))

    def h(self, x) -> np.ndarray:
        return np.asarray(x, dtype=float)[: self.spatial_dims]

    def jacobian(self, x=None) -> np.ndarray:
        return self.H


class Bearing2D(_Model):
    """Azimuth from a sensor at ``sensor`` (x north, y east): ``z = atan2(y - s_y, x - s_x)``."""

    dim = 1

    def __init__(self, state_dim: int, sensor, sigma: float, spatial_dims: int = 2):
        sensor = validation.as_vector(sensor, "sensor position")
        if sensor.shape[0] not in (2, 3):
            raise ValueError(f"sensor position must have length 2 or 3 (altitude ignored), got {sensor.shape[0]}")
        self.sensor = sensor[:2]
        self._sensor = tuple(self.sensor.tolist())
        super().__init__(state_dim, spatial_dims, np.array([[sigma**2]]))

    def _delta(self, x) -> tuple[float, float, float]:
        """``(dx, dy, rho^2)`` as Python floats (scalar geometry is cheaper without numpy scalars)."""
        px, py = (x.tolist() if isinstance(x, np.ndarray) else list(x))[:2]
        dx, dy = px - self._sensor[0], py - self._sensor[1]
        rho2 = dx * dx + dy * dy
        if rho2 < MIN_RHO2:
            raise ValueError("the bearing is undefined: the target is at the sensor position")
        return dx, dy, rho2

    def h(self, x) -> np.ndarray:
        return self.linearize(x)[0]

    def jacobian(self, x) -> np.ndarray:
        return self.linearize(x)[1]

    def linearize(self, x) -> tuple[np.ndarray, np.ndarray]:
        dx, dy, rho2 = self._delta(x)
        H = np.zeros((1, self.state_dim))
        H[0, 0], H[0, 1] = -dy / rho2, dx / rho2
        return np.array([math.atan2(dy, dx)]), H

    def residual(self, z, z_hat) -> np.ndarray:
        r = np.asarray(z, dtype=float) - z_hat
        r[0] = (r[0] + math.pi) % (2.0 * math.pi) - math.pi
        return r


class Bearing3D(_Model):
    """Azimuth and elevation of the line of sight from ``sensor`` (NED):
    ``az = atan2(dy, dx)``, ``el = atan2(-dz, hypot(dx, dy))``. ``R`` is 2x2 (radians^2)."""

    dim = 2

    def __init__(self, state_dim: int, sensor, R):
        self.sensor = validation.as_vector(sensor, "sensor position", 3)
        self._sensor = tuple(self.sensor.tolist())
        super().__init__(state_dim, 3, R)

    def _delta(self, x) -> tuple[float, float, float, float]:
        """``(dx, dy, dz, rho^2)`` as Python floats: scalar geometry is cheaper without numpy scalars."""
        px, py, pz = (x.tolist() if isinstance(x, np.ndarray) else list(x))[:3]
        sx, sy, sz = self._sensor
        dx, dy, dz = px - sx, py - sy, pz - sz
        rho2 = dx * dx + dy * dy
        if rho2 < MIN_RHO2:
            raise ValueError("azimuth is undefined: the target is straight above or below the sensor")
        return dx, dy, dz, rho2

    def h(self, x) -> np.ndarray:
        return self.linearize(x)[0]

    def jacobian(self, x) -> np.ndarray:
        return self.linearize(x)[1]

    def linearize(self, x) -> tuple[np.ndarray, np.ndarray]:
        dx, dy, dz, rho2 = self._delta(x)
        rho = math.sqrt(rho2)
        r2 = rho2 + dz * dz
        H = np.zeros((2, self.state_dim))
        H[0, 0], H[0, 1] = -dy / rho2, dx / rho2
        H[1, 0], H[1, 1], H[1, 2] = dz * dx / (rho * r2), dz * dy / (rho * r2), -rho / r2
        return np.array([math.atan2(dy, dx), math.atan2(-dz, rho)]), H

    def residual(self, z, z_hat) -> np.ndarray:
        r = np.asarray(z, dtype=float) - z_hat
        r[0] = (r[0] + math.pi) % (2.0 * math.pi) - math.pi
        return r


def los_to_azel(line_of_sight) -> np.ndarray:
    """Azimuth/elevation of a line-of-sight vector in NED (it need not be unit length)."""
    v = validation.as_vector(line_of_sight, "line of sight", 3)
    return np.array([np.arctan2(v[1], v[0]), np.arctan2(-v[2], np.hypot(v[0], v[1]))])


def azel_to_los(azel) -> np.ndarray:
    """Unit line-of-sight vector in NED for an azimuth/elevation pair."""
    return azel_to_los_array(validation.as_vector(azel, "azimuth/elevation", 2))


def azel_to_los_array(azel: np.ndarray) -> np.ndarray:
    """:func:`azel_to_los` on an array of pairs ``(..., 2)`` -> ``(..., 3)``, unchecked (the caller's arrays):
    ``(cos el cos az, cos el sin az, -sin el)``, elevation positive up (NED ``z`` down)."""
    az, el = azel[..., 0], azel[..., 1]
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)], -1)


def bearing3d_linearization(points, sensors) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`Bearing3D.linearize` for many position/sensor pairs at once (numpy broadcasting over the leading
    axes of ``points`` and ``sensors``, both ``(..., 3)``): ``h`` = (azimuth, elevation) ``(..., 2)``, its
    Jacobian with respect to the position ``(..., 2, 3)``, and ``rho^2`` ``(...)``, the squared horizontal
    distance — the bearing is defined only where ``rho^2 >= MIN_RHO2`` (elsewhere the values are not finite)."""
    d = np.asarray(points, float) - np.asarray(sensors, float)
    dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
    rho2 = dx * dx + dy * dy
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.sqrt(rho2)
        r2 = rho2 + dz * dz
        J = np.zeros(d.shape[:-1] + (2, 3))
        J[..., 0, 0], J[..., 0, 1] = -dy / rho2, dx / rho2
        J[..., 1, 0], J[..., 1, 1], J[..., 1, 2] = dz * dx / (rho * r2), dz * dy / (rho * r2), -rho / r2
    return np.stack([np.arctan2(dy, dx), np.arctan2(-dz, rho)], -1), J, rho2


def bearing3d_information(points, sensors, azel, R) -> tuple[np.ndarray, np.ndarray]:
    """The extended information filter's terms (Merino (3.52)) of ``m`` bearings, each linearised at its own
    position ``mu_j``: ``I_j = H_j^T R_j^-1 H_j`` ``(m, 3, 3)`` and ``i_j = H_j^T R_j^-1 (nu_j + H_j mu_j)``
    ``(m, 3)``, with ``nu_j = z_j - h(mu_j)`` (azimuth wrapped) and ``h``, ``H`` those of :class:`Bearing3D` on the
    position (:func:`bearing3d_linearization`); ``R^-1`` of each 2x2 in closed form. ``points``, ``sensors``
    ``(m, 3)``, ``azel`` ``(m, 2)``, ``R`` ``(m, 2, 2)``; the caller makes sure each bearing is defined there."""
    points = np.asarray(points, float)
    z_hat, J, _ = bearing3d_linearization(points, sensors)
    nu = np.asarray(azel, float) - z_hat
    nu[:, 0] = wrap_angle(nu[:, 0])
    a, b, c = R[:, 0, 0], R[:, 0, 1], R[:, 1, 1]
    R_inv = np.stack([np.stack([c, -b], -1), np.stack([-b, a], -1)], -2) / (a * c - b * b)[:, None, None]
    JtRi = np.swapaxes(J, -1, -2) @ R_inv
    return JtRi @ J, (JtRi @ (nu + (J @ points[..., None])[..., 0])[..., None])[..., 0]


def bearing_gate_distances(sensors, azel, R, means, covs) -> np.ndarray:
    """Merino (3.64) for every pair of ``m`` bearings and ``k`` position beliefs at once: ``d^2 = nu^T S^-1 nu``
    with ``S = H P H^T + R`` and ``nu = z - h(mu)`` (azimuth wrapped), ``h`` and ``H`` those of
    :class:`Bearing3D` at the belief's mean (:func:`bearing3d_linearization`).

    ``sensors`` ``(m, 3)``, ``azel`` ``(m, 2)``, ``R`` ``(m, 2, 2)``; ``means`` ``(k, 3)``, ``covs`` ``(k, 3, 3)``
    (positions only: a bearing sees nothing else). Returns an ``(m, k)`` array, NaN where the bearing is
    undefined (the belief straight above or below the sensor) or ``S`` is not positive definite."""
    z_hat, J, rho2 = bearing3d_linearization(means[None, :, :], sensors[:, None, :])
    with np.errstate(invalid="ignore", divide="ignore"):
        S = J @ covs[None] @ np.swapaxes(J, -1, -2) + R[:, None]
        nu0 = wrap_angle(azel[:, None, 0] - z_hat[..., 0])
        nu1 = azel[:, None, 1] - z_hat[..., 1]
        a, b, c = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
        det = a * c - b * b
        d2 = (c * nu0 * nu0 - 2.0 * b * nu0 * nu1 + a * nu1 * nu1) / det  # S^-1 of a 2x2 in closed form
    return np.where((rho2 >= MIN_RHO2) & (a > 0.0) & (det > 0.0), d2, np.nan)
