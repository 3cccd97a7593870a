"""Feature following (spec 003 Eqs. 10-17): the offset path, the pointing residual against a 3-D rotation,
the optimiser against closed forms and brute force, and the vector-field set-points flown by the fixed wing."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from agent.vehicles.base import goal_to_setpoint
from agent.vehicles.fixed_wing import FixedWingModel
from perception.rotations import rot_x
from tasking.feature_following import (
    FlightPathLimits,
    PathFollower,
    centring_gimbal_angle,
    in_image,
    lateral_los_angle,
    offset_path,
    optimise_flight_path,
    pointing_residual,
)
from tasking.feature_path import (
    GRAVITY,
    PolynomialPath,
    bank_angle,
    curvature,
    fit_feature,
    lateral_acceleration,
    roll_rate,
    signed_curvature,
)


def arc_feature(radius: float, degrees: float = 180.0, points: int = 13) -> np.ndarray:
    """A clockwise (right-turning) arc about (0, radius), starting at the origin heading north."""
    a = np.radians(np.linspace(0.0, degrees, points))
    return np.stack([radius * np.sin(a), radius * (1 - np.cos(a))], axis=1)


def exact_arc(radius: float, degrees: float, pieces: int = 12) -> PolynomialPath:
    """The same arc with exact knot conditions (p, p', p'' of the circle, τ = arc length)."""
    tau = np.linspace(0.0, math.radians(degrees) * radius, pieces + 1)
    a = tau / radius
    cond = np.zeros((tau.size, 3, 3))
    cond[:, 0, :2] = np.stack([radius * np.sin(a), radius * (1 - np.cos(a))], axis=1)
    cond[:, 1, :2] = np.stack([np.cos(a), np.sin(a)], axis=1)
    cond[:, 2, :2] = np.stack([-np.sin(a), np.cos(a)], axis=1) / radius
    return PolynomialPath.from_knot_conditions(tau, cond)


ROAD = np.array([[0, 0], [300, 50], [600, -50], [900, 100], [1200, 300], [1400, 600]], dtype=float)


def test_offset_of_a_straight_feature_is_the_parallel_line():
    feature = fit_feature([[0.0, 0.0], [500.0, 0.0]])
    path = offset_path(feature, -40.0, -150.0)  # 40 m left (west) of a northbound feature, 150 m up
    tau = np.linspace(0, 500, 51)
    np.testing.assert_allclose(path.position(tau), np.stack([tau, np.full(51, -40.0), np.full(51, -150.0)], 1),
                               atol=1e-9)


def test_offset_inside_an_arc_is_the_smaller_concentric_arc():
    radius, d = 500.0, 120.0  # offset to the right = inside of a right turn
    feature = exact_arc(radius, 180.0)
    path = offset_path(feature, d, -100.0)
    tau = np.linspace(0.0, feature.tau_f, 400)
    r = np.linalg.norm(path.position(tau)[:, :2] - [0.0, radius], axis=1)
    np.testing.assert_allclose(r, radius - d, rtol=1e-6)
    np.testing.assert_allclose(signed_curvature(path, tau), 1 / (radius - d), rtol=1e-4)


def test_offset_beyond_the_turn_radius_is_a_cusp():
    feature = fit_feature(arc_feature(100.0, 90.0, 7))
    with pytest.raises(ValueError, match="cusp"):
        offset_path(feature, 150.0, -100.0)  # 150 m inside a 100 m radius turn


def test_los_angle_closed_form():
    feature = fit_feature([[0.0, 0.0], [500.0, 0.0]])
    for d, h in ((-50.0, 100.0), (80.0, 200.0), (0.0, 120.0)):
        path = offset_path(feature, d, -h)
        np.testing.assert_allclose(lateral_los_angle(path, feature, [0.0, 250.0, 500.0]), math.atan2(-d, h))


@settings(max_examples=60, deadline=None)
@given(
    bank=st.floats(-0.6, 0.6),
    gimbal=st.floats(-1.2, 1.2),
    los=st.floats(-1.3, 1.3),
)
def test_residual_is_the_angle_between_optical_axis_and_line_of_sight(bank, gimbal, los):
    """Oracle: rotate the body-frame optical axis (lateral gimbal angle from body down) by the roll and
    measure the angle to the LOS of a feature abeam, in 3-D."""
    axis_world = rot_x(bank) @ np.array([0.0, math.sin(gimbal), math.cos(gimbal)])
    los_world = np.array([0.0, math.sin(los), math.cos(los)])
    angle = math.acos(np.clip(axis_world @ los_world, -1.0, 1.0))
    residual = pointing_residual(los, bank, gimbal)
    assert abs(residual) == pytest.approx(angle, abs=1e-6)
    assert abs(pointing_residual(los, bank, centring_gimbal_angle(los, bank))) < 1e-12  # Eq. 12 solved
    assert bool(in_image(residual, math.radians(30))) == (angle < math.radians(15))  # Eq. 13


def test_straight_feature_gets_the_smallest_offset_inside_the_look_range():
    """Wide gimbal range: ε = 0 for many offsets; the tie-break takes the smallest |d|, where the LOS sits on the
    10° edge of the look range: d = -h tan 10° (feature on the right, no bank on a straight line)."""
    h = 200.0
    flight = optimise_flight_path(fit_feature([[0.0, 0.0], [800.0, 0.0]]), h)
    assert flight.epsilon < 1e-9
    assert flight.offset == pytest.approx(-h * math.tan(math.radians(10.0)), abs=1.0)  # fine grid step: 1 m


def test_fixed_camera_on_an_arc_matches_the_closed_form_offset():
    """Fixed camera at φ_c from body down: centred iff λ + φ = φ_c, with λ = atan(-d/h) and
    φ = atan(v² / (g (R - d))) on an arc of radius R. Solved by brentq for the fastest speed (the tie-break
    favours small |d|, which a steeper bank allows)."""
    radius, h, phi_c = 600.0, 200.0, math.radians(25.0)
    feature = exact_arc(radius, 120.0)
    limits = FlightPathLimits(look_range=(phi_c, phi_c))
    flight = optimise_flight_path(feature, h, limits, speeds=3, spacing=20.0)
    v = flight.speed
    assert v == pytest.approx(limits.speed_range[1])

    def centring(d):
        return math.atan2(-d, h) + math.atan(v * v / (GRAVITY * (radius - d))) - phi_c

    d_star = brentq(centring, -300.0, 0.0)
    assert flight.offset == pytest.approx(d_star, abs=2.5)
    assert flight.epsilon < math.radians(0.5)


def test_optimum_meets_the_constraints_on_a_finer_grid_and_beats_brute_force():
    limits = FlightPathLimits(look_range=(math.radians(15.0), math.radians(15.0)))  # a fixed camera: ε > 0
    feature = fit_feature(ROAD)
    flight = optimise_flight_path(feature, 250.0, limits, speeds=3, offsets=21, spacing=20.0)
    tau = feature.sample_tau(2.0)
    path, v = flight.uav_path, flight.speed
    assert np.all(np.abs(bank_angle(path, tau, v)) <= limits.max_bank + 1e-3)
    assert np.all(np.abs(roll_rate(path, tau, v)) <= limits.max_roll_rate * 1.05)
    assert np.all(lateral_acceleration(path, tau, v) <= limits.max_acceleration * 1.05)
    assert flight.epsilon < 0.5 * limits.field_of_view
    np.testing.assert_allclose(flight.lateral_acceleration, v * v * curvature(path, flight.tau), rtol=1e-9, atol=1e-12)
    # brute force over a grid the optimiser did not use: no flyable (v, d) has a smaller ε
    for d in np.linspace(-300, 300, 13):
        try:
            candidate = offset_path(feature, d, -250.0)
        except ValueError:  # a cusp inside a turn
            continue
        for speed in (15.0, 20.0, 25.0):
            bank = bank_angle(candidate, flight.tau, speed)
            flyable = (
                np.all(np.abs(bank) <= limits.max_bank)
                and np.all(np.abs(roll_rate(candidate, flight.tau, speed)) <= limits.max_roll_rate)
                and np.all(lateral_acceleration(candidate, flight.tau, speed) <= limits.max_acceleration)
            )
            lam = lateral_los_angle(candidate, feature, flight.tau)
            eps = np.max(np.abs(pointing_residual(lam, bank, limits.look_range[0])))
            assert not flyable or eps >= flight.epsilon - 1e-9


def test_infeasible_problems_raise():
    tight = fit_feature(arc_feature(25.0, 180.0, 13))  # a 25 m radius turn needs > 35° of bank at 15 m/s
    with pytest.raises(ValueError, match="no flyable path"):
        optimise_flight_path(tight, 100.0, speeds=2, offsets=5)
    with pytest.raises(ValueError, match="altitude"):
        optimise_flight_path(fit_feature(ROAD), -10.0)  # below the feature
    with pytest.raises(ValueError, match="speed_range"):
        FlightPathLimits(speed_range=(25.0, 15.0))  # v_min > v_max
    with pytest.raises(ValueError, match="look_range"):
        FlightPathLimits(look_range=(0.0, math.radians(95.0)))  # looking above the horizon


@pytest.fixture(scope="module")
def road_flight():
    return optimise_flight_path(fit_feature(ROAD), 200.0, speeds=3, offsets=21, spacing=20.0)


def test_follower_geometry(road_flight):
    follower = PathFollower(road_flight)
    path = road_flight.uav_path
    for tau in (10.0, 500.0, 1200.0):
        p = path.position(tau)
        assert follower.closest_tau(p) == pytest.approx(tau, abs=1e-6)
        tangent = path.derivative(tau, 1)[:2] / np.linalg.norm(path.derivative(tau, 1)[:2])
        right = np.array([-tangent[1], tangent[0]])
        assert follower.cross_track_error(p + [*(30 * right), 0.0]) == pytest.approx(30.0, abs=0.5)
        goal = follower.goal(p)
        ahead = (goal.position[:2] - p[:2]) / follower.carrot_distance
        assert ahead @ tangent == pytest.approx(1.0, abs=1e-6)  # on the path: straight along it
        off_right = follower.goal(p + [*(50 * right), 0.0]).position[:2] - (p[:2] + 50 * right)
        assert off_right @ right < 0  # right of the path: steer left
        np.testing.assert_allclose(follower.feature_point(p), road_flight.feature.position(tau), atol=1e-6)
    end = follower.goal(path.position(path.tau_f))
    assert end.is_orbit and end.orbit_radius == follower.loiter_radius
    goals = follower.setpoints(100.0)
    assert len(goals) == math.ceil(path.tau_f / 100.0) + 1 and goals[0].speed == road_flight.speed
    with pytest.raises(ValueError, match="finite"):
        follower.goal([math.nan, 0.0, -200.0])  # NaN vehicle position


def test_fixed_wing_flies_the_path_within_a_few_metres(road_flight):
    """Closed loop: the agent's fixed-wing model fed the follower's goals at 5 Hz holds the path."""
    follower = PathFollower(road_flight)
    path = road_flight.uav_path
    start = path.position(0.0)
    tangent = path.derivative(0.0, 1)
    vehicle = FixedWingModel(start, heading=math.atan2(tangent[1], tangent[0]), airspeed=road_flight.speed)
    errors = []
    while not follower.finished(vehicle.state().position):
        vehicle.set_setpoint(goal_to_setpoint(follower.goal(vehicle.state().position)))
        vehicle.step(0.2)
        errors.append(abs(follower.cross_track_error(vehicle.state().position)))
        assert len(errors) < 2000
    assert np.mean(errors) < 3.0 and np.max(errors) < 10.0
