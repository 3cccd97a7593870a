"""What the autopilot last said about itself, kept from the messages the link delivers.

Each handler replaces one frozen record, so the agent's thread reads a consistent record while the link's
thread writes the next one (an attribute assignment is atomic in CPython). A message whose fields are out
of range (a latitude beyond ±90°, a NaN position, ...) raises ``ValueError`` and changes nothing; the link
counts it as ``bad_value``.

Messages and their fields (MAVLink common.xml):

* HEARTBEAT: ``base_mode`` (MAV_MODE_FLAG_SAFETY_ARMED), ``custom_mode`` (the flight mode), ``autopilot``
  (MAV_AUTOPILOT), arrival time;
* LOCAL_POSITION_NED: ``x, y, z`` [m], ``vx, vy, vz`` [m/s] in the autopilot's local frame, ``time_boot_ms``;
* ATTITUDE (``roll, pitch, yaw`` [rad]) or ATTITUDE_QUATERNION (``q1..q4`` = w, x, y, z);
* GLOBAL_POSITION_INT: ``lat, lon`` [degE7], ``alt`` (AMSL) and ``relative_alt`` [mm];
* GPS_GLOBAL_ORIGIN: the EKF origin ``latitude, longitude`` [degE7], ``altitude`` [mm AMSL];
* HOME_POSITION: home ``latitude, longitude, altitude`` and its local ``x, y, z``;
* BATTERY_STATUS ``battery_remaining`` [%] (-1: unknown), ``fault_bitmask``; SYS_STATUS ``battery_remaining``
  and ``onboard_control_sensors_{present,enabled,health}`` (a present, enabled sensor that is not healthy is
  a failure);
* EXTENDED_SYS_STATE ``landed_state`` (MAV_LANDED_STATE);
* GIMBAL_DEVICE_ATTITUDE_STATUS (gimbal protocol v2): ``q`` (w, x, y, z) and ``flags``: the yaw is relative
  to the vehicle's heading with GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME, to north with ..._YAW_IN_EARTH_FRAME,
  and, with neither (older gimbals, as the message's definition says), to north only with ..._YAW_LOCK.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agent.vehicles.mavlink_protocol import mavlink
from perception.rotations import euler_from_rotation, rotation_from_quaternion

SENSOR_BITS = ("onboard_control_sensors_present", "onboard_control_sensors_enabled",
               "onboard_control_sensors_health")


@dataclass(frozen=True)
class Heartbeat:
    arrival: float  # local monotonic time [s]
    base_mode: int
    custom_mode: int
    autopilot: int  # MAV_AUTOPILOT

    @property
    def armed(self) -> bool:
        return bool(self.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)


@dataclass(frozen=True)
class LocalPosition:
    time_boot_ms: int
    arrival: float  # local monotonic time [s]
    position: np.ndarray  # autopilot local NED [m]
    velocity: np.ndarray  # [m/s]


@dataclass(frozen=True)
class GimbalAttitude:
    time_boot_ms: int
    roll: float
    pitch: float
    yaw: float  # [rad], from north, or from the vehicle's nose when ``yaw_in_vehicle_frame``
    yaw_in_vehicle_frame: bool


def _finite(*values) -> None:
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"non-finite value in {values}")


def _geodetic(lat_e7: int, lon_e7: int, alt_mm: int) -> tuple[float, float, float]:
    lat, lon = lat_e7 * 1e-7, lon_e7 * 1e-7
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise ValueError(f"latitude/longitude out of range: {lat}, {lon}")
    return lat, lon, alt_mm * 1e-3


def _euler(w: float, x: float, y: float, z: float) -> tuple[float, float, float]:
    roll, pitch, yaw = euler_from_rotation(rotation_from_quaternion([x, y, z, w]))
    return float(roll), float(pitch), float(yaw)


class Telemetry:
    """The latest of each record (``None`` until its message arrived), updated by :meth:`handle`."""

    def __init__(self):
        self.heartbeat: Heartbeat | None = None
        self.local: LocalPosition | None = None
        self.attitude: tuple[float, float, float] | None = None  # roll, pitch, yaw [rad]
        self.global_position: tuple[float, float, float] | None = None  # lat, lon [deg], alt AMSL [m]
        self.origin: tuple[float, float, float] | None = None  # GPS_GLOBAL_ORIGIN
        self.home: tuple[tuple[float, float, float], np.ndarray] | None = None  # geodetic, local NED
        self.battery: float | None = None  # remaining charge, 0-1
        self.battery_fault = False
        self.sensors_failed = False
        self.landed_state: int | None = None
        self.gimbal: GimbalAttitude | None = None

    def handle(self, msg, arrival: float) -> None:
        """Take one message from the autopilot's system, received at local monotonic time ``arrival``."""
        handler = getattr(self, "_on_" + msg.get_type().lower(), None)
        if handler is not None:
            handler(msg, arrival)

    def _on_heartbeat(self, msg, arrival: float) -> None:
        self.heartbeat = Heartbeat(arrival, msg.base_mode, msg.custom_mode, msg.autopilot)

    def _on_local_position_ned(self, msg, arrival: float) -> None:
        values = (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz)
        _finite(*values)
        self.local = LocalPosition(msg.time_boot_ms, arrival, np.array(values[:3]), np.array(values[3:]))

    def _on_attitude(self, msg, arrival: float) -> None:
        _finite(msg.roll, msg.pitch, msg.yaw)
        self.attitude = (msg.roll, msg.pitch, msg.yaw)

    def _on_attitude_quaternion(self, msg, arrival: float) -> None:
        _finite(msg.q1, msg.q2, msg.q3, msg.q4)
        self.attitude = _euler(msg.q1, msg.q2, msg.q3, msg.q4)

    def _on_global_position_int(self, msg, arrival: float) -> None:
        self.global_position = _geodetic(msg.lat, msg.lon, msg.alt)

    def _on_gps_global_origin(self, msg, arrival: float) -> None:
        self.origin = _geodetic(msg.latitude, msg.longitude, msg.altitude)

    def _on_home_position(self, msg, arrival: float) -> None:
        _finite(msg.x, msg.y, msg.z)
        self.home = (_geodetic(msg.latitude, msg.longitude, msg.altitude), np.array([msg.x, msg.y, msg.z]))

    def _on_battery_status(self, msg, arrival: float) -> None:
        self._battery(msg.battery_remaining)
        self.battery_fault = msg.fault_bitmask != 0

    def _on_sys_status(self, msg, arrival: float) -> None:
        self._battery(msg.battery_remaining)
        present, enabled, health = (getattr(msg, name) for name in SENSOR_BITS)
        self.sensors_failed = bool(present & enabled & ~health)

    def _battery(self, percent: int) -> None:
        if percent == -1:
            return  # unknown (the field's documented "not sent" value)
        if not 0 <= percent <= 100:
            raise ValueError(f"battery_remaining must be -1 or 0-100 %, got {percent}")
        self.battery = percent / 100.0

    def _on_extended_sys_state(self, msg, arrival: float) -> None:
        self.landed_state = msg.landed_state

    def _on_gimbal_device_attitude_status(self, msg, arrival: float) -> None:
        _finite(*msg.q)
        flags = msg.flags
        if flags & (mavlink.GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME | mavlink.GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME):
            in_vehicle = bool(flags & mavlink.GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME)
        else:
            in_vehicle = not flags & mavlink.GIMBAL_DEVICE_FLAGS_YAW_LOCK
        self.gimbal = GimbalAttitude(msg.time_boot_ms, *_euler(*msg.q), in_vehicle)

    @property
    def failed(self) -> bool:
        """The autopilot reports a failure: a sensor unhealthy (SYS_STATUS) or a battery fault."""
        return self.sensors_failed or self.battery_fault
