"""The multirotor model: hard limits, arrival without overshoot, speed limit, attitude, orbit convergence."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.vehicles.base import Setpoint, wrap_angle
from agent.vehicles.multirotor import MultirotorModel
from tests.agent.vehicles.flights import LIMIT_EXAMPLES, TOL, agent_steps, fly, plans


@LIMIT_EXAMPLES
@given(
    plan=plans,
    dt=agent_steps,
    max_speed=st.floats(1.0, 20.0),
    max_accel=st.floats(0.5, 8.0),
    max_climb=st.floats(0.5, 5.0),
    yaw_rate_deg=st.floats(10.0, 180.0),
)
def test_multirotor_limits_never_exceeded(plan, dt, max_speed, max_accel, max_climb, yaw_rate_deg):
    vehicle = MultirotorModel([10.0, -5.0, -20.0], max_speed, max_accel, max_climb, math.radians(yaw_rate_deg))
    states = fly(vehicle, plan, dt)
    for before, after in zip(states, states[1:], strict=False):
        assert after.t == pytest.approx(before.t + dt)
        assert np.linalg.norm(after.velocity) <= max_speed + TOL
        assert abs(after.velocity[2]) <= max_climb + TOL
        assert np.linalg.norm(after.velocity - before.velocity) / dt <= max_accel + TOL
        assert abs(wrap_angle(after.yaw - before.yaw)) / dt <= math.radians(yaw_rate_deg) + TOL
        assert np.all(np.isfinite(after.position))
        # attitude comes from an acceleration of at most max_accel
        assert abs(after.roll) <= math.atan(max_accel / 9.80665) + TOL
        assert abs(after.pitch) <= math.atan(max_accel / 9.80665) + TOL


@pytest.mark.parametrize(
    "start, target",
    [
        ((0.0, 0.0, 0.0), (100.0, 0.0, -20.0)),
        ((0.0, 0.0, 0.0), (0.0, 0.0, -30.0)),
        ((10.0, 10.0, -5.0), (14.0, 13.0, -6.0)),
        ((0.0, 0.0, -10.0), (-200.0, 150.0, -60.0)),
        ((0.0, 0.0, -10.0), (0.3, 0.0, -10.0)),
    ],
)
def test_multirotor_reaches_setpoint_and_stops_without_overshoot(start, target):
    start, target = np.array(start), np.array(target)
    vehicle = MultirotorModel(start)
    vehicle.set_setpoint(Setpoint(target))
    direction = (target - start) / np.linalg.norm(target - start)
    overshoot = -np.inf
    for _ in range(600):  # 120 s
        vehicle.step(0.2)
        state = vehicle.state()
        overshoot = max(overshoot, float((state.position - target) @ direction))
    assert overshoot <= 0.01  # never past the point along the approach line
    assert np.linalg.norm(state.position - target) < 0.05
    assert np.linalg.norm(state.velocity) < 0.05
    # it flew a straight line: the lateral deviation stays tiny
    assert np.linalg.norm(np.cross(state.position - start, direction)) < 0.05


def test_multirotor_respects_setpoint_speed_limit_and_yaws_along_velocity():
    vehicle = MultirotorModel([0.0, 0.0, -10.0])
    vehicle.set_setpoint(Setpoint([0.0, 300.0, -10.0], speed=4.0))
    for _ in range(100):
        vehicle.step(0.2)
        assert np.linalg.norm(vehicle.state().velocity) <= 4.0 + TOL
    state = vehicle.state()
    assert state.yaw == pytest.approx(math.pi / 2)  # heading east
    assert np.linalg.norm(state.velocity) == pytest.approx(4.0)


def test_multirotor_attitude_signs():
    # accelerating north from rest with yaw north: nose down (negative pitch), no roll
    vehicle = MultirotorModel([0.0, 0.0, -10.0])
    vehicle.set_setpoint(Setpoint([100.0, 0.0, -10.0]))
    vehicle.step(0.1)
    state = vehicle.state()
    assert state.pitch == pytest.approx(-math.atan(3.0 / 9.80665))
    assert state.roll == pytest.approx(0.0, abs=1e-12)
    # same acceleration with the vehicle yawed east: it is a leftward acceleration, left wing down
    vehicle = MultirotorModel([0.0, 0.0, -10.0], initial_yaw=math.pi / 2)
    vehicle.set_setpoint(Setpoint([100.0, 0.0, -10.0]))
    vehicle.step(0.02)  # one sub-step: horizontal speed still below the yaw threshold
    state = vehicle.state()
    assert state.roll == pytest.approx(-math.atan(3.0 / 9.80665))
    assert state.pitch == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("radius, direction", [(5.0, 1), (15.0, -1), (60.0, 1)])
def test_multirotor_converges_onto_orbit(radius, direction):
    center = np.array([60.0, -40.0])
    vehicle = MultirotorModel([0.0, 0.0, 0.0])
    vehicle.set_setpoint(Setpoint([0.0, 0.0, -20.0], orbit=(center, radius, direction)))
    errors, spins = [], []
    for _ in range(600):
        vehicle.step(0.2)
        state = vehicle.state()
        rel = state.position[:2] - center
        errors.append(np.hypot(*rel) - radius)
        spins.append(rel[0] * state.velocity[1] - rel[1] * state.velocity[0])
    assert np.max(np.abs(errors[-150:])) < 0.5
    assert np.all(np.sign(spins[-150:]) == direction)  # +1: clockwise from above
    assert state.position[2] == pytest.approx(-20.0, abs=0.01)


def test_multirotor_holds_its_initial_position():
    vehicle = MultirotorModel([3.0, 4.0, -5.0])
    for _ in range(50):
        vehicle.step(0.2)
    state = vehicle.state()
    np.testing.assert_allclose(state.position, [3.0, 4.0, -5.0])
    np.testing.assert_allclose(state.velocity, 0.0)


def test_multirotor_constructor_errors():
    with pytest.raises(ValueError, match="initial_position"):
        MultirotorModel([0.0, 0.0])
    with pytest.raises(ValueError, match="max_accel"):
        MultirotorModel([0.0, 0.0, 0.0], max_accel=0.0)


@pytest.mark.parametrize("orbit", [False, True])
def test_velocity_feed_forward_removes_the_lag_behind_a_moving_point(orbit):
    """A point (or an orbit centre) moving north at 5 m/s: with its velocity as feed-forward the vehicle holds
    it within one step's motion (the guidance acts in the moving frame); without, a position loop trails it by metres
    (its approach speed min(k d, sqrt(2 a_dec d)) reaches 5 m/s only d = 8.3 m behind)."""
    def trail(feed_forward):
        vehicle = MultirotorModel([0.0, 0.0, -30.0], max_speed=12.0, max_accel=3.0)
        for k in range(300):
            t = 0.1 * k
            centre = np.array([5.0 * t, 0.0])
            ff = (5.0, 0.0) if feed_forward else None
            if orbit:
                setpoint = Setpoint([*centre, -30.0], orbit=(centre, 20.0, 1), velocity=ff)
            else:
                setpoint = Setpoint([*centre, -30.0], velocity=ff)
            vehicle.set_setpoint(setpoint)
            vehicle.step(0.1)
        offset = vehicle.state().position[:2] - np.array([5.0 * 30.0, 0.0])
        return abs(np.hypot(*offset) - (20.0 if orbit else 0.0))

    assert trail(True) < 0.5  # within what the point moves in one 0.1 s step
    assert trail(False) > 3.0


def test_feed_forward_never_breaks_the_speed_limit():
    vehicle = MultirotorModel([0.0, 0.0, -30.0], max_speed=8.0, max_accel=3.0)
    vehicle.set_setpoint(Setpoint([100.0, 0.0, -60.0], velocity=(25.0, 0.0)))
    for _ in range(100):
        vehicle.step(0.2)
        assert np.linalg.norm(vehicle.state().velocity) <= 8.0 + 1e-9
