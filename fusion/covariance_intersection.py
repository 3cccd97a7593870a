"""Covariance intersection: conservative fusion whatever the cross-correlation.

``Y_c = sum_i w_i Y_i``, ``y_c = sum_i w_i y_i`` with ``w`` on the simplex (Merino (3.43)-(3.46);
Julier & Uhlmann, 1997). The result is consistent for any unknown correlation between the inputs and
any admissible weights; the weights only decide how much is lost.

* :func:`ci` optimises the weights: ``"det"`` maximises ``log det Y_c`` (minimum entropy, Merino §3.2.3),
  ``"trace"`` minimises ``tr(Y_c^-1)``. Both objectives are convex in ``w``. For two beliefs,
  ``Y_c = Y_b + w D`` with ``D = Y_a - Y_b``, and the joint eigenvalues of the pair turn each objective into
  ``n`` scalar terms with closed-form first and second derivatives (``-log det Y_c = const - sum_i log m_i(w)``,
  ``m_i`` affine in ``w``; Reinhardt, Noack & Hanebeck, 2012): a safeguarded Newton search on ``[0, 1]`` that
  checks the end points first (:func:`fusion.pair_weights.ci_weight`). For more, SLSQP on the simplex with
  analytic gradients ``d log det Y_c / d w_i = tr(Y_c^-1 Y_i)`` and ``d tr(Y_c^-1) / d w_i = -tr(Y_c^-1 Y_i Y_c^-1)``.
* :func:`fast_ci` uses the closed-form weights ``w_i ∝ 1 / tr(P_i)`` (Niehsen, 2002), so the more
  informative estimate gets the larger weight.

Both accept any beliefs that implement ``scaled`` and ``fuse`` with ``y``/``Y`` attributes
(:class:`~fusion.gaussian.Gaussian` and :class:`~fusion.trajectory.Trajectory`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.optimize

from fusion.pair_weights import ci_weight

#: Objective value used where the combined information matrix is singular (chosen here).
_SINGULAR_PENALTY = 1e300


def ci(beliefs: Sequence, objective: str | Sequence[float] = "det"):
    """Covariance intersection of two or more beliefs with optimised (or given) weights."""
    beliefs = list(beliefs)
    _check_beliefs(beliefs)
    if isinstance(objective, str):
        weights = optimal_weights([b.Y for b in beliefs], objective)
    else:
        weights = _check_weights(objective, len(beliefs))
    return combine(beliefs, weights)


def fast_ci(beliefs: Sequence):
    """Covariance intersection with weights ``w_i ∝ 1 / tr(P_i)`` (Niehsen, 2002).

    A belief whose information matrix is singular has an unbounded covariance and gets weight 0."""
    beliefs = list(beliefs)
    _check_beliefs(beliefs)
    return combine(beliefs, fast_weights([b.Y for b in beliefs]))


def fast_weights(matrices: Sequence[np.ndarray]) -> np.ndarray:
    """Niehsen's (2002) closed-form weights ``w_i = (1 / tr P_i) / sum_j (1 / tr P_j)`` for the information
    matrices ``Y_i = P_i^-1``; a singular ``Y_i`` (unbounded covariance) gets weight 0."""
    inv_traces = np.array([_inverse_trace_of_cov(Y) for Y in matrices])
    if inv_traces.sum() <= 0.0:
        raise ValueError("fast CI needs at least one belief with a finite covariance")
    return inv_traces / inv_traces.sum()


def combine(beliefs: Sequence, weights: Sequence[float]):
    """The weighted exponential product ``sum_i w_i (y_i, Y_i)``."""
    result = beliefs[0].scaled(float(weights[0]))
    for belief, w in zip(beliefs[1:], weights[1:], strict=True):
        result = result.fuse(belief.scaled(float(w)))
    return result


def optimal_weights(matrices: Sequence[np.ndarray], objective: str = "det") -> np.ndarray:
    """Simplex weights that optimise ``objective`` ("det" or "trace") for the information matrices.

    Two matrices: the exact optimum of :func:`fusion.pair_weights.ci_weight` (which raises ``ValueError`` for
    inputs that are not finite, square, of one size, symmetric and positive semi-definite); more: SLSQP."""
    if objective not in ("det", "trace"):
        raise ValueError(f"objective must be 'det', 'trace' or a list of weights, got {objective!r}")
    if len(matrices) == 1:
        return np.ones(1)
    if len(matrices) == 2:
        w = ci_weight(matrices[0], matrices[1], objective)
        return np.array([w, 1.0 - w])
    return _simplex_optimum(list(matrices), _neg_logdet if objective == "det" else _trace_of_inverse)


def _simplex_optimum(matrices: list[np.ndarray], cost) -> np.ndarray:
    n = len(matrices)
    stack = np.stack(matrices)

    def fun(w):
        value, inv = cost(np.tensordot(w, stack, axes=1))
        if inv is None:
            return value, np.zeros(n)
        if cost is _neg_logdet:
            grad = -np.einsum("ij,kji->k", inv, stack)
        else:
            grad = -np.einsum("ij,kjl,li->k", inv, stack, inv)
        return value, grad

    start = np.full(n, 1.0 / n)
    res = scipy.optimize.minimize(
        fun, start, jac=True, method="SLSQP", bounds=[(0.0, 1.0)] * n,
        constraints=[{"type": "eq", "fun": lambda w: w.sum() - 1.0, "jac": lambda w: np.ones(n)}],
        options={"ftol": 1e-12, "maxiter": 200},
    )
    w = np.clip(res.x, 0.0, None)
    w = w / w.sum()
    return w if fun(w)[0] <= fun(start)[0] else start


def _neg_logdet_value(Y: np.ndarray) -> float:
    sign, logdet = np.linalg.slogdet(Y)
    return _SINGULAR_PENALTY if sign <= 0 else -float(logdet)


def _neg_logdet(Y: np.ndarray):
    """``-log det Y`` and ``Y^-1`` (the gradient of the many-input search needs the inverse)."""
    value = _neg_logdet_value(Y)
    return (value, None) if value >= _SINGULAR_PENALTY else (value, np.linalg.inv(Y))


def _trace_of_inverse(Y: np.ndarray):
    try:
        inv = np.linalg.inv(Y)
        np.linalg.cholesky(Y)
    except np.linalg.LinAlgError:
        return _SINGULAR_PENALTY, None
    return float(np.trace(inv)), inv


def _inverse_trace_of_cov(Y: np.ndarray) -> float:
    value, _ = _trace_of_inverse(Y)
    return 0.0 if value >= _SINGULAR_PENALTY else 1.0 / value


def _check_beliefs(beliefs: list) -> None:
    if not beliefs:
        raise ValueError("covariance intersection needs at least one belief")
    dims = {b.y.shape[0] for b in beliefs}
    if len(dims) != 1:
        raise ValueError(f"covariance intersection needs beliefs of one dimension, got {sorted(dims)}")


def _check_weights(weights, count: int) -> np.ndarray:
    w = np.asarray(weights, dtype=float)
    if w.shape != (count,):
        raise ValueError(f"expected {count} weights, got shape {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0) or abs(w.sum() - 1.0) > 1e-9:
        raise ValueError(f"weights must be non-negative and sum to 1, got {list(w)}")
    return w
