"""Message handling without sockets: commands and their ACKs, offboard type_mask decoding, parameters,
streams, TIMESYNC, messages for another system."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from agent.vehicles import vehicle_from_config
from agent.vehicles.mavlink_protocol import PX4_MAIN_OFFBOARD, mavlink, px4_modes
from mesh_sim.autopilot.battery import Battery
from mesh_sim.autopilot.counters import Counters
from mesh_sim.autopilot.delay_line import DelayLine
from mesh_sim.autopilot.flight import FlightController
from mesh_sim.autopilot.gimbal import Gimbal
from mesh_sim.autopilot.offboard import LOOKAHEAD, SetpointRejected, decode_target
from mesh_sim.autopilot.params import Params
from mesh_sim.autopilot.router import MessageRouter
from mesh_sim.autopilot.streams import ONBOARD_RATES, StreamSchedule
from mesh_sim.autopilot.telemetry import Telemetry

SYSID = 3
ORIGIN = (43.5605, 1.4664, 150.0)
GCS = mavlink.MAVLink(None, srcSystem=245, srcComponent=190)  # what a ground station encodes with
IGNORE_ALL_BUT_POSITION = 0b110111111000
IGNORE_ALL_BUT_VELOCITY = 0b110111000111


@pytest.fixture
def sim():
    model = vehicle_from_config({"kind": "multirotor"}, [0.0, 0.0, 0.0])
    params = Params(MAV_SYS_ID=SYSID)
    controller = FlightController(model, params, Battery(), Gimbal(), position_valid_after=1.5)
    telemetry = Telemetry(controller, ORIGIN, SYSID, mavlink.MAV_TYPE_QUADROTOR)
    counters = Counters()
    router = MessageRouter(controller, telemetry, params, counters)
    streams = StreamSchedule(ONBOARD_RATES, telemetry.supports)
    return router, streams, counters


def long(command: int, *params: float, target: int = SYSID):
    params = list(params) + [math.nan] * (7 - len(params))
    return GCS.command_long_encode(target, 1, command, 0, *params)


def roundtrip(msg):
    """``msg`` as the simulator would decode it from the wire."""
    return mavlink.MAVLink(None).decode(bytearray(msg.pack(GCS)))


def ack_of(replies):
    acks = [r for r in replies if r.get_type() == "COMMAND_ACK"]
    assert len(acks) == 1, replies
    return acks[0]


def step(router, until: float) -> None:
    c = router.controller
    while c.t < until - 1e-9:
        c.step(min(c.t + 0.02, until))


def test_an_unsupported_command_is_acked_unsupported_and_counted(sim):
    router, streams, counters = sim
    # MAV_CMD_DO_SET_SERVO: a command this simulator does not implement
    ack = ack_of(router.handle(roundtrip(long(mavlink.MAV_CMD_DO_SET_SERVO, 1, 1500)), streams))
    assert ack.result == mavlink.MAV_RESULT_UNSUPPORTED and ack.command == mavlink.MAV_CMD_DO_SET_SERVO
    assert (ack.target_system, ack.target_component) == (245, 190)
    assert counters.rejected["unsupported_command"] == 1


def test_a_command_for_another_system_is_ignored_and_counted(sim):
    router, streams, counters = sim
    step(router, 2.0)
    # an ARM command addressed to system 7, not to us (3)
    assert router.handle(roundtrip(long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=7)), streams) == []
    assert not router.controller.armed and counters.rejected["other_target"] == 1


def test_command_int_is_handled_like_command_long(sim):
    router, streams, _ = sim
    step(router, 2.0)
    msg = GCS.command_int_encode(SYSID, 1, 0, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 1, 0, 0, 0, 0, 0, 0)
    assert ack_of(router.handle(roundtrip(msg), streams)).result == mavlink.MAV_RESULT_ACCEPTED
    assert router.controller.armed


def test_a_nan_where_a_number_is_needed_is_denied_not_a_crash(sim):
    router, streams, _ = sim
    # DO_SET_MODE with NaN as the main mode
    msg = long(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, math.nan)
    assert ack_of(router.handle(roundtrip(msg), streams)).result == mavlink.MAV_RESULT_DENIED


def test_takeoff_altitude_is_amsl_and_nan_means_mis_takeoff_alt(sim):
    router, streams, _ = sim
    step(router, 2.0)
    router.handle(roundtrip(long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)), streams)
    ack = ack_of(router.handle(roundtrip(long(mavlink.MAV_CMD_NAV_TAKEOFF, *[0] * 6, ORIGIN[2] + 7.0)), streams))
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    step(router, 10.0)
    assert router.controller.position[2] == pytest.approx(-7.0, abs=0.3)


def test_set_mode_offboard_is_refused_before_setpoints_and_accepted_after(sim):
    router, streams, _ = sim
    step(router, 2.0)
    set_offboard = roundtrip(long(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                  PX4_MAIN_OFFBOARD, 0))
    assert ack_of(router.handle(set_offboard, streams)).result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    setpoint = GCS.set_position_target_local_ned_encode(0, SYSID, 1, mavlink.MAV_FRAME_LOCAL_NED,
                                                        IGNORE_ALL_BUT_POSITION, 1, 2, -3, 0, 0, 0, 0, 0, 0, 0, 0)
    assert router.handle(roundtrip(setpoint), streams) == []
    assert ack_of(router.handle(set_offboard, streams)).result == mavlink.MAV_RESULT_ACCEPTED
    assert px4_modes(router.controller.custom_mode) == (PX4_MAIN_OFFBOARD, 0)


def test_request_message_acks_then_sends_the_message(sim):
    router, streams, _ = sim
    replies = router.handle(roundtrip(long(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)),
                            streams)
    assert [r.get_type() for r in replies] == ["COMMAND_ACK", "AUTOPILOT_VERSION"]
    assert replies[1].capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    # HOME_POSITION before the position is valid: not yet
    replies = router.handle(roundtrip(long(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION)),
                            streams)
    assert ack_of(replies).result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    step(router, 2.0)
    replies = router.handle(roundtrip(long(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION)),
                            streams)
    assert replies[1].latitude == round(ORIGIN[0] * 1e7) and replies[1].altitude == round(ORIGIN[2] * 1000)


def test_set_message_interval_changes_disables_and_restores_a_stream(sim):
    router, streams, _ = sim
    lpn = mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED
    assert streams.intervals[lpn] == pytest.approx(1 / 30)
    for interval_us, expected in ((50_000, 0.05), (-1, None), (0, 1 / 30)):
        ack = ack_of(router.handle(roundtrip(long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, lpn, interval_us)), streams))
        assert ack.result == mavlink.MAV_RESULT_ACCEPTED
        assert streams.intervals.get(lpn) == (None if expected is None else pytest.approx(expected))
    # a message it cannot stream
    ack = ack_of(router.handle(roundtrip(long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 12345, 1000)), streams))
    assert ack.result == mavlink.MAV_RESULT_DENIED


def test_stream_schedule_sends_at_the_rate_without_bursts():
    schedule = StreamSchedule({1: 10.0}, lambda msg_id: True)
    sent = sum(len(schedule.due(k * 0.001)) for k in range(1000))
    assert sent == 10
    assert schedule.due(5.0) == [1] and schedule.due(5.01) == []  # a stall is not made up for


def test_params_read_set_and_int_params_travel_bytewise(sim):
    router, streams, counters = sim
    msg = GCS.param_set_encode(SYSID, 1, b"MIS_TAKEOFF_ALT", 7.5, mavlink.MAV_PARAM_TYPE_REAL32)
    (value,) = router.handle(roundtrip(msg), streams)
    assert value.param_id == "MIS_TAKEOFF_ALT" and value.param_value == pytest.approx(7.5)
    assert router.params["MIS_TAKEOFF_ALT"] == 7.5
    (value,) = router.handle(roundtrip(GCS.param_request_read_encode(SYSID, 1, b"MAV_SYS_ID", -1)), streams)
    assert value.param_type == mavlink.MAV_PARAM_TYPE_INT32
    assert np.frombuffer(np.float32(value.param_value).tobytes(), dtype="<i4")[0] == SYSID
    values = router.handle(roundtrip(GCS.param_request_list_encode(SYSID, 1)), streams)
    assert len(values) == len(router.params) == values[0].param_count
    # an unknown name and an out-of-range value: counted, nothing changed
    assert router.handle(roundtrip(GCS.param_set_encode(SYSID, 1, b"NOPE", 1.0, 9)), streams) == []
    (value,) = router.handle(roundtrip(GCS.param_set_encode(SYSID, 1, b"COM_OF_LOSS_T", -5.0, 9)), streams)
    assert value.param_value == 1.0
    assert counters.rejected["unknown_parameter"] == 1 and counters.rejected["bad_parameter_value"] == 1


def test_timesync_requests_are_answered_and_replies_ignored(sim):
    router, streams, _ = sim
    step(router, 1.0)
    (reply,) = router.handle(roundtrip(GCS.timesync_encode(0, 123456789)), streams)
    assert reply.ts1 == 123456789 and reply.tc1 == pytest.approx(1e9, rel=1e-6)
    assert router.handle(roundtrip(GCS.timesync_encode(5, 123456789)), streams) == []


def test_gimbal_commands_and_messages_point_the_gimbal(sim):
    router, streams, _ = sim
    ack = ack_of(router.handle(roundtrip(long(mavlink.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, -45.0, 30.0)), streams))
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    step(router, 2.0)
    gimbal = router.controller.gimbal
    assert (gimbal.pitch, gimbal.yaw) == (pytest.approx(math.radians(-45)), pytest.approx(math.radians(30)))
    router.handle(roundtrip(GCS.gimbal_manager_set_pitchyaw_encode(SYSID, 1, 0, 0, -0.5, math.nan, 0, 0)), streams)
    step(router, 3.0)
    assert (gimbal.pitch, gimbal.yaw) == (pytest.approx(-0.5), pytest.approx(math.radians(30)))
    status = router.telemetry.gimbal_device_attitude_status()
    w, x, y, z = status.q
    assert math.atan2(2 * (w * y - z * x), 1 - 2 * (y * y + x * x)) == pytest.approx(-0.5, abs=1e-6)


class Target:
    """A SET_POSITION_TARGET_LOCAL_NED's fields."""

    def __init__(self, mask, position=(0, 0, 0), velocity=(0, 0, 0), frame=mavlink.MAV_FRAME_LOCAL_NED):
        self.type_mask, self.coordinate_frame = mask, frame
        self.x, self.y, self.z = position
        self.vx, self.vy, self.vz = velocity


def test_velocity_only_setpoints_become_a_carrot_at_that_speed():
    here = np.array([1.0, 2.0, -5.0])
    target = decode_target(Target(IGNORE_ALL_BUT_VELOCITY, velocity=(3.0, 4.0, 0.0)), here, 0.0, now=10.0)
    setpoint = target.setpoint(here, 10.5)
    np.testing.assert_allclose(setpoint.position, here + LOOKAHEAD * np.array([3.0, 4.0, 0.0]))
    assert setpoint.speed == pytest.approx(5.0)


def test_position_with_velocity_feed_forward_moves_the_reference():
    here = np.zeros(3)
    target = decode_target(Target(0b110111000000, (10.0, 0.0, -5.0), (2.0, 0.0, 0.0)), here, 0.0, now=1.0)
    np.testing.assert_allclose(target.setpoint(here, 1.5).position, [11.0, 0.0, -5.0])
    assert target.setpoint(here, 1.5).speed is None


def test_body_frame_velocities_are_rotated_by_the_yaw():
    target = decode_target(Target(IGNORE_ALL_BUT_VELOCITY, velocity=(2.0, 0.0, 0.0), frame=mavlink.MAV_FRAME_BODY_NED),
                           np.zeros(3), math.pi / 2, now=0.0)
    np.testing.assert_allclose(target.velocity, [0.0, 2.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("bad, reason", [
    (Target(IGNORE_ALL_BUT_POSITION, (math.nan, 0.0, -5.0)), "non_finite_setpoint"),
    (Target(IGNORE_ALL_BUT_POSITION, (1.0, 0.0, -5.0), frame=mavlink.MAV_FRAME_GLOBAL_INT), "unsupported_frame"),
    (Target(IGNORE_ALL_BUT_POSITION, (1.0, 0.0, -5.0), frame=mavlink.MAV_FRAME_BODY_NED), "unsupported_frame"),
])
def test_unusable_setpoints_are_refused_with_a_reason(bad, reason):
    with pytest.raises(SetpointRejected) as raised:
        decode_target(bad, np.zeros(3), 0.0, now=0.0)
    assert raised.value.reason == reason


def test_a_nan_in_an_ignored_field_is_fine():
    target = decode_target(Target(IGNORE_ALL_BUT_POSITION, (1.0, 2.0, -3.0), (math.nan,) * 3), np.zeros(3), 0.0, 0.0)
    np.testing.assert_allclose(target.setpoint(np.zeros(3), 1.0).position, [1.0, 2.0, -3.0])


def test_delay_line_keeps_order_and_delay():
    line = DelayLine(0.25)
    line.push(1.0, "a")
    line.push(1.1, "b")
    assert line.pop_due(1.2) == [] and line.next_due() == 1.25
    assert line.pop_due(1.3) == ["a"] and line.pop_due(1.4) == ["b"] and len(line) == 0
    with pytest.raises(ValueError):
        DelayLine(-1.0)


def test_ftp_requests_get_a_file_not_found_nak(sim):
    router, streams, _ = sim
    # an OpenFileRO (opcode 4) of "@PARAM/param.pck", sequence 7, session 0: what MAVProxy sends first
    request = list((struct.pack("<HBBBBBBI", 7, 0, 4, 16, 0, 0, 0, 0) + b"@PARAM/param.pck").ljust(251, b"\0"))
    (reply,) = router.handle(roundtrip(GCS.file_transfer_protocol_encode(0, SYSID, 1, request)), streams)
    seq, session, opcode, size, req_opcode = struct.unpack_from("<HBBBB", bytes(reply.payload))
    assert (seq, opcode, size, req_opcode, reply.payload[12]) == (8, 129, 1, 4, 10)  # NAK, FileNotFound
    assert (reply.target_system, reply.target_component) == (245, 190)
    nak = list(bytes(reply.payload))
    assert router.handle(roundtrip(GCS.file_transfer_protocol_encode(0, SYSID, 1, nak)), streams) == []


def test_the_default_origin_is_the_default_scenario_origin_and_the_cli_takes_the_options():
    from agent.config import AgentScenario
    from mesh_sim.autopilot.options import DEFAULT_ORIGIN, options_from_args
    from mesh_sim.cli import build_parser

    assert DEFAULT_ORIGIN == AgentScenario.origin
    options = options_from_args(build_parser().parse_args(["autopilot", "--instance", "3", "--latency-ms", "50"]))
    assert options.system_id == 4 and options.latency_ms == 50.0
    assert options.offboard_bind == ("127.0.0.1", 14583) and options.offboard_remote == ("127.0.0.1", 14543)
    assert options.gcs_bind == ("127.0.0.1", 18573) and options.gcs_remote == ("127.0.0.1", 14550)


def test_sys_status_and_battery_status_report_the_battery_and_whether_it_may_arm(sim):
    router, _, _ = sim
    telemetry, battery = router.telemetry, router.controller.battery
    assert not telemetry.sys_status().onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK  # t = 0
    step(router, 2.0)
    status = telemetry.sys_status()
    assert status.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK
    assert status.battery_remaining == 100 and status.voltage_battery == 16200  # 4 cells x 4.05 V
    battery.remaining = 0.1  # below BAT_LOW_THR
    status, pack = telemetry.sys_status(), telemetry.battery_status()
    assert not status.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK
    assert status.battery_remaining == 10 and pack.battery_remaining == 10
    assert pack.charge_state == mavlink.MAV_BATTERY_CHARGE_STATE_LOW
    assert pack.voltages[:5] == [3645] * 4 + [65535]  # 3.6 V + 0.1 x 0.45 V per cell; no fifth cell


def test_the_scenarios_vehicle_keys_reach_the_model():
    from mesh_sim.autopilot.options import options_from_args
    from mesh_sim.autopilot.simulator import Simulator
    from mesh_sim.cli import build_parser

    args = ["autopilot", "--offboard-port", "0", "--gcs-port", "0", "--vehicle-param", "max_speed=12.5",
            "--vehicle-param", "max_accel=4"]
    simulator = Simulator(options_from_args(build_parser().parse_args(args)))
    try:
        assert (simulator.controller.model.max_speed, simulator.controller.model.max_accel) == (12.5, 4.0)
    finally:
        simulator.close()


@pytest.mark.parametrize("text", ["max_speed", "max_speed=fast", "=3"])  # no value, not a number, no key
def test_a_malformed_vehicle_param_is_a_usage_error(text):
    from mesh_sim.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(["autopilot", "--vehicle-param", text])


def test_a_vehicle_param_the_model_refuses_stops_the_simulator_with_exit_2(capsys):
    import threading

    from mesh_sim.autopilot.options import AutopilotOptions
    from mesh_sim.autopilot.simulator import run

    options = AutopilotOptions(offboard_port=0, gcs_port=0, vehicle_params=(("warp_factor", 9.0),))
    assert run(options, threading.Event()) == 2
    assert "warp_factor" in capsys.readouterr().err  # one line on stderr: stdout carries the JSON lines
