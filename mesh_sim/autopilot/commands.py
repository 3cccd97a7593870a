"""MAVLink commands (COMMAND_LONG and COMMAND_INT) -> the flight controller, the gimbal, the streams.

The command protocol (https://mavlink.io/en/services/command.html): every command addressed to this
vehicle gets one COMMAND_ACK with a MAV_RESULT; a command it does not implement gets
``MAV_RESULT_UNSUPPORTED``, as PX4 answers. For a message request the ACK comes first, then the message
(MAV_CMD_REQUEST_MESSAGE, and the older MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES that MAVSDK still sends).
COMMAND_INT carries params 5 and 6 as integers (``x``, ``y``) and param 7 as ``z``; the commands handled
here read them as numbers alike.

Parameters per command (MAVLink common.xml, PX4 ``Commander::handle_command``):

* COMPONENT_ARM_DISARM: p1 1 arm / 0 disarm, p2 21196 forces;
* NAV_TAKEOFF: p7 altitude AMSL (NaN: ``MIS_TAKEOFF_ALT`` above home);
* DO_SET_MODE: p1 base mode (``MAV_MODE_FLAG_CUSTOM_MODE_ENABLED`` required), p2 PX4 main mode, p3 sub mode;
* NAV_LAND, NAV_RETURN_TO_LAUNCH: no parameters used;
* SET_MESSAGE_INTERVAL: p1 message id, p2 interval µs; REQUEST_MESSAGE: p1 message id;
* DO_GIMBAL_MANAGER_PITCHYAW: p1 pitch, p2 yaw (degrees; NaN: keep).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from agent.vehicles.mavlink_protocol import mavlink
from mesh_sim.autopilot.flight import ACCEPTED, DENIED, FORCE_DISARM, TEMPORARILY_REJECTED, FlightController, Outcome
from mesh_sim.autopilot.streams import StreamSchedule
from mesh_sim.autopilot.telemetry import Telemetry

UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED


@dataclass(frozen=True)
class Command:
    """One COMMAND_LONG or COMMAND_INT: its id and params 1-7 as floats."""

    command: int
    params: tuple[float, ...]

    @classmethod
    def from_message(cls, msg) -> Command:
        if msg.get_type() == "COMMAND_INT":
            return cls(msg.command, (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y),
                                     msg.z))
        return cls(msg.command, (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7))

    def integer(self, index: int) -> int:
        """Param ``index`` (1-based) as an int; ``ValueError`` if it is not a finite whole number."""
        value = self.params[index - 1]
        if not (math.isfinite(value) and value == int(value)):
            raise ValueError(f"param{index} of command {self.command} must be a whole number, got {value!r}")
        return int(value)


class CommandHandler:
    def __init__(self, controller: FlightController, telemetry: Telemetry):
        self.controller = controller
        self.telemetry = telemetry
        self._handlers = {
            mavlink.MAV_CMD_COMPONENT_ARM_DISARM: self._arm_disarm,
            mavlink.MAV_CMD_NAV_TAKEOFF: self._takeoff,
            mavlink.MAV_CMD_DO_SET_MODE: self._set_mode,
            mavlink.MAV_CMD_NAV_LAND: lambda command, streams: (controller.land(), []),
            mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: lambda command, streams: (controller.return_to_launch(), []),
            mavlink.MAV_CMD_SET_MESSAGE_INTERVAL: self._set_message_interval,
            mavlink.MAV_CMD_REQUEST_MESSAGE: self._request_message,
            mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._request_autopilot_capabilities,
            mavlink.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW: self._gimbal_pitchyaw,
        }

    def execute(self, command: Command, streams: StreamSchedule) -> tuple[Outcome, list]:
        """The outcome of ``command`` received on the link of ``streams``, and the messages to send after the ACK.

        A parameter the command cannot use (NaN where a number is needed, a fraction where an id is) is
        ``MAV_RESULT_DENIED`` with the reason."""
        handler = self._handlers.get(command.command)
        if handler is None:
            return Outcome(UNSUPPORTED, f"command {command.command} is not supported"), []
        try:
            return handler(command, streams)
        except ValueError as error:
            return Outcome(DENIED, str(error)), []

    def _arm_disarm(self, command: Command, streams):
        arm = command.integer(1)
        if arm == 1:
            return self.controller.arm(), []
        if arm == 0:
            return self.controller.disarm(force=command.params[1] == FORCE_DISARM), []
        raise ValueError(f"param1 of COMPONENT_ARM_DISARM must be 0 or 1, got {arm}")

    def _takeoff(self, command: Command, streams):
        altitude = command.params[6]
        height = altitude - self.telemetry.home_altitude() if math.isfinite(altitude) else None
        return self.controller.takeoff(height), []

    def _set_mode(self, command: Command, streams):
        if not command.integer(1) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            raise ValueError("DO_SET_MODE without MAV_MODE_FLAG_CUSTOM_MODE_ENABLED is not supported")
        sub = command.integer(3) if math.isfinite(command.params[2]) else 0
        return self.controller.set_mode(command.integer(2), sub), []

    def _set_message_interval(self, command: Command, streams: StreamSchedule):
        msg_id = command.integer(1)
        if streams.set_interval(msg_id, command.params[1]):
            return Outcome(ACCEPTED), []
        return Outcome(DENIED, f"message {msg_id} cannot be streamed at interval {command.params[1]!r} µs"), []

    def _send_once(self, msg_id: int):
        if not self.telemetry.supports(msg_id):
            return Outcome(DENIED, f"message {msg_id} is not supported"), []
        msg = self.telemetry.message(msg_id)
        if msg is None:
            return Outcome(TEMPORARILY_REJECTED, f"message {msg_id} is not available yet"), []
        return Outcome(ACCEPTED), [msg]

    def _request_message(self, command: Command, streams):
        return self._send_once(command.integer(1))

    def _request_autopilot_capabilities(self, command: Command, streams):
        return self._send_once(mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)

    def _gimbal_pitchyaw(self, command: Command, streams):
        self.controller.gimbal.point(math.radians(command.params[0]), math.radians(command.params[1]))
        return Outcome(ACCEPTED), []
