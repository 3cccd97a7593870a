"""The weight that makes the inverse covariance intersection of two Gaussian beliefs tightest.

Inverse covariance intersection (ICI; Noack, Sijs, Reinhardt & Hanebeck, "Decentralized data fusion with
inverse covariance intersection", Automatica 79, 2017; the equations are restated at bennoack.net/ICI) fuses
two information matrices with one weight ``w in [0, 1]``:
``Y(w) = Y_a + Y_b - (w Y_a^-1 + (1-w) Y_b^-1)^-1``. This module finds the ``w`` that maximises
``log det Y(w)`` (``"det"``) or minimises ``tr Y(w)^-1`` (``"trace"``) without a generic minimiser.

**Joint diagonalisation.** With ``S = Y_a + Y_b = L L^T`` and ``L^-1 Y_a L^-T = U diag(p) U^T``, the matrix
``V = L^-T U`` gives ``Y_a = V^-T diag(p) V^-1`` and ``Y_b = V^-T diag(q) V^-1`` with ``q = 1 - p`` and
``0 <= p_i <= 1`` (``p_i = 0`` where ``Y_a`` carries no information, ``p_i = 1`` where ``Y_b`` carries none).
Then ``Y_a^-1 = V diag(1/p) V^T``, likewise for ``b``, and ``(w/p + (1-w)/q)^-1 = p q / r`` with
``r = p + w (q - p)``, so ICI acts on each direction separately:

    Y(w) = V^-T diag(e(w)) V^-1,   e_i(w) = 1 - p_i q_i / r_i(w),
    log det Y(w) = log det S + sum_i log e_i(w),   tr Y(w)^-1 = sum_i |v_i|^2 / e_i(w).

Each ``e_i`` is positive and concave in ``w`` (``-pq/r`` with ``r`` affine and positive), so ``-log det Y(w)``
and ``tr Y(w)^-1`` are convex (``-log`` and ``1/x`` are convex and decreasing): the optimum is an end point or
the single root of the derivative, found by Newton's method safeguarded by bisection on the bracket. The
n scalar terms come from one ``n x n`` Cholesky factorisation and one symmetric eigendecomposition.
"""

from __future__ import annotations

import numpy as np

from fusion import validation

#: Stop when a step of the weight is this small (chosen here: near the float64 resolution of w).
_W_TOL = 1e-12
#: Iteration cap of the safeguarded Newton search (chosen here: bisection alone reaches _W_TOL in 40 steps).
_MAX_ITER = 100

OBJECTIVES = ("det", "trace")
#: The error when neither input informs some direction (then no ICI weight or result is defined).
UNINFORMED = "ICI needs the two beliefs together to inform every direction (Y_a + Y_b is singular)"


def ici_weight(Ya: np.ndarray, Yb: np.ndarray, objective: str = "det") -> float:
    """The ICI weight ``w`` (on ``Y_a``) that maximises ``log det Y(w)`` or minimises ``tr Y(w)^-1``.

    Raises ``ValueError`` unless both information matrices are finite, symmetric positive semi-definite and of one
    size, with a positive-definite sum (together they inform every direction)."""
    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be 'det' or 'trace', got {objective!r}")
    p, c = _joint_diagonalisation(Ya, Yb, vectors=objective == "trace")
    # n scalar terms in plain floats: numpy's per-call overhead on arrays of n = 6 would dominate the search.
    terms = [(p_i, p_i * (1.0 - p_i), 1.0 - 2.0 * p_i, c_i) for p_i, c_i in zip(p.tolist(), c.tolist(), strict=True)]
    det = objective == "det"

    def slope(w: float) -> tuple[float, float]:
        """First and second derivative at ``w`` of ``-log det Y`` or ``tr Y^-1`` (both to be minimised)."""
        g = h = 0.0
        for p_i, pq, d, c_i in terms:  # d = q - p, r = p + w d, e = 1 - pq / r
            r = p_i + w * d
            e = 1.0 - pq / r
            de = pq * d / (r * r)
            dde = -2.0 * de * d / r
            if det:
                g -= de / e
                h += (de * de - e * dde) / (e * e)
            else:
                g -= c_i * de / (e * e)
                h += c_i * (2.0 * de * de - e * dde) / (e * e * e)
        return g, h

    return _convex_minimum(slope)


def _joint_diagonalisation(Ya, Yb, vectors: bool) -> tuple[np.ndarray, np.ndarray]:
    """``p`` (the eigenvalues of ``Y_a`` relative to ``Y_a + Y_b``) and ``c_i = |v_i|^2`` (ones unless asked).

    ``Y_a`` is positive semi-definite exactly when every ``p_i >= 0``, and ``Y_b`` when every ``p_i <= 1``, so the
    decomposition doubles as the check of its inputs."""
    Ya = _symmetric(Ya, "ICI input information matrix Y_a")
    Yb = _symmetric(Yb, "ICI input information matrix Y_b", Ya.shape[0])
    try:
        L_inv = np.linalg.inv(np.linalg.cholesky(Ya + Yb))
    except np.linalg.LinAlgError:
        raise ValueError(UNINFORMED) from None
    M = L_inv @ Ya @ L_inv.T
    M = 0.5 * (M + M.T)
    if not vectors:
        p = np.linalg.eigvalsh(M)
        c = np.ones_like(p)
    else:
        p, U = np.linalg.eigh(M)
        c = np.sum((L_inv.T @ U) ** 2, axis=0)
    for name, bad in (("Y_a", p[0] < -validation.PSD_RTOL), ("Y_b", p[-1] > 1.0 + validation.PSD_RTOL)):
        if bad:
            raise ValueError(f"ICI input information matrix {name} is not positive semi-definite")
    # Keep r = p + w (q - p) positive where one input carries no information (p = 0 or 1): the objective is then
    # the limit of the covariance form, which moves the optimum off that input's end point.
    eps = np.finfo(float).eps
    return np.clip(p, eps, 1.0 - eps), c


def _symmetric(M, name: str, size: int | None = None) -> np.ndarray:
    """A finite square matrix, symmetric to ``validation.SYMMETRY_RTOL`` (the cheap part of ``validation.as_psd``)."""
    M = validation.as_square(M, name, size)
    if np.max(np.abs(M - M.T)) > validation.SYMMETRY_RTOL * max(1.0, float(np.max(np.abs(M)))):
        raise ValueError(f"{name} is not symmetric")
    return M


def _convex_minimum(slope) -> float:
    """The minimiser on ``[0, 1]`` of a convex function given its ``(f', f'')``: an end point if the slope
    there points outwards, else the root of ``f'`` by Newton steps kept inside a shrinking bracket."""
    if slope(0.0)[0] >= 0.0:
        return 0.0
    if slope(1.0)[0] <= 0.0:
        return 1.0
    lo, hi, w = 0.0, 1.0, 0.5
    for _ in range(_MAX_ITER):
        g, h = slope(w)
        if g == 0.0:
            return w
        if g > 0.0:
            hi = w
        else:
            lo = w
        newton = w - g / h if h > 0.0 else lo  # a step that is not a descent falls back to bisection
        nxt = newton if lo < newton < hi else 0.5 * (lo + hi)
        if abs(nxt - w) < _W_TOL:
            return nxt
        w = nxt
    return w
