"""The PX4 parameters the simulator honours, and their MAVLink parameter protocol encoding.

Names and defaults are PX4's (``src/modules/*/module.yaml`` / ``*_params.c``); a client reads and sets them
with PARAM_REQUEST_LIST / PARAM_REQUEST_READ / PARAM_SET and gets PARAM_VALUE back
(https://mavlink.io/en/services/parameter.html). PX4 sends integer parameters *bytewise*: the int32's
four bytes travel in the float ``param_value`` unchanged (it advertises
``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE`` in AUTOPILOT_VERSION), which is what
:func:`encode_value` / :func:`decode_value` do.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from agent.vehicles.mavlink_protocol import mavlink

REAL32 = mavlink.MAV_PARAM_TYPE_REAL32
INT32 = mavlink.MAV_PARAM_TYPE_INT32


@dataclass(frozen=True)
class ParamSpec:
    name: str
    type: int  # REAL32 or INT32
    default: float
    minimum: float
    maximum: float


#: The parameters, in PARAM_VALUE index order.
SPECS = (
    ParamSpec("MIS_TAKEOFF_ALT", REAL32, 2.5, 0.0, 10000.0),  # takeoff altitude above home [m]
    ParamSpec("COM_OF_LOSS_T", REAL32, 1.0, 0.0, 60.0),  # offboard setpoint timeout [s]
    ParamSpec("COM_DISARM_LAND", REAL32, 2.0, -1.0, 20.0),  # auto-disarm this long after landing [s]
    ParamSpec("RTL_RETURN_ALT", REAL32, 60.0, 0.0, 10000.0),  # return altitude above home [m]
    ParamSpec("BAT_LOW_THR", REAL32, 0.15, 0.0, 1.0),  # low-battery level: arming refused below it
    ParamSpec("MAV_SYS_ID", INT32, 1, 1, 250),  # this vehicle's MAVLink system id
    ParamSpec("MAV_TYPE", INT32, mavlink.MAV_TYPE_QUADROTOR, 0, 255),
)


def encode_value(spec: ParamSpec, value: float) -> float:
    """The ``param_value`` float carrying ``value`` (bytewise for INT32, as PX4 does)."""
    if spec.type == INT32:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def decode_value(spec: ParamSpec, param_value: float) -> float:
    """The value a PARAM_SET's ``param_value`` carries for ``spec``."""
    if spec.type == INT32:
        return float(struct.unpack("<i", struct.pack("<f", param_value))[0])
    return float(param_value)


class Params:
    """Current values of :data:`SPECS`, by name and by index."""

    def __init__(self, **overrides: float):
        self._specs = {spec.name: spec for spec in SPECS}
        self._values = {spec.name: float(spec.default) for spec in SPECS}
        for name, value in overrides.items():
            self.set(name, value)

    def __getitem__(self, name: str) -> float:
        return self._values[name]

    def __len__(self) -> int:
        return len(SPECS)

    def spec(self, name: str) -> ParamSpec | None:
        return self._specs.get(name)

    def set(self, name: str, value: float) -> None:
        """Set ``name``; ``ValueError`` (naming it) for an unknown name or a value outside its range."""
        spec = self._specs.get(name)
        if spec is None:
            raise ValueError(f"unknown parameter {name!r}")
        if not (math.isfinite(value) and spec.minimum <= value <= spec.maximum):
            raise ValueError(f"{name} must be within [{spec.minimum:g}, {spec.maximum:g}], got {value!r}")
        self._values[name] = float(int(value)) if spec.type == INT32 else float(value)

    def value_message(self, mav, name: str):
        """PARAM_VALUE of ``name`` encoded with the pymavlink encoder ``mav``."""
        spec = self._specs[name]
        index = SPECS.index(spec)
        return mav.param_value_encode(name.encode(), encode_value(spec, self._values[name]), spec.type, len(SPECS),
                                      index)

    def name_of(self, param_id: str, index: int) -> str | None:
        """The parameter a PARAM_REQUEST_READ names: by ``index`` when it is >= 0, else by ``param_id``."""
        if index >= 0:
            return SPECS[index].name if index < len(SPECS) else None
        return param_id if param_id in self._specs else None

    @property
    def names(self) -> list[str]:
        return [spec.name for spec in SPECS]
