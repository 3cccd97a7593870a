"""The two-input covariance-intersection weight (:func:`fusion.pair_weights.ci_weight`, used by
:func:`fusion.covariance_intersection.optimal_weights` and :func:`~fusion.covariance_intersection.ci`).

CI (Julier & Uhlmann 1997; Merino (3.43)-(3.44)) fuses ``M(w) = w Y_a + (1-w) Y_b`` and picks ``w`` to minimise
``f(w) = -log det M(w)`` ("det") or ``f(w) = tr M(w)^-1`` ("trace"). Oracles, independent of the joint
diagonalisation under test:

* a dense grid over ``w`` plus SciPy's bounded minimiser (``minimize_scalar``) on the best grid cell, both on
  ``f`` evaluated in float64 (from the eigenvalues of ``M(w)``). Such a search can only resolve ``w`` to where
  ``f`` rises by no more than its rounding noise (measured for each problem): about ``1e-8`` for a
  well-conditioned pair, up to a few ``1e-6`` for condition numbers near ``1e8``. The weights must agree to
  ``1e-6`` beyond that resolution;
* exact rational arithmetic (``fractions.Fraction``; the float64 inputs are exact rationals) for what float
  evaluation is too noisy to check: the returned objective is never worse than the oracle's, and the sign of the
  exact derivative ``f'`` brackets the returned weight within ``1e-9 + 1e-14 cond(Y_a + Y_b)``.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
import scipy.optimize
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fusion.covariance_intersection import ci, optimal_weights
from fusion.gaussian import Gaussian
from fusion.pair_weights import ci_weight

SETTINGS = settings(max_examples=80, deadline=None)
OBJECTIVES = ("det", "trace")
WEIGHT_TOL = 1e-6  # agreement with the float oracle, beyond its own resolution (from the issue)
EXACT_BRACKET = 1e-9  # the exact optimum lies within this of the returned weight, ... (chosen here)
EXACT_BRACKET_PER_COND = 1e-14  # ... plus this times cond(Y_a + Y_b) (about 50 eps: a backward-stable method's
# forward error; measured here, 3e-9 at cond 4e6 for "trace")
OBJECTIVE_RTOL = 1e-14  # "never worse": exact objectives, up to this relative slack, ... (chosen here)
OBJECTIVE_RTOL_PER_COND = 4.0 * np.finfo(float).eps  # ... plus this times cond(Y_a + Y_b): rounding the inputs
# (a relative eps) moves the exact objective by up to about eps cond relative, so no float64 method can promise less


# -- random pairs of information matrices ------------------------------------------------------------------------
@st.composite
def spd_matrix(draw, n: int, max_log_cond: float = 8.0, singular: bool = False) -> np.ndarray:
    """``Q diag(s) Q^T``: a random rotation, eigenvalues log-spread over a condition number up to
    ``10**max_log_cond``, an overall scale in ``[1e-3, 1e3]``; ``singular`` zeroes up to ``n - 1`` eigenvalues."""
    Q, _ = np.linalg.qr(draw(arrays(np.float64, (n, n), elements=st.floats(-1.0, 1.0))) + np.eye(n))
    log_cond = draw(st.floats(0.0, max_log_cond))
    positions = np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=n, max_size=n)))
    if n > 1:
        positions[0], positions[-1] = 0.0, 1.0  # the condition number is exactly 10**log_cond
    s = 10.0 ** (draw(st.floats(-3.0, 3.0)) + log_cond * positions)
    if singular and n > 1:
        s[: draw(st.integers(1, n - 1))] = 0.0
    M = (Q * s) @ Q.T
    return 0.5 * (M + M.T)


@st.composite
def spd_pairs(draw, max_n: int = 6):
    """Two information matrices of one size 1..6, each with a condition number up to 1e8; one of them may be
    singular (uninformed in some directions), which moves the optimum off its end point."""
    n = draw(st.integers(1, max_n))
    singular = draw(st.sampled_from([None, "a", "b"]))
    return draw(spd_matrix(n, singular=singular == "a")), draw(spd_matrix(n, singular=singular == "b"))


# -- float oracle -------------------------------------------------------------------------------------------------
def objective_float(Ya, Yb, w: float, objective: str) -> float:
    """``f(w)`` in float64 from the eigenvalues of ``M(w)``; ``inf`` where ``M(w)`` is numerically singular (a
    Cholesky factorisation or ``slogdet`` of a singular ``M`` can succeed on a rounding-sized pivot and return a
    huge finite value of either sign)."""
    eigenvalues = np.linalg.eigvalsh(w * Ya + (1.0 - w) * Yb)
    if eigenvalues[0] <= 8.0 * eigenvalues.size * np.finfo(float).eps * eigenvalues[-1]:
        return np.inf
    return -float(np.sum(np.log(eigenvalues))) if objective == "det" else float(np.sum(1.0 / eigenvalues))


def oracle_weight(Ya, Yb, objective: str) -> float:
    """The best of a 1001-point grid, SciPy's bounded Brent search on the grid cells around it, and the end points."""
    f = lambda w: objective_float(Ya, Yb, w, objective)  # noqa: E731
    grid = np.linspace(0.0, 1.0, 1001)
    values = [f(w) for w in grid]
    k = int(np.argmin(values))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    res = scipy.optimize.minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 1e-12})
    return min((f(float(res.x)), float(res.x)), (values[k], float(grid[k])), (f(0.0), 0.0), (f(1.0), 1.0))[1]


def derivatives(Ya, Yb, w: float, objective: str) -> tuple[float, float]:
    """``f'(w)`` and ``f''(w)`` in float64 by plain solves: ``-tr(M^-1 D)`` and ``tr((M^-1 D)^2)`` ("det"),
    ``-tr(M^-1 D M^-1)`` and ``2 tr(M^-1 D M^-1 D M^-1)`` ("trace"), ``D = Y_a - Y_b``."""
    M = w * Ya + (1.0 - w) * Yb
    X = np.linalg.solve(M, Ya - Yb)
    if objective == "det":
        return -float(np.trace(X)), float(np.trace(X @ X))
    M_inv = np.linalg.inv(M)
    return -float(np.trace(X @ M_inv)), 2.0 * float(np.trace(X @ X @ M_inv))


def oracle_resolution(Ya, Yb, w: float, objective: str) -> float:
    """How far from ``w`` a search on float values of ``f`` cannot tell the optimum: where ``f`` rises by no more
    than its rounding noise, ``min(noise / |f'|, sqrt(2 noise / f''))``. The noise is measured as the spread of ``f``
    over ``w +- 1e-9`` (where ``f`` itself moves by ~1e-18 near an interior optimum)."""
    around = np.clip(w + 1e-10 * np.arange(-10, 11), 0.0, 1.0)
    values = np.array([objective_float(Ya, Yb, v, objective) for v in around])
    if not np.all(np.isfinite(values)):
        return 0.0  # an end point next to a singular M: no flat neighbourhood
    noise = float(values.max() - values.min()) + 4.0 * np.finfo(float).eps * max(1.0, abs(float(values[10])))
    slope, curvature = derivatives(Ya, Yb, w, objective)
    bounds = [1.0]
    if slope != 0.0:
        bounds.append(noise / abs(slope))
    if curvature > 0.0:
        bounds.append(float(np.sqrt(2.0 * noise / curvature)))
    return min(bounds)


# -- exact arithmetic ---------------------------------------------------------------------------------------------
def rational(M) -> list[list[Fraction]]:
    return [[Fraction(x) for x in row] for row in np.asarray(M, dtype=float).tolist()]


def combination(Ya, Yb, w) -> list[list[Fraction]]:
    """``M(w) = w Y_a + (1-w) Y_b`` exactly, for a float ``w``."""
    w = Fraction(w)
    return [[w * a + (1 - w) * b for a, b in zip(ra, rb, strict=True)] for ra, rb in zip(rational(Ya), rational(Yb),
                                                                                          strict=True)]


def solve_exact(M, B) -> list[list[Fraction]]:
    """``M^-1 B`` by Gaussian elimination in rationals (``M`` non-singular)."""
    n = len(M)
    A = [list(rm) + list(rb) for rm, rb in zip(M, B, strict=True)]
    for k in range(n):
        pivot = next(i for i in range(k, n) if A[i][k] != 0)
        A[k], A[pivot] = A[pivot], A[k]
        for i in range(n):
            if i != k and A[i][k] != 0:
                factor = A[i][k] / A[k][k]
                A[i] = [x - factor * y for x, y in zip(A[i], A[k], strict=True)]
    return [[x / A[i][i] for x in A[i][n:]] for i in range(n)]


def det_exact(M) -> Fraction:
    A, det = [list(row) for row in M], Fraction(1)
    n = len(A)
    for k in range(n):
        pivot = next((i for i in range(k, n) if A[i][k] != 0), None)
        if pivot is None:
            return Fraction(0)
        if pivot != k:
            A[k], A[pivot], det = A[pivot], A[k], -det
        det *= A[k][k]
        for i in range(k + 1, n):
            factor = A[i][k] / A[k][k]
            A[i] = [x - factor * y for x, y in zip(A[i], A[k], strict=True)]
    return det


def identity(n: int) -> list[list[Fraction]]:
    return [[Fraction(int(i == j)) for j in range(n)] for i in range(n)]


def trace_of_inverse_exact(M) -> Fraction:
    inv = solve_exact(M, identity(len(M)))
    return sum(inv[i][i] for i in range(len(M)))


def slope_exact(Ya, Yb, w: float, objective: str) -> Fraction:
    """``f'(w)``: ``-tr(M^-1 D)`` ("det") or ``-tr(M^-1 D M^-1)`` ("trace"), ``D = Y_a - Y_b``."""
    M = combination(Ya, Yb, w)
    n = len(M)
    D = [[a - b for a, b in zip(ra, rb, strict=True)] for ra, rb in zip(rational(Ya), rational(Yb), strict=True)]
    X = solve_exact(M, D)
    if objective == "det":
        return -sum(X[i][i] for i in range(n))
    inv = solve_exact(M, identity(n))
    return -sum(X[i][k] * inv[k][i] for i in range(n) for k in range(n))


def log_abs(x: Fraction) -> float:
    return math.log(abs(x.numerator)) - math.log(x.denominator)


def never_worse(Ya, Yb, w: float, w_ref: float, objective: str) -> bool:
    """Exactly: ``f(w) <= f(w_ref) + rtol max(1, |f(w_ref)|)`` with ``rtol = OBJECTIVE_RTOL +
    OBJECTIVE_RTOL_PER_COND cond(Y_a + Y_b)`` (``f(w_ref) = inf`` loses to anything)."""
    rtol = OBJECTIVE_RTOL + OBJECTIVE_RTOL_PER_COND * float(np.linalg.cond(Ya + Yb))
    M, M_ref = combination(Ya, Yb, w), combination(Ya, Yb, w_ref)
    if det_exact(M_ref) == 0:
        return True
    if objective == "det":  # -log det M <= -log det M_ref + tol  <=  det M >= det M_ref (1 - tol)
        d_ref = det_exact(M_ref)
        return det_exact(M) >= d_ref * (1 - Fraction(min(0.5, rtol * max(1.0, abs(log_abs(d_ref))))))
    if det_exact(M) == 0:
        return False
    t, t_ref = trace_of_inverse_exact(M), trace_of_inverse_exact(M_ref)
    return t <= t_ref + Fraction(rtol) * max(Fraction(1), t_ref)


def assert_exact_optimum_within(Ya, Yb, w: float, objective: str, delta: float) -> None:
    """The exact derivative changes sign within ``delta`` of ``w`` (or points out of ``[0, 1]`` at an end point)."""
    if w > 0.0:
        assert slope_exact(Ya, Yb, max(0.0, w - delta), objective) <= 0, f"the optimum lies below w - {delta}"
    if w < 1.0:
        assert slope_exact(Ya, Yb, min(1.0, w + delta), objective) >= 0, f"the optimum lies above w + {delta}"


# -- against the oracles ------------------------------------------------------------------------------------------
@SETTINGS
@given(spd_pairs(), st.sampled_from(OBJECTIVES))
def test_weight_agrees_with_grid_and_brent_oracle(pair, objective):
    """To 1e-6 beyond what a float search can resolve, and never a worse objective (checked exactly)."""
    Ya, Yb = pair
    assume(np.max(np.abs(Ya - Yb)) > 1e-12 * np.max(np.abs(Ya + Yb)))  # identical: any w (test_identical_inputs_...)
    w = ci_weight(Ya, Yb, objective)
    assert 0.0 <= w <= 1.0
    w_oracle = oracle_weight(Ya, Yb, objective)
    assert abs(w - w_oracle) <= WEIGHT_TOL + oracle_resolution(Ya, Yb, w_oracle, objective)
    assert never_worse(Ya, Yb, w, w_oracle, objective)
    np.testing.assert_array_equal(optimal_weights([Ya, Yb], objective), [w, 1.0 - w])


@SETTINGS
@given(spd_pairs(max_n=4), st.sampled_from(OBJECTIVES))
def test_weight_is_the_exact_optimum(pair, objective):
    """The sign of the exact derivative brackets the weight within ``1e-9 + 1e-14 cond(Y_a + Y_b)``, where float
    searches stop near 1e-6.

    Not for nearly flat objectives (``f''`` below 1e-3 relative, e.g. nearly identical inputs): there the optimum
    is not determined by the float64 inputs' information, and any weight gives nearly the same fusion (see
    :func:`test_identical_inputs_give_that_input`)."""
    Ya, Yb = pair
    w = ci_weight(Ya, Yb, objective)
    _, curvature = derivatives(Ya, Yb, w, objective)
    assume(curvature > 1e-3 * (1.0 if objective == "det" else objective_float(Ya, Yb, w, objective)))
    assert_exact_optimum_within(Ya, Yb, w, objective, EXACT_BRACKET + EXACT_BRACKET_PER_COND * np.linalg.cond(Ya + Yb))


# -- special inputs -----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("objective", OBJECTIVES)
@pytest.mark.parametrize("n", [1, 3, 6])
def test_an_uninformative_input_leaves_the_other(objective, n):
    rng = np.random.default_rng(n)
    A = rng.normal(size=(n, n))
    a = Gaussian.from_moments(rng.normal(size=n), A @ A.T + 0.1 * np.eye(n))
    zero = Gaussian.zeros(n)
    np.testing.assert_array_equal(optimal_weights([a.Y, zero.Y], objective), [1.0, 0.0])
    np.testing.assert_array_equal(optimal_weights([zero.Y, a.Y], objective), [0.0, 1.0])
    for pair in ([a, zero], [zero, a]):
        c = ci(pair, objective)
        np.testing.assert_array_equal(c.Y, a.Y)
        np.testing.assert_array_equal(c.y, a.y)


@pytest.mark.parametrize("objective", OBJECTIVES)
def test_two_uninformative_inputs(objective):
    np.testing.assert_array_equal(optimal_weights([np.zeros((3, 3)), np.zeros((3, 3))], objective), [0.0, 1.0])


@SETTINGS
@given(st.integers(1, 6).flatmap(spd_matrix), st.sampled_from(OBJECTIVES))
def test_identical_inputs_give_that_input(Y, objective):
    """Any weight gives the same ``M``; the result is the input itself."""
    a = Gaussian.from_info(np.arange(Y.shape[0], dtype=float), Y)
    w = ci_weight(Y, Y, objective)
    assert 0.0 <= w <= 1.0
    c = ci([a, a], objective)
    np.testing.assert_allclose(c.Y, a.Y, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(c.y, a.y, rtol=1e-12, atol=1e-300)


@SETTINGS
@given(spd_pairs(), st.sampled_from(OBJECTIVES), st.floats(-3.0, 3.0))
def test_end_point_when_one_input_dominates(pair, objective, log_gap):
    """``Y_a >= Y_b``: ``f`` decreases all the way to ``w = 1`` (``f'(1) <= 0``), and ``w = 0`` for the swapped
    pair: exactly, as the oracle finds too.

    Where that slope is below what float64 resolves (``|f'(1)| <= 1e-14 cond(Y_a + Y_b) |f(1)|``: "trace" with a
    huge ``extra`` in a few directions, whose covariance is then negligible) the objective is flat to rounding over
    all of ``[0, 1]``, and rounding ``Y_a = base + extra`` can itself break ``Y_a >= Y_b``: not tested."""
    base, extra = pair
    eigenvalues = np.linalg.eigvalsh(base)
    assume(eigenvalues[0] > 1e-10 * eigenvalues[-1])  # numerically positive definite
    Ya, Yb = base + 10.0**log_gap * extra, base
    slope, _ = derivatives(Ya, Yb, 1.0, objective)
    scale = max(1.0, abs(objective_float(Ya, Yb, 1.0, objective)))
    assume(abs(slope) > EXACT_BRACKET_PER_COND * np.linalg.cond(Ya + Yb) * scale)
    assert ci_weight(Ya, Yb, objective) == 1.0
    assert ci_weight(Yb, Ya, objective) == 0.0
    w_oracle = oracle_weight(Ya, Yb, objective)
    assert 1.0 - w_oracle <= WEIGHT_TOL + oracle_resolution(Ya, Yb, w_oracle, objective)


@pytest.mark.parametrize("objective", OBJECTIVES)
@pytest.mark.parametrize("k", [1.0 + 1e-9, 2.0, 1e6])
def test_proportional_inputs_take_the_larger(objective, k):
    Y = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]])
    assert ci_weight(k * Y, Y, objective) == 1.0
    assert ci_weight(Y, k * Y, objective) == 0.0


@pytest.mark.parametrize("objective", OBJECTIVES)
def test_interior_optimum_of_crossed_pairs(objective):
    """``diag(k, 1/k)`` against ``diag(1/k, k)``: ``f`` is symmetric about ``w = 1/2``, its optimum."""
    for k in (2.0, 1e4):
        assert ci_weight(np.diag([k, 1 / k]), np.diag([1 / k, k]), objective) == pytest.approx(0.5, abs=1e-15)


@SETTINGS
@given(st.integers(1, 4).flatmap(lambda n: st.tuples(spd_matrix(n, 3.0), spd_matrix(n, 3.0))),
       st.sampled_from(OBJECTIVES), st.integers(1, 3))
def test_a_direction_neither_input_informs_is_left_out(pair, objective, extra):
    """``Y_a + Y_b`` singular: every ``M(w)`` is singular in the same directions, and the weight optimises the
    informed directions (pseudo-determinant, trace of the pseudo-inverse), whatever the basis: padded with zero
    rows and columns, then rotated, the pair gets a weight as good for the unpadded pair as its own."""
    Ya, Yb = pair
    n = Ya.shape[0]
    Pa, Pb = np.zeros((n + extra, n + extra)), np.zeros((n + extra, n + extra))
    Pa[:n, :n], Pb[:n, :n] = Ya, Yb
    Q, _ = np.linalg.qr(np.random.default_rng(n + extra).normal(size=(n + extra, n + extra)))
    Ra, Rb = Q @ Pa @ Q.T, Q @ Pb @ Q.T
    f = lambda w: objective_float(Ya, Yb, w, objective)  # noqa: E731
    best = f(ci_weight(Ya, Yb, objective))
    for padded in ((Pa, Pb), (0.5 * (Ra + Ra.T), 0.5 * (Rb + Rb.T))):
        assert f(ci_weight(*padded, objective)) <= best + 1e-9 * max(1.0, abs(best))


# -- bad input ----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("Ya", "Yb", "match"),
    [
        (np.array([[1.0, np.nan], [np.nan, 1.0]]), np.eye(2), "Y_a contains non-finite"),
        (np.eye(2), np.array([[np.inf, 0.0], [0.0, 1.0]]), "Y_b contains non-finite"),
        (np.ones((2, 3)), np.ones((2, 3)), "Y_a must be a square matrix"),
        (np.ones(2), np.ones(2), "Y_a must be a square matrix"),
        (np.eye(2), np.eye(3), "Y_b must be 2x2"),
        (np.array([[2.0, 1.0], [0.0, 2.0]]), np.eye(2), "Y_a is not symmetric"),
        (-0.5 * np.eye(2), 2.0 * np.eye(2), "Y_a is not positive semi-definite"),
        (2.0 * np.eye(2), -0.5 * np.eye(2), "Y_b is not positive semi-definite"),
        (np.diag([1.0, -1.0]), np.diag([1.0, 1.0]), "Y_a is not positive semi-definite"),  # Y_a + Y_b singular
    ],
    ids=["nan", "inf", "not-square", "vector", "mismatched", "not-symmetric", "negative-a", "negative-b",
         "negative-in-null-space-of-sum"],
)
@pytest.mark.parametrize("objective", OBJECTIVES)
def test_bad_matrices_are_clear_errors(Ya, Yb, match, objective):
    with pytest.raises(ValueError, match=f"CI input information matrix {match}"):
        optimal_weights([Ya, Yb], objective)


def test_ci_of_a_non_finite_belief_is_a_clear_error():
    good = Gaussian.from_moments([0.0, 0.0], np.eye(2))
    bad = Gaussian(np.zeros(2), np.array([[1.0, np.nan], [np.nan, 1.0]]))  # the unchecked constructor
    with pytest.raises(ValueError, match="non-finite"):
        ci([good, bad])
