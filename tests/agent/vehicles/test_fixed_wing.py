"""The fixed-wing model: hard limits, orbit convergence, loitering around a point, small orbits clamped."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.vehicles.base import Setpoint, wrap_angle
from agent.vehicles.fixed_wing import FixedWingModel
from tests.agent.vehicles.flights import LIMIT_EXAMPLES, TOL, agent_steps, fly, plans


@LIMIT_EXAMPLES
@given(
    plan=plans,
    dt=agent_steps,
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


def test_fixed_wing_flies_along_a_moving_setpoint_with_feed_forward():
    """A planned path's set-point (position + velocity): the aircraft joins it and flies along, no loitering."""
    vehicle = FixedWingModel([0.0, 30.0, -60.0], 0.0)
    velocity = np.array([18.0, 0.0])
    for k in range(150):  # 30 s: the point moves north at the airspeed along east = 0
        point = np.array([18.0 * 0.2 * k, 0.0, -60.0])
        vehicle.set_setpoint(Setpoint(point, velocity=velocity))
        vehicle.step(0.2)
    state = vehicle.state()
    assert abs(state.position[1]) < 1.0 and abs(state.position[0] - 18.0 * 0.2 * 150) < 10.0
    assert abs(wrap_angle(state.yaw)) < 0.05


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


def test_fixed_wing_constructor_errors():
    with pytest.raises(ValueError, match="heading"):
        FixedWingModel([0.0, 0.0, 0.0], float("inf"))
    with pytest.raises(ValueError, match="max_bank"):
        FixedWingModel([0.0, 0.0, 0.0], 0.0, max_bank=math.radians(95.0))
