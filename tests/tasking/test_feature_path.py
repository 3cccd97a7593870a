"""Feature paths (spec 003 Eqs. 1-9): the Eq.-2 solver, the piecewise fit of a polyline, and curvature, bank,
roll rate and lateral acceleration against closed forms, finite differences and scipy's spline."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import CubicSpline

from agent.vehicles.base import GRAVITY as AGENT_GRAVITY
from tasking.feature_path import (
    GRAVITY,
    PolynomialPath,
    bank_angle,
    boundary_matrix,
    boundary_polynomial,
    curvature,
    fit_feature,
    lateral_acceleration,
    roll_rate,
    signed_curvature,
    unit_tangent,
)


def circle_path(radius: float, clockwise: bool = True, pieces: int = 24) -> PolynomialPath:
    """A full circle of ``radius`` about the origin, parametrised by arc length (knot conditions exact)."""
    tau = np.linspace(0.0, 2 * math.pi * radius, pieces + 1)
    a = tau / radius
    s = -1 if clockwise else 1  # from the south point, clockwise (seen from above) heads west
    cond = np.zeros((tau.size, 3, 3))
    cond[:, 0, :2] = radius * np.stack([-np.cos(a), s * np.sin(a)], axis=1)
    cond[:, 1, :2] = np.stack([np.sin(a), s * np.cos(a)], axis=1)
    cond[:, 2, :2] = np.stack([np.cos(a), -s * np.sin(a)], axis=1) / radius
    return PolynomialPath.from_knot_conditions(tau, cond)


def test_eq2_matrix_is_the_corrected_quintic_system():
    tf = 2.5
    expected = np.array([
        [1, 0, 0, 0, 0, 0],
        [0, 1, 0, 0, 0, 0],
        [0, 0, 2, 0, 0, 0],
        [1, tf, tf**2, tf**3, tf**4, tf**5],
        [0, 1, 2 * tf, 3 * tf**2, 4 * tf**3, 5 * tf**4],
        [0, 0, 2, 6 * tf, 12 * tf**2, 20 * tf**3],
    ])
    np.testing.assert_allclose(boundary_matrix(tf, 2, 2), expected)


@settings(max_examples=40, deadline=None)
@given(
    tf=st.floats(0.1, 50.0),
    n0=st.integers(0, 3),
    nf=st.integers(0, 3),
    seed=st.integers(0, 2**31),
)
def test_boundary_polynomial_meets_its_conditions(tf, n0, nf, seed):
    rng = np.random.default_rng(seed)
    start, end = rng.normal(size=(n0 + 1, 2)), rng.normal(size=(nf + 1, 2))
    coef = boundary_polynomial(tf, start, end)
    assert coef.shape == (2, n0 + nf + 2)  # minimum degree N* = N0 + Nf + 1
    for axis in range(2):
        poly = np.polynomial.Polynomial(coef[axis])
        for r in range(n0 + 1):
            assert poly.deriv(r)(0.0) == pytest.approx(start[r, axis], abs=1e-7 * (1 + tf**5))
        for r in range(nf + 1):
            assert poly.deriv(r)(tf) == pytest.approx(end[r, axis], rel=1e-6, abs=1e-6)


def test_fit_equals_scipys_natural_cubic_spline_and_interpolates_the_points():
    pts = np.array([[0.0, 0.0], [100.0, 30.0], [180.0, 120.0], [200.0, 260.0], [320.0, 300.0]])
    path = fit_feature(pts, down=-5.0)
    chord = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    np.testing.assert_allclose(path.knots, chord)
    np.testing.assert_allclose(path.position(chord)[:, :2], pts, atol=1e-9)
    spline = CubicSpline(chord, pts, bc_type="natural")
    tau = np.linspace(0, path.tau_f, 301)
    for r in range(3):
        np.testing.assert_allclose(path.derivative(tau, r)[:, :2], spline(tau, r), atol=1e-7)
    np.testing.assert_allclose(path.position(tau)[:, 2], -5.0)
    np.testing.assert_allclose(path.derivative(tau, 1)[:, 2], 0.0)


def test_two_points_give_the_straight_segment():
    path = fit_feature([[0.0, 0.0], [30.0, 40.0]])
    assert path.tau_f == pytest.approx(50.0)
    np.testing.assert_allclose(path.position(25.0), [15.0, 20.0, 0.0])
    np.testing.assert_allclose(curvature(path, np.linspace(0, 50, 11)), 0.0, atol=1e-12)


def test_circle_curvature_bank_and_acceleration_closed_forms():
    r, v = 250.0, 20.0
    tau = np.linspace(0.0, 2 * math.pi * r, 97)
    for clockwise, sign in ((True, 1.0), (False, -1.0)):
        path = circle_path(r, clockwise)
        np.testing.assert_allclose(curvature(path, tau), 1 / r, rtol=1e-4)  # κ = 1/r (Eq. 3)
        np.testing.assert_allclose(signed_curvature(path, tau), sign / r, rtol=1e-4)
        np.testing.assert_allclose(bank_angle(path, tau, v), sign * math.atan(v * v / (GRAVITY * r)), rtol=1e-4)
        np.testing.assert_allclose(lateral_acceleration(path, tau, v), v * v / r, rtol=1e-4)  # a = v²/r
        np.testing.assert_allclose(roll_rate(path, tau, v), 0.0, atol=1e-5)  # constant bank


def test_right_turn_is_positive_bank():
    """North then east is a right (clockwise) turn: positive curvature and bank (right wing down)."""
    path = fit_feature([[0.0, 0.0], [200.0, 0.0], [300.0, 100.0], [300.0, 300.0]])
    assert signed_curvature(path, path.tau_f / 2) > 0
    assert bank_angle(path, path.tau_f / 2, 18.0) > 0


def test_curvature_equals_finite_difference_of_the_tangent():
    path = fit_feature([[0.0, 0.0], [120.0, 50.0], [150.0, 200.0], [260.0, 240.0]], down=-100.0)
    tau = np.linspace(5.0, path.tau_f - 5.0, 40)
    h = 1e-4
    dT = (unit_tangent(path, tau + h) - unit_tangent(path, tau - h)) / (2 * h)
    norm = np.linalg.norm(path.derivative(tau, 1), axis=1)
    np.testing.assert_allclose(curvature(path, tau), np.linalg.norm(dT, axis=1) / norm, rtol=1e-5, atol=1e-9)


def test_roll_rate_equals_finite_difference_of_bank():
    path = fit_feature([[0.0, 0.0], [120.0, 50.0], [150.0, 200.0], [260.0, 240.0]])
    tau = np.linspace(5.0, path.tau_f - 5.0, 40)
    v, h = 22.0, 1e-4
    dphi = (bank_angle(path, tau + h, v) - bank_angle(path, tau - h, v)) / (2 * h)
    expected = dphi * v / np.linalg.norm(path.derivative(tau, 1), axis=1)  # Eq. 7
    np.testing.assert_allclose(roll_rate(path, tau, v), expected, rtol=1e-5, atol=1e-9)


def test_gravity_is_the_vehicle_models_gravity():
    assert GRAVITY == AGENT_GRAVITY


@pytest.mark.parametrize(
    ("points", "message"),
    [
        ([[0.0, 0.0]], "at least 2 points"),  # a single point is no path
        ([], "must be \\(N, 2\\)"),  # no points at all
        ([[0.0, 0.0], [10.0, 0.0], [10.0, 0.0], [20.0, 5.0]], "repeats point 1"),  # repeated consecutive point
        ([[0.0, 0.0], [math.nan, 1.0]], "non-finite"),  # NaN coordinate
        ([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], "must be \\(N, 2\\)"),  # 3-D points instead of (north, east)
    ],
)
def test_bad_polylines_raise(points, message):
    with pytest.raises(ValueError, match=message):
        fit_feature(points)


def test_bad_tau_and_speed_raise():
    path = fit_feature([[0.0, 0.0], [100.0, 0.0]])
    with pytest.raises(ValueError, match="tau must lie in"):
        path.position([100.5])  # beyond τ_f
    with pytest.raises(ValueError, match="tau must be"):
        path.position(-1.0)  # before the start
    with pytest.raises(ValueError, match="finite"):
        path.position(math.nan)  # NaN τ, one point
    with pytest.raises(ValueError, match="non-finite"):
        path.position([1.0, math.nan])  # NaN τ in an array
    with pytest.raises(ValueError, match="speed must be positive"):
        bank_angle(path, 10.0, 0.0)  # a stalled aircraft
    with pytest.raises(ValueError, match="order"):
        path.derivative(1.0, 4)
    with pytest.raises(ValueError, match="tau_f must be positive"):
        boundary_polynomial(0.0, np.zeros((3, 1)), np.zeros((3, 1)))  # zero-length segment
