"""The vehicle registry: ``[vehicle]`` configs build each kind, name the bad field, and fly through the planner."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.vehicles import VEHICLES, vehicle_from_config
from agent.vehicles.base import Vehicle, goal_to_setpoint
from agent.vehicles.fixed_wing import FixedWingModel
from agent.vehicles.multirotor import MultirotorModel
from tasking.planner import PlaceholderPlanner
from tasking.search import lawnmower_waypoints


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
        vehicle.set_setpoint(goal_to_setpoint(planner.goal_for(state.position, [])))
        vehicle.step(0.2)
    positions = np.array(positions)
    closest = [np.min(np.linalg.norm(positions[:, :2] - waypoint[:2], axis=1)) for waypoint in path]
    assert max(closest) < planner.acceptance_radius  # every waypoint of the lane was visited
    assert np.all(np.abs(positions[-500:, 2] + 60.0) < 0.5)


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


def test_every_registered_vehicle_builds_with_its_defaults():
    assert set(VEHICLES) == {"multirotor", "fixed_wing", "mavlink"}
    for kind, factory in VEHICLES.items():
        assert factory.kind == kind
        if factory.georeferenced:  # the MAVLink vehicle needs an autopilot: tests/agent/test_mavlink_*.py
            continue
        vehicle = vehicle_from_config({"kind": kind}, [1.0, 2.0, -30.0], 0.25)
        assert isinstance(vehicle, Vehicle)
        np.testing.assert_allclose(vehicle.state().position, [1.0, 2.0, -30.0])
        assert vehicle.state().yaw == pytest.approx(0.25)
