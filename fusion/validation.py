"""Input checks shared by every belief type.

Each check raises ``ValueError`` with a message that names the argument and the problem, so that a
bad matrix coming off the wire or out of a config file is rejected before it touches a belief.
"""

from __future__ import annotations

import math

import numpy as np

from fusion import lapack

#: Relative tolerance for symmetry and for the smallest admissible eigenvalue of a PSD matrix.
#: Chosen here: loose enough for matrices that went through a few float64 operations.
SYMMETRY_RTOL = 1e-8
PSD_RTOL = 1e-9


def positive(name: str, value) -> float:
    """``value`` as a float if it is a positive finite number, else ``ValueError`` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"{name} must be a number, got {value!r}")
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


def as_vector(value, name: str, size: int | None = None) -> np.ndarray:
    """Return ``value`` as a finite float64 vector, optionally of a given size."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a vector, got shape {arr.shape}")
    if size is not None and arr.shape[0] != size:
        raise ValueError(f"{name} must have length {size}, got {arr.shape[0]}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains non-finite values (NaN or inf)")
    return arr


def as_square(value, name: str, size: int | None = None) -> np.ndarray:
    """Return ``value`` as a finite float64 square matrix, optionally of a given size."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1]:
        raise ValueError(f"{name} must be a square matrix, got shape {arr.shape}")
    if size is not None and arr.shape[0] != size:
        raise ValueError(f"{name} must be {size}x{size}, got {arr.shape[0]}x{arr.shape[1]}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains non-finite values (NaN or inf)")
    return arr


def as_symmetric(value, name: str, size: int | None = None) -> np.ndarray:
    """A finite square matrix that is symmetric to ``SYMMETRY_RTOL``, returned exactly symmetrised."""
    arr = as_square(value, name, size)
    scale = max(1.0, float(np.max(np.abs(arr))) if arr.size else 1.0)
    if arr.size and float(np.abs(arr - arr.T).max()) > SYMMETRY_RTOL * scale:  # |A - A^T| <= atol, entrywise
        raise ValueError(f"{name} is not symmetric")
    return 0.5 * (arr + arr.T)


def as_psd(value, name: str, size: int | None = None) -> np.ndarray:
    """A symmetric positive semi-definite matrix (zero is allowed: it means no information)."""
    arr = as_symmetric(value, name, size)
    if arr.size and min_eigenvalue(arr) < -PSD_RTOL * max(1.0, float(np.max(np.abs(arr)))):
        raise ValueError(f"{name} is not positive semi-definite (it has a negative eigenvalue)")
    return arr


def as_pd(value, name: str, size: int | None = None) -> np.ndarray:
    """A symmetric positive-definite matrix, e.g. a covariance or a noise matrix."""
    arr = as_symmetric(value, name, size)
    if arr.size and lapack.cholesky(arr) is None:
        raise ValueError(f"{name} is not positive definite")
    return arr


def shaped(value, name: str, shape: tuple) -> np.ndarray:
    """``value`` as a float array of ``shape`` (``None`` matches any length): the hot-path check. Finiteness
    is checked on the result of the operation instead, where one test covers every input."""
    arr = value if type(value) is np.ndarray and value.dtype == np.float64 else np.asarray(value, dtype=float)
    got = arr.shape
    if got == shape or (
        len(got) == len(shape) and all(w is None or g == w for g, w in zip(got, shape, strict=True))
    ):
        return arr
    expected = "x".join("m" if w is None else str(w) for w in shape)
    raise ValueError(f"{name} must have shape {expected}, got {got}")


def measurement_terms(H, R_inv, z, state_dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cheap checks for the hot path of a linear(ised) update: shapes, and a finite ``H`` and ``z``.

    ``R^-1`` is only shape-checked: its symmetry and definiteness are checked once, where the
    measurement model is built (``as_pd`` on ``R``), not at every update."""
    H = np.asarray(H, dtype=float)
    if H.ndim != 2 or H.shape[1] != state_dim:
        raise ValueError(f"measurement matrix H must be m x {state_dim}, got shape {H.shape}")
    if not np.isfinite(H).all():
        raise ValueError("measurement matrix H contains non-finite values (NaN or inf)")
    R_inv = np.asarray(R_inv, dtype=float)
    if R_inv.shape != (H.shape[0], H.shape[0]):
        raise ValueError(f"inverse measurement noise R^-1 must be {H.shape[0]}x{H.shape[0]}, got shape {R_inv.shape}")
    z = as_vector(np.atleast_1d(z), "measurement z", H.shape[0])
    return H, R_inv, z


def min_eigenvalue(matrix: np.ndarray) -> float:
    """Smallest eigenvalue of a symmetric matrix."""
    return float(np.linalg.eigvalsh(matrix)[0])


def is_psd(matrix: np.ndarray) -> bool:
    """True when a symmetric matrix is positive semi-definite to ``PSD_RTOL``.

    A Cholesky factorisation succeeds exactly for positive-definite matrices and costs a fraction of an
    eigen-decomposition, so it is tried first; only a matrix it rejects (semi-definite or indefinite)
    pays for the smallest eigenvalue."""
    if matrix.size == 0:
        return True
    if lapack.cholesky(matrix) is not None:  # LAPACK directly: numpy's wrapper costs as much as the work
        return True
    scale = max(1.0, float(np.max(np.abs(matrix))))
    return min_eigenvalue(matrix) >= -PSD_RTOL * scale
