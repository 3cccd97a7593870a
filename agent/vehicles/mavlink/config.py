"""The ``[vehicle] kind = "mavlink"`` table: where the autopilot is, which one it is, how long to wait.

Keys (SI units; every default chosen here unless it cites a source):

================== ======================= =================================================================
key                default                 meaning
================== ======================= =================================================================
``url``            (required)              pymavlink connection string: ``udpin:0.0.0.0:14540`` (PX4 SITL's
                                           offboard link), ``udpout:host:port``, ``tcp:127.0.0.1:5760``
                                           (ArduPilot SITL), or a serial device such as ``/dev/ttyUSB0``
``baud``           57600                   serial baud rate (a SiK radio's default); ignored for UDP/TCP
``autopilot``      ``"auto"``              ``"px4"`` or ``"ardupilot"``: the start-up sequence and modes;
                                           ``"auto"``: the HEARTBEAT's MAV_AUTOPILOT says
``takeoff_altitude`` 10.0                  metres above home at which the take-off ends
``cruise_speed``   5.0                     m/s: orbit speed and the default speed limit of a setpoint
``max_accel``      3.0                     m/s²: orbits are flown at most at sqrt(0.8 max_accel r), as the
                                           kinematic multirotor flies them (v²/r within the limit)
``setpoint_rate_hz`` 10.0                  SET_POSITION_TARGET_LOCAL_NED stream rate (PX4 leaves OFFBOARD
                                           below 2 Hz: PX4 user guide, "Offboard Mode")
``heartbeat_timeout`` 2.0                  s without an autopilot HEARTBEAT = link lost (issue 14: > 2 s)
``stream_timeout`` 1.0                     s without a LOCAL_POSITION_NED (requested at 30 Hz: ~30 missed) =
                                           the pose is stale and the link presumed lost
``connect_timeout`` 10.0                   s to wait for the first autopilot HEARTBEAT
``position_timeout`` 30.0                  s to wait for a position and the local frame's origin
``command_timeout`` 1.0                    s to wait for a COMMAND_ACK before sending the command again
``command_attempts`` 3                     times a command is sent before it times out
``battery_reserve`` 0.2                    remaining charge (0-1) below which the vehicle is unhealthy
``max_message_rate`` 2000.0                messages per second the link parses; beyond it input is dropped
                                           and counted as a flood
``component_id``   191                     this process's component id (MAV_COMP_ID_ONBOARD_COMPUTER)
================== ======================= =================================================================
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from agent.vehicles.mavlink_protocol import mavlink
from fusion.validation import positive

AUTOPILOTS = ("auto", "px4", "ardupilot")
URL_SCHEMES = ("udpin:", "udpout:", "udp:", "udpbcast:", "tcp:", "tcpin:")


@dataclass(frozen=True)
class MavlinkConfig:
    url: str
    baud: int = 57600
    autopilot: str = "auto"
    takeoff_altitude: float = 10.0
    cruise_speed: float = 5.0
    max_accel: float = 3.0
    setpoint_rate_hz: float = 10.0
    heartbeat_timeout: float = 2.0
    stream_timeout: float = 1.0
    connect_timeout: float = 10.0
    position_timeout: float = 30.0
    command_timeout: float = 1.0
    command_attempts: int = 3
    battery_reserve: float = 0.2
    max_message_rate: float = 2000.0
    component_id: int = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER

    def __post_init__(self):
        if not isinstance(self.url, str) or not (self.url.startswith(URL_SCHEMES) or self._is_device(self.url)):
            raise ValueError(f"url: expected a pymavlink connection string ({', '.join(URL_SCHEMES)}host:port, "
                             f"or a serial device path), got {self.url!r}")
        if self.autopilot not in AUTOPILOTS:
            raise ValueError(f"autopilot: expected one of {list(AUTOPILOTS)}, got {self.autopilot!r}")
        for name in ("baud", "command_attempts"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: must be a positive integer, got {value!r}")
        if isinstance(self.component_id, bool) or not isinstance(self.component_id, int) \
                or not 1 <= self.component_id <= 255:
            raise ValueError(f"component_id: must be an integer in [1, 255], got {self.component_id!r}")
        for name in ("takeoff_altitude", "cruise_speed", "max_accel", "setpoint_rate_hz", "heartbeat_timeout",
                     "stream_timeout", "connect_timeout", "position_timeout", "command_timeout", "max_message_rate"):
            try:
                positive(name, getattr(self, name))
            except ValueError as error:
                raise ValueError(f"{name}: {error}") from None
        if isinstance(self.battery_reserve, bool) or not isinstance(self.battery_reserve, int | float) \
                or not 0 <= self.battery_reserve < 1:
            raise ValueError(f"battery_reserve: must be a fraction in [0, 1), got {self.battery_reserve!r}")

    @staticmethod
    def _is_device(url: str) -> bool:
        return url.startswith("/dev/") or url.upper().startswith("COM")

    @classmethod
    def from_params(cls, params: dict) -> MavlinkConfig:
        """The config of a ``[vehicle]`` table without its ``kind``; ``ValueError`` names a missing, unknown or
        bad key."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(params) - known)
        if unknown:
            raise ValueError(f"{unknown[0]}: unknown mavlink parameter, expected some of {sorted(known)}")
        if "url" not in params:
            raise ValueError("url: the mavlink vehicle needs the autopilot's connection string")
        return cls(**params)
