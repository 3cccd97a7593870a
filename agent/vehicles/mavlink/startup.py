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
ASK_AGAIN = 1.0  # s between requests for the origin and home (chosen here)
CONFIRM_TIMEOUT = 3.0  # s for the HEARTBEAT to show a new mode (three 1 Hz heartbeats; chosen here)


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
    """Until the vehicle knows where it is in the scenario's frame and where its home is (step 2 of the module
    docstring: the take-off is judged against home, so a vehicle restarted in the air is not climbed again); the
    origin and home are asked for again every :data:`ASK_AGAIN` seconds (an autopilot without a GPS fix has
    neither, and our simulator, like PX4, none before its position is valid)."""
    deadline = time.monotonic() + vehicle.config.position_timeout

    def located() -> bool:
        telemetry = vehicle.telemetry
        return telemetry.local is not None and vehicle.frames() is not None and telemetry.home is not None

    while not located():
        if time.monotonic() > deadline:
            raise LinkError(f"timed out after {vehicle.config.position_timeout:g} s waiting for a local position "
                            f", its origin (GPS_GLOBAL_ORIGIN or HOME_POSITION) and home (HOME_POSITION)")
        for message in (mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, mavlink.MAVLINK_MSG_ID_HOME_POSITION):
            try:
                vehicle.commander.run(mavlink.MAV_CMD_REQUEST_MESSAGE, message)
            except MavlinkError as error:  # not ready yet: ask again
                log.debug("request for message %d: %s", message, error)
        asked = time.monotonic()
        while not located() and time.monotonic() - asked < ASK_AGAIN:
            time.sleep(POLL)


def set_mode(vehicle, custom_main: int, custom_sub: int = 0) -> None:
    vehicle.commander.run(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_main,
                          custom_sub)


def arm(vehicle) -> None:
    if not vehicle.telemetry.heartbeat.armed:
        vehicle.commander.run(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)


def confirmed(vehicle, mode: int) -> None:
    """Wait for the HEARTBEAT that shows the vehicle armed in ``mode`` (an ACK says the command was taken; the
    heartbeat, sent at 1 Hz, says it took effect)."""
    def done() -> bool:
        heartbeat = vehicle.telemetry.heartbeat
        return heartbeat.armed and vehicle.mode_of(heartbeat.custom_mode) == mode

    wait_until(done, CONFIRM_TIMEOUT, f"a HEARTBEAT showing the vehicle armed in custom mode {mode}")


def start_px4(vehicle) -> None:
    vehicle.begin_takeoff(stream_during_climb=True)
    wait_until(lambda: vehicle.setpoints_sent >= WARMUP_SETPOINTS, 5.0, "the setpoint stream to start")
    arm(vehicle)
    set_mode(vehicle, PX4_MAIN_OFFBOARD)
    confirmed(vehicle, PX4_MAIN_OFFBOARD)


def start_ardupilot(vehicle) -> None:
    set_mode(vehicle, ARDUCOPTER_GUIDED)
    arm(vehicle)
    confirmed(vehicle, ARDUCOPTER_GUIDED)
    vehicle.begin_takeoff(stream_during_climb=False)
    vehicle.commander.run(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, vehicle.config.takeoff_altitude)


STARTS = {"px4": (start_px4, PX4_MAIN_OFFBOARD), "ardupilot": (start_ardupilot, ARDUCOPTER_GUIDED)}


def start(vehicle) -> int:
    """The whole start-up of the module docstring for ``vehicle.autopilot``; returns the mode (PX4 main
    mode, ArduPilot custom mode) the vehicle must stay in."""
    request_streams(vehicle.commander)
    wait_for_position(vehicle)
    run, mode = STARTS[vehicle.autopilot]
    run(vehicle)
    return mode
