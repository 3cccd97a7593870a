"""The vehicle interface: the protocol and clock of the kinematic models, setpoints and goal conversion."""

from __future__ import annotations

import numpy as np
import pytest

from agent.vehicles.base import Setpoint, Vehicle, VehicleState, goal_to_setpoint
from agent.vehicles.fixed_wing import FixedWingModel
from agent.vehicles.multirotor import MultirotorModel
from tasking.orbit import goto_goal, orbit_setpoint


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


def test_goal_to_setpoint():
    setpoint = goal_to_setpoint(goto_goal([10.0, 20.0], altitude=30.0, speed=5.0))
    np.testing.assert_allclose(setpoint.position, [10.0, 20.0, -30.0])
    assert setpoint.speed == 5.0 and setpoint.orbit is None
    setpoint = goal_to_setpoint(orbit_setpoint([1.0, 2.0], radius=15.0, altitude=40.0, direction=-1))
    np.testing.assert_allclose(setpoint.position, [1.0, 2.0, -40.0])
    center, radius, direction = setpoint.orbit
    np.testing.assert_allclose(center, [1.0, 2.0])
    assert (radius, direction) == (15.0, -1)
    assert setpoint.speed is None and setpoint.velocity is None
    setpoint = goal_to_setpoint(orbit_setpoint([1.0, 2.0], 15.0, 40.0, velocity=[3.0, -4.0]))
    assert setpoint.velocity.tolist() == [3.0, -4.0]  # a moving centre's velocity reaches the vehicle


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
        ({"position": [0.0, 0.0, 0.0], "velocity": [1.0, float("inf")]}, "setpoint velocity"),  # infinite
        ({"position": [0.0, 0.0, 0.0], "velocity": [1.0, 2.0, 3.0]}, "setpoint velocity"),  # three components
    ],
)
def test_setpoint_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Setpoint(**kwargs)
