"""What goes wrong between the MAVLink vehicle and its autopilot, as exceptions that say what and why.

:class:`MavlinkError` is the family: ``python -m agent --mavlink URL`` turns any of them into exit code 2
before the agent starts.
"""

from __future__ import annotations

from agent.vehicles.base import VehicleError


class MavlinkError(VehicleError):
    """The MAVLink vehicle cannot do what was asked of it."""


class LinkError(MavlinkError):
    """The link cannot be opened, no autopilot heartbeat arrived, or the autopilot never sent what the
    vehicle needs (its position, its local frame's origin)."""


class CommandRefused(MavlinkError):
    """The autopilot answered a COMMAND_LONG with a COMMAND_ACK whose result is not MAV_RESULT_ACCEPTED."""


class CommandTimeout(MavlinkError):
    """No COMMAND_ACK came back for a command after every try."""
