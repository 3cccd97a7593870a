"""Covariance intersection (Merino (3.43)-(3.46); Julier & Uhlmann 1997; Niehsen 2002).

Oracles: brute-force grids over the weight, random samples of the simplex, and the closed-form
covariance of the CI estimate error computed from a known joint covariance of the input errors.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fusion.covariance_intersection import ci, fast_ci
from fusion.gaussian import Gaussian

SETTINGS = settings(max_examples=60, deadline=None)
FLOATS = st.floats(min_value=-3.0, max_value=3.0, allow_nan=False, allow_infinity=False)


def random_spd(rng, n, ridge=0.2):
    A = rng.normal(size=(n, n))
    return A @ A.T + ridge * np.eye(n)


def random_belief(rng, n):
    return Gaussian.from_moments(rng.normal(size=n), random_spd(rng, n))


def recover_weights(result, beliefs):
    """Weights ``w`` on the simplex with ``(y_c, Y_c) = sum_i w_i (y_i, Y_i)``, by constrained least squares.

    Returns the weights and the relative residual; the residual is ``inf`` when the weights are not
    identifiable from the inputs (their information pairs are linearly dependent)."""
    A = np.stack([np.concatenate([b.Y.ravel(), b.y]) for b in beliefs], axis=1)
    target = np.concatenate([result.Y.ravel(), result.y])
    scale = np.linalg.norm(target)
    A_c = np.vstack([A, scale * np.ones((1, len(beliefs)))])
    t_c = np.concatenate([target, [scale]])
    if np.linalg.matrix_rank(A_c, tol=1e-9 * np.linalg.norm(A_c)) < len(beliefs):
        return None, np.inf
    w, *_ = np.linalg.lstsq(A_c, t_c, rcond=None)
    return w, np.linalg.norm(A_c @ w - t_c) / scale


def logdet(M):
    sign, value = np.linalg.slogdet(M)
    return value if sign > 0 else -np.inf


def trace_inv(M):
    return float(np.trace(np.linalg.inv(M)))


def grid_optimum(f, lo=0.0, hi=1.0):
    """Maximise ``f`` on ``[lo, hi]`` by two nested dense grids (resolution 1e-6)."""
    grid = np.linspace(lo, hi, 1001)
    w0 = grid[int(np.argmax([f(w) for w in grid]))]
    fine = np.linspace(max(lo, w0 - 1e-3), min(hi, w0 + 1e-3), 2001)
    return fine[int(np.argmax([f(w) for w in fine]))]


def min_eig(M):
    return float(np.linalg.eigvalsh(0.5 * (M + M.T))[0])


# -- basic properties ------------------------------------------------------------------------------
@pytest.mark.parametrize("objective", ["det", "trace"])
@pytest.mark.parametrize("count", [1, 2, 3, 5])
def test_ci_of_identical_estimates_is_that_estimate(objective, count):
    """ci([a, a, ...]) == a: n equal estimates (whatever their correlation) carry the information of one."""
    rng = np.random.default_rng(count)
    a = random_belief(rng, 3)
    c = ci([a] * count, objective)
    np.testing.assert_allclose(c.Y, a.Y, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(c.y, a.y, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(c.cov, a.cov, rtol=1e-9)


def test_fast_ci_of_identical_estimates_is_that_estimate():
    a = random_belief(np.random.default_rng(7), 4)
    c = fast_ci([a, a, a])
    np.testing.assert_allclose(c.Y, a.Y, rtol=1e-12)
    np.testing.assert_allclose(c.y, a.y, rtol=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_fast_ci_gives_more_weight_to_smaller_covariance(seed):
    rng = np.random.default_rng(seed)
    a = random_belief(rng, 3)
    # b: a clearly larger, differently shaped covariance
    b = Gaussian.from_moments(rng.normal(size=3), 3.0 * np.linalg.inv(a.Y) + random_spd(rng, 3))
    tr_a, tr_b = np.trace(np.linalg.inv(a.Y)), np.trace(np.linalg.inv(b.Y))
    assert tr_a < tr_b
    for order in ([a, b], [b, a]):
        c = fast_ci(order)
        (w_first, w_second), residual = recover_weights(c, order)
        assert residual < 1e-10
        w_a = w_first if order[0] is a else w_second
        assert w_a > 0.5
        assert w_first + w_second == pytest.approx(1.0, abs=1e-9)
        # Niehsen's closed form w_a = (1/tr P_a) / (1/tr P_a + 1/tr P_b)
        assert w_a == pytest.approx(tr_b / (tr_a + tr_b), rel=1e-8)
        np.testing.assert_allclose(c.y, w_first * order[0].y + w_second * order[1].y, rtol=1e-9, atol=1e-12)


def test_fast_ci_gives_zero_weight_to_uninformative_input():
    a = random_belief(np.random.default_rng(3), 2)
    c = fast_ci([Gaussian.zeros(2), a])
    np.testing.assert_allclose(c.Y, a.Y, rtol=1e-12)


# -- optimal weights against brute force ----------------------------------------------------------
@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("objective", ["det", "trace"])
def test_two_belief_weight_matches_grid_search(seed, objective):
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(2, 5))
    a, b = random_belief(rng, n), random_belief(rng, n)
    if objective == "det":
        f = lambda w: logdet(w * a.Y + (1 - w) * b.Y)  # noqa: E731
    else:
        f = lambda w: -trace_inv(w * a.Y + (1 - w) * b.Y)  # noqa: E731
    w_grid = grid_optimum(f)
    c = ci([a, b], objective)
    (w_a, w_b), residual = recover_weights(c, [a, b])
    assert residual < 1e-10
    assert w_a + w_b == pytest.approx(1.0, abs=1e-9)
    assert abs(w_a - w_grid) < 1e-4
    assert f(w_a) >= f(w_grid) - 1e-9 * max(1.0, abs(f(w_grid)))


@pytest.mark.parametrize("objective", ["det", "trace"])
def test_two_belief_weight_at_end_point_when_one_input_dominates(objective):
    """If ``Y_a >= Y_b`` the optimum is ``w = 1`` (an end point the bounded search never evaluates)."""
    rng = np.random.default_rng(11)
    b = random_belief(rng, 3)
    a = b.fuse(random_belief(rng, 3))
    for pair, expected in (([a, b], a), ([b, a], a)):
        c = ci(pair, objective)
        np.testing.assert_allclose(c.Y, expected.Y, rtol=1e-9)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("objective", ["det", "trace"])
def test_many_belief_optimum_beats_random_simplex_weights(seed, objective):
    rng = np.random.default_rng(200 + seed)
    count, n = int(rng.integers(3, 5)), int(rng.integers(2, 5))
    beliefs = [random_belief(rng, n) for _ in range(count)]
    stack = np.stack([b.Y for b in beliefs])
    f = logdet if objective == "det" else (lambda M: -trace_inv(M))
    c = ci(beliefs, objective)
    w, residual = recover_weights(c, beliefs)
    assert residual < 1e-8
    assert np.all(w >= -1e-8) and w.sum() == pytest.approx(1.0, abs=1e-8)
    best = f(c.Y)
    samples = rng.dirichlet(np.full(count, 0.5), size=3000)
    samples = np.vstack([samples, np.eye(count), np.full(count, 1.0 / count)])
    values = np.array([f(np.tensordot(s, stack, axes=1)) for s in samples])
    assert best >= values.max() - 1e-7 * max(1.0, abs(values.max()))


def test_given_weights_are_used_verbatim():
    rng = np.random.default_rng(5)
    beliefs = [random_belief(rng, 3) for _ in range(3)]
    weights = [0.2, 0.3, 0.5]
    c = ci(beliefs, weights)
    np.testing.assert_allclose(c.Y, sum(w * b.Y for w, b in zip(weights, beliefs, strict=True)), rtol=1e-12)
    np.testing.assert_allclose(c.y, sum(w * b.y for w, b in zip(weights, beliefs, strict=True)), rtol=1e-12)


@pytest.mark.parametrize(
    "weights",
    [[-0.1, 0.6, 0.5], [0.2, 0.2, 0.2], [0.5, 0.5], [0.25, 0.25, 0.25, 0.25], [float("nan"), 0.5, 0.5]],
    ids=["negative", "not-summing-to-1", "too-few", "too-many", "nan"],
)
def test_bad_weights_raise(weights):
    rng = np.random.default_rng(6)
    beliefs = [random_belief(rng, 2) for _ in range(3)]
    with pytest.raises(ValueError, match="weights"):
        ci(beliefs, weights)


def test_unknown_objective_raises():
    rng = np.random.default_rng(6)
    with pytest.raises(ValueError, match="objective must be"):
        ci([random_belief(rng, 2), random_belief(rng, 2)], "foo")


def test_empty_and_mismatched_inputs_raise():
    rng = np.random.default_rng(6)
    with pytest.raises(ValueError, match="at least one belief"):
        ci([])
    with pytest.raises(ValueError, match="one dimension"):
        ci([random_belief(rng, 2), random_belief(rng, 3)])
    with pytest.raises(ValueError, match="at least one belief"):
        fast_ci([])


# -- consistency under unknown correlation --------------------------------------------------------
def actual_error_cov(gains, joint):
    """Covariance of ``sum_i K_i e_i`` when the stacked errors ``e`` have covariance ``joint``."""
    K = np.hstack(gains)
    return K @ joint @ K.T


def ci_gain_blocks(result, beliefs, weights):
    """``x_c - x = P_c sum_i w_i Y_i e_i`` for zero-mean errors ``e_i`` of the inputs."""
    P_c = np.linalg.inv(result.Y)
    return [w * P_c @ b.Y for w, b in zip(weights, beliefs, strict=True)]


def assert_not_overconfident(claimed, actual):
    scale = max(1.0, float(np.max(np.abs(actual))))
    assert min_eig(claimed - actual) >= -1e-9 * scale


@st.composite
def correlated_estimates(draw, count=2):
    """A random joint covariance of the stacked estimate errors (arbitrary cross-covariances)."""
    n = draw(st.integers(1, 4))
    m = count * n
    A = draw(arrays(np.float64, (m, m), elements=FLOATS))
    joint = A @ A.T + 0.05 * np.eye(m)
    # The estimates' values do not enter the error covariance; random values make the weights identifiable.
    means = draw(arrays(np.float64, (count, n), elements=FLOATS))
    blocks = [joint[i * n : (i + 1) * n, i * n : (i + 1) * n] for i in range(count)]
    return joint, [Gaussian.from_moments(mu, P) for mu, P in zip(means, blocks, strict=True)]


@SETTINGS
@given(correlated_estimates(), st.sampled_from(["det", "trace"]), st.floats(0.0, 1.0))
def test_ci_never_overconfident_for_correlated_pairs(problem, objective, omega):
    joint, (a, b) = problem
    for weights in ([omega, 1.0 - omega], None):
        c = ci([a, b], objective if weights is None else weights)
        if weights is None:
            weights, residual = recover_weights(c, [a, b])
            if weights is None:  # a and b carry identical information: any weight gives the same result
                weights = [1.0, 0.0]
            else:
                assert residual < 1e-8
        actual = actual_error_cov(ci_gain_blocks(c, [a, b], weights), joint)
        assert_not_overconfident(np.linalg.inv(c.Y), actual)


@SETTINGS
@given(correlated_estimates())
def test_fast_ci_never_overconfident_for_correlated_pairs(problem):
    joint, (a, b) = problem
    c = fast_ci([a, b])
    tr = np.array([np.trace(np.linalg.inv(a.Y)), np.trace(np.linalg.inv(b.Y))])
    weights = (1 / tr) / (1 / tr).sum()
    np.testing.assert_allclose(c.Y, weights[0] * a.Y + weights[1] * b.Y, rtol=1e-9)
    assert_not_overconfident(np.linalg.inv(c.Y), actual_error_cov(ci_gain_blocks(c, [a, b], weights), joint))


@settings(max_examples=30, deadline=None)
@given(correlated_estimates(count=3), st.data())
def test_ci_never_overconfident_for_three_correlated_estimates(problem, data):
    joint, beliefs = problem
    raw = np.array([data.draw(st.floats(0.0, 1.0)) for _ in beliefs]) + 1e-3
    random_weights = raw / raw.sum()
    c = ci(beliefs, random_weights)
    assert_not_overconfident(np.linalg.inv(c.Y), actual_error_cov(ci_gain_blocks(c, beliefs, random_weights), joint))
    c = ci(beliefs, "det")
    w, residual = recover_weights(c, beliefs)
    if residual < 1e-8:  # the weights are identifiable (the information matrices are independent)
        assert_not_overconfident(np.linalg.inv(c.Y), actual_error_cov(ci_gain_blocks(c, beliefs, w), joint))


def strongly_correlated_pair(rng, n, rho):
    """Errors ``e_b = rho e_a + sqrt(1 - rho^2) v`` with ``e_a, v ~ N(0, P)``: cross-covariance ``rho P``."""
    P = random_spd(rng, n)
    joint = np.block([[P, rho * P], [rho * P, P]])
    return joint, Gaussian.from_moments(np.zeros(n), P), Gaussian.from_moments(np.zeros(n), P)


@pytest.mark.parametrize("seed", range(3))
def test_naive_fusion_is_overconfident_but_ci_is_not(seed):
    """The counter-check: the same oracle flags the naive product of correlated estimates."""
    rng = np.random.default_rng(seed)
    joint, a, b = strongly_correlated_pair(rng, 3, rho=0.95)
    naive = a.fuse(b)
    P_naive = np.linalg.inv(naive.Y)
    actual_naive = actual_error_cov([P_naive @ a.Y, P_naive @ b.Y], joint)
    assert min_eig(P_naive - actual_naive) < -0.1 * np.max(np.abs(actual_naive))
    for objective in ("det", "trace"):
        c = ci([a, b], objective)
        w, _ = recover_weights(c, [a, b])
        if w is None:  # a and b are identical here, so every weight gives the same belief
            w = [0.5, 0.5]
        assert_not_overconfident(np.linalg.inv(c.Y), actual_error_cov(ci_gain_blocks(c, [a, b], w), joint))


@pytest.mark.parametrize("seed", range(3))
def test_naive_fusion_overconfident_for_distinct_correlated_inputs(seed):
    """Different covariances, strong positive correlation: naive fails, optimised CI holds."""
    rng = np.random.default_rng(50 + seed)
    n = 3
    L = np.linalg.cholesky(random_spd(rng, n))
    M = np.linalg.cholesky(random_spd(rng, n))
    # e_a = L u, e_b = M (0.97 u + 0.243 v): correlated through the shared u
    G = np.block([[L, np.zeros((n, n))], [0.97 * M, np.sqrt(1 - 0.97**2) * M]])
    joint = G @ G.T
    a = Gaussian.from_moments(np.zeros(n), joint[:n, :n])
    b = Gaussian.from_moments(np.zeros(n), joint[n:, n:])
    P_naive = np.linalg.inv(a.Y + b.Y)
    actual_naive = actual_error_cov([P_naive @ a.Y, P_naive @ b.Y], joint)
    assert min_eig(P_naive - actual_naive) < 0
    c = ci([a, b])
    w, residual = recover_weights(c, [a, b])
    assert residual < 1e-9
    assert_not_overconfident(np.linalg.inv(c.Y), actual_error_cov(ci_gain_blocks(c, [a, b], w), joint))


def test_ci_consistency_monte_carlo():
    """Sample correlated errors and check the empirical CI error covariance (a sanity check of the oracle)."""
    rng = np.random.default_rng(9)
    joint, a, b = strongly_correlated_pair(rng, 2, rho=0.9)
    b = Gaussian.from_moments(np.zeros(2), 2.0 * np.linalg.inv(b.Y))
    joint[2:, 2:] *= 2.0
    joint[:2, 2:] *= np.sqrt(2.0)
    joint[2:, :2] *= np.sqrt(2.0)
    e = rng.multivariate_normal(np.zeros(4), joint, size=100_000)
    c = ci([a, b])
    w, _ = recover_weights(c, [a, b])
    K = np.hstack(ci_gain_blocks(c, [a, b], w))
    err = e @ K.T
    empirical = err.T @ err / len(err)
    np.testing.assert_allclose(empirical, actual_error_cov(ci_gain_blocks(c, [a, b], w), joint), rtol=0.05, atol=0.02)
    assert min_eig(np.linalg.inv(c.Y) - empirical) > -0.02 * np.max(np.abs(empirical))
