"""From a connected autopilot to a vehicle flying the agent's setpoints: streams, position, arming, mode,
take-off. Every command waits for its COMMAND_ACK (:mod:`agent.vehicles.mavlink.commands`), so a refusal
stops the start with an error that names the command and the autopilot's answer.

1. **streams**: MAV_CMD_SET_MESSAGE_INTERVAL (param1 the message id, param2 the interval in µs) for every
   message the vehicle reads (:data:`STREAMS`). LOCAL_POSITION_NED and ATTITUDE are required: a refusal is an
   error. The others are optional (an autopilot without a gimbal may refuse its status): a refusal is logged.
2. **position**: wait until a LOCAL_POSITION_NED and the local frame's origin are known, asking for
   GPS_GLOBAL_ORIGIN and HOME_POSITION with MAV_CMD_REQUEST_MESSAGE (PX4 and ArduPilot send both on request).
3. **PX4** (PX4 user guide, "Offboard Mode"): the vehicle must already receive setpoints before it may be
   armed in, or switched to, OFFBOARD, so the stream starts first (the take-off point: ``takeoff_altitude``
   above home, over the vehicle); then MAV_CMD_COMPONENT_ARM_DISARM (param1 = 1) and MAV_CMD_DO_SET_MODE
   (param1 MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, param2 the PX4 main mode OFFBOARD, param3 sub mode 0). The
   vehicle climbs in OFFBOARD to the take-off point.
   **ArduPilot** (ArduCopter "Copter Commands in Guided Mode"): MAV_CMD_DO_SET_MODE GUIDED (custom mode 4),
   arm, MAV_CMD_NAV_TAKEOFF (param7 the altitude above home); position targets are streamed only once the
   take-off is over, since a new target during the take-off replaces it.

An autopilot that is armed already is not armed again (the agent restarted on a flying vehicle).
"""

from __future__ import annotations

import logging
import math
import time

from agent.vehicles.mavlink.errors import LinkError, MavlinkError
from agent.vehicles.mavlink_protocol import ARDUCOPTER_GUIDED, PX4_MAIN_OFFBOARD, mavlink

log = logging.getLogger("skymesh.mavlink")

#: message id -> (rate [Hz], required); rates chosen here: the agent runs at 5 Hz, the setpoint stream at 10 Hz
STREAMS = {
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: (20.0, True),
    mavlink.MAVLINK_MSG_ID_ATTITUDE: (20.0, True),
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: (5.0, False),
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: (1.0, False),
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: (1.0, False),
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: (1.0, False),
    mavlink.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS: (10.0, False),
}
WARMUP_SETPOINTS = 5  # setpoints streamed before PX4 is asked for OFFBOARD (chosen here: 0.5 s at 10 Hz)
POLL = 0.02  # s


def wait_until(condition, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise LinkError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(POLL)


def request_streams(commander) -> None:
    for message, (rate, required) in STREAMS.items():
        try:
            commander.run(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, message, 1e6 / rate)
        except MavlinkError as error:
            if required:
                raise
            log.info("optional stream %s not set: %s", mavlink.mavlink_map[message].msgname, error)


def wait_for_position(vehicle) -> None:
    """Until the vehicle knows where it is in the scenario's frame (step 2 of the module docstring)."""
    deadline = time.monotonic() + vehicle.config.position_timeout
    telemetry = vehicle.telemetry
    while telemetry.local is None or vehicle.frames() is None:
        for message in (mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, mavlink.MAVLINK_MSG_ID_HOME_POSITION):
            try:
                vehicle.commander.run(mavlink.MAV_CMD_REQUEST_MESSAGE, message)
            except MavlinkError as error:  # not ready yet (no GPS fix): ask again
                log.debug("request for message %d: %s", message, error)
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise LinkError(f"timed out after {vehicle.config.position_timeout:g} s waiting for a local position "
                            f"and its origin (GPS_GLOBAL_ORIGIN or HOME_POSITION)")
        try:
            wait_until(lambda: telemetry.local is not None and vehicle.frames() is not None, min(1.0, remaining),
                       "a position")
        except LinkError:
            continue


def set_mode(vehicle, custom_main: int, custom_sub: int = 0) -> None:
    vehicle.commander.run(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_main,
                          custom_sub)


def arm(vehicle) -> None:
    if not vehicle.telemetry.heartbeat.armed:
        vehicle.commander.run(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)


def start_px4(vehicle) -> None:
    vehicle.begin_takeoff(stream_during_climb=True)
    wait_until(lambda: vehicle.setpoints_sent >= WARMUP_SETPOINTS, 5.0, "the setpoint stream to start")
    arm(vehicle)
    set_mode(vehicle, PX4_MAIN_OFFBOARD)


def start_ardupilot(vehicle) -> None:
    set_mode(vehicle, ARDUCOPTER_GUIDED)
    arm(vehicle)
    vehicle.begin_takeoff(stream_during_climb=False)
    vehicle.commander.run(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, vehicle.config.takeoff_altitude)


STARTS = {"px4": start_px4, "ardupilot": start_ardupilot}


def start(vehicle) -> None:
    """The whole start-up of the module docstring for ``vehicle.config.autopilot``."""
    request_streams(vehicle.commander)
    wait_for_position(vehicle)
    STARTS[vehicle.config.autopilot](vehicle)
