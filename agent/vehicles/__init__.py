"""Vehicles (DESIGN §4): the ``[vehicle]`` table of a scenario -> a :class:`agent.vehicles.base.Vehicle`.

To add a vehicle, write a module in this package that defines

* ``from_config(params: dict, initial_position, initial_heading: float) -> Vehicle`` — the vehicle for
  the ``[vehicle]`` table without its ``kind`` key, starting at the NED ``initial_position`` with the
  heading ``initial_heading`` (rad); a bad key or value is a ``ValueError`` that names it,

and add a :class:`VehicleFactory` entry to :data:`VEHICLES`. A ``georeferenced`` vehicle (one that maps
geodetic positions into the scenario's frame) also takes ``origin``, the scenario's ``(lat, lon, alt)``.
Modules are imported only when their vehicle is built, so a vehicle's dependencies (a MAVLink library) cost
nothing to the others.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from agent.vehicles.base import Vehicle


@dataclass(frozen=True)
class VehicleFactory:
    kind: str  # the [vehicle] kind
    module: str  # dotted path of the module that defines from_config()
    description: str
    georeferenced: bool = False  # from_config also takes the scenario's geodetic origin

    def load(self):
        return importlib.import_module(self.module)

    def __call__(self, params: dict, initial_position, initial_heading: float = 0.0, origin=None) -> Vehicle:
        if self.georeferenced:
            return self.load().from_config(params, initial_position, initial_heading, origin)
        return self.load().from_config(params, initial_position, initial_heading)


VEHICLES: dict[str, VehicleFactory] = {
    v.kind: v
    for v in [
        VehicleFactory(
            "multirotor",
            "agent.vehicles.multirotor",
            "kinematic multirotor: acceleration-limited point mass that hovers at a point or orbits it",
        ),
        VehicleFactory(
            "fixed_wing",
            "agent.vehicles.fixed_wing",
            "kinematic fixed wing: constant airspeed, coordinated turns, loiters around a point",
        ),
        VehicleFactory(
            "mavlink",
            "agent.vehicles.mavlink",
            "a PX4 or ArduPilot autopilot over MAVLink 2 (real or SITL): setpoints streamed, telemetry read",
            georeferenced=True,
        ),
    ]
}


def vehicle_from_config(config: dict, initial_position, initial_heading: float = 0.0, origin=None) -> Vehicle:
    """Build a vehicle from ``{"kind": "multirotor" | "fixed_wing" | "mavlink", ...}`` (a key of :data:`VEHICLES`).

    Angles are in degrees in the config (DESIGN §3: degrees only at the edges) and say so in their
    names: ``yaw_rate_deg``, ``max_bank_deg``, ``roll_rate_deg``. Other keys are SI units
    (``max_speed``, ``max_accel``, ``max_climb``, ``position_gain`` for a multirotor; ``airspeed``,
    ``climb_rate``, ``heading_gain``, ``altitude_gain``, ``loiter_margin`` for a fixed wing). Missing
    keys take the model defaults. ``initial_heading`` (rad) is the multirotor's initial yaw or the
    fixed wing's heading. ``origin``: the scenario's geodetic origin ``(lat, lon, alt)``, which a MAVLink
    vehicle needs (its keys: :mod:`agent.vehicles.mavlink.config`). Raises ``ValueError`` naming the field
    for an unknown kind, an unknown key or a bad value.
    """
    if not isinstance(config, dict):
        raise ValueError(f"vehicle config must be a dict, got {type(config).__name__}")
    kind = config.get("kind")
    if kind not in VEHICLES:
        raise ValueError(f"kind: unknown vehicle kind {kind!r}, expected one of {sorted(VEHICLES)}")
    params = {key: value for key, value in config.items() if key != "kind"}
    return VEHICLES[kind](params, initial_position, initial_heading, origin)
