"""Inverse covariance intersection (ICI): conservative fusion when the correlation is common information.

Noack, Sijs, Reinhardt & Hanebeck, "Decentralized data fusion with inverse covariance intersection",
Automatica 79 (2017), restated at bennoack.net/ICI. For estimates ``(a, P_a)``, ``(b, P_b)`` and a weight
``w in [0, 1]``, with ``Gamma = w P_a + (1-w) P_b``:

    P^-1 = P_a^-1 + P_b^-1 - Gamma^-1,
    x    = K a + L b,   K = P (P_a^-1 - w Gamma^-1),   L = P (P_b^-1 - (1-w) Gamma^-1).

In information form (``Y = P^-1``, ``y = P^-1 x``) this is ``Y = Y_a + Y_b - Gamma^-1`` and, multiplying ``x``
by ``Y``, ``y = y_a + y_b - Gamma^-1 (w a + (1-w) b)``: the product of the two beliefs with the Gaussian
``N(w a + (1-w) b, Gamma)`` divided out — the largest common information the two could share. ICI is
consistent for any ``w`` whenever the inputs' correlation comes from common information they both fused
(Noack et al. 2017), as in decentralized data fusion, and is then never looser than covariance
intersection: by the matrix convexity of the inverse, ``Gamma^-1 <= w Y_a + (1-w) Y_b``, so
``Y_ici(w) >= (1-w) Y_a + w Y_b``, the CI information with weight ``1-w``.

:func:`ici` accepts any belief with ``y``/``Y`` attributes, ``fuse`` and ``with_information``
(:class:`~fusion.gaussian.Gaussian`, :class:`~fusion.trajectory.Trajectory`).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dpotrf, dpotrs

from fusion.pair_weights import ici_weight


def ici(a, b, omega: str | float = "det"):
    """ICI of two beliefs with the weight ``omega`` on ``a``, or the weight optimising ``"det"`` / ``"trace"``
    of the fused covariance (:func:`fusion.pair_weights.ici_weight`)."""
    product = a.fuse(b)  # checks that the two beliefs are compatible
    if not np.all(np.isfinite(product.y)):
        raise ValueError("ICI input information vectors contain non-finite values (NaN or inf)")
    if isinstance(omega, str):
        w = ici_weight(a.Y, b.Y, omega)
    else:
        w = float(omega)
        if not 0.0 <= w <= 1.0:
            raise ValueError(f"omega must lie in [0, 1], got {omega}")
    P_a = _spd_solve(a.Y, None, "ICI input information matrix Y_a")
    P_b = _spd_solve(b.Y, None, "ICI input information matrix Y_b")
    mean_mix = w * (P_a @ a.y) + (1.0 - w) * (P_b @ b.y)
    gamma_inv = _spd_solve(w * P_a + (1.0 - w) * P_b, mean_mix, "the mixed covariance w P_a + (1-w) P_b")
    Y = product.Y - gamma_inv[:, :-1]
    return product.with_information(product.y - gamma_inv[:, -1], 0.5 * (Y + Y.T))


def _spd_solve(M: np.ndarray, column: np.ndarray | None, name: str) -> np.ndarray:
    """``M^-1`` (and ``M^-1 column`` as an extra last column) by Cholesky; ``ValueError`` unless ``M`` is finite
    and positive definite."""
    n = M.shape[0]
    rhs = np.eye(n) if column is None else np.concatenate([np.eye(n), column[:, None]], axis=1)
    if not np.all(np.isfinite(M)):
        raise ValueError(f"{name} contains non-finite values (NaN or inf)")
    factor, info = dpotrf(M, lower=1, clean=0)
    if info != 0:
        raise ValueError(f"{name} is not positive definite: inverse covariance intersection needs finite covariances")
    solution, _ = dpotrs(factor, rhs, lower=1)
    return solution if column is not None else 0.5 * (solution + solution.T)
