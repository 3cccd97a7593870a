"""Commands to the autopilot, each confirmed by its COMMAND_ACK (MAVLink "Command Protocol").

A COMMAND_LONG is sent and answered by a COMMAND_ACK carrying the same ``command`` and a MAV_RESULT:

* MAV_RESULT_ACCEPTED: done;
* MAV_RESULT_IN_PROGRESS: the autopilot works on it (a take-off, a calibration): wait again;
* any other result (DENIED, UNSUPPORTED, FAILED, TEMPORARILY_REJECTED, CANCELLED, ...): refused —
  :class:`CommandRefused` names the command and the result;
* no answer within ``timeout``: sent again, with ``confirmation`` counting the retransmissions as the
  protocol asks (0 for the first), up to ``attempts`` times, then :class:`CommandTimeout`.

Acknowledgements arrive on the link's thread (:meth:`Commander.on_ack`) and are matched to the waiting
caller by command id; an ack addressed to another system or component is not ours (``target_system`` /
``target_component`` 0 mean "anyone", for autopilots that leave them empty).
"""

from __future__ import annotations

import threading
import time

from agent.vehicles.mavlink.errors import CommandRefused, CommandTimeout
from agent.vehicles.mavlink_protocol import mavlink


def command_name(command: int) -> str:
    entry = mavlink.enums["MAV_CMD"].get(command)
    return entry.name if entry is not None else f"MAV_CMD {command}"


def result_name(result: int) -> str:
    entry = mavlink.enums["MAV_RESULT"].get(result)
    return entry.name if entry is not None else f"MAV_RESULT {result}"


class Commander:
    """Sends COMMAND_LONGs over ``link`` (:class:`agent.vehicles.mavlink.link.MavlinkLink`) to ``target``
    (system id, component id) and waits for their acknowledgements (module docstring)."""

    def __init__(self, link, target: tuple[int, int], timeout: float, attempts: int):
        self.link, self.target, self.timeout, self.attempts = link, target, timeout, attempts
        self.sent = 0  # COMMAND_LONGs sent, retransmissions included
        self._acks: dict[int, object] = {}
        self._arrived = threading.Condition()

    def on_ack(self, msg) -> None:
        """A COMMAND_ACK from the autopilot's system (called on the link's thread)."""
        ours = (getattr(msg, "target_system", 0) in (0, self.link.connection.mav.srcSystem)
                and getattr(msg, "target_component", 0) in (0, self.link.component_id))
        if ours:
            with self._arrived:
                self._acks[msg.command] = msg
                self._arrived.notify_all()

    def run(self, command: int, *params: float) -> None:
        """Send ``command`` with up to seven ``params`` (the rest 0) until the autopilot accepts it; raises
        :class:`CommandRefused` or :class:`CommandTimeout` (module docstring)."""
        values = [*map(float, params), *[0.0] * (7 - len(params))]
        for attempt in range(self.attempts):
            with self._arrived:
                self._acks.pop(command, None)
            self.link.send(lambda mav, confirmation=attempt: mav.command_long_send(
                *self.target, command, confirmation, *values))
            self.sent += 1
            if self._acknowledged(command):
                return
        raise CommandTimeout(f"{command_name(command)}: no COMMAND_ACK from the autopilot after {self.attempts} "
                             f"tries of {self.timeout:g} s")

    def _acknowledged(self, command: int) -> bool:
        """Wait for the ack of ``command``: ``True`` if accepted, ``False`` on timeout; raises if refused."""
        deadline = time.monotonic() + self.timeout
        while True:
            with self._arrived:
                self._arrived.wait_for(lambda: command in self._acks, max(0.0, deadline - time.monotonic()))
                ack = self._acks.pop(command, None)
            if ack is None:
                return False
            if ack.result == mavlink.MAV_RESULT_ACCEPTED:
                return True
            if ack.result != mavlink.MAV_RESULT_IN_PROGRESS:
                raise CommandRefused(f"{command_name(command)}: refused by the autopilot ({result_name(ack.result)})")
            deadline = time.monotonic() + self.timeout  # in progress: the autopilot is still on it
