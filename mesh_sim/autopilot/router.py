"""Incoming MAVLink messages -> the part of the simulator that handles them, and the replies.

What a PX4 ``mavlink_receiver`` does with the messages simulated here:

* COMMAND_LONG / COMMAND_INT -> :mod:`~mesh_sim.autopilot.commands`, answered by COMMAND_ACK (addressed to
  the sender) and any requested message;
* SET_POSITION_TARGET_LOCAL_NED -> the offboard setpoint (:mod:`~mesh_sim.autopilot.offboard`);
* PARAM_REQUEST_LIST / PARAM_REQUEST_READ / PARAM_SET -> PARAM_VALUE (:mod:`~mesh_sim.autopilot.params`);
  PX4 answers a PARAM_SET of an unknown name with nothing, and a rejected value with the current value;
* TIMESYNC with ``tc1 == 0`` (a request) -> TIMESYNC with ``tc1`` = our time in ns and ``ts1`` echoed;
* PING with ``target_system == 0`` (a request; MAVSDK sends one a second) -> PING echoing ``time_usec`` and
  ``seq``, addressed to the sender (PX4 ``handle_message_ping``);
* GIMBAL_MANAGER_SET_PITCHYAW -> the gimbal (radians);
* FILE_TRANSFER_PROTOCOL -> a NAK (:mod:`~mesh_sim.autopilot.ftp`: no file system here);
* anything else (HEARTBEAT of a ground station, ...) is counted by type and otherwise ignored.

A message whose ``target_system`` is neither 0 (broadcast) nor ours, or whose ``target_component`` is
neither 0 nor the autopilot's, is not for us: it is counted (``other_target``) and ignored, as PX4 does.
"""

from __future__ import annotations

from agent.vehicles.mavlink_protocol import mavlink
from mesh_sim.autopilot import ftp
from mesh_sim.autopilot.commands import Command, CommandHandler
from mesh_sim.autopilot.counters import Counters
from mesh_sim.autopilot.flight import FlightController
from mesh_sim.autopilot.offboard import SetpointRejected, decode_target
from mesh_sim.autopilot.params import Params, decode_value
from mesh_sim.autopilot.streams import StreamSchedule
from mesh_sim.autopilot.telemetry import Telemetry

COMPONENT = mavlink.MAV_COMP_ID_AUTOPILOT1


class MessageRouter:
    def __init__(self, controller: FlightController, telemetry: Telemetry, params: Params, counters: Counters):
        self.controller = controller
        self.telemetry = telemetry
        self.params = params
        self.counters = counters
        self.commands = CommandHandler(controller, telemetry)
        self._handlers = {
            "COMMAND_LONG": self._command,
            "COMMAND_INT": self._command,
            "SET_POSITION_TARGET_LOCAL_NED": self._position_target,
            "PARAM_REQUEST_LIST": self._param_list,
            "PARAM_REQUEST_READ": self._param_read,
            "PARAM_SET": self._param_set,
            "TIMESYNC": self._timesync,
            "PING": self._ping,
            "FILE_TRANSFER_PROTOCOL": self._ftp,
            "GIMBAL_MANAGER_SET_PITCHYAW": self._gimbal_pitchyaw,
        }

    def handle(self, msg, streams: StreamSchedule) -> list:
        """The replies to ``msg``, received on the link whose streams are ``streams``."""
        if not self._for_us(msg):
            self.counters.reject("other_target")
            return []
        handler = self._handlers.get(msg.get_type())
        return [] if handler is None else handler(msg, streams)

    def _for_us(self, msg) -> bool:
        system = getattr(msg, "target_system", 0)
        component = getattr(msg, "target_component", 0)
        return system in (0, self.telemetry.sysid) and component in (0, COMPONENT)

    def _command(self, msg, streams):
        command = Command.from_message(msg)
        outcome, messages = self.commands.execute(command, streams)
        if outcome.result == mavlink.MAV_RESULT_UNSUPPORTED:
            self.counters.reject("unsupported_command")
        ack = self.telemetry.encoder.command_ack_encode(command.command, outcome.result, 0, 0,
                                                        msg.get_srcSystem(), msg.get_srcComponent())
        return [ack, *messages]

    def _position_target(self, msg, streams):
        c = self.controller
        state = c.model.state()
        try:
            c.set_offboard_target(decode_target(msg, state.position, state.yaw, c.t))
        except SetpointRejected as rejected:
            self.counters.reject(rejected.reason)
        return []

    def _param_list(self, msg, streams):
        return [self.params.value_message(self.telemetry.encoder, name) for name in self.params.names]

    def _param_read(self, msg, streams):
        name = self.params.name_of(_param_id(msg), msg.param_index)
        if name is None:
            self.counters.reject("unknown_parameter")
            return []
        return [self.params.value_message(self.telemetry.encoder, name)]

    def _param_set(self, msg, streams):
        name = _param_id(msg)
        spec = self.params.spec(name)
        if spec is None:
            self.counters.reject("unknown_parameter")
            return []
        try:
            self.params.set(name, decode_value(spec, msg.param_value))
        except ValueError:
            self.counters.reject("bad_parameter_value")
        return [self.params.value_message(self.telemetry.encoder, name)]

    def _timesync(self, msg, streams):
        if msg.tc1 != 0:  # a reply to someone's request, not a request
            return []
        return [self.telemetry.encoder.timesync_encode(int(self.controller.t * 1e9), msg.ts1)]

    def _ping(self, msg, streams):
        if msg.target_system != 0:  # a reply, not a request
            return []
        return [self.telemetry.encoder.ping_encode(msg.time_usec, msg.seq, msg.get_srcSystem(), msg.get_srcComponent())]

    def _ftp(self, msg, streams):
        payload = ftp.nak(msg.payload)
        if payload is None:
            return []
        return [self.telemetry.encoder.file_transfer_protocol_encode(0, msg.get_srcSystem(), msg.get_srcComponent(),
                                                                     payload)]

    def _gimbal_pitchyaw(self, msg, streams):
        self.controller.gimbal.point(msg.pitch, msg.yaw)
        return []


def _param_id(msg) -> str:
    param_id = msg.param_id
    return param_id.decode(errors="replace") if isinstance(param_id, bytes) else str(param_id)
