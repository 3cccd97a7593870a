"""``[vehicle] kind = "mavlink"``: a PX4 or ArduPilot autopilot over MAVLink 2 (issue 14).

One job a module: :mod:`.config` (the ``[vehicle]`` keys), :mod:`.link` (the connection and its thread,
bad input counted), :mod:`.commands` (COMMAND_LONG and its ACK), :mod:`.telemetry` (what the autopilot said),
:mod:`.clock` (its time on ours), :mod:`.frames` (its local frame and the scenario's), :mod:`.guidance`
(setpoint -> position and velocity feed-forward), :mod:`.startup` (streams, arming, mode, take-off) and
:mod:`.vehicle` (the :class:`~agent.vehicles.base.Vehicle`).
"""

from agent.vehicles.mavlink.errors import CommandRefused, CommandTimeout, LinkError, MavlinkError
from agent.vehicles.mavlink.vehicle import MavlinkVehicle, from_config

__all__ = ["CommandRefused", "CommandTimeout", "LinkError", "MavlinkError", "MavlinkVehicle", "from_config"]
