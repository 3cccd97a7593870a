"""Kinematic vehicle models: hard limits, arrival without overshoot, orbit convergence, config errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.vehicles.kinematic import (
    FixedWingModel,
    MultirotorModel,
    Setpoint,
    Vehicle,
    VehicleState,
    goal_to_setpoint,
    vehicle_from_config,
    wrap_angle,
)
from tasking.orbit import goto_goal, orbit_setpoint
from tasking.planner import PlaceholderPlanner
from tasking.search import lawnmower_waypoints

TOL = 1e-9

coord = st.floats(-300.0, 300.0)
depth = st.floats(-150.0, 0.0)


@st.composite
def setpoints(draw, min_radius: float = 1.0):
    position = np.array([draw(coord), draw(coord), draw(depth)])
    speed = draw(st.none() | st.floats(0.5, 30.0))
    orbit = None
    if draw(st.booleans()):
        orbit = (
            np.array([draw(coord), draw(coord)]),
            draw(st.floats(min_radius, 200.0)),
            draw(st.sampled_from([1, -1])),
        )
    duration = draw(st.integers(1, 40))
    return Setpoint(position, speed=speed, orbit=orbit), duration


def fly(vehicle, plan, dt):
    """Fly ``plan`` [(setpoint, steps)] and return the list of states (initial included)."""
    states = [vehicle.state()]
    for setpoint, steps in plan:
        vehicle.set_setpoint(setpoint)
        for _ in range(steps):
            vehicle.step(dt)
            states.append(vehicle.state())
    return states


@settings(max_examples=40, deadline=None)
@given(
    plan=st.lists(setpoints(), min_size=1, max_size=5),
    dt=st.sampled_from([0.05, 0.2, 0.5, 1.0]),
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


@settings(max_examples=40, deadline=None)
@given(
    plan=st.lists(setpoints(), min_size=1, max_size=5),
    dt=st.sampled_from([0.05, 0.2, 0.5, 1.0]),
    airspeed=st.floats(8.0, 40.0),
    max_bank_deg=st.floats(10.0, 60.0),
    climb_rate=st.floats(0.5, 6.0),
)
def test_fixed_wing_limits_never_exceeded(plan, dt, airspeed, max_bank_deg, climb_rate):
    vehicle = FixedWingModel([0.0, 0.0, -50.0], 0.3, airspeed, math.radians(max_bank_deg), climb_rate)
    max_turn = 9.80665 * math.tan(math.radians(max_bank_deg)) / airspeed
    assert vehicle.max_turn_rate == pytest.approx(max_turn)
    states = fly(vehicle, plan, dt)
    for before, after in zip(states, states[1:], strict=False):
        assert np.linalg.norm(after.velocity) == pytest.approx(airspeed)
        assert abs(after.velocity[2]) <= climb_rate + TOL
        assert abs(after.roll) <= math.radians(max_bank_deg) + TOL
        # |turn| per step <= max_turn * dt < pi, so the wrapped difference is the true turn
        assert abs(wrap_angle(after.yaw - before.yaw)) / dt <= max_turn * (1 + 1e-9) + TOL
        # the velocity points along the heading (no wind)
        assert math.atan2(after.velocity[1], after.velocity[0]) == pytest.approx(after.yaw, abs=1e-9)


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


@pytest.mark.parametrize("radius_factor", [1.0, 1.5, 3.0])
@pytest.mark.parametrize("start, heading, direction", [((0.0, 0.0, -50.0), 1.0, -1), ((400.0, -300.0, -90.0), -2.0, 1)])
def test_fixed_wing_converges_onto_orbit_of_requested_radius(radius_factor, start, heading, direction):
    vehicle = FixedWingModel(start, heading)
    radius = radius_factor * vehicle.min_turn_radius
    center = np.array([100.0, 50.0])
    vehicle.set_setpoint(Setpoint([0.0, 0.0, -60.0], orbit=(center, radius, direction)))
    errors, spins = [], []
    for _ in range(1500):  # 300 s
        vehicle.step(0.2)
        state = vehicle.state()
        rel = state.position[:2] - center
        errors.append(np.hypot(*rel) - radius)
        spins.append(rel[0] * state.velocity[1] - rel[1] * state.velocity[0])
    late = np.abs(errors[-300:])  # the last minute
    assert late.max() < 0.5, late.max()
    assert np.all(np.sign(spins[-300:]) == direction)
    assert state.position[2] == pytest.approx(-60.0, abs=0.01)


def test_fixed_wing_loiters_around_position_setpoint_and_clamps_small_orbits():
    vehicle = FixedWingModel([0.0, 0.0, -40.0], 0.0)
    target = np.array([-300.0, 200.0, -70.0])
    vehicle.set_setpoint(Setpoint(target))
    closest = np.inf
    for _ in range(1500):
        vehicle.step(0.2)
        closest = min(closest, np.hypot(*(vehicle.state().position[:2] - target[:2])))
    assert closest < 2.0  # it overflies the point first (a search waypoint is really visited)
    rel = vehicle.state().position[:2] - target[:2]
    assert np.hypot(*rel) == pytest.approx(vehicle.loiter_radius, abs=0.5)
    # re-sending the same setpoint every cycle does not restart the approach
    vehicle.set_setpoint(Setpoint(target))
    vehicle.step(10.0)
    rel = vehicle.state().position[:2] - target[:2]
    assert np.hypot(*rel) == pytest.approx(vehicle.loiter_radius, abs=0.5)
    assert vehicle.loiter_radius >= vehicle.min_turn_radius
    # an orbit tighter than the aircraft can fly is flown at the minimum turning radius
    vehicle.set_setpoint(Setpoint(target, orbit=(target[:2], 5.0, 1)))
    for _ in range(1500):
        vehicle.step(0.2)
    rel = vehicle.state().position[:2] - target[:2]
    assert np.hypot(*rel) == pytest.approx(vehicle.min_turn_radius, abs=0.5)


@pytest.mark.parametrize("config", [{"kind": "multirotor", "max_speed": 12.0}, {"kind": "fixed_wing"}])
def test_vehicles_fly_a_lawnmower_lane_through_the_planner(config):
    area = (0.0, 600.0, 0.0, 600.0)
    vehicle = vehicle_from_config(config, [-50.0, -50.0, 0.0], 0.0)
    planner = PlaceholderPlanner(0, 2, area, altitude=60.0, spacing=80.0)  # accepts at 40 m
    path = lawnmower_waypoints(area, 80.0, 60.0, lane_index=0, lanes=2)
    positions = []
    for _ in range(2000):  # 400 s
        state = vehicle.state()
        positions.append(state.position)
        vehicle.set_setpoint(goal_to_setpoint(planner.plan(state.position, [])))
        vehicle.step(0.2)
    positions = np.array(positions)
    closest = [np.min(np.linalg.norm(positions[:, :2] - waypoint[:2], axis=1)) for waypoint in path]
    assert max(closest) < planner.acceptance_radius  # every waypoint of the lane was visited
    assert np.all(np.abs(positions[-500:, 2] + 60.0) < 0.5)


def test_vehicles_follow_the_protocol_and_report_time():
    for vehicle in (MultirotorModel([0.0, 0.0, -5.0]), FixedWingModel([0.0, 0.0, -5.0], 0.0)):
        assert isinstance(vehicle, Vehicle)
        state = vehicle.state()
        assert isinstance(state, VehicleState) and state.t == 0.0
        vehicle.step(0.0)
        vehicle.step(0.3)
        vehicle.step(0.2)
        assert vehicle.state().t == pytest.approx(0.5)
        with pytest.raises(ValueError, match="dt"):
            vehicle.step(-0.1)
        with pytest.raises(ValueError, match="dt"):
            vehicle.step(float("nan"))
        with pytest.raises(TypeError):
            vehicle.set_setpoint((1.0, 2.0, 3.0))


def test_multirotor_holds_its_initial_position():
    vehicle = MultirotorModel([3.0, 4.0, -5.0])
    for _ in range(50):
        vehicle.step(0.2)
    state = vehicle.state()
    np.testing.assert_allclose(state.position, [3.0, 4.0, -5.0])
    np.testing.assert_allclose(state.velocity, 0.0)


def test_goal_to_setpoint():
    setpoint = goal_to_setpoint(goto_goal([10.0, 20.0], altitude=30.0, speed=5.0))
    np.testing.assert_allclose(setpoint.position, [10.0, 20.0, -30.0])
    assert setpoint.speed == 5.0 and setpoint.orbit is None
    setpoint = goal_to_setpoint(orbit_setpoint([1.0, 2.0], radius=15.0, altitude=40.0, direction=-1))
    np.testing.assert_allclose(setpoint.position, [1.0, 2.0, -40.0])
    center, radius, direction = setpoint.orbit
    np.testing.assert_allclose(center, [1.0, 2.0])
    assert (radius, direction) == (15.0, -1)
    assert setpoint.speed is None


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"position": [0.0, 0.0]}, "setpoint position"),
        ({"position": [0.0, 0.0, float("nan")]}, "setpoint position"),
        ({"position": [0.0, 0.0, 0.0], "speed": 0.0}, "speed"),
        ({"position": [0.0, 0.0, 0.0], "orbit": ([0.0, 0.0], -1.0, 1)}, "orbit radius"),
        ({"position": [0.0, 0.0, 0.0], "orbit": ([0.0, 0.0], 10.0, 0)}, "direction"),
        ({"position": [0.0, 0.0, 0.0], "orbit": ([0.0, 0.0, 0.0], 10.0, 1)}, "orbit center"),
        ({"position": [0.0, 0.0, 0.0], "orbit": ([0.0, 0.0], 10.0)}, "orbit"),
    ],
)
def test_setpoint_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Setpoint(**kwargs)


def test_vehicle_from_config_builds_both_kinds():
    multirotor = vehicle_from_config(
        {"kind": "multirotor", "max_speed": 13.0, "yaw_rate_deg": 45.0}, [1.0, 2.0, -3.0], 0.5
    )
    assert isinstance(multirotor, MultirotorModel)
    assert multirotor.max_speed == 13.0 and multirotor.max_accel == 3.0
    assert multirotor.yaw_rate == pytest.approx(math.radians(45.0))
    assert multirotor.state().yaw == pytest.approx(0.5)
    np.testing.assert_allclose(multirotor.state().position, [1.0, 2.0, -3.0])
    wing = vehicle_from_config({"kind": "fixed_wing", "airspeed": 20, "max_bank_deg": 30}, [0.0, 0.0, -50.0], -1.0)
    assert isinstance(wing, FixedWingModel)
    assert wing.airspeed == 20.0 and wing.max_bank == pytest.approx(math.radians(30.0))
    assert wing.state().yaw == pytest.approx(-1.0)
    assert wing.min_turn_radius == pytest.approx(400.0 / (9.80665 * math.tan(math.radians(30.0))))


@pytest.mark.parametrize(
    "config, match",
    [
        ({}, "kind"),
        ({"kind": "helicopter"}, "kind"),
        ({"kind": "multirotor", "max_speed": 0.0}, "max_speed"),
        ({"kind": "multirotor", "max_speed": -3.0}, "max_speed"),
        ({"kind": "multirotor", "max_accel": float("nan")}, "max_accel"),
        ({"kind": "multirotor", "max_climb": "fast"}, "max_climb"),
        ({"kind": "multirotor", "yaw_rate_deg": True}, "yaw_rate_deg"),
        ({"kind": "multirotor", "airspeed": 10.0}, "airspeed"),
        ({"kind": "multirotor", "yaw_rate": 1.0}, "yaw_rate"),
        ({"kind": "fixed_wing", "airspeed": -18.0}, "airspeed"),
        ({"kind": "fixed_wing", "max_bank_deg": 0.0}, "max_bank_deg"),
        ({"kind": "fixed_wing", "max_bank_deg": 90.0}, "max_bank_deg"),
        ({"kind": "fixed_wing", "climb_rate": 20.0, "airspeed": 15.0}, "climb_rate"),
        ({"kind": "fixed_wing", "max_speed": 10.0}, "max_speed"),
    ],
)
def test_vehicle_from_config_errors_name_the_field(config, match):
    with pytest.raises(ValueError, match=match):
        vehicle_from_config(config, [0.0, 0.0, 0.0], 0.0)


def test_constructor_errors():
    with pytest.raises(ValueError, match="initial_position"):
        MultirotorModel([0.0, 0.0])
    with pytest.raises(ValueError, match="max_accel"):
        MultirotorModel([0.0, 0.0, 0.0], max_accel=0.0)
    with pytest.raises(ValueError, match="heading"):
        FixedWingModel([0.0, 0.0, 0.0], float("inf"))
    with pytest.raises(ValueError, match="max_bank"):
        FixedWingModel([0.0, 0.0, 0.0], 0.0, max_bank=math.radians(95.0))
