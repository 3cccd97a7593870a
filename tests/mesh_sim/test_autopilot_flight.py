"""The flight state machine without sockets: arming checks, takeoff, offboard and its timeout, land, RTL."""

from __future__ import annotations

import numpy as np
import pytest

from agent.vehicles import vehicle_from_config
from agent.vehicles.mavlink_protocol import (
    PX4_HOLD,
    PX4_LAND,
    PX4_OFFBOARD,
    PX4_TAKEOFF,
    mavlink,
)
from mesh_sim.autopilot.battery import Battery
from mesh_sim.autopilot.flight import FlightController
from mesh_sim.autopilot.gimbal import Gimbal
from mesh_sim.autopilot.offboard import OffboardTarget
from mesh_sim.autopilot.params import Params

NAN3 = np.full(3, np.nan)


def controller(kind: str = "multirotor", battery: float = 1.0, **params) -> FlightController:
    model = vehicle_from_config({"kind": kind}, [0.0, 0.0, 0.0])
    return FlightController(model, Params(**params), Battery(remaining=battery), Gimbal(), position_valid_after=1.5)


def run(c: FlightController, until: float, dt: float = 0.02, feed=None) -> None:
    """Step ``c`` to ``until``; ``feed(t)`` is called before each step (a setpoint stream)."""
    t = c.t
    while t < until - 1e-9:
        t = min(t + dt, until)
        if feed is not None:
            feed(t)
        c.step(t)


def position_target(c: FlightController, position) -> OffboardTarget:
    return OffboardTarget(np.asarray(position, float), NAN3, c.t, c.position)


def airborne_at(c: FlightController, height: float = 5.0) -> None:
    run(c, 1.6)
    assert c.arm().result == mavlink.MAV_RESULT_ACCEPTED
    assert c.takeoff(height).result == mavlink.MAV_RESULT_ACCEPTED
    run(c, c.t + 10.0)


def test_arming_is_refused_until_the_position_estimate_is_valid():
    c = controller()
    run(c, 0.5)
    outcome = c.arm()
    assert outcome.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED and not c.armed
    assert "position" in c.statustexts[-1][1]
    run(c, 1.6)
    assert c.arm().result == mavlink.MAV_RESULT_ACCEPTED and c.armed


def test_arming_is_denied_below_the_battery_reserve():
    c = controller(battery=0.10)  # below BAT_LOW_THR 0.15
    run(c, 2.0)
    assert c.arm().result == mavlink.MAV_RESULT_DENIED and not c.armed


def test_takeoff_climbs_to_mis_takeoff_alt_then_holds():
    c = controller()
    run(c, 1.6)
    c.arm()
    assert c.takeoff(None).result == mavlink.MAV_RESULT_ACCEPTED
    assert c.custom_mode == PX4_TAKEOFF and c.landed_state == mavlink.MAV_LANDED_STATE_TAKEOFF
    run(c, 8.0)
    assert c.custom_mode == PX4_HOLD
    assert c.position[2] == pytest.approx(-2.5, abs=0.3)  # MIS_TAKEOFF_ALT default
    assert c.landed_state == mavlink.MAV_LANDED_STATE_IN_AIR


def test_takeoff_is_refused_while_disarmed():
    c = controller()
    run(c, 2.0)
    assert c.takeoff(5.0).result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED


def test_offboard_is_refused_without_a_setpoint_stream_and_flies_the_setpoint_with_one():
    c = controller()
    airborne_at(c)
    assert c.start_offboard().result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    target = [10.0, -5.0, -8.0]
    c.set_offboard_target(position_target(c, target))
    assert c.start_offboard().result == mavlink.MAV_RESULT_ACCEPTED and c.custom_mode == PX4_OFFBOARD
    run(c, c.t + 10.0, feed=lambda t: c.set_offboard_target(position_target(c, target)))
    np.testing.assert_allclose(c.position, target, atol=0.2)
    assert c.custom_mode == PX4_OFFBOARD


def test_offboard_setpoint_timeout_switches_to_hold_and_says_so():
    c = controller()
    airborne_at(c)
    c.set_offboard_target(position_target(c, [0.0, 0.0, -5.0]))
    c.start_offboard()
    last = c.t
    run(c, last + 0.9)
    assert c.custom_mode == PX4_OFFBOARD  # COM_OF_LOSS_T = 1 s not yet over
    run(c, last + 1.1)
    assert c.custom_mode == PX4_HOLD
    assert any("Offboard" in text and "Hold" in text for _, text in c.statustexts)


def test_offboard_loss_time_follows_the_parameter():
    c = controller(COM_OF_LOSS_T=3.0)
    airborne_at(c)
    c.set_offboard_target(position_target(c, [0.0, 0.0, -5.0]))
    c.start_offboard()
    run(c, c.t + 2.5)
    assert c.custom_mode == PX4_OFFBOARD


def test_land_touches_down_then_disarms_after_com_disarm_land():
    c = controller()
    airborne_at(c)
    c.land()
    assert c.custom_mode == PX4_LAND and c.landed_state == mavlink.MAV_LANDED_STATE_LANDING
    run(c, c.t + 10.0, dt=0.05)
    assert not c.airborne and not c.armed
    assert c.position[2] == pytest.approx(0.0, abs=0.1)
    texts = [text for _, text in c.statustexts]
    assert "Landing detected" in texts and "Disarmed by landing" in texts


def test_disarm_in_the_air_needs_force():
    c = controller()
    airborne_at(c)
    assert c.disarm().result == mavlink.MAV_RESULT_DENIED and c.armed
    assert c.disarm(force=True).result == mavlink.MAV_RESULT_ACCEPTED and not c.armed


def test_return_to_launch_climbs_flies_home_and_lands():
    c = controller(RTL_RETURN_ALT=12.0)
    airborne_at(c)
    c.set_offboard_target(position_target(c, [30.0, 20.0, -5.0]))
    c.start_offboard()
    run(c, c.t + 15.0, feed=lambda t: c.set_offboard_target(position_target(c, [30.0, 20.0, -5.0])))
    assert c.return_to_launch().result == mavlink.MAV_RESULT_ACCEPTED
    highest = [0.0]

    def watch(t):
        highest[0] = min(highest[0], c.position[2])

    run(c, c.t + 60.0, dt=0.05, feed=watch)
    assert highest[0] == pytest.approx(-12.0, abs=0.5)
    np.testing.assert_allclose(c.position, [0.0, 0.0, 0.0], atol=0.2)
    assert not c.armed


def test_a_fixed_wing_waits_on_the_ground_until_takeoff():
    c = controller("fixed_wing")
    run(c, 1.6)
    c.arm()
    run(c, 5.0)
    np.testing.assert_allclose(c.position, [0.0, 0.0, 0.0])
    c.takeoff(30.0)
    run(c, 25.0)
    assert c.position[2] == pytest.approx(-30.0, abs=0.5) and c.custom_mode == PX4_HOLD


def test_manual_modes_need_rc_and_unknown_modes_are_denied():
    c = controller()
    run(c, 2.0)
    assert c.set_mode(3, 0).result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED  # POSCTL
    assert c.set_mode(42, 0).result == mavlink.MAV_RESULT_DENIED


def test_the_battery_drains_only_while_armed():
    c = controller()
    c.battery.flight_time = 100.0
    run(c, 10.0)
    assert c.battery.remaining == 1.0
    c.arm()
    run(c, 20.0)
    assert c.battery.remaining == pytest.approx(0.9, abs=1e-6)


def test_a_velocity_setpoint_stream_flies_at_that_velocity():
    c = controller()
    airborne_at(c)

    def velocity_target(t):
        c.set_offboard_target(OffboardTarget(NAN3, np.array([2.0, -1.0, 0.0]), c.t, c.position))

    velocity_target(c.t)
    c.start_offboard()
    start = c.position.copy()
    run(c, c.t + 6.0, feed=velocity_target)
    np.testing.assert_allclose(c.model.state().velocity, [2.0, -1.0, 0.0], atol=0.05)
    assert c.position[2] == pytest.approx(start[2], abs=0.05)  # z was held


def test_angular_rates_follow_the_turn():
    c = controller()
    airborne_at(c)
    c.set_offboard_target(position_target(c, [0.0, 20.0, -5.0]))  # due east: the yaw turns from 0 to +90 deg
    c.start_offboard()
    yaws, rates = [], []

    def record(t):
        c.set_offboard_target(position_target(c, [0.0, 20.0, -5.0]))
        yaws.append(c.model.state().yaw)
        rates.append(c.angular_rates[2])

    run(c, c.t + 3.0, feed=record)
    assert max(rates) == pytest.approx(np.radians(90.0), rel=0.05)  # the multirotor's yaw_rate limit
    assert np.sum(rates[1:]) * 0.02 == pytest.approx(yaws[-1] - yaws[0], abs=1e-6)  # rates[k]: the step before k


def test_landed_state_follows_an_offboard_descent_to_the_ground():
    c = controller()
    airborne_at(c)
    c.set_offboard_target(position_target(c, [0.0, 0.0, -5.0]))
    c.start_offboard()
    assert c.landed_state == mavlink.MAV_LANDED_STATE_IN_AIR
    c.set_offboard_target(position_target(c, [0.0, 0.0, 0.0]))
    assert c.landed_state == mavlink.MAV_LANDED_STATE_LANDING
    run(c, c.t + 10.0, feed=lambda t: c.set_offboard_target(position_target(c, [0.0, 0.0, 0.0])))
    assert c.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND and not c.airborne


def test_a_vehicle_started_in_the_air_is_armed_and_holds_there():
    """--altitude: a fleet run's autopilots start where the kinematic models do, in the air, armed and holding;
    home is the ground below."""
    model = vehicle_from_config({"kind": "multirotor"}, [10.0, -20.0, -80.0])
    c = FlightController(model, Params(), Battery(), Gimbal(), airborne=True)
    assert c.armed and c.custom_mode == PX4_HOLD
    assert c.landed_state == mavlink.MAV_LANDED_STATE_IN_AIR
    assert c.home.tolist() == [10.0, -20.0, 0.0]
    run(c, 5.0)
    assert c.position == pytest.approx([10.0, -20.0, -80.0], abs=1e-6)
    c.set_offboard_target(position_target(c, [30.0, -20.0, -80.0]))
    assert c.start_offboard().result == mavlink.MAV_RESULT_ACCEPTED  # no arming, no take-off: straight on
