"""Inverse covariance intersection (Noack, Sijs, Reinhardt & Hanebeck 2017) and its optimal weight.

Oracles: the covariance-form equations (gains ``K``, ``L``) evaluated with plain matrix inverses, scalar
closed forms, dense grids over the weight, and the exact error covariance of the fused estimate when the
inputs share common information (Noack et al.'s correlation model).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fusion.gaussian import Gaussian
from fusion.inverse_covariance_intersection import ici
from fusion.pair_weights import ici_weight

SETTINGS = settings(max_examples=60, deadline=None)
ENTRIES = st.floats(min_value=-3.0, max_value=3.0, allow_nan=False, allow_infinity=False)


def ici_moments(a_mean, P_a, b_mean, P_b, w):
    """The covariance form of ICI (Noack et al. 2017): ``P``, ``x``, ``K``, ``L``."""
    inv = np.linalg.inv
    gamma_inv = inv(w * P_a + (1 - w) * P_b)
    P = inv(inv(P_a) + inv(P_b) - gamma_inv)
    K = P @ (inv(P_a) - w * gamma_inv)
    L = P @ (inv(P_b) - (1 - w) * gamma_inv)
    return P, K @ a_mean + L @ b_mean, K, L


def ici_information(Y_a, Y_b, w):
    inv = np.linalg.inv
    return Y_a + Y_b - inv(w * inv(Y_a) + (1 - w) * inv(Y_b))


@st.composite
def spd(draw, n):
    A = draw(arrays(np.float64, (n, n), elements=ENTRIES))
    return A @ A.T + 0.1 * np.eye(n)


@st.composite
def pairs(draw):
    n = draw(st.integers(1, 4))
    means = draw(arrays(np.float64, (2, n), elements=ENTRIES))
    return (Gaussian.from_moments(means[0], draw(spd(n))), Gaussian.from_moments(means[1], draw(spd(n))))


# -- the fusion equations ---------------------------------------------------------------------------
@pytest.mark.parametrize("w", [0.0, 0.3, 1.0])
def test_scalar_closed_form(w):
    """1-D: ``1/P = 1/p_a + 1/p_b - 1/(w p_a + (1-w) p_b)``, ``x = P ((1/p_a - w/g) a + (1/p_b - (1-w)/g) b)``."""
    a, p_a, b, p_b = 1.0, 2.0, -3.0, 5.0
    g = w * p_a + (1 - w) * p_b
    P = 1.0 / (1 / p_a + 1 / p_b - 1 / g)
    x = P * ((1 / p_a - w / g) * a + (1 / p_b - (1 - w) / g) * b)
    fused = ici(Gaussian.from_moments([a], [[p_a]]), Gaussian.from_moments([b], [[p_b]]), w)
    assert fused.cov[0, 0] == pytest.approx(P, rel=1e-12)
    assert fused.mean[0] == pytest.approx(x, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("objective", ["det", "trace"])
def test_scalar_optimum_keeps_the_better_estimate(objective):
    """1-D: ``1/P(w)`` is largest where ``g = w p_a + (1-w) p_b`` is largest, i.e. at the weight end point of the
    *larger* variance: ``P = min(p_a, p_b)`` and the mean is the better estimate's (gain 1 on it, 0 on the other)."""
    better, worse = Gaussian.from_moments([4.0], [[0.5]]), Gaussian.from_moments([-1.0], [[3.0]])
    for a, b, w in ((better, worse, 0.0), (worse, better, 1.0)):
        assert ici_weight(a.Y, b.Y, objective) == w
        fused = ici(a, b, objective)
        assert fused.cov[0, 0] == pytest.approx(0.5, rel=1e-12)
        assert fused.mean[0] == pytest.approx(4.0, rel=1e-12)


@SETTINGS
@given(pairs(), st.floats(0.0, 1.0))
def test_information_form_matches_the_covariance_form(pair, w):
    a, b = pair
    P, x, K, L = ici_moments(a.mean, a.cov, b.mean, b.cov, w)
    fused = ici(a, b, w)
    scale = np.max(np.abs(P))
    np.testing.assert_allclose(fused.cov, P, rtol=1e-6, atol=1e-8 * scale)
    np.testing.assert_allclose(fused.mean, x, rtol=1e-6, atol=1e-6 * (1 + np.max(np.abs(x))))
    np.testing.assert_allclose(K + L, np.eye(a.dim), atol=1e-6)  # unbiased: the gains sum to the identity


def test_identical_estimates_give_that_estimate():
    """Two copies of one estimate share all their information: ICI returns it, whatever the weight."""
    a = Gaussian.from_moments([1.0, 2.0, 3.0], np.diag([1.0, 2.0, 3.0]) + 0.5)
    for w in (0.0, 0.4, 1.0, "det", "trace"):
        assert ici(a, a, w).allclose(a, rtol=1e-9, atol=1e-12)


def test_trajectories_keep_their_grid():
    from fusion.motion import ConstantVelocity
    from fusion.trajectory import Trajectory, TrajectoryModel

    model = TrajectoryModel(ConstantVelocity(1, q=0.5), step=1.0, window=3)
    rng = np.random.default_rng(1)
    a, b = (Trajectory.prior(model, 7).update(np.eye(2), np.eye(2), rng.normal(size=2)) for _ in range(2))
    fused = ici(a, b, 0.25)
    assert (fused.epoch, fused.model) == (7, model)
    expected = ici_information(a.Y, b.Y, 0.25)
    np.testing.assert_allclose(fused.Y, expected, rtol=1e-8, atol=1e-10)


# -- uninformed directions ------------------------------------------------------------------------------
def test_an_uninformative_input_leaves_the_other():
    """A belief with no information at all: the optimal weight keeps the other belief (``w = 0`` keeps ``a``)."""
    a = Gaussian.from_moments([1.0, -2.0], [[2.0, 0.5], [0.5, 1.0]])
    for objective in ("det", "trace"):
        assert ici(a, Gaussian.zeros(2), objective).allclose(a, rtol=1e-12)
        assert ici(Gaussian.zeros(2), a, objective).allclose(a, rtol=1e-12)


@pytest.mark.parametrize("w", [1e-3, 0.3, 0.9])
def test_a_partly_uninformed_input_is_the_limit_of_the_covariance_form(w):
    """``Y_b`` informs only x: the information form at weight ``w`` equals the covariance form with
    ``Y_b + delta I``, ``delta -> 0`` (here ``1e-9``)."""
    a = Gaussian.from_moments([1.0, -2.0], [[2.0, 0.5], [0.5, 1.0]])
    b = Gaussian.from_info([3.0, 0.0], [[4.0, 0.0], [0.0, 0.0]])
    b_reg = Gaussian.from_info(b.y, b.Y + 1e-9 * np.eye(2))
    P, x, _, _ = ici_moments(a.mean, a.cov, b_reg.mean, b_reg.cov, w)
    fused = ici(a, b, w)
    np.testing.assert_allclose(fused.cov, P, rtol=1e-6)
    np.testing.assert_allclose(fused.mean, x, rtol=1e-6)
    best = ici(a, b, "det")
    assert all(np.linalg.slogdet(best.Y)[1] >= np.linalg.slogdet(ici(a, b, v).Y)[1] - 1e-12
               for v in np.linspace(0.0, 1.0, 201))


# -- the optimal weight -------------------------------------------------------------------------------
def grid_optimum(f):
    grid = np.linspace(0.0, 1.0, 1001)
    w0 = grid[int(np.argmin([f(w) for w in grid]))]
    fine = np.linspace(max(0.0, w0 - 1e-3), min(1.0, w0 + 1e-3), 2001)
    return fine[int(np.argmin([f(w) for w in fine]))]


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("objective", ["det", "trace"])
def test_weight_matches_a_dense_grid(seed, objective):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 7))
    Y_a, Y_b = (A @ A.T + 0.05 * np.eye(n) for A in rng.normal(size=(2, n, n)))
    if objective == "det":
        f = lambda w: -np.linalg.slogdet(ici_information(Y_a, Y_b, w))[1]  # noqa: E731
    else:
        f = lambda w: np.trace(np.linalg.inv(ici_information(Y_a, Y_b, w)))  # noqa: E731
    w_grid = grid_optimum(f)
    w = ici_weight(Y_a, Y_b, objective)
    assert 0.0 <= w <= 1.0
    assert f(w) <= f(w_grid) + 1e-10 * max(1.0, abs(f(w_grid)))
    assert abs(w - w_grid) < 1e-3 or abs(f(w) - f(w_grid)) < 1e-9 * max(1.0, abs(f(w_grid)))


@pytest.mark.parametrize("objective", ["det", "trace"])
def test_weight_is_an_end_point_when_one_input_dominates(objective):
    """``Y_a >= Y_b``: ``w = 0`` makes ``Gamma = P_b`` and the fused information ``Y_a``, the best possible."""
    rng = np.random.default_rng(4)
    A, B = rng.normal(size=(2, 3, 3))
    Y_b = B @ B.T + 0.1 * np.eye(3)
    Y_a = Y_b + A @ A.T
    assert ici_weight(Y_a, Y_b, objective) == 0.0
    assert ici_weight(Y_b, Y_a, objective) == 1.0


# -- consistency under common information -------------------------------------------------------------
@st.composite
def common_information_problem(draw):
    """``Y_a = A + C``, ``Y_b = B + C``: two estimates that fused the same information ``C`` (DDF); their errors
    are ``e_a = P_a (alpha + gamma)``, ``e_b = P_b (beta + gamma)`` with independent information noises of
    covariances ``A``, ``B``, ``C``, so ``cov(e_a, e_b) = P_a C P_b``."""
    n = draw(st.integers(1, 4))
    parts = [draw(arrays(np.float64, (n, n), elements=ENTRIES)) for _ in range(3)]
    A, B, C = (M @ M.T for M in parts)
    A, B = A + 0.05 * np.eye(n), B + 0.05 * np.eye(n)
    return A, B, C


@SETTINGS
@given(common_information_problem(), st.one_of(st.floats(0.0, 1.0), st.sampled_from(["det", "trace"])))
def test_ici_bounds_the_true_error_covariance(problem, omega):
    A, B, C = problem
    n = A.shape[0]
    Y_a, Y_b = A + C, B + C
    a, b = Gaussian.from_info(np.zeros(n), Y_a), Gaussian.from_info(np.zeros(n), Y_b)
    fused = ici(a, b, omega)
    w = omega if not isinstance(omega, str) else ici_weight(Y_a, Y_b, omega)
    P_a, P_b = np.linalg.inv(Y_a), np.linalg.inv(Y_b)
    P, _, K, L = ici_moments(np.zeros(n), P_a, np.zeros(n), P_b, w)
    cross = P_a @ C @ P_b
    actual = K @ P_a @ K.T + L @ P_b @ L.T + K @ cross @ L.T + L @ cross.T @ K.T
    claimed = fused.cov
    np.testing.assert_allclose(claimed, P, rtol=1e-5, atol=1e-9 * np.max(np.abs(P)))
    gap = np.linalg.eigvalsh(claimed - 0.5 * (actual + actual.T))
    assert gap.min() >= -1e-7 * np.max(np.abs(claimed))


# -- bad input ---------------------------------------------------------------------------------------
def test_bad_inputs_are_clear_errors():
    good = Gaussian.from_moments([0.0, 0.0], np.eye(2))
    with pytest.raises(ValueError, match="omega must lie in"):
        ici(good, good, 1.5)
    with pytest.raises(ValueError, match="objective must be"):
        ici(good, good, "entropy")
    with pytest.raises(ValueError, match="dimension mismatch"):
        ici(good, Gaussian.from_moments([0.0], [[1.0]]))
    x_only = Gaussian.from_info([0.0, 0.0], [[1.0, 0.0], [0.0, 0.0]])
    for omega in ("det", 0.5):
        with pytest.raises(ValueError, match="together to inform every direction"):
            ici(x_only, x_only, omega)
    for Y_a, Y_b, name in ((2 * np.eye(2), -0.5 * np.eye(2), "Y_b"), (-0.5 * np.eye(2), 2 * np.eye(2), "Y_a")):
        with pytest.raises(ValueError, match=f"{name} is not positive semi-definite"):
            ici_weight(Y_a, Y_b)
    with pytest.raises(ValueError, match="Y_a is not symmetric"):
        ici_weight(np.array([[2.0, 1.0], [0.0, 2.0]]), np.eye(2))
    nan_info = Gaussian(np.zeros(2), np.array([[1.0, np.nan], [np.nan, 1.0]]))
    for omega in ("trace", 0.5):
        with pytest.raises(ValueError, match="non-finite"):
            ici(good, nan_info, omega)
    nan_mean = Gaussian(np.array([np.inf, 0.0]), np.eye(2))
    with pytest.raises(ValueError, match="non-finite"):
        ici(good, nan_mean, 0.5)
    with pytest.raises(ValueError, match="must be 2x2"):
        ici_weight(np.eye(2), np.eye(3))
