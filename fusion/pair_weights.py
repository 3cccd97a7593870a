"""The weight that makes the covariance intersection (CI) or the inverse covariance intersection (ICI) of two
Gaussian beliefs tightest, without a generic minimiser.

Both rules fuse two information matrices ``Y_a``, ``Y_b`` with one weight ``w in [0, 1]`` and are scored by
``log det`` of the fused information (``"det"``, to be maximised) or ``tr`` of the fused covariance (``"trace"``,
to be minimised):

* CI (Julier & Uhlmann, 1997; Merino (3.43)-(3.44)): ``M(w) = w Y_a + (1-w) Y_b``;
* ICI (Noack, Sijs, Reinhardt & Hanebeck, "Decentralized data fusion with inverse covariance intersection",
  Automatica 79, 2017; the equations are restated at bennoack.net/ICI):
  ``Y(w) = Y_a + Y_b - (w Y_a^-1 + (1-w) Y_b^-1)^-1``.

**Joint diagonalisation.** With a whitening ``W`` of ``S = Y_a + Y_b`` (``W S W^T = I``: the inverse Cholesky
factor ``L^-1`` for ICI; for CI ``diag(s^-1/2) U_S^T`` from the eigenvalues ``S = U_S diag(s) U_S^T``, which also
reveal a direction that neither input informs) and ``W Y_a W^T = U diag(p) U^T``, the matrix ``V = W^T U`` gives
``Y_a = V^-T diag(p) V^-1`` and ``Y_b = V^-T diag(q) V^-1`` with ``q = 1 - p`` and ``0 <= p_i <= 1`` (``p_i = 0``
where ``Y_a`` carries no information, ``p_i = 1`` where ``Y_b`` carries none): the ``p_i`` are the generalised
eigenvalues of the pencil ``(Y_a, S)``. Both rules then act on each direction separately, and each objective is
``n`` scalar terms (the reduction of the two-input CI optimisation to the pair's joint eigenvalues is the idea of
Reinhardt, Noack & Hanebeck, "Closed-form optimization of covariance intersection for low-dimensional matrices",
FUSION 2012):

    CI:   M(w) = V^-T diag(m(w)) V^-1,  m_i(w) = w p_i + (1-w) q_i,
          -log det M(w) = -log det S - sum_i log m_i(w),   tr M(w)^-1 = sum_i |v_i|^2 / m_i(w);
    ICI:  Y(w) = V^-T diag(e(w)) V^-1,  e_i(w) = 1 - p_i q_i / r_i(w),  r_i(w) = p_i + w (q_i - p_i),
          log det Y(w) = log det S + sum_i log e_i(w),   tr Y(w)^-1 = sum_i |v_i|^2 / e_i(w)

(for ICI, ``Y_a^-1 = V diag(1/p) V^T``, likewise for ``b``, and ``(w/p + (1-w)/q)^-1 = p q / r``). Each ``m_i``
is affine and positive, each ``e_i`` positive and concave in ``w`` (``-pq/r`` with ``r`` affine and positive), so
every objective is convex (``-log`` and ``1/x`` are convex and decreasing): the optimum is an end point or the
single root of the derivative, found by Newton's method safeguarded by bisection on the bracket. The ``n``
scalar terms come from one ``n x n`` factorisation of ``S`` and one symmetric eigendecomposition; the search
then costs a few passes over ``n`` floats and converges to the float64 resolution of ``w``.
"""

from __future__ import annotations

import math

import numpy as np

from fusion import validation

#: Stop when a step of the weight is this small (chosen here: near the float64 resolution of w).
_W_TOL = 1e-12
#: Iteration cap of the safeguarded Newton search (chosen here: bisection alone reaches _W_TOL in 40 steps).
_MAX_ITER = 100

#: An eigenvalue of ``Y_a + Y_b`` at most this times ``n`` times the largest is a direction neither CI input informs
#: (chosen here: numpy.linalg.matrix_rank's ``n eps`` with a margin of 8; measured here, rounding leaves the null
#: eigenvalues of a rotated singular sum below ``0.71 n eps`` of the largest).
_RANK_RTOL = 8.0 * np.finfo(float).eps
_EPS = float(np.finfo(float).eps)

OBJECTIVES = ("det", "trace")
#: The error when neither input informs some direction (then no ICI weight or result is defined).
UNINFORMED = "ICI needs the two beliefs together to inform every direction (Y_a + Y_b is singular)"


def ci_weight(Ya: np.ndarray, Yb: np.ndarray, objective: str = "det") -> float:
    """The CI weight ``w`` (on ``Y_a``) that maximises ``log det M(w)`` or minimises ``tr M(w)^-1`` for
    ``M(w) = w Y_a + (1-w) Y_b`` (Julier & Uhlmann, 1997; Merino (3.43)-(3.44); the scalar form through the joint
    eigenvalues: Reinhardt, Noack & Hanebeck, 2012).

    With ``M(w) = Y_b + w D``, ``D = Y_a - Y_b = V^-T diag(p - q) V^-1``, the derivatives are closed-form sums
    (``d_i = p_i - q_i``, ``c_i = |v_i|^2``)::

        d/dw   -log det M = -tr(M^-1 D)                =   -sum_i d_i / m_i
        d2/dw2 -log det M =  tr(M^-1 D M^-1 D)         =    sum_i (d_i / m_i)^2
        d/dw   tr M^-1    = -tr(M^-1 D M^-1)           =   -sum_i c_i d_i / m_i^2
        d2/dw2 tr M^-1    = 2 tr(M^-1 D M^-1 D M^-1)   =  2 sum_i c_i d_i^2 / m_i^3

    A direction that neither input informs (``Y_a + Y_b`` singular) carries no information whatever ``w`` is; the
    objectives are then taken on the directions that are informed (the pseudo-determinant and the trace of the
    pseudo-inverse), and two beliefs without any information get ``w = 0``.

    Raises ``ValueError`` unless both information matrices are finite, symmetric positive semi-definite and of one
    size."""
    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be 'det' or 'trace', got {objective!r}")
    p, c = _joint_diagonalisation(Ya, Yb, vectors=objective == "trace", rule="CI")
    # n scalar terms in plain floats: numpy's per-call overhead on arrays of n = 6 would dominate the search.
    terms = [(p_i, 1.0 - p_i, 2.0 * p_i - 1.0, c_i) for p_i, c_i in zip(p, c, strict=True)]
    det = objective == "det"

    def slope(w: float) -> tuple[float, float]:
        """First and second derivative at ``w`` of ``-log det M`` or ``tr M^-1`` (both to be minimised)."""
        g = h = 0.0
        v = 1.0 - w
        for p_i, q_i, d, c_i in terms:  # d = p - q
            m = w * p_i + v * q_i  # m_i(w) = w p_i + (1-w) q_i: a sum of non-negative terms, no cancellation
            t = d / m
            if det:  # -tr(M^-1 D) = -sum d/m;  tr(M^-1 D M^-1 D) = sum (d/m)^2
                g -= t
                h += t * t
            else:  # -tr(M^-1 D M^-1) = -sum c d/m^2;  2 tr(M^-1 D M^-1 D M^-1) = 2 sum c d^2/m^3
                u = c_i * t / m
                g -= u
                h += 2.0 * u * t
        return g, h

    return _convex_minimum(slope)


def ici_weight(Ya: np.ndarray, Yb: np.ndarray, objective: str = "det") -> float:
    """The ICI weight ``w`` (on ``Y_a``) that maximises ``log det Y(w)`` or minimises ``tr Y(w)^-1``.

    Raises ``ValueError`` unless both information matrices are finite, symmetric positive semi-definite and of one
    size, with a positive-definite sum (together they inform every direction)."""
    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be 'det' or 'trace', got {objective!r}")
    p, c = _joint_diagonalisation(Ya, Yb, vectors=objective == "trace")
    # n scalar terms in plain floats: numpy's per-call overhead on arrays of n = 6 would dominate the search.
    terms = [(p_i, p_i * (1.0 - p_i), 1.0 - 2.0 * p_i, c_i) for p_i, c_i in zip(p, c, strict=True)]
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


def _joint_diagonalisation(Ya, Yb, vectors: bool, rule: str = "ICI") -> tuple[list[float], list[float]]:
    """``p`` (the eigenvalues of ``Y_a`` relative to ``S = Y_a + Y_b``, ascending, kept inside ``[eps, 1 - eps]``) and
    ``c_i = |v_i|^2`` (ones unless asked), as plain floats.

    ``W`` whitens ``S`` (``W S W^T = I``) and ``W Y_a W^T = U diag(p) U^T``, ``V = W^T U``. ICI whitens with the
    Cholesky factor, ``W = L^-1``, and a singular ``S`` is an error; CI with the eigenvalues of ``S``, restricted
    to its range (:func:`_informed_whitening`).

    ``Y_a`` is positive semi-definite exactly when every ``p_i >= 0``, and ``Y_b`` when every ``p_i <= 1``, so the
    decomposition doubles as the check of its inputs. Every step is one numpy call on the whole matrix (the
    symmetric eigensolvers read one triangle, so nothing is symmetrised): numpy's per-call overhead, not the
    arithmetic, is most of the cost at these sizes."""
    name_a, name_b = f"{rule} input information matrix Y_a", f"{rule} input information matrix Y_b"
    Ya, Yb, S = _checked_pair(Ya, Yb, name_a, name_b)
    if rule == "ICI":
        try:
            W = np.linalg.inv(np.linalg.cholesky(S))
        except np.linalg.LinAlgError:
            raise ValueError(UNINFORMED) from None
    else:
        W = _informed_whitening(Ya, Yb, S, name_a, name_b)
    if not vectors:
        p = np.linalg.eigvalsh(W @ Ya @ W.T).tolist()
        c = [1.0] * len(p)
    else:
        p, U = np.linalg.eigh(W @ Ya @ W.T)
        p, c = p.tolist(), np.sum((W.T @ U) ** 2, axis=0).tolist()
    if p and (p[0] < -validation.PSD_RTOL or p[-1] > 1.0 + validation.PSD_RTOL):
        # A p_i outside [0, 1] is a negative eigenvalue of Y_a or Y_b, or the rounding error of an ill-conditioned
        # S (about eps |W|^2 |S|): the eigenvalues of the inputs decide, with the tolerance of every other check.
        validation.as_psd(Ya, name_a)
        validation.as_psd(Yb, name_b)
    # Keep the scalar terms positive where one input carries no information (p = 0 or 1): for ICI
    # r = p + w (q - p), whose objective is then the limit of the covariance form, which moves the optimum off that
    # input's end point; for CI m = w p + (1-w) q, whose objective is then finite but far from optimal there.
    lo, hi = _EPS, 1.0 - _EPS
    return [lo if p_i < lo else hi if p_i > hi else p_i for p_i in p], c


def _checked_pair(Ya, Yb, name_a: str, name_b: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``Y_a``, ``Y_b`` as float arrays and ``S = Y_a + Y_b``, after the checks of :func:`_symmetric` (finite,
    square, of one size, symmetric): made in full, with their messages, only when a cheap screen fails — a shape
    other than ``(n, n)``, a non-finite sum of ``S`` (a NaN or inf anywhere in the inputs makes it one; so can an
    overflow, which the full check then lets through) or inputs that are not exactly symmetric."""
    Ya, Yb = np.asarray(Ya, dtype=float), np.asarray(Yb, dtype=float)
    if Ya.ndim == 2 and Ya.shape[0] == Ya.shape[1] and Yb.shape == Ya.shape:
        S = Ya + Yb
        # bit-for-bit symmetric: the bytes of the transpose (a C-order copy) are the bytes of the matrix
        if math.isfinite(S.sum()) and Ya.tobytes() == Ya.T.tobytes() and Yb.tobytes() == Yb.T.tobytes():
            return Ya, Yb, S
    Ya = _symmetric(Ya, name_a)
    Yb = _symmetric(Yb, name_b, Ya.shape[0])
    return Ya, Yb, Ya + Yb


def _informed_whitening(Ya: np.ndarray, Yb: np.ndarray, S: np.ndarray, name_a: str, name_b: str) -> np.ndarray:
    """``W = diag(s_r^-1/2) U_r^T`` (``r x n``) from ``S = Y_a + Y_b = U diag(s) U^T``, on the ``r`` eigenvalues
    above :data:`_RANK_RTOL` ``n s_max``: ``W S W^T = I_r``. The common null space of two positive semi-definite
    matrices is the null space of their sum, so ``W`` keeps every direction either input informs. (A Cholesky
    factorisation of a singular sum in a rotated basis can succeed on a rounding-sized pivot, which would weigh a
    direction of pure rounding noise.)

    A singular ``S`` is where the range alone cannot see a negative eigenvalue of an input (``Y_a = -Y_b``): the
    inputs' own eigenvalues are checked then."""
    s, U = np.linalg.eigh(S)
    if s[0] > _RANK_RTOL * s.size * s[-1]:  # the common case: S is positive definite
        return (U / np.sqrt(s)).T
    validation.as_psd(Ya, name_a)
    validation.as_psd(Yb, name_b)
    keep = s > _RANK_RTOL * s.size * s[-1]
    return (U[:, keep] / np.sqrt(s[keep])).T


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
