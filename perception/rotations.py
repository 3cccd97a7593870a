"""Rotation conventions, pinned once (DESIGN.md §3).

Every matrix here is *active*: ``R_a_from_b`` maps the coordinates of a vector in frame ``b`` to its
coordinates in frame ``a`` (``v_a = R_a_from_b @ v_b``); composition reads right to left,
``R_a_from_c = R_a_from_b @ R_b_from_c``.

* Elementary rotations ``rot_x``, ``rot_y``, ``rot_z`` (right-handed, angle in radians).
* Vehicle attitude: aerospace Z-Y-X Euler angles (yaw ψ, then pitch θ, then roll φ), body FRD to
  world NED: ``R_ned_from_frd = R_z(ψ) R_y(θ) R_x(φ)`` (spec 002 §2.2, "3-2-1 Euler from the Piccolo
  telemetry"). Thesis 000 Eq. 2.7 uses an intrinsic Y-Z-X (y-up) convention; spec 000 §2.5 allows a
  deliberate, consistent swap to Z-Y-X with a z axis, which is what is done here. Hand-checked cases
  (tests/perception/test_rotations.py): yaw +90° maps body forward to east, pitch +90° maps body
  forward to up (NED ``-z``), roll +90° maps the right wing to down.
* Quaternions are Hamilton, unit, **scalar last** ``(x, y, z, w)`` (the order scipy uses); the matrix
  is the standard ``R(q)`` of spec 000 Eq. 2.6, which is active for the same frames as above.

All functions broadcast over leading axes (``(..., 3, 3)`` matrices, ``(..., 4)`` quaternions).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "rot_x",
    "rot_y",
    "rot_z",
    "rotation_from_euler",
    "euler_from_rotation",
    "rotation_from_quaternion",
    "quaternion_from_rotation",
    "quaternion_from_euler",
    "quaternion_multiply",
    "as_rotation",
]

#: Tolerance on ``|R^T R - I|`` and ``|det R - 1|`` accepted by :func:`as_rotation` (chosen here).
ROTATION_ATOL = 1e-9


def _elementary(angle, i: int, j: int) -> np.ndarray:
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    k = 3 - i - j  # the fixed axis
    R[..., k, k] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def rot_x(angle) -> np.ndarray:
    """``[[1, 0, 0], [0, c, -s], [0, s, c]]``: rotation by ``angle`` about x."""
    return _elementary(angle, 1, 2)


def rot_y(angle) -> np.ndarray:
    """``[[c, 0, s], [0, 1, 0], [-s, 0, c]]``: rotation by ``angle`` about y."""
    return _elementary(angle, 2, 0)


def rot_z(angle) -> np.ndarray:
    """``[[c, -s, 0], [s, c, 0], [0, 0, 1]]``: rotation by ``angle`` about z."""
    return _elementary(angle, 0, 1)


def rotation_from_euler(roll, pitch, yaw) -> np.ndarray:
    """``R_ned_from_frd = R_z(yaw) R_y(pitch) R_x(roll)`` (aerospace Z-Y-X, radians)."""
    return rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)


def euler_from_rotation(R) -> tuple[np.ndarray | float, np.ndarray | float, np.ndarray | float]:
    """Inverse of :func:`rotation_from_euler`: ``(roll, pitch, yaw)`` with pitch in ``[-π/2, π/2]``,
    roll and yaw in ``(-π, π]``. At gimbal lock (``|pitch| = π/2``) only ``yaw ∓ roll`` is defined;
    roll is then set to 0."""
    R = np.asarray(R, dtype=float)
    pitch = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    locked = np.hypot(R[..., 0, 0], R[..., 1, 0]) < 1e-12
    roll = np.where(locked, 0.0, np.arctan2(R[..., 2, 1], R[..., 2, 2]))
    yaw = np.where(locked, np.arctan2(-R[..., 0, 1], R[..., 1, 1]), np.arctan2(R[..., 1, 0], R[..., 0, 0]))
    if np.ndim(pitch) == 0:
        return float(roll), float(pitch), float(yaw)
    return roll, pitch, yaw


def rotation_from_quaternion(q) -> np.ndarray:
    """Matrix of the unit quaternion ``q = (x, y, z, w)`` (spec 000 Eq. 2.6). ``q`` is normalised
    first; a zero or non-finite quaternion raises :class:`ValueError`."""
    q = np.asarray(q, dtype=float)
    if q.shape[-1:] != (4,):
        raise ValueError(f"a quaternion must have 4 components (x, y, z, w), got shape {q.shape}")
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if not (np.all(np.isfinite(q)) and np.all(norm > 1e-12)):
        raise ValueError("a quaternion must be finite and non-zero")
    x, y, z, w = np.moveaxis(q / norm, -1, 0)
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - z * w)
    R[..., 0, 2] = 2 * (x * z + y * w)
    R[..., 1, 0] = 2 * (x * y + z * w)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - x * w)
    R[..., 2, 0] = 2 * (x * z - y * w)
    R[..., 2, 1] = 2 * (y * z + x * w)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def quaternion_from_rotation(R) -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)`` of a rotation matrix, with ``w >= 0`` (Shepperd's method:
    the largest of ``w², x², y², z²`` is taken from the diagonal, the rest from off-diagonal sums)."""
    R = np.asarray(R, dtype=float)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"a rotation matrix must be 3x3, got shape {R.shape}")
    flat = R.reshape(-1, 3, 3)
    out = np.empty((flat.shape[0], 4))
    for k, m in enumerate(flat):
        t = np.trace(m)
        diag = (t, m[0, 0], m[1, 1], m[2, 2])
        i = int(np.argmax(diag))
        if i == 0:
            s = 2.0 * np.sqrt(1.0 + t)
            q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s)
        elif i == 1:
            s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
            q = (0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s)
        elif i == 2:
            s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
            q = ((m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s)
        else:
            s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
            q = ((m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s)
        q = np.asarray(q)
        q /= np.linalg.norm(q)
        out[k] = -q if q[3] < 0 else q
    return out.reshape(R.shape[:-2] + (4,))


def quaternion_multiply(a, b) -> np.ndarray:
    """Hamilton product ``a ⊗ b`` of scalar-last quaternions; ``R(a ⊗ b) = R(a) R(b)``."""
    ax, ay, az, aw = np.moveaxis(np.asarray(a, dtype=float), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b, dtype=float), -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quaternion_from_euler(roll, pitch, yaw) -> np.ndarray:
    """``q = q_z(yaw) ⊗ q_y(pitch) ⊗ q_x(roll)``, scalar last: the quaternion of
    :func:`rotation_from_euler`."""
    roll, pitch, yaw = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (roll, pitch, yaw)))
    zero = np.zeros(roll.shape)
    qx = np.stack([np.sin(roll / 2), zero, zero, np.cos(roll / 2)], axis=-1)
    qy = np.stack([zero, np.sin(pitch / 2), zero, np.cos(pitch / 2)], axis=-1)
    qz = np.stack([zero, zero, np.sin(yaw / 2), np.cos(yaw / 2)], axis=-1)
    return quaternion_multiply(qz, quaternion_multiply(qy, qx))


def as_rotation(R, name: str = "rotation") -> np.ndarray:
    """``R`` as a finite 3x3 proper rotation (orthonormal to :data:`ROTATION_ATOL`, ``det = +1``),
    else :class:`ValueError` naming ``name``."""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        raise ValueError(f"{name} must be a 3x3 matrix, got shape {R.shape}")
    if not np.all(np.isfinite(R)):
        raise ValueError(f"{name} contains non-finite values")
    if not np.allclose(R.T @ R, np.eye(3), rtol=0.0, atol=ROTATION_ATOL):
        raise ValueError(f"{name} is not orthonormal")
    if abs(np.linalg.det(R) - 1.0) > ROTATION_ATOL:
        raise ValueError(f"{name} is a reflection (det = {np.linalg.det(R):+.3f}), not a rotation")
    return R
