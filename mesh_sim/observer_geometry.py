"""Geometry of what the ground station draws: covariance ellipsoids and bearing rays, in NED.

:func:`cov_to_ellipsoid` gives the half-sizes and rotation (a scalar-last quaternion, as Rerun's
``Ellipsoids3D`` takes it) of the ``n_sigma`` ellipsoid of a position covariance; :func:`ray_end` where a
drawn bearing ray from a UAV ends; :func:`nearest_truth` which true target a track's label names.
"""

from __future__ import annotations

import numpy as np

from agent.evaluation import MATCH_GATE
from fusion.measurement import azel_to_los

RAY_LENGTH = 150.0  # m; a ray stops earlier where it meets flat ground z = 0 (chosen here)


def cov_to_ellipsoid(cov, n_sigma: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Half-sizes and rotation (quaternion x, y, z, w) of the ``n_sigma`` ellipsoid of a 3x3 covariance.

    With ``R`` the rotation of the quaternion, ``R @ diag((half_sizes / n_sigma) ** 2) @ R.T == cov``
    (up to rounding; negative eigenvalues from rounding are clipped to zero)."""
    cov = np.asarray(cov, dtype=np.float64)
    if cov.shape != (3, 3) or not np.all(np.isfinite(cov)):
        raise ValueError(f"need a finite 3x3 covariance, got shape {cov.shape}")
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    if np.linalg.det(v) < 0:
        v[:, 2] = -v[:, 2]  # a proper rotation (columns are eigenvectors; the sign of one is free)
    half = n_sigma * np.sqrt(np.maximum(w, 0.0))
    return half, _matrix_to_quat_xyzw(v)


def _matrix_to_quat_xyzw(m: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a rotation matrix (Shepperd: divide by the largest component)."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    candidates = (tr, m[0, 0], m[1, 1], m[2, 2])
    i = int(np.argmax(candidates))
    if i == 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    else:
        a = i - 1
        b, c = (a + 1) % 3, (a + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[a, a] - m[b, b] - m[c, c])
        q = [0.0, 0.0, 0.0, (m[c, b] - m[b, c]) / s]
        q[a] = 0.25 * s
        q[b] = (m[b, a] + m[a, b]) / s
        q[c] = (m[c, a] + m[a, c]) / s
    q = np.asarray(q)
    return q / np.linalg.norm(q)


def quat_xyzw_to_matrix(q) -> np.ndarray:
    """The rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = np.asarray(q, dtype=np.float64)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def ray_end(origin: np.ndarray, azel, length: float = RAY_LENGTH) -> np.ndarray:
    """End of a bearing ray from ``origin`` (NED): ``length`` metres, or less where it reaches z = 0."""
    los = azel_to_los(azel)
    if los[2] > 1e-9 and origin[2] < 0.0:
        length = min(length, -origin[2] / los[2])
    return origin + length * los


def nearest_truth(ids: list[str], positions: np.ndarray, centre: np.ndarray, cov: np.ndarray,
                  gate: float = MATCH_GATE) -> str | None:
    """The id of the true target nearest to a track of position ``centre`` and covariance ``cov`` in Mahalanobis
    distance ``d^2 = (x - c)^T P^-1 (x - c)``, if within ``gate`` (the evaluator's match,
    :data:`agent.evaluation.MATCH_GATE`); ``None`` otherwise or without targets."""
    if not ids:
        return None
    d = np.asarray(positions, float) - centre
    d2 = np.einsum("ij,ij->i", d, np.linalg.solve(cov, d.T).T)
    best = int(np.argmin(d2))
    return ids[best] if d2[best] <= gate else None
