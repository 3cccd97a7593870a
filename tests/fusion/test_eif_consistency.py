"""Consistency of the extended information filter with bearing measurements (Monte Carlo ANEES against
the chi-square bounds, DESIGN.md §2), and the trajectory (delayed-state) filter against a plain Kalman
filter (filterpy) and against an independently assembled batch information solution (Merino §3.1.3)."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.stats import chi2

from fusion import information_filter as inf
from fusion.gaussian import Gaussian
from fusion.measurement import Bearing2D, Bearing3D, PositionMeasurement
from fusion.motion import ConstantVelocity, Static
from fusion.trajectory import Trajectory, TrajectoryModel

RUNS = 300


def anees_bounds(runs: int, dim: int) -> tuple[float, float]:
    """Two-sided 95 % interval of the average NEES of ``runs`` consistent estimates of a ``dim``-D state."""
    return chi2.ppf(0.025, runs * dim) / runs, chi2.ppf(0.975, runs * dim) / runs


SENSORS_3D = np.array([[-80.0, -60.0, -60.0], [90.0, -40.0, -50.0], [0.0, 100.0, -70.0], [-60.0, 80.0, -40.0]])
SENSORS_2D = np.array([[-80.0, -60.0], [90.0, -40.0], [0.0, 100.0], [-60.0, 80.0]])


def monte_carlo_nees(make_model, truth, sensors, sigma, filter_sigma, prior_std, steps, seed):
    """Average final NEES of a static-target EIF over ``RUNS`` runs.

    Measurements are simulated with noise ``sigma``; the filter is told ``filter_sigma``."""
    rng = np.random.default_rng(seed)
    d = truth.size
    truth_models = [make_model(s, sigma) for s in sensors]
    filter_models = [make_model(s, filter_sigma) for s in sensors]
    motion = Static(d)
    P0 = np.eye(d) * prior_std**2
    total = 0.0
    for _ in range(RUNS):
        belief = Gaussian.from_moments(truth + rng.normal(size=d) * prior_std, P0)  # a consistent broad prior
        for _ in range(steps):
            belief = inf.predict(belief, motion, 1.0)
            for true_model, model in zip(truth_models, filter_models, strict=True):
                z = true_model.h(truth) + rng.normal(size=true_model.dim) * sigma
                belief = inf.eif_update(belief, model, z)
        total += belief.nees(truth)
    return total / RUNS


def bearing3d(sensor, sigma):
    return Bearing3D(3, sensor, np.eye(2) * sigma**2)


def bearing2d(sensor, sigma):
    return Bearing2D(2, sensor, sigma)


# Fixed seeds: the test is deterministic. Each ANEES check is a 95 % test, so an arbitrary seed fails
# one time in twenty even for a perfect filter; the counter-checks below show the tests have power.
@pytest.mark.parametrize("n_sensors", [2, 3, 4])
def test_eif_bearing3d_static_target_anees(n_sensors):
    truth = np.array([10.0, -20.0, 0.0])
    anees = monte_carlo_nees(bearing3d, truth, SENSORS_3D[:n_sensors], 1e-2, 1e-2, 3.0, steps=5, seed=2)
    lo, hi = anees_bounds(RUNS, 3)
    assert lo < anees < hi, (anees, lo, hi)


@pytest.mark.parametrize("n_sensors", [2, 3, 4])
def test_eif_bearing2d_static_target_anees(n_sensors):
    truth = np.array([10.0, -20.0])
    anees = monte_carlo_nees(bearing2d, truth, SENSORS_2D[:n_sensors], 1e-2, 1e-2, 3.0, steps=5, seed=2)
    lo, hi = anees_bounds(RUNS, 2)
    assert lo < anees < hi, (anees, lo, hi)


@pytest.mark.parametrize(("make_model", "truth", "sensors"), [
    (bearing3d, np.array([10.0, -20.0, 0.0]), SENSORS_3D[:3]),
    (bearing2d, np.array([10.0, -20.0]), SENSORS_2D[:3]),
])
def test_anees_check_detects_mis_specified_noise(make_model, truth, sensors):
    """Counter-check: a filter that believes the bearings are twice as accurate fails the same test."""
    anees = monte_carlo_nees(make_model, truth, sensors, 1e-2, 0.5e-2, 3.0, steps=5, seed=2)
    assert anees > anees_bounds(RUNS, truth.size)[1]
    anees = monte_carlo_nees(make_model, truth, sensors, 1e-2, 2e-2, 3.0, steps=5, seed=2)
    assert anees < anees_bounds(RUNS, truth.size)[0]


# -- trajectory filter ---------------------------------------------------------------------------------
def _cv_setup(seed, spatial_dims=2, window=4):
    rng = np.random.default_rng(seed)
    step = float(rng.uniform(0.2, 1.5))
    motion = ConstantVelocity(spatial_dims, q=float(rng.uniform(0.05, 1.0)))
    model = TrajectoryModel(motion, step, window)
    A = rng.normal(size=(spatial_dims, spatial_dims))
    R = A @ A.T + 0.2 * np.eye(spatial_dims)
    meas = PositionMeasurement(motion.dim, R, spatial_dims)
    return rng, motion, model, meas


def _simulate(rng, motion, step, meas, count):
    F, Q = motion.transition(step), motion.noise(step)
    x = np.concatenate([rng.normal(size=motion.spatial_dims) * 10, rng.normal(size=motion.spatial_dims)])
    states, zs = [], []
    for _ in range(count):
        states.append(x)
        zs.append(meas.h(x) + np.linalg.cholesky(meas.R) @ rng.normal(size=meas.dim))
        x = F @ x + np.linalg.cholesky(Q) @ rng.normal(size=x.size)
    return states, zs


def _rel(actual, expected):
    return float(np.linalg.norm(np.asarray(actual) - expected) / np.linalg.norm(expected))


@pytest.mark.parametrize("window", [2, 3, 5, 8])
@pytest.mark.parametrize("spatial_dims", [2, 3])
def test_trajectory_newest_marginal_matches_kalman_filter(window, spatial_dims):
    rng, motion, model, meas = _cv_setup(window * 10 + spatial_dims, spatial_dims, window)
    _, zs = _simulate(rng, motion, model.step, meas, 30)
    traj = Trajectory.prior(model, epoch=0).update(meas.H, meas.R_inv, zs[0])
    traj = traj.advanced_to(1).update(meas.H, meas.R_inv, zs[1])

    # independent check of the start: p(x_1 | z_0, z_1) under a flat prior, by weighted least squares
    F, Q = motion.transition(model.step), motion.noise(model.step)
    start = traj.current()
    kf_start = _two_measurement_posterior(F, Q, meas.H, meas.R, zs[0], zs[1])
    assert _rel(start.cov, kf_start[1]) < 1e-8
    assert _rel(start.mean, kf_start[0]) < 1e-8

    kf = KalmanFilter(dim_x=motion.dim, dim_z=meas.dim)
    kf.x, kf.P = start.mean.copy(), start.cov.copy()
    kf.F, kf.Q, kf.H, kf.R = F, Q, meas.H, meas.R
    for k in range(2, 30):
        traj = traj.advanced_to(k)
        kf.predict()
        if k % 5 != 0:  # some epochs without a measurement
            traj = traj.update(meas.H, meas.R_inv, zs[k])
            kf.update(zs[k])
        current = traj.current()
        assert _rel(current.mean, kf.x) < 1e-9, k
        assert _rel(current.cov, kf.P) < 1e-9, k


def _two_measurement_posterior(F, Q, H, R, z0, z1):
    """``p(x_1 | z_0, z_1)`` for ``x_1 = F x_0 + w``: ``x_0 = F^-1 (x_1 - w)``, so
    ``z_0 = H F^-1 x_1 + (v_0 - H F^-1 w)`` and ``z_1 = H x_1 + v_1`` — a generalised least-squares problem."""
    Fi = np.linalg.inv(F)
    G = np.vstack([H @ Fi, H])
    m = H.shape[0]
    C = np.zeros((2 * m, 2 * m))
    C[:m, :m] = R + H @ Fi @ Q @ Fi.T @ H.T
    C[m:, m:] = R
    Ci = np.linalg.inv(C)
    P = np.linalg.inv(G.T @ Ci @ G)
    return P @ G.T @ Ci @ np.concatenate([z0, z1]), P


def _batch_solution(F, Q, H, R, first_epoch, last_epoch, measurements):
    """Joint Gaussian over all states ``first_epoch..last_epoch``, assembled factor by factor."""
    n = F.shape[0]
    count = last_epoch - first_epoch + 1
    Y = np.zeros((n * count, n * count))
    y = np.zeros(n * count)
    Qi, Ri = np.linalg.inv(Q), np.linalg.inv(R)
    for k in range(1, count):  # residual x_k - F x_{k-1} = J [x_{k-1}; x_k] with J = [-F, I]
        J = np.hstack([-F, np.eye(n)])
        sl = slice((k - 1) * n, (k + 1) * n)
        Y[sl, sl] += J.T @ Qi @ J
    for epoch, z in measurements:
        sl = slice((epoch - first_epoch) * n, (epoch - first_epoch + 1) * n)
        Y[sl, sl] += H.T @ Ri @ H
        y[sl] += H.T @ Ri @ z
    P = np.linalg.inv(Y)
    return P @ y, P


@pytest.mark.parametrize("seed", range(6))
def test_trajectory_late_measurements_match_batch_solution(seed):
    """Measurements applied late (``offset > 0``), in arbitrary order, give the marginal over the window
    of the batch solution built from all the factors."""
    window = 5
    rng, motion, model, meas = _cv_setup(500 + seed, 2, window)
    last = 14
    _, zs = _simulate(rng, motion, model.step, meas, last + 1)
    traj = Trajectory.prior(model, epoch=0)
    applied = []
    pending = list(range(last + 1))
    for k in range(last + 1):
        traj = traj.advanced_to(k)
        # deliver a random subset of the measurements of the states still inside the window
        for epoch in [e for e in pending if k - window < e <= k]:
            if rng.random() < 0.5 or epoch in (0, 1):
                offset = k - epoch
                if rng.random() < 0.5:
                    traj = traj.update(meas.H, meas.R_inv, zs[epoch], offset=offset)
                else:  # the EIF update of a linear model is exact at any linearisation point
                    traj = traj.eif_update(meas, zs[epoch], offset=offset, linearization_point=rng.normal(size=4))
                applied.append((epoch, zs[epoch]))
                pending.remove(epoch)
        pending = [e for e in pending if e > k - window + 1]  # the rest falls out of the window: lost
    assert any(k - e > 0 for e, _ in applied)  # the scenario really contains late data
    mu, P = _batch_solution(motion.transition(model.step), motion.noise(model.step), meas.H, meas.R,
                            -(window - 1), last, applied)
    n = motion.dim
    P_win, mu_win = P[-window * n :, -window * n :], mu[-window * n :]
    assert _rel(np.linalg.inv(traj.Y), P_win) < 1e-7
    assert _rel(np.linalg.solve(traj.Y, traj.y), mu_win) < 1e-7
    for offset in range(window):
        block = slice((window - 1 - offset) * n, (window - offset) * n)
        assert _rel(traj.state(offset).cov, P_win[block, block]) < 1e-7
        assert _rel(traj.state(offset).mean, mu_win[block]) < 1e-7


def test_trajectory_measurement_order_does_not_matter():
    """Late delivery of a measurement gives the same belief as on-time delivery (batch oracle aside)."""
    rng, motion, model, meas = _cv_setup(77, 2, 4)
    _, zs = _simulate(rng, motion, model.step, meas, 6)
    on_time = Trajectory.prior(model, 0)
    late = Trajectory.prior(model, 0)
    for k in range(6):
        on_time = on_time.advanced_to(k).update(meas.H, meas.R_inv, zs[k])
        late = late.advanced_to(k)
        if k >= 2:
            late = late.update(meas.H, meas.R_inv, zs[k - 2], offset=2)
    late = late.update(meas.H, meas.R_inv, zs[4], offset=1).update(meas.H, meas.R_inv, zs[5], offset=0)
    assert _rel(late.Y, on_time.Y) < 1e-9
    assert _rel(late.y, on_time.y) < 1e-9
