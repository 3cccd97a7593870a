"""The unscented transform (Merino Alg. 3.5; Julier & Uhlmann).

Sigma points ``X_0 = mu`` (``W_0 = kappa / (kappa + n)``) and ``X_{i}, X_{n+i} = mu +- (sqrt((kappa+n) P))_i``
(``W = 1 / (2 (kappa + n))``), with the lower Cholesky factor as the matrix square root (the thesis
leaves it open; the thesis's index typo on the negative points is corrected to column ``i``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fusion import lapack, validation


def default_kappa(n: int) -> float:
    """``kappa = max(3 - n, 0)``: Julier's choice that matches the Gaussian's fourth moment where it
    can, clipped at 0 so that the centre weight is never negative (chosen here; Merino gives none)."""
    return float(max(3 - n, 0))


def sigma_points(mean, cov, kappa: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Return the ``2n+1`` sigma points (rows) and their weights."""
    mean = validation.as_vector(mean, "mean")
    n = mean.shape[0]
    cov = validation.as_symmetric(cov, "covariance", n)
    kappa = default_kappa(n) if kappa is None else float(kappa)
    if not np.isfinite(kappa):
        raise ValueError(f"kappa must be finite, got {kappa}")
    if kappa + n <= 0:
        raise ValueError(f"kappa + n must be positive, got kappa={kappa}, n={n}")
    root = lapack.cholesky((kappa + n) * cov)  # exists exactly when the covariance is positive definite
    if root is None:  # semi-definite (or not a covariance at all): check, then the symmetric square root
        cov = validation.as_psd(cov, "covariance", n)
        w, v = np.linalg.eigh((kappa + n) * cov)
        root = v * np.sqrt(np.clip(w, 0.0, None))
    points = np.vstack([mean, mean + root.T, mean - root.T])
    weights = np.full(2 * n + 1, 1.0 / (2.0 * (kappa + n)))
    weights[0] = kappa / (kappa + n)
    return points, weights


def unscented_transform(
    f: Callable[[np.ndarray], np.ndarray], mean, cov, kappa: float | None = None, *, vectorized: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of ``f(x)`` for ``x ~ N(mean, cov)`` (Merino Alg. 3.5). ``vectorized``: ``f`` maps
    all the sigma points at once, rows ``(2n+1, n)`` -> ``(2n+1, m)``, instead of one point at a time."""
    points, weights = sigma_points(mean, cov, kappa)
    if vectorized:
        Y = np.asarray(f(points), dtype=float).reshape(len(points), -1)
    else:
        Y = np.array([np.atleast_1d(np.asarray(f(p), dtype=float)) for p in points])
    if not np.all(np.isfinite(Y)):
        raise ValueError("the transformed sigma points contain non-finite values")
    mu = weights @ Y
    d = Y - mu
    cov_y = (weights[:, None] * d).T @ d
    return mu, 0.5 * (cov_y + cov_y.T)
