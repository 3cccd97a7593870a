"""Telemetry: the MAVLink messages a PX4 vehicle publishes, encoded from the simulator's state.

Field conventions are those of the MAVLink common message set and of PX4's stream implementations
(``src/modules/mavlink/streams/*.hpp``): NED metres and m/s in LOCAL_POSITION_NED; degE7, millimetres and
cm/s in GLOBAL_POSITION_INT (``alt`` above mean sea level, taken here as the WGS-84 height the scenario
origin is given in, ``relative_alt`` above home); radians in ATTITUDE; ``time_boot_ms`` counted from the
simulator's own boot. Geodetic coordinates come from :mod:`agent.vehicles.geodesy` (the one place that
converts) relative to the scenario origin, which is also GPS_GLOBAL_ORIGIN. The angular rates of ATTITUDE
are the Euler-angle rates over the last physics step (the body rates, to first order in roll and pitch): the
kinematic models have no rate state. Messages about the position
(LOCAL_POSITION_NED, GLOBAL_POSITION_INT, HOME_POSITION, GPS_GLOBAL_ORIGIN) are not published before the
position estimate is valid, as PX4 publishes them only once EKF2 has a position.
"""

from __future__ import annotations

import math

import numpy as np

from agent.vehicles.geodesy import ned_to_geodetic
from agent.vehicles.mavlink_protocol import mavlink
from mesh_sim.autopilot.battery import CELLS
from mesh_sim.autopilot.flight import FlightController
from perception.rotations import quaternion_from_euler

PX4_VERSION = (1, 14, 0)  # the PX4 release whose behaviour is reproduced (AUTOPILOT_VERSION.flight_sw_version)
SENSORS = (  # SYS_STATUS: present, enabled and healthy
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY | mavlink.MAV_SYS_STATUS_AHRS
)
CAPABILITIES = (  # AUTOPILOT_VERSION.capabilities: what this simulator implements
    mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
)
GIMBAL_FLAGS = (mavlink.GIMBAL_DEVICE_FLAGS_ROLL_LOCK | mavlink.GIMBAL_DEVICE_FLAGS_PITCH_LOCK
                | mavlink.GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME)
GIMBAL_DEVICE_ID = 1  # a gimbal attached to the autopilot (1..6: not a MAVLink component)


def _wxyz(roll: float, pitch: float, yaw: float) -> list[float]:
    """MAVLink's scalar-first quaternion of Z-Y-X Euler angles (perception.rotations is scalar-last)."""
    x, y, z, w = quaternion_from_euler(roll, pitch, yaw)
    return [float(w), float(x), float(y), float(z)]


class Telemetry:
    """Encodes, by message id, the current state of one vehicle (``None`` when it has nothing to say)."""

    def __init__(self, controller: FlightController, origin: tuple[float, float, float], sysid: int,
                 vehicle_type: int):
        self.controller = controller
        self.origin = origin
        self.vehicle_type = vehicle_type
        self.sysid = sysid
        self.encoder = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1)
        self._encoders = {
            mavlink.MAVLINK_MSG_ID_HEARTBEAT: self.heartbeat,
            mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self.local_position_ned,
            mavlink.MAVLINK_MSG_ID_ATTITUDE: self.attitude,
            mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: self.attitude_quaternion,
            mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self.global_position_int,
            mavlink.MAVLINK_MSG_ID_HOME_POSITION: self.home_position,
            mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: self.gps_global_origin,
            mavlink.MAVLINK_MSG_ID_SYS_STATUS: self.sys_status,
            mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: self.battery_status,
            mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self.extended_sys_state,
            mavlink.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS: self.gimbal_device_attitude_status,
            mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self.autopilot_version,
        }

    def supports(self, msg_id: int) -> bool:
        return msg_id in self._encoders

    def message(self, msg_id: int):
        """The message ``msg_id`` now, or ``None`` (not supported, or nothing valid to publish yet)."""
        encode = self._encoders.get(msg_id)
        return None if encode is None else encode()

    @property
    def time_boot_ms(self) -> int:
        return int(self.controller.t * 1000.0) & 0xFFFFFFFF

    def _geodetic(self, ned) -> tuple[float, float, float]:
        return ned_to_geodetic(ned, self.origin)

    def home_altitude(self) -> float:
        """Home's altitude [m] in the frame of GLOBAL_POSITION_INT.alt."""
        return self._geodetic(self.controller.home)[2]

    # -- the messages ------------------------------------------------------------------------------------
    def heartbeat(self):
        c = self.controller
        base_mode = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if c.armed else 0)
        status = mavlink.MAV_STATE_ACTIVE if c.armed else mavlink.MAV_STATE_STANDBY
        return self.encoder.heartbeat_encode(self.vehicle_type, mavlink.MAV_AUTOPILOT_PX4, base_mode, c.custom_mode,
                                             status)

    def local_position_ned(self):
        if not self.controller.position_valid:
            return None
        s = self.controller.model.state()
        x, y, z = map(float, s.position)
        vx, vy, vz = map(float, s.velocity)
        return self.encoder.local_position_ned_encode(self.time_boot_ms, x, y, z, vx, vy, vz)

    def attitude(self):
        s = self.controller.model.state()
        return self.encoder.attitude_encode(self.time_boot_ms, s.roll, s.pitch, s.yaw, *self.controller.angular_rates)

    def attitude_quaternion(self):
        s = self.controller.model.state()
        w, x, y, z = _wxyz(s.roll, s.pitch, s.yaw)
        return self.encoder.attitude_quaternion_encode(self.time_boot_ms, w, x, y, z, *self.controller.angular_rates)

    def global_position_int(self):
        c = self.controller
        if not c.position_valid:
            return None
        s = c.model.state()
        lat, lon, alt = self._geodetic(s.position)
        v = np.clip(np.round(s.velocity * 100.0), -32768, 32767).astype(int)
        heading = round(math.degrees(s.yaw) * 100.0) % 36000
        return self.encoder.global_position_int_encode(
            self.time_boot_ms, round(lat * 1e7), round(lon * 1e7), round(alt * 1000.0),
            round((c.home[2] - s.position[2]) * 1000.0), int(v[0]), int(v[1]), int(v[2]), heading)

    def home_position(self):
        c = self.controller
        if not c.position_valid:
            return None
        lat, lon, alt = self._geodetic(c.home)
        x, y, z = map(float, c.home)
        return self.encoder.home_position_encode(round(lat * 1e7), round(lon * 1e7), round(alt * 1000.0), x, y, z,
                                                 [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, int(c.t * 1e6))

    def gps_global_origin(self):
        if not self.controller.position_valid:
            return None
        lat, lon, alt = self.origin
        return self.encoder.gps_global_origin_encode(round(lat * 1e7), round(lon * 1e7), round(alt * 1000.0),
                                                     int(self.controller.t * 1e6))

    def sys_status(self):
        c = self.controller
        b = c.battery
        health = SENSORS if c.position_valid else SENSORS & ~mavlink.MAV_SYS_STATUS_SENSOR_GPS
        armable = c.position_valid and b.remaining >= c.params["BAT_LOW_THR"]
        present = SENSORS | mavlink.MAV_SYS_STATUS_PREARM_CHECK
        health |= mavlink.MAV_SYS_STATUS_PREARM_CHECK if armable else 0
        return self.encoder.sys_status_encode(present, present, health, 0, round(b.voltage * 1000.0),
                                              round(b.current * 100.0), round(b.remaining * 100.0), 0, 0, 0, 0, 0, 0)

    def battery_status(self):
        b = self.controller.battery
        cell_mv = round(1000.0 * b.voltage / CELLS)
        voltages = [cell_mv] * CELLS + [65535] * (10 - CELLS)  # UINT16_MAX: no such cell
        charge_state = (mavlink.MAV_BATTERY_CHARGE_STATE_LOW if b.remaining < self.controller.params["BAT_LOW_THR"]
                        else mavlink.MAV_BATTERY_CHARGE_STATE_OK)
        return self.encoder.battery_status_encode(
            0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, 32767, voltages,
            round(b.current * 100.0), round(b.consumed_mah), -1, round(b.remaining * 100.0), round(b.time_remaining),
            charge_state)

    def extended_sys_state(self):
        return self.encoder.extended_sys_state_encode(mavlink.MAV_VTOL_STATE_UNDEFINED, self.controller.landed_state)

    def gimbal_device_attitude_status(self):
        g = self.controller.gimbal
        return self.encoder.gimbal_device_attitude_status_encode(
            0, 0, self.time_boot_ms, GIMBAL_FLAGS, _wxyz(0.0, g.pitch, g.yaw), math.nan, math.nan, math.nan, 0,
            math.nan, math.nan, GIMBAL_DEVICE_ID)

    def autopilot_version(self):
        major, minor, patch = PX4_VERSION
        version = (major << 24) | (minor << 16) | (patch << 8) | mavlink.FIRMWARE_VERSION_TYPE_OFFICIAL
        return self.encoder.autopilot_version_encode(CAPABILITIES, version, version, 0, 0, [0] * 8, [0] * 8, [0] * 8,
                                                     0, 0, self.sysid)

    def statustext(self, severity: int, text: str):
        return self.encoder.statustext_encode(severity, text.encode()[:50])
