"""Small dense solves through LAPACK directly.

The beliefs of a tracker are built from 6x6 blocks (a trajectory window is ``L`` of them), so most linear
algebra on the hot path is a 6x6 system. ``numpy.linalg.solve`` and ``inv`` spend about 25 µs of Python in
their wrappers (type dispatch, error state) around 1 µs of arithmetic on such a system; calling LAPACK's
routines through SciPy's thin wrappers costs about 6 µs. The routines are the ones NumPy calls, so the
results are those of ``numpy.linalg`` (LU with partial pivoting for a general system, Cholesky for a
symmetric positive-definite one). Every direct LAPACK call of the library is here.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.linalg.lapack import dgesv, dpotrf, dpotri, dpotrs, dtrtrs


def solve(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A^-1 B`` by LU factorisation with partial pivoting (LAPACK ``dgesv``, as ``numpy.linalg.solve``).
    Raises ``numpy.linalg.LinAlgError`` when ``A`` is exactly singular."""
    _, _, x, info = dgesv(A, B)
    if info > 0:
        raise np.linalg.LinAlgError("singular matrix")
    if info < 0:  # an argument LAPACK rejected: a programming error, not bad data
        raise ValueError(f"dgesv: argument {-info} is invalid")
    return x


def cholesky(A: np.ndarray) -> np.ndarray | None:
    """The lower-triangular ``C`` with ``C C^T = A`` (LAPACK ``dpotrf``, upper triangle zeroed), or ``None``
    when the symmetric matrix ``A`` is not positive definite (the factorisation exists exactly then)."""
    factor, info = dpotrf(A, lower=1, clean=1)
    return factor if info == 0 else None


def cholesky_solve(factor: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A^-1 B`` from the :func:`cholesky` factor of ``A`` (LAPACK ``dpotrs``)."""
    return dpotrs(factor, B, lower=1)[0]


def triangular_solve(factor: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``C^-1 b`` for the lower-triangular :func:`cholesky` factor ``C`` (LAPACK ``dtrtrs``)."""
    return dtrtrs(factor, b, lower=1)[0]


def spd_inverse(A: np.ndarray) -> np.ndarray:
    """``A^-1`` of a symmetric positive-definite matrix by Cholesky (LAPACK ``dpotrf``/``dpotri``), returned
    exactly symmetric. Raises ``numpy.linalg.LinAlgError`` when ``A`` is not positive definite."""
    factor = cholesky(A)
    if factor is None:
        raise np.linalg.LinAlgError("the matrix is not positive definite")
    inverse, info = dpotri(factor, lower=1)  # the lower triangle of A^-1; the upper one is left as it was
    if info != 0:
        raise np.linalg.LinAlgError("the matrix is singular")
    upper = _upper(A.shape[0])
    inverse[upper] = inverse.T[upper]  # mirror the lower triangle
    return inverse


@functools.cache
def _upper(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the strict upper triangle of an ``n x n`` matrix."""
    return np.triu_indices(n, 1)
