"""Command-line options of ``skymesh autopilot`` / ``python -m mesh_sim.autopilot`` (one parser for both).

Defaults reproduce PX4 SITL instance ``I`` (:mod:`agent.vehicles.mavlink_protocol`): system id ``1 + I``
(PX4 SITL's ``MAV_SYS_ID``), offboard link bound on ``14580 + I`` sending to ``14540 + I``, ground-station
link bound on ``18570 + I`` sending to ``14550``. Every port can be overridden, so that tests and
benchmarks run on free ports.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

from agent.vehicles.mavlink_protocol import (
    PX4_GCS_PORT,
    PX4_LOCAL_GCS_PORT,
    PX4_LOCAL_OFFBOARD_PORT,
    PX4_OFFBOARD_PORT,
)

#: skymesh's default scenario origin (lat, lon [deg], alt [m]), ``agent.config.AgentScenario.origin`` (a test keeps
#: them equal; importing agent.config here would cost the simulator two seconds of start-up)
DEFAULT_ORIGIN = (43.5605, 1.4664, 150.0)


@dataclass(frozen=True)
class AutopilotOptions:
    instance: int = 0
    sysid: int | None = None  # None: 1 + instance
    vehicle: str = "multirotor"
    vehicle_params: tuple[tuple[str, float], ...] = ()  # the model's [vehicle] keys, e.g. (("max_speed", 12.0),)
    north: float = 0.0  # start position [m] from the origin
    east: float = 0.0
    heading_deg: float = 0.0
    altitude: float = 0.0  # start height [m] above the origin; > 0: in the air, armed, holding (not PX4 SITL's way)
    origin: tuple[float, float, float] = DEFAULT_ORIGIN
    host: str = "127.0.0.1"  # where the remote ends are, and the address the local ports bind
    offboard_port: int | None = None  # None: 14580 + instance
    offboard_remote_port: int | None = None  # None: 14540 + instance
    gcs_port: int | None = None  # None: 18570 + instance
    gcs_remote_port: int = PX4_GCS_PORT
    latency_ms: float = 0.0  # one-way delay of every datagram, each direction
    flight_time: float = 1200.0  # s of armed flight on a full battery
    battery: float = 1.0  # initial charge, 0..1
    position_valid_after: float = 1.5  # s after boot
    duration: float | None = None  # s: exit after this long (None: run until stopped)
    parent_pid: int | None = None
    stats: Path | None = None

    @property
    def system_id(self) -> int:
        return 1 + self.instance if self.sysid is None else self.sysid

    @property
    def offboard_bind(self) -> tuple[str, int]:
        return self.host, PX4_LOCAL_OFFBOARD_PORT + self.instance if self.offboard_port is None else self.offboard_port

    @property
    def offboard_remote(self) -> tuple[str, int]:
        port = PX4_OFFBOARD_PORT + self.instance if self.offboard_remote_port is None else self.offboard_remote_port
        return self.host, port

    @property
    def gcs_bind(self) -> tuple[str, int]:
        return self.host, PX4_LOCAL_GCS_PORT + self.instance if self.gcs_port is None else self.gcs_port

    @property
    def gcs_remote(self) -> tuple[str, int]:
        return self.host, self.gcs_remote_port


def _origin(text: str) -> tuple[float, float, float]:
    try:
        lat, lon, alt = (float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LAT,LON,ALT (degrees, degrees, metres), got {text!r}") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 360 and math.isfinite(alt)):
        raise argparse.ArgumentTypeError(f"origin out of range: {text!r}")
    return lat, lon, alt


def _vehicle_param(text: str) -> tuple[str, float]:
    """``max_speed=12`` -> ``("max_speed", 12.0)``: one ``[vehicle]`` key of the kinematic model."""
    key, sep, value = text.partition("=")
    try:
        number = float(value)
    except ValueError:
        number = None
    if not sep or not key or number is None:
        raise argparse.ArgumentTypeError(f"expected KEY=NUMBER (a [vehicle] key), got {text!r}")
    return key, number


def _port(text: str) -> int:
    value = int(text)
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"a UDP port is 0..65535 (0: any free port), got {text}")
    return value


def _non_negative(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be a non-negative number, got {text}")
    return value


def _fraction(text: str) -> float:
    value = float(text)
    if not 0 <= value <= 1:
        raise argparse.ArgumentTypeError(f"must be within [0, 1], got {text}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The autopilot simulator's options, added to ``parser``."""
    parser.add_argument("--instance", type=int, default=0, help="PX4 SITL instance number I (ports, system id)")
    parser.add_argument("--sysid", type=int, help="MAVLink system id (default 1 + I)")
    parser.add_argument("--vehicle", choices=["multirotor", "fixed_wing"], default="multirotor")
    parser.add_argument("--vehicle-param", type=_vehicle_param, action="append", default=[], dest="vehicle_params",
                        metavar="KEY=NUMBER", help="a [vehicle] key of the kinematic model, e.g. max_speed=12 "
                        "(repeatable; a scenario's keys, as skymesh run --vehicle mavlink passes them)")
    parser.add_argument("--north", type=float, default=AutopilotOptions.north,
                        help="start position north of the origin [m]")
    parser.add_argument("--east", type=float, default=AutopilotOptions.east,
                        help="start position east of the origin [m]")
    parser.add_argument("--heading", type=float, default=AutopilotOptions.heading_deg, dest="heading_deg",
                        help="start heading [deg]")
    parser.add_argument("--altitude", type=_non_negative, default=AutopilotOptions.altitude,
                        help="start this high [m], armed and holding (default 0: on the ground, as PX4 SITL boots); "
                             "skymesh run --vehicle mavlink starts at the scenario's altitude, as its kinematic runs")
    parser.add_argument("--origin", type=_origin, default=AutopilotOptions.origin, metavar="LAT,LON,ALT",
                        help="NED origin and GPS_GLOBAL_ORIGIN (default: skymesh's default scenario origin)")
    parser.add_argument("--host", default=AutopilotOptions.host,
                        help="address to bind and to send to (default 127.0.0.1)")
    parser.add_argument("--offboard-port", type=_port, help="local offboard port (default 14580 + I)")
    parser.add_argument("--offboard-remote-port", type=_port, help="offboard computer's port (default 14540 + I)")
    parser.add_argument("--gcs-port", type=_port, help="local ground-station port (default 18570 + I)")
    parser.add_argument("--gcs-remote-port", type=_port, default=AutopilotOptions.gcs_remote_port,
                        help="ground station's port (14550)")
    parser.add_argument("--latency-ms", type=_non_negative, default=AutopilotOptions.latency_ms,
                        help="one-way delay, each direction [ms]")
    parser.add_argument("--flight-time", type=float, default=AutopilotOptions.flight_time,
                        help="armed seconds on a full battery")
    parser.add_argument("--battery", type=_fraction, default=AutopilotOptions.battery,
                        help="initial battery charge, 0..1")
    parser.add_argument("--position-valid-after", type=_non_negative,
                        default=AutopilotOptions.position_valid_after,
                        help="seconds after boot before the position estimate is valid (arming refused before)")
    parser.add_argument("--duration", type=_non_negative, help="exit after this many seconds")
    parser.add_argument("--parent-pid", type=int, help="exit when this process is gone")
    parser.add_argument("--stats", type=Path, help="write the counters as JSON to this file at exit")


def options_from_args(args: argparse.Namespace) -> AutopilotOptions:
    fields = AutopilotOptions.__dataclass_fields__
    values = {name: getattr(args, name) for name in fields if hasattr(args, name)}
    values["vehicle_params"] = tuple(values.get("vehicle_params", ()))
    return AutopilotOptions(**values)
