"""The unscented transform (Merino Alg. 3.5): exact for linear maps, close to Monte Carlo for a polar to
Cartesian conversion, Julier's kappa rule (matching the Gaussian fourth moment), and kappa validation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fusion.unscented import default_kappa, sigma_points, unscented_transform

SETTINGS = settings(max_examples=60, deadline=None)
FLOATS = st.floats(-3.0, 3.0, allow_nan=False, allow_infinity=False)


@st.composite
def linear_problems(draw):
    n = draw(st.integers(1, 6))
    m = draw(st.integers(1, 5))
    A = draw(arrays(np.float64, (n, n), elements=FLOATS))
    P = A @ A.T + 0.1 * np.eye(n)
    mu = draw(arrays(np.float64, (n,), elements=st.floats(-10, 10)))
    M = draw(arrays(np.float64, (m, n), elements=FLOATS))
    b = draw(arrays(np.float64, (m,), elements=st.floats(-10, 10)))
    kappa = draw(st.one_of(st.none(), st.floats(-n + 0.1, 5.0)))
    return mu, P, M, b, kappa


@SETTINGS
@given(linear_problems())
def test_ut_of_linear_map_is_exact(problem):
    mu, P, M, b, kappa = problem
    mean, cov = unscented_transform(lambda x: M @ x + b, mu, P, kappa)
    scale = max(1.0, np.abs(M @ P @ M.T).max())
    np.testing.assert_allclose(mean, M @ mu + b, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(M @ mu + b).max()))
    np.testing.assert_allclose(cov, M @ P @ M.T, rtol=1e-9, atol=1e-9 * scale)


def test_ut_of_linear_map_with_singular_covariance_is_exact():
    """A rank-deficient covariance falls back to the symmetric square root and is still exact."""
    mu = np.array([1.0, 2.0, 3.0])
    u = np.array([1.0, -1.0, 2.0])
    P = np.outer(u, u)
    M = np.array([[1.0, 2.0, 0.5], [0.0, -1.0, 3.0]])
    mean, cov = unscented_transform(lambda x: M @ x, mu, P)
    np.testing.assert_allclose(mean, M @ mu, rtol=1e-12)
    np.testing.assert_allclose(cov, M @ P @ M.T, rtol=1e-9, atol=1e-12)


def _polar_to_cartesian(x):
    r, theta = x
    return np.array([r * np.cos(theta), r * np.sin(theta)])


@pytest.mark.parametrize(("mu", "sd"), [((100.0, np.pi / 4), (2.0, 0.1)), ((30.0, -2.0), (3.0, 0.2))])
def test_ut_of_polar_to_cartesian_close_to_monte_carlo(mu, sd):
    rng = np.random.default_rng(1)
    P = np.diag(np.square(sd))
    mean, cov = unscented_transform(_polar_to_cartesian, np.array(mu), P)
    samples = rng.multivariate_normal(mu, P, size=400_000)
    y = np.stack([samples[:, 0] * np.cos(samples[:, 1]), samples[:, 0] * np.sin(samples[:, 1])], axis=1)
    mc_mean, mc_cov = y.mean(axis=0), np.cov(y.T)
    # the exact mean: E[r cos t] = mu_r cos(mu_t) exp(-sd_t^2 / 2)
    exact_mean = mu[0] * np.exp(-sd[1] ** 2 / 2) * np.array([np.cos(mu[1]), np.sin(mu[1])])
    np.testing.assert_allclose(mc_mean, exact_mean, rtol=2e-3, atol=1e-2)  # the oracle itself
    np.testing.assert_allclose(mean, exact_mean, rtol=1e-2, atol=0.01 * mu[0] * sd[1])
    # covariance within a few per cent (relative to its largest eigenvalue)
    assert np.linalg.norm(cov - mc_cov, 2) < 0.03 * np.linalg.norm(mc_cov, 2)
    # and the UT is better than first-order linearisation on the mean (which ignores the shrinkage)
    linear_mean = _polar_to_cartesian(mu)
    assert np.linalg.norm(mean - exact_mean) < 0.2 * np.linalg.norm(linear_mean - exact_mean)


# -- kappa -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", range(1, 10))
def test_default_kappa_rule(n):
    assert default_kappa(n) == max(3 - n, 0)
    points, weights = sigma_points(np.zeros(n), np.eye(n))
    assert points.shape == (2 * n + 1, n)
    assert weights[0] >= 0.0  # the centre weight is never negative with the default
    assert weights.sum() == pytest.approx(1.0, abs=1e-12)
    k = max(3 - n, 0)
    assert weights[0] == pytest.approx(k / (k + n))
    np.testing.assert_allclose(weights[1:], 1.0 / (2 * (k + n)))


@pytest.mark.parametrize("n", [1, 2, 3])
def test_default_kappa_matches_gaussian_fourth_moment(n):
    """Julier's rationale for ``kappa = 3 - n``: the sigma points reproduce ``E[x_i^4] = 3 sigma_i^4``."""
    sd = np.array([0.5, 2.0, 1.3])[:n]
    points, weights = sigma_points(np.ones(n), np.diag(sd**2))
    d = points - 1.0
    np.testing.assert_allclose(weights @ d**4, 3 * sd**4, rtol=1e-12)
    np.testing.assert_allclose(weights @ d**2, sd**2, rtol=1e-12)


@SETTINGS
@given(linear_problems())
def test_sigma_points_reproduce_mean_and_covariance(problem):
    mu, P, _, _, kappa = problem
    points, weights = sigma_points(mu, P, kappa)
    np.testing.assert_allclose(weights @ points, mu, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(mu).max()))
    d = points - mu
    np.testing.assert_allclose((weights[:, None] * d).T @ d, P, rtol=1e-9, atol=1e-9 * np.abs(P).max())


@pytest.mark.parametrize(("n", "kappa"), [(1, -1.0), (3, -3.0), (3, -5.0), (2, -2.5)])
def test_kappa_making_kappa_plus_n_non_positive_raises(n, kappa):
    with pytest.raises(ValueError, match="kappa \\+ n must be positive"):
        sigma_points(np.zeros(n), np.eye(n), kappa)
    with pytest.raises(ValueError, match="kappa \\+ n must be positive"):
        unscented_transform(lambda x: x, np.zeros(n), np.eye(n), kappa)


def test_negative_kappa_above_minus_n_is_allowed():
    points, weights = sigma_points(np.zeros(3), np.eye(3), kappa=-1.0)
    assert weights[0] == pytest.approx(-0.5)
    assert weights.sum() == pytest.approx(1.0)
