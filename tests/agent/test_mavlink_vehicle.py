"""The MAVLink vehicle against a scripted autopilot over real UDP MAVLink 2 bytes on loopback
(:mod:`tests.agent.mavlink_peer`): heartbeats, streams, the start-up sequences and their ACKs, the setpoint
stream and its frames, the heartbeat watch, the time mapping and the gimbal."""

from __future__ import annotations

import math
import socket
import time

import numpy as np
import pymap3d
import pytest

from agent.vehicles.base import Setpoint, Vehicle
from agent.vehicles.mavlink import CommandRefused, CommandTimeout
from agent.vehicles.mavlink_protocol import PX4_MAIN_MANUAL, PX4_MAIN_OFFBOARD, mavlink, px4_custom_mode, px4_modes
from tests.agent.mavlink_peer import (
    ORIGIN,
    SCENARIO_ORIGIN,
    ScriptedAutopilot,
    connect,
    flying_vehicle,
    free_port,
    wait_for,
)
from tests.agent.test_plugins import assert_implements


@pytest.fixture
def peer():
    autopilot = ScriptedAutopilot(free_port())
    yield autopilot
    autopilot.close()


@pytest.fixture
def flying():
    with flying_vehicle() as (peer, vehicle):
        yield peer, vehicle


def scenario_to_local(ned) -> np.ndarray:
    """Independent reference (pymap3d): a scenario NED point in the autopilot's local frame."""
    lat, lon, alt = pymap3d.ned2geodetic(*ned, *SCENARIO_ORIGIN)
    return np.array(pymap3d.geodetic2ned(lat, lon, alt, *ORIGIN))


def local_to_scenario(ned) -> np.ndarray:
    lat, lon, alt = pymap3d.ned2geodetic(*ned, *ORIGIN)
    return np.array(pymap3d.geodetic2ned(lat, lon, alt, *SCENARIO_ORIGIN))


def test_the_vehicle_is_a_vehicle(flying):
    assert_implements(flying[1], Vehicle)


def test_heartbeats_go_both_ways_and_name_the_autopilot(flying):
    peer, vehicle = flying
    assert vehicle.link.autopilot == (1, 1)
    start = time.monotonic()
    time.sleep(2.2)
    ours = [(t, m) for t, m in peer.received["HEARTBEAT"] if t >= start]
    assert 2 <= len(ours) <= 3  # 1 Hz
    msg = ours[-1][1]
    assert msg.type == mavlink.MAV_TYPE_ONBOARD_CONTROLLER and msg.autopilot == mavlink.MAV_AUTOPILOT_INVALID
    assert (msg.get_srcSystem(), msg.get_srcComponent()) == (1, mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)
    assert vehicle.telemetry.heartbeat is not None and vehicle.healthy


def test_the_streams_it_reads_are_requested_with_set_message_interval(flying):
    peer, _ = flying
    intervals = {int(m.param1): m.param2 for m in peer.messages("COMMAND_LONG")
                 if m.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL}
    assert intervals[mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED] == pytest.approx(50_000)  # µs: 20 Hz
    assert intervals[mavlink.MAVLINK_MSG_ID_ATTITUDE] == pytest.approx(50_000)
    assert {mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mavlink.MAVLINK_MSG_ID_BATTERY_STATUS,
            mavlink.MAVLINK_MSG_ID_SYS_STATUS, mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
            mavlink.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS} <= set(intervals)
    requested = {int(m.param1) for m in peer.messages("COMMAND_LONG") if m.command == mavlink.MAV_CMD_REQUEST_MESSAGE}
    assert mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN in requested


def test_px4_start_up_streams_setpoints_then_arms_then_switches_to_offboard_and_climbs(flying):
    peer, vehicle = flying
    commands = [(t, m) for t, m in peer.received["COMMAND_LONG"]]
    arm = next(t for t, m in commands if m.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM and m.param1 == 1)
    mode = next((t, m) for t, m in commands if m.command == mavlink.MAV_CMD_DO_SET_MODE)
    setpoints_before_arm = [t for t, _ in peer.received["SET_POSITION_TARGET_LOCAL_NED"] if t < arm]
    assert len(setpoints_before_arm) >= 5  # PX4 needs the stream before arming in / switching to OFFBOARD
    assert arm < mode[0]
    assert mode[1].param1 == mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and mode[1].param2 == PX4_MAIN_OFFBOARD
    assert peer.armed and px4_modes(peer.custom_mode)[0] == PX4_MAIN_OFFBOARD
    assert not any(m.command == mavlink.MAV_CMD_NAV_TAKEOFF for _, m in commands)  # PX4 climbs in offboard
    assert vehicle.healthy  # the fixture waited for the take-off to end, at 95 % of 3 m
    assert peer.position[2] == pytest.approx(-3.0, abs=0.2)


def test_ardupilot_start_up_is_guided_arm_takeoff_and_streams_only_after_the_climb():
    ardupilot = ScriptedAutopilot(free_port(), autopilot=mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)
    try:
        vehicle = connect(ardupilot)  # autopilot = "auto": the HEARTBEAT says MAV_AUTOPILOT_ARDUPILOTMEGA
        assert vehicle.autopilot == "ardupilot"
        commands = [m.command for m in ardupilot.messages("COMMAND_LONG")
                    if m.command not in (mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAV_CMD_REQUEST_MESSAGE)]
        assert commands == [mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_CMD_COMPONENT_ARM_DISARM,
                            mavlink.MAV_CMD_NAV_TAKEOFF]
        takeoff = ardupilot.messages("COMMAND_LONG")[-1]
        assert takeoff.param7 == 3.0 and ardupilot.custom_mode == 4  # GUIDED
        assert vehicle.health_reason == "taking off" and not ardupilot.received["SET_POSITION_TARGET_LOCAL_NED"]
        wait_for(lambda: vehicle.healthy, timeout=15.0)
        wait_for(lambda: ardupilot.received["SET_POSITION_TARGET_LOCAL_NED"])
        vehicle.close()
    finally:
        ardupilot.close()


def test_a_vehicle_already_flying_is_not_armed_again_and_keeps_its_altitude():
    airborne = ScriptedAutopilot(free_port(), start=(5.0, 5.0, -30.0))  # the agent restarts on a flying vehicle
    airborne.armed, airborne.home = True, np.zeros(3)  # armed, 30 m above its home
    try:
        vehicle = connect(airborne)
        try:
            commands = {m.command for m in airborne.messages("COMMAND_LONG")}
            assert mavlink.MAV_CMD_COMPONENT_ARM_DISARM not in commands and mavlink.MAV_CMD_DO_SET_MODE in commands
            assert vehicle.healthy  # no climb to do: 30 m is above the 3 m take-off altitude
            setpoint = airborne.messages("SET_POSITION_TARGET_LOCAL_NED")[-1]
            assert [setpoint.x, setpoint.y, setpoint.z] == pytest.approx([5.0, 5.0, -30.0], abs=1e-3)
        finally:
            vehicle.close()
    finally:
        airborne.close()


def test_a_flying_vehicle_whose_home_arrives_late_is_not_kept_taking_off():
    """The home is not known when the start-up begins (the autopilot answers HOME_POSITION requests only 2 s
    later): the climb is judged against home as it arrives, so the vehicle, 30 m up, is healthy once it does, even
    after the agent's own setpoint replaced the climb point (skymesh run --vehicle mavlink found agents stuck)."""
    airborne = ScriptedAutopilot(free_port(), start=(5.0, 5.0, -30.0), home_after=2.0)
    airborne.armed, airborne.home = True, np.zeros(3)
    try:
        vehicle = connect(airborne)
        try:
            vehicle.set_setpoint(Setpoint(vehicle.state().position))  # hold where it is: no climb
            wait_for(lambda: vehicle.healthy, timeout=6.0)
            assert vehicle.telemetry.home is not None
        finally:
            vehicle.close()
    finally:
        airborne.close()


def test_a_denied_arm_command_is_a_clear_error(peer):
    peer.refuse[mavlink.MAV_CMD_COMPONENT_ARM_DISARM] = mavlink.MAV_RESULT_DENIED
    with pytest.raises(CommandRefused, match="MAV_CMD_COMPONENT_ARM_DISARM: refused by the autopilot "
                                             r"\(MAV_RESULT_DENIED\)"):
        connect(peer)


def test_an_unsupported_mode_is_a_clear_error(peer):
    peer.refuse[mavlink.MAV_CMD_DO_SET_MODE] = mavlink.MAV_RESULT_UNSUPPORTED
    with pytest.raises(CommandRefused, match=r"MAV_CMD_DO_SET_MODE.*MAV_RESULT_UNSUPPORTED"):
        connect(peer)


def test_a_lost_ack_is_retried_with_the_confirmation_counted(peer):
    peer.drop_acks[mavlink.MAV_CMD_COMPONENT_ARM_DISARM] = 2
    vehicle = connect(peer, command_timeout=0.3)
    try:
        arms = [m for m in peer.messages("COMMAND_LONG") if m.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM]
        assert [m.confirmation for m in arms] == [0, 1, 2]
        assert peer.armed
    finally:
        vehicle.close()


def test_a_command_never_acknowledged_times_out_naming_it(peer):
    peer.drop_acks[mavlink.MAV_CMD_COMPONENT_ARM_DISARM] = 99
    with pytest.raises(CommandTimeout, match="MAV_CMD_COMPONENT_ARM_DISARM: no COMMAND_ACK .* after 2 tries"):
        connect(peer, command_timeout=0.2, command_attempts=2)


def test_the_state_is_in_the_scenario_frame_and_matches_an_independent_conversion(flying):
    peer, vehicle = flying
    local = vehicle.telemetry.local
    state = vehicle.state()
    np.testing.assert_allclose(state.position, local_to_scenario(local.position), atol=1e-3)
    assert state.position == pytest.approx([120.0, -80.0, -18.0], abs=0.3)  # 3 m up at the autopilot's origin
    assert state.fresh and state.roll == pytest.approx(0.01) and state.pitch == pytest.approx(-0.02)
    assert abs(state.yaw - 0.3) < 1e-3  # the two frames' norths differ by the meridians' convergence only


def streamed(peer, since: float) -> list:
    """The SET_POSITION_TARGET_LOCAL_NED the autopilot received since ``since`` (monotonic)."""
    return [m for t, m in peer.received["SET_POSITION_TARGET_LOCAL_NED"] if t >= since]


def test_setpoints_stream_at_10_hz_a_reference_moving_at_the_speed_limit_in_the_autopilot_frame(flying):
    peer, vehicle = flying
    start = vehicle.state().position
    goal = np.array([150.0, -60.0, -20.0])  # scenario NED, 36 m away
    vehicle.set_setpoint(Setpoint(goal, speed=4.0))
    time.sleep(0.3)
    since, followed_from = time.monotonic(), vehicle.state().position
    time.sleep(2.0)
    window = streamed(peer, since)
    followed = np.linalg.norm(vehicle.state().position - followed_from) / (time.monotonic() - since)
    assert len(window) / 2.0 >= 9.0  # configured 10 Hz; >= 5 Hz is the requirement
    for msg in window:
        assert msg.coordinate_frame == mavlink.MAV_FRAME_LOCAL_NED
        used = mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE
        assert msg.type_mask & used == 0 and msg.type_mask & mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE
        position = np.array([msg.x, msg.y, msg.z])  # the autopilot's local frame
        velocity = np.array([msg.vx, msg.vy, msg.vz])
        toward = scenario_to_local(goal) - position  # converted independently (pymap3d)
        assert np.linalg.norm(velocity) == pytest.approx(4.0, rel=1e-6)  # the setpoint's speed limit, far from it
        assert velocity @ toward / (4.0 * np.linalg.norm(toward)) > 0.9999  # feed-forward toward the goal (float32)
        along = local_to_scenario(position) - start  # the reference is on the line from the start to the goal
        line = (goal - start) / np.linalg.norm(goal - start)
        assert np.linalg.norm(along - (along @ line) * line) < 0.05
    first, last = (local_to_scenario([m.x, m.y, m.z]) for m in (window[0], window[-1]))
    assert np.linalg.norm(last - first) / (len(window) - 1) == pytest.approx(0.4, rel=0.1)  # 4 m/s at 10 Hz
    assert followed == pytest.approx(4.0, abs=0.6)  # and the vehicle follows: its mean speed over the 2 s window
    assert np.linalg.norm(vehicle.state().position - vehicle.reference.position) < 2.0


def test_an_orbit_setpoint_streams_the_orbit_field_and_the_vehicle_goes_round(flying):
    peer, vehicle = flying
    center, radius = np.array([105.0, -80.0]), 15.0  # the vehicle (120, -80) is on the circle, north of its centre
    vehicle.set_setpoint(Setpoint([0.0, 0.0, -20.0], orbit=(center, radius, 1)))

    def bearing() -> float:
        north, east = vehicle.state().position[:2] - center
        return math.atan2(east, north)

    wait_for(lambda: abs(vehicle.state().position[2] + 20.0) < 0.05, timeout=10.0)  # down to the orbit's depth
    since, before = time.monotonic(), bearing()
    time.sleep(3.0)
    turned = (bearing() - before) % (2 * math.pi)
    assert turned == pytest.approx(5.0 * 3.0 / radius, rel=0.15)  # clockwise at 5 m/s (cruise_speed)
    for msg in streamed(peer, since):
        reference = local_to_scenario([msg.x, msg.y, msg.z])
        velocity = np.array([msg.vx, msg.vy, msg.vz])
        assert np.hypot(*(reference[:2] - center)) == pytest.approx(radius, abs=0.2)
        assert reference[2] == pytest.approx(-20.0, abs=0.1)
        assert np.hypot(velocity[0], velocity[1]) == pytest.approx(5.0, rel=1e-6)  # the field's speed everywhere
        radial = (reference[:2] - center) / radius
        assert radial[0] * velocity[1] - radial[1] * velocity[0] > 4.9  # tangent, clockwise seen from above


def test_a_silent_autopilot_makes_the_vehicle_unhealthy_within_the_timeouts(flying):
    """The link drops: the position stream's absence tells first (stream_timeout, 1 s after the last position),
    then the heartbeat's (heartbeat_timeout, 2 s after the last heartbeat)."""
    peer, vehicle = flying
    peer.silent.set()  # the autopilot falls silent: no heartbeat, no position
    detected = wait_for(lambda: not vehicle.healthy, timeout=4.0)
    assert 1.0 <= detected - peer.last_pose_sent <= 1.25, detected - peer.last_pose_sent
    assert vehicle.health_reason.startswith("position stale")
    lost = wait_for(lambda: vehicle.health_reason.startswith("autopilot heartbeat lost"), timeout=4.0)
    assert 2.0 <= lost - peer.last_heartbeat_sent <= 2.25, lost - peer.last_heartbeat_sent
    assert not vehicle.state().fresh
    vehicle.step(0.2)
    assert vehicle.stale_steps == 1
    peer.silent.clear()
    wait_for(lambda: vehicle.healthy, timeout=3.0)  # it comes back with the autopilot


def test_a_low_battery_makes_the_vehicle_unhealthy(flying):
    peer, vehicle = flying
    peer.battery = 15  # % (BATTERY_STATUS and SYS_STATUS)
    wait_for(lambda: not vehicle.healthy, timeout=3.0)
    assert vehicle.health_reason == "battery 15% below the reserve 20%" and vehicle.battery == 0.15


def test_a_mode_change_by_the_autopilot_makes_the_vehicle_unhealthy(flying):
    peer, vehicle = flying
    peer.custom_mode = px4_custom_mode(PX4_MAIN_MANUAL)  # a pilot took over
    wait_for(lambda: not vehicle.healthy, timeout=3.0)
    assert vehicle.health_reason.startswith("autopilot left the commanded mode")


def test_the_autopilot_time_maps_to_the_local_clock_by_timesync(flying):
    peer, vehicle = flying
    wait_for(lambda: vehicle.clock.source == "timesync")
    expected = time.time() - peer.boot_ms() * 1e-3  # local - boot, now
    assert vehicle.clock.offset == pytest.approx(expected, abs=0.01)
    assert vehicle.clock.round_trip < 0.05
    assert time.time() - vehicle.state().t == pytest.approx(0.0, abs=0.1)  # the pose is at most a sample old


def test_without_timesync_the_stamps_give_the_offset():
    quiet = ScriptedAutopilot(free_port(), answer_timesync=False, boot_offset=5000.0)
    try:
        vehicle = connect(quiet)
        assert vehicle.clock.source == "stamps"
        assert vehicle.clock.offset == pytest.approx(time.time() - quiet.boot_ms() * 1e-3, abs=0.02)
        vehicle.close()
    finally:
        quiet.close()


def test_the_gimbal_is_pointed_with_gimbal_manager_set_pitchyaw_and_read_back(flying):
    peer, vehicle = flying
    here = vehicle.state().position
    vehicle.point(here + np.array([0.0, 40.0, 40.0]))  # 40 m east, 40 m below
    wait_for(lambda: peer.received["GIMBAL_MANAGER_SET_PITCHYAW"])
    msg = peer.messages("GIMBAL_MANAGER_SET_PITCHYAW")[-1]
    buffer = msg.get_msgbuf()
    assert buffer[0] == 0xFD and int.from_bytes(buffer[7:10], "little") == 287  # MAVLink 2, id 287
    assert (msg.target_system, msg.target_component, msg.gimbal_device_id) == (1, 1, 0)
    assert msg.flags == mavlink.GIMBAL_MANAGER_FLAGS_YAW_IN_EARTH_FRAME
    assert msg.pitch == pytest.approx(-math.pi / 4, abs=1e-3)
    assert msg.yaw == pytest.approx(math.pi / 2, abs=1e-3)
    assert math.isnan(msg.pitch_rate) and math.isnan(msg.yaw_rate)
    peer.gimbal_q = [math.cos(-math.pi / 8), 0.0, math.sin(-math.pi / 8), 0.0]  # pitched 45° down
    wait_for(lambda: vehicle.gimbal_attitude() is not None and vehicle.gimbal_attitude().pitch < -0.7)
    attitude = vehicle.gimbal_attitude()
    assert attitude.pitch == pytest.approx(-math.pi / 4, abs=1e-4) and not attitude.yaw_in_vehicle_frame


def test_metrics_report_the_link(flying):
    _, vehicle = flying
    metrics = vehicle.metrics()["vehicle"]
    assert metrics["kind"] == "mavlink" and metrics["setpoints_sent"] > 0 and metrics["commands_sent"] >= 10
    assert metrics["clock"]["source"] in ("timesync", "stamps")


def test_ardupilot_over_tcp_flies_and_survives_the_autopilot_closing_the_connection():
    ardupilot = ScriptedAutopilot(free_port(socket.SOCK_STREAM), autopilot=mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                  tcp=True)  # as ArduPilot SITL serves tcp:127.0.0.1:5760
    try:
        vehicle = connect(ardupilot)
        try:
            wait_for(lambda: vehicle.healthy, timeout=15.0)
            ardupilot.silent.set()  # the autopilot restarts: it closes the connection and is silent a while
            ardupilot.hang_up()
            wait_for(lambda: not vehicle.healthy, timeout=4.0)
            assert vehicle.rejected["link_closed"] >= 1 and vehicle.link._thread.is_alive()
            ardupilot.silent.clear()
            wait_for(lambda: vehicle.healthy, timeout=5.0)  # the link reconnected; the heartbeat is back
        finally:
            vehicle.close()
    finally:
        ardupilot.close()
