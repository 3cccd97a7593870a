"""The cascaded navigation filter (spec 003 Eqs. 18-39) and its χ² fault test (Eqs. 40-44): the DCM against
perception's rotations, the Jacobian against finite differences, each filter against filterpy's Kalman filter,
NEES by Monte Carlo, the gate against scipy, false alarms on clean data and isolation of a faulty GPS."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import binom, chi2

from agent.vehicles.base import GRAVITY as AGENT_GRAVITY
from fusion.navigation import (
    GRAVITY,
    GpsFaultIsolation,
    NavigationFilter,
    NavigationNoise,
    dcm_from_quaternion,
    dcm_jacobian,
)
from fusion.navigation_faults import InnovationTest, SensorMonitor, chi2_gate, innovation_test
from perception.rotations import quaternion_from_euler, rotation_from_quaternion

NOISE = NavigationNoise.from_std(attitude=math.radians(2.0), speed=1.0, cross_speed=0.3, specific_force=0.1)
R_GPS = 1.5**2 * np.eye(3)
R_VEL = 0.2**2 * np.eye(3)
DT = 0.1
CHOL = {name: np.linalg.cholesky(m) for name, m in (
    ("q", NOISE.quaternion), ("v", NOISE.body_velocity), ("f", NOISE.specific_force), ("gps", R_GPS), ("vel", R_VEL))}


@settings(max_examples=50, deadline=None)
@given(st.tuples(*[st.floats(-1, 1)] * 4).filter(lambda q: np.linalg.norm(q) > 0.1))
def test_dcm_is_perceptions_rotation_for_unit_quaternions(q):
    q = np.asarray(q) / np.linalg.norm(q)
    np.testing.assert_allclose(dcm_from_quaternion(q), rotation_from_quaternion(q), atol=1e-12)


def test_dcm_jacobian_matches_finite_differences():
    rng = np.random.default_rng(3)
    q, x, dt, h = rng.normal(size=4), rng.normal(size=3) * 10, 0.05, 1e-6
    F2 = dcm_jacobian(q, x, dt)
    assert F2.shape == (3, 7)
    u = np.concatenate([q, x])
    for j in range(7):
        du = np.zeros(7)
        du[j] = h
        plus = dt * dcm_from_quaternion((u + du)[:4]) @ (u + du)[4:]
        minus = dt * dcm_from_quaternion((u - du)[:4]) @ (u - du)[4:]
        np.testing.assert_allclose(F2[:, j], (plus - minus) / (2 * h), rtol=1e-6, atol=1e-9)


def test_gravity_is_the_vehicle_models():
    assert GRAVITY == AGENT_GRAVITY


TURN = quaternion_from_euler(0.1, 0.02, 0.02 * np.arange(400))  # a slow right turn, 10 Hz steps


class Truth:
    """A level turn at 20 m/s simulated with the filter's own model, noise drawn from its covariances: the
    filter's inputs are the truth plus N(0, 𝒫_q), N(0, 𝒫_v), N(0, 𝒫_a) errors; GPS adds N(0, R)."""

    def __init__(self, rng: np.random.Generator, position=(0.0, 0.0, -100.0)):
        self.normal = lambda key: CHOL[key] @ rng.standard_normal(CHOL[key].shape[0])
        self.p = np.array(position, dtype=float)
        self.v = np.array([20.0, 0.0, 0.0])
        self.k = 0

    def step(self):
        """Advance one DT; return the filter inputs ``(q̂, V, f̂^b)``."""
        q = TURN[self.k]
        v_body = np.array([20.0, 0.0, 0.0]) + self.normal("v")
        f_body = np.array([0.0, 1.0, -GRAVITY])
        self.p = self.p + DT * dcm_from_quaternion(q) @ v_body
        self.v = self.v + DT * dcm_from_quaternion(q) @ f_body + [0.0, 0.0, GRAVITY * DT]
        self.k += 1
        return q + self.normal("q"), 20.0, f_body + self.normal("f")

    def gps(self, bias=0.0):
        return self.p + bias + self.normal("gps"), self.v + self.normal("vel")


def new_filter(truth: Truth, rng, **kwargs) -> NavigationFilter:
    P0p, P0v = 4.0 * np.eye(3), 0.25 * np.eye(3)
    return NavigationFilter(truth.p + rng.multivariate_normal(np.zeros(3), P0p), P0p,
                            truth.v + rng.multivariate_normal(np.zeros(3), P0v), P0v, NOISE, **kwargs)


def test_position_and_velocity_filters_equal_filterpys_kalman_filter():
    """Oracle: the standard KF with F = I, control input u = Δt C(q̂) x (+ g Δt), Q = F_2 𝒫 F_2ᵀ, H = I."""
    rng = np.random.default_rng(7)
    truth = Truth(rng)
    nav = new_filter(truth, rng)
    oracles = {}
    for name in ("position", "velocity"):
        kf = KalmanFilter(dim_x=3, dim_z=3)
        kf.x, kf.P, kf.F, kf.H = getattr(nav, name).copy(), getattr(nav, f"{name}_cov").copy(), np.eye(3), np.eye(3)
        oracles[name] = kf
    for k in range(60):
        q, V, f = truth.step()
        C = rotation_from_quaternion(q) * np.dot(q, q)  # the filter's DCM is not normalised
        F2p = dcm_jacobian(q, [V, 0, 0], DT)
        F2v = dcm_jacobian(q, f, DT)
        oracles["position"].predict(u=DT * C @ [V, 0, 0], B=np.eye(3), Q=F2p @ NOISE.position_inputs @ F2p.T)
        oracles["velocity"].predict(u=DT * C @ f + [0, 0, GRAVITY * DT], B=np.eye(3),
                                    Q=F2v @ NOISE.velocity_inputs @ F2v.T)
        nav.predict(q, V, f, DT)
        if k % 5 == 4:
            zp, zv = truth.gps()
            oracles["position"].update(zp, R=R_GPS)
            oracles["velocity"].update(zv, R=R_VEL)
            nav.update_position(zp, R_GPS)
            nav.update_velocity(zv, R_VEL)
        for name, kf in oracles.items():
            np.testing.assert_allclose(getattr(nav, name), kf.x, rtol=1e-10, atol=1e-9)
            np.testing.assert_allclose(getattr(nav, f"{name}_cov"), kf.P, rtol=1e-9, atol=1e-12)


def test_nees_is_consistent_by_monte_carlo():
    """Average NEES over 80 runs at two epochs lies within the two-sided 99 % χ² bounds (3 dof per run)."""
    runs, steps, ds = 80, 80, 10
    checkpoints = (39, 79)  # just after a GPS epoch
    nees = {name: np.zeros((runs, len(checkpoints))) for name in ("position", "velocity")}
    for run in range(runs):
        rng = np.random.default_rng(1000 + run)
        truth = Truth(rng)
        nav = new_filter(truth, rng)
        for k in range(steps):
            nav.predict(*truth.step(), DT)
            if k % ds == ds - 1:
                zp, zv = truth.gps()
                nav.update_position(zp, R_GPS)
                nav.update_velocity(zv, R_VEL)
            if k in checkpoints:
                i = checkpoints.index(k)
                for name, true in (("position", truth.p), ("velocity", truth.v)):
                    e = true - getattr(nav, name)
                    nees[name][run, i] = e @ np.linalg.solve(getattr(nav, f"{name}_cov"), e)
    lo, hi = chi2.ppf(0.005, 3 * runs) / runs, chi2.ppf(0.995, 3 * runs) / runs
    for name, values in nees.items():
        anees = values.mean(axis=0)
        assert np.all((lo < anees) & (anees < hi)), (name, anees, lo, hi)


def test_eq38_velocity_covariance_is_the_papers_heuristic():
    rng = np.random.default_rng(0)
    truth = Truth(rng)
    nav = new_filter(truth, rng, velocity_covariance="eq38")
    q, V, f = truth.step()
    nav.predict(q, V, f, DT)
    F2 = dcm_jacobian(q, [V, 0, 0], DT)
    expected = F2 @ (NOISE.position_inputs + DT * NOISE.velocity_inputs) @ F2.T / DT
    np.testing.assert_allclose(nav.velocity_cov, expected, rtol=1e-12)


@pytest.mark.parametrize("dim", [1, 2, 3, 6])
@pytest.mark.parametrize("probability", [0.95, 0.99, 0.999])
def test_gate_is_the_chi2_quantile_per_dimension(dim, probability):
    assert chi2_gate(dim, probability) == pytest.approx(chi2.ppf(probability, dim) / dim, rel=1e-12)


def test_gate_for_a_gps_fix_matches_the_hand_value():
    assert chi2_gate(3, 0.99) == pytest.approx(11.345 / 3, abs=1e-3)  # spec 003 §2.8: 11.34 / 3


def test_innovation_statistics():
    nu, S = np.array([1.0, -2.0, 0.5]), np.diag([1.0, 4.0, 0.25])
    test = innovation_test(nu, S)
    assert test.d2 == pytest.approx(1.0 + 1.0 + 1.0)  # Eq. 43
    assert test.chi2 == pytest.approx(1.0)  # Eq. 44
    assert test.log_likelihood == pytest.approx(-1.5)  # log of Eq. 40


def run_clean(seed: int, epochs: int, monitor: SensorMonitor) -> NavigationFilter:
    rng = np.random.default_rng(seed)
    truth = Truth(rng)
    nav = new_filter(truth, rng)
    for k in range(epochs):
        truth.k %= len(TURN)
        nav.predict(*truth.step(), DT)
        nav.update_position(truth.gps()[0], R_GPS, monitor, t=k * DT)
    return nav


def test_false_alarms_on_clean_data_are_at_the_nominal_rate():
    """A consistent filter's innovations are white with covariance P^νν: the 99 % gate rejects 1 % of good data
    (within binomial 99.9 % bounds), and 3-of-5 isolation never trips."""
    monitor = SensorMonitor("gps", 3, probability=0.99)
    run_clean(11, 2000, monitor)
    lo, hi = binom.ppf(0.0005, monitor.data, 0.01), binom.ppf(0.9995, monitor.data, 0.01)
    assert monitor.data == 2000 and lo <= monitor.rejections <= hi, monitor.rejections
    assert not monitor.isolated


def run_receivers(seed: int, bias_of, scheme: str, steps: int = 400, fault_step: int = 100, receivers: str = "AB"):
    """GPS ``receivers`` at 5 Hz (every other 10 Hz step); receiver A carries ``bias_of(t - t_fault)`` from
    ``fault_step`` on. ``scheme``: "none" (no test), "gate" (Eq. 44 against the one filter, one monitor per
    receiver) or "bank" (:class:`GpsFaultIsolation`). Returns the monitors and the position errors."""
    rng = np.random.default_rng(seed)
    truth = Truth(rng)
    nav = new_filter(truth, rng)
    bank = GpsFaultIsolation(nav, receivers) if scheme == "bank" else None
    monitors = bank.monitors if bank else {name: SensorMonitor(name, 3) if scheme == "gate" else None
                                           for name in receivers}
    errors = []
    for k in range(steps):
        (bank or nav).predict(*truth.step(), DT)
        t = (k + 1) * DT
        if k % 2 == 1:
            bias = bias_of(t - fault_step * DT) if k >= fault_step else np.zeros(3)
            for name in receivers:
                z = truth.gps(bias if name == "A" else 0.0)[0]
                if bank:
                    bank.update_position(name, z, R_GPS, t)
                else:
                    nav.update_position(z, R_GPS, monitors[name], t)
        errors.append(np.linalg.norm(truth.p - nav.position))
    return monitors, np.array(errors)


@pytest.mark.parametrize("scheme", ["gate", "bank"])
def test_step_bias_is_isolated_within_three_epochs_and_the_filter_continues_on_the_other_receiver(scheme):
    """A 15 m (10 σ) north step on receiver A: d² ≈ 15²/(1.5² + P) ≫ 11.3, so every faulty datum fails and the
    3-of-5 rule isolates A by its third faulty epoch (two 0.2 s GPS periods after the first). B stays in use."""
    step = lambda _dt: np.array([15.0, 0.0, 0.0])  # noqa: E731
    for seed in range(3):
        monitors, errors = run_receivers(seed, step, scheme, steps=200)
        a, b = monitors["A"], monitors["B"]
        first_faulty_epoch = 10.2  # the fault starts at step 100; GPS data at t = 10.2, 10.4, ...
        # at the third faulty epoch at the latest (earlier if a false alarm is still in the 5-datum window)
        assert first_faulty_epoch - 1e-9 <= a.isolated_at <= first_faulty_epoch + 2 * 0.2 + 1e-9
        assert not b.isolated
        assert np.max(errors[110:]) < 3.0  # GPS σ 1.5 m, averaged: the fix never follows the fault
        _, ungated = run_receivers(seed, step, "none", steps=200)
        assert np.mean(ungated[150:]) > 5.0  # without the test the filter sits about halfway to the bias


def test_drift_on_the_only_receiver_is_isolated_against_dead_reckoning():
    """A 0.5 m/s north drift on the only receiver. Its reference is dead reckoning, whose covariance grows, so the
    gate is crossed later (16-29 s here) and the filter keeps the part of the drift it took in; but it stops
    following it, unlike the filter without the test, which ends ~17 m off."""
    drift = lambda dt: np.array([0.5 * dt, 0.0, 0.0])  # noqa: E731
    for seed in range(2):
        monitors, errors = run_receivers(seed, drift, "bank", fault_step=50, receivers="A")
        _, ungated = run_receivers(seed, drift, "none", fault_step=50, receivers="A")
        assert monitors["A"].isolated and monitors["A"].isolated_at - 5.0 < 30.0, seed
        assert np.mean(errors[-50:]) < 0.75 * np.mean(ungated[-50:]) and np.mean(ungated[-50:]) > 15.0, seed


def test_drift_is_isolated_by_the_observer_bank_with_three_receivers():
    """A 0.5 m/s north drift on A of A, B, C. Tested against the filter fed by B and C, A's innovation is the whole
    drift and crosses the gate (d² > 11.3: about 5-6 m) after roughly 10 s; B and C, each tested against a
    filter that A feeds only in part, are not blamed, and the fix stays at the healthy receivers' accuracy."""
    drift = lambda dt: np.array([0.5 * dt, 0.0, 0.0])  # noqa: E731
    delays = []
    for seed in range(3):
        monitors, errors = run_receivers(seed, drift, "bank", steps=250, fault_step=50, receivers="ABC")
        assert monitors["A"].isolated and not (monitors["B"].isolated or monitors["C"].isolated), seed
        delays.append(monitors["A"].isolated_at - 5.0)
        assert np.max(errors[50:]) < 2.5, seed
    assert 5.0 < np.mean(delays) < 15.0, delays


def test_observer_bank_rejects_unknown_receivers():
    nav = NavigationFilter(np.zeros(3), np.eye(3), np.zeros(3), np.eye(3))
    with pytest.raises(ValueError, match="distinct"):
        GpsFaultIsolation(nav, ["A", "A"])  # the same receiver twice
    with pytest.raises(ValueError, match="unknown receiver"):
        GpsFaultIsolation(nav, ["A"]).update_position("C", np.zeros(3), R_GPS, 0.0)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda nav: nav.predict([0.0, 0.0, 0.0, math.nan], 20.0, [0, 0, -9.8], 0.1), "non-finite"),  # NaN attitude
        (lambda nav: nav.predict([0.0, 0.0, 0.0, 0.0], 20.0, [0, 0, -9.8], 0.1), "quaternion is zero"),
        (lambda nav: nav.predict([0.0, 0.0, 0.0, 1.0], 20.0, [0, 0, -9.8], -0.1), "dt must be a positive"),
        (lambda nav: nav.predict([0.0, 0.0, 0.0, 1.0], math.inf, [0, 0, -9.8], 0.1), "speed must be finite"),
        (lambda nav: nav.update_position([0.0, 0.0], R_GPS), "length 3"),  # a 2-D GPS fix
        (lambda nav: nav.update_position([0.0, 0.0, math.nan], R_GPS), "non-finite"),  # NaN GPS fix
        (lambda nav: nav.update_velocity([0.0, 0.0, 0.0], -R_VEL), "not positive definite"),  # negative noise
    ],
)
def test_bad_inputs_raise(call, message):
    nav = NavigationFilter(np.zeros(3), np.eye(3), np.zeros(3), np.eye(3))
    with pytest.raises(ValueError, match=message):
        call(nav)


def test_bad_configuration_raises():
    with pytest.raises(ValueError, match="velocity_covariance"):
        NavigationFilter(np.zeros(3), np.eye(3), np.zeros(3), np.eye(3), velocity_covariance="eq36")
    with pytest.raises(ValueError, match="attitude standard deviation"):
        NavigationNoise.from_std(attitude=0.0)
    with pytest.raises(ValueError, match="gate probability"):
        chi2_gate(3, 1.0)
    with pytest.raises(ValueError, match="k <= n"):
        SensorMonitor("gps", 3, k=6, n=5)
    with pytest.raises(ValueError, match="3-D data"):
        SensorMonitor("gps", 3).admit(InnovationTest(1.0, 2), 0.0)  # a 2-D innovation for a 3-D sensor
