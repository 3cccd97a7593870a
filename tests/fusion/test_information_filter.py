"""The information filter against filterpy's Kalman filter, and the motion models against independent
closed forms, numerical quadrature and a Monte Carlo simulation of the SDE (Merino Alg. 3.1-3.2, (3.58)-(3.59))."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
from filterpy.kalman import KalmanFilter

from fusion import information_filter as inf
from fusion.gaussian import Gaussian
from fusion.measurement import PositionMeasurement
from fusion.motion import ConstantVelocity, Singer, Static, van_loan


def random_spd(rng, n, ridge=0.1):
    A = rng.normal(size=(n, n))
    return A @ A.T + ridge * np.eye(n)


def rel_err(actual, expected):
    return float(np.linalg.norm(np.asarray(actual) - expected) / np.linalg.norm(expected))


# -- IF == KF on random linear-Gaussian problems --------------------------------------------------
def _linear_problem(seed, model_kind, spatial_dims):
    rng = np.random.default_rng(seed)
    dt = float(rng.uniform(0.1, 2.0))
    if model_kind == "cv":
        model = ConstantVelocity(spatial_dims=spatial_dims, q=float(rng.uniform(0.01, 2.0)))
    else:
        alpha, sigma_m = float(rng.uniform(0.05, 1.0)), float(rng.uniform(0.2, 2))
        model = Singer(spatial_dims=spatial_dims, alpha=alpha, sigma_m=sigma_m)
    n = model.dim
    R = random_spd(rng, spatial_dims, ridge=0.05)
    meas = PositionMeasurement(n, R, spatial_dims=spatial_dims)
    x0 = rng.normal(size=n) * 5
    P0 = random_spd(rng, n, ridge=0.5)
    return rng, dt, model, meas, x0, P0


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("spatial_dims", [2, 3])
@pytest.mark.parametrize("model_kind", ["cv", "singer"])
def test_information_filter_matches_filterpy_kalman(seed, spatial_dims, model_kind):
    rng, dt, model, meas, x0, P0 = _linear_problem(seed, model_kind, spatial_dims)
    n, m = model.dim, spatial_dims
    F, Q = model.transition(dt), model.noise(dt)

    kf = KalmanFilter(dim_x=n, dim_z=m)
    kf.x, kf.P = x0.copy(), P0.copy()
    kf.F, kf.Q, kf.H, kf.R = F, Q, meas.H, meas.R
    belief = Gaussian.from_moments(x0, P0)

    truth = x0 + np.linalg.cholesky(P0) @ rng.normal(size=n)
    for step in range(20):
        truth = F @ truth + np.linalg.cholesky(Q + 1e-15 * np.eye(n)) @ rng.normal(size=n)
        kf.predict()
        belief = inf.predict(belief, model, dt)
        if step % 4 != 3:  # every fourth step has no measurement
            z = truth[:m] + np.linalg.cholesky(meas.R) @ rng.normal(size=m)
            kf.update(z)
            belief = inf.update(belief, meas, z)
        assert rel_err(belief.mean, kf.x) < 1e-9, step
        assert rel_err(belief.cov, kf.P) < 1e-9, step


def test_update_hand_checked_scalar():
    """Prior N(0, 4), measurement z = 2 with R = 4: posterior N(1, 2)."""
    post = inf.update(Gaussian.from_moments([0.0, 0.0], np.diag([4.0, 1.0])), PositionMeasurement(2, [[4.0]], 1), [2.0])
    np.testing.assert_allclose(post.mean, [1.0, 0.0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(post.cov, np.diag([2.0, 1.0]), rtol=1e-12, atol=1e-15)


# -- special cases of prediction -------------------------------------------------------------------
def test_static_prediction_leaves_belief_unchanged():
    rng = np.random.default_rng(0)
    g = Gaussian.from_moments(rng.normal(size=3), random_spd(rng, 3))
    p = inf.predict(g, Static(3), 7.5)
    np.testing.assert_allclose(p.Y, g.Y, rtol=1e-12)
    np.testing.assert_allclose(p.y, g.y, rtol=1e-12)


def test_zero_noise_cv_prediction_is_pure_transition():
    rng = np.random.default_rng(1)
    mu, P = rng.normal(size=4), random_spd(rng, 4)
    p = inf.predict(Gaussian.from_moments(mu, P), ConstantVelocity(2, q=0.0), 1.5)
    F = np.array([[1, 0, 1.5, 0], [0, 1, 0, 1.5], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    np.testing.assert_allclose(p.mean, F @ mu, rtol=1e-9)
    np.testing.assert_allclose(p.cov, F @ P @ F.T, rtol=1e-9)


@pytest.mark.parametrize("model", [ConstantVelocity(3, q=0.5), Singer(2, alpha=0.3, sigma_m=1.0), Static(4)])
def test_prediction_of_zero_information_stays_zero(model):
    p = inf.predict(Gaussian.zeros(model.dim), model, 2.0)
    assert not p.has_information
    np.testing.assert_array_equal(p.Y, 0.0)
    np.testing.assert_array_equal(p.y, 0.0)


def test_prediction_of_partial_information_keeps_rank():
    """Information on position only stays rank-deficient: velocity is still unobserved after prediction."""
    g = Gaussian.from_info([1.0, 0.0], [[2.0, 0.0], [0.0, 0.0]])
    p = inf.predict(g, ConstantVelocity(1, q=0.3), 1.0)
    assert np.linalg.matrix_rank(p.Y, tol=1e-12) == 1
    np.testing.assert_allclose(p.Y, p.Y.T, atol=0)


# -- motion models against independent discretisations --------------------------------------------
def _quadrature_noise(A, Qc, dt):
    """``Q = int_0^dt expm(A s) Qc expm(A s)^T ds`` by adaptive quadrature."""
    integrand = lambda s: scipy.linalg.expm(A * s) @ Qc @ scipy.linalg.expm(A * s).T  # noqa: E731
    Q, _ = scipy.integrate.quad_vec(integrand, 0.0, dt, epsabs=1e-13, epsrel=1e-11)
    return Q


@pytest.mark.parametrize("dt", [0.05, 0.7, 3.0])
@pytest.mark.parametrize("spatial_dims", [1, 2, 3])
def test_cv_matches_van_loan_and_quadrature(dt, spatial_dims):
    q = 0.37
    model = ConstantVelocity(spatial_dims, q=q)
    A = np.kron(np.array([[0.0, 1.0], [0.0, 0.0]]), np.eye(spatial_dims))
    Qc = np.kron(np.diag([0.0, q]), np.eye(spatial_dims))
    F_vl, Q_vl = van_loan(A, Qc, dt)
    np.testing.assert_allclose(model.transition(dt), F_vl, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(model.noise(dt), Q_vl, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(model.noise(dt), _quadrature_noise(A, Qc, dt), rtol=1e-8, atol=1e-15)
    np.testing.assert_allclose(model.transition(dt), scipy.linalg.expm(A * dt), rtol=1e-12, atol=1e-14)


def test_cv_state_ordering_hand_checked():
    """Positions first, then velocities (Merino (3.54)): x' = x + dt v."""
    F = ConstantVelocity(2).transition(2.0)
    np.testing.assert_allclose(F @ [1.0, 2.0, 3.0, 4.0], [7.0, 10.0, 3.0, 4.0])
    np.testing.assert_allclose(F @ ConstantVelocity(2).inverse_transition(2.0), np.eye(4), atol=1e-15)


def _singer_F_closed_form(alpha, T):
    """Singer (1970) transition per axis."""
    e = np.exp(-alpha * T)
    return np.array(
        [[1.0, T, (alpha * T - 1.0 + e) / alpha**2], [0.0, 1.0, (1.0 - e) / alpha], [0.0, 0.0, e]]
    )


@pytest.mark.parametrize(
    ("alpha", "sigma_m", "dt"),
    [(0.1, 1.0, 1.0), (0.8, 2.5, 0.4), (2.0, 0.5, 3.0), (1.0, 1.0, 25.0), (5.0, 0.3, 12.0), (0.2, 1.0, 100.0)],
)
def test_singer_against_closed_form_and_quadrature(alpha, sigma_m, dt):
    """Includes long steps (``alpha dt`` up to 60) such as a prediction across a communication outage."""
    model = Singer(2, alpha=alpha, sigma_m=sigma_m)
    F1 = _singer_F_closed_form(alpha, dt)
    np.testing.assert_allclose(model.transition(dt), np.kron(F1, np.eye(2)), rtol=1e-10, atol=1e-14)
    if alpha * dt < 5:  # beyond that F^-1 has entries ~e^{alpha dt} and the product loses digits
        np.testing.assert_allclose(model.transition(dt) @ model.inverse_transition(dt), np.eye(6), atol=1e-10)
    # Q = int_0^dt F(s) b b^T F(s)^T ds * 2 alpha sigma^2 with the closed-form F(s) (independent of expm)
    q = 2.0 * alpha * sigma_m**2
    Q1, _ = scipy.integrate.quad_vec(
        lambda s: q * np.outer(_singer_F_closed_form(alpha, s)[:, 2], _singer_F_closed_form(alpha, s)[:, 2]),
        0.0, dt, epsabs=1e-14, epsrel=1e-11, limit=2000,
    )
    np.testing.assert_allclose(model.noise(dt), np.kron(Q1, np.eye(2)), rtol=1e-8, atol=1e-14)
    assert np.linalg.eigvalsh(model.noise(dt))[0] > 0


def test_singer_noise_by_euler_maruyama_monte_carlo():
    """Simulate ``da = -alpha a dt + sqrt(2 alpha) sigma dW`` from rest; the sample covariance of
    (p, v, a) after ``dt`` must match ``Q(dt)`` within the statistical tolerance."""
    alpha, sigma_m, dt = 0.5, 1.5, 2.0
    rng = np.random.default_rng(42)
    samples, steps = 40_000, 400
    h = dt / steps
    p = np.zeros(samples)
    v = np.zeros(samples)
    a = np.zeros(samples)
    for _ in range(steps):
        dW = rng.normal(scale=np.sqrt(h), size=samples)
        p += v * h + 0.5 * a * h * h
        v += a * h
        a += -alpha * a * h + np.sqrt(2 * alpha) * sigma_m * dW
    X = np.stack([p, v, a])
    S = X @ X.T / samples
    Q = Singer(1, alpha=alpha, sigma_m=sigma_m).noise(dt)
    # compare as correlations and relative variances: ~1/sqrt(N) = 0.5 % statistical error, ~0.5 % bias
    d = np.sqrt(np.diag(Q))
    np.testing.assert_allclose(np.diag(S) / np.diag(Q), 1.0, atol=0.04)
    np.testing.assert_allclose(S / np.outer(d, d), Q / np.outer(d, d), atol=0.03)


def test_singer_approaches_constant_acceleration_for_small_alpha():
    dt = 1.7
    F_ca = np.array([[1.0, dt, dt**2 / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    for alpha, tol in ((1e-3, 2e-3), (1e-6, 2e-6)):
        F = Singer(1, alpha=alpha, sigma_m=1.0).transition(dt)
        np.testing.assert_allclose(F, F_ca, atol=tol)
    # and the difference shrinks with alpha: the limit is approached, not coincidentally close
    e3 = np.abs(Singer(1, alpha=1e-3).transition(dt) - F_ca).max()
    e1 = np.abs(Singer(1, alpha=1e-1).transition(dt) - F_ca).max()
    assert e3 < e1 / 50


def test_singer_stationary_acceleration_variance():
    """For long steps the acceleration forgets its start: Var(a) -> sigma_m^2, F[a, a] -> 0."""
    model = Singer(1, alpha=2.0, sigma_m=1.3)
    assert model.noise(50.0)[2, 2] == pytest.approx(1.3**2, rel=1e-9)
    # and the velocity grows like a random walk with intensity 2 sigma^2 / alpha (for alpha T >> 1)
    assert model.noise(50.0)[1, 1] == pytest.approx(2 * 1.3**2 / 2.0 * 50.0 - 3 * 1.3**2 / 2.0**2, rel=1e-9)
    assert model.transition(50.0)[2, 2] == pytest.approx(0.0, abs=1e-12)


def test_van_loan_scalar_ou_closed_form():
    """``dx = -a x dt + dW``, ``E dW^2 = q dt``: F = e^{-a dt}, Q = q (1 - e^{-2 a dt}) / (2 a)."""
    a, q, dt = 0.7, 2.0, 1.3
    F, Q = van_loan(np.array([[-a]]), np.array([[q]]), dt)
    assert F[0, 0] == pytest.approx(np.exp(-a * dt), rel=1e-12)
    assert Q[0, 0] == pytest.approx(q * (1 - np.exp(-2 * a * dt)) / (2 * a), rel=1e-10)
