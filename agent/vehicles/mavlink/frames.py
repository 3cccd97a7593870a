"""The autopilot's local NED frame <-> the scenario's NED frame.

PX4 and ArduPilot report LOCAL_POSITION_NED, and take SET_POSITION_TARGET_LOCAL_NED
(``MAV_FRAME_LOCAL_NED``), relative to their EKF origin (GPS_GLOBAL_ORIGIN), which is not the scenario's
``origin``. Both are local tangent frames of WGS-84 points, so a point maps exactly through its geodetic
coordinates (:mod:`agent.vehicles.geodesy`, the one place that converts)::

    p_scenario = geodetic_to_ned(ned_to_geodetic(p_local, origin_autopilot), origin_scenario)

and a velocity (a free vector) by the rotation between the two frames,
``R = C_e^n(scenario) C_e^n(autopilot)ᵀ`` (Groves (2.150)): a rotation about the down axis by the
convergence of the meridians, plus a tilt of the order of the frames' distance over the Earth's radius.

Heights: MAVLink's altitudes (GPS_GLOBAL_ORIGIN, HOME_POSITION) are above mean sea level, and so is the
scenario's ``origin`` altitude; the geoid's undulation is the same for both origins to within centimetres
over an operating area, so it cancels and the heights are used as ellipsoidal ones.
"""

from __future__ import annotations

import math

import numpy as np

from agent.vehicles.geodesy import ecef_to_ned_rotation, geodetic_to_ned, ned_to_geodetic
from fusion.validation import as_vector


class FrameMap:
    """The map between the autopilot's local frame (origin ``autopilot_origin``) and the scenario's
    (``scenario_origin``); both ``(lat [deg], lon [deg], altitude [m])``."""

    def __init__(self, scenario_origin, autopilot_origin):
        self.scenario_origin = tuple(float(v) for v in scenario_origin)
        self.autopilot_origin = tuple(float(v) for v in autopilot_origin)
        rotation = ecef_to_ned_rotation(*self.scenario_origin[:2]) @ ecef_to_ned_rotation(
            *self.autopilot_origin[:2]).T
        self._to_scenario = rotation
        self.yaw_offset = math.atan2(rotation[1, 0], rotation[0, 0])  # scenario yaw = autopilot yaw + this

    @classmethod
    def from_home(cls, scenario_origin, home_geodetic, home_local) -> FrameMap:
        """The map when the autopilot told only its home: ``home_geodetic`` (lat, lon, alt) lies at
        ``home_local`` (NED) in its local frame (HOME_POSITION's ``latitude``... and ``x, y, z``). The origin is
        the point ``-home_local`` from home in home's tangent frame, corrected once for the tilt between the
        two tangent frames (the residual is of order ``|home_local|³ / R²``)."""
        home_local = as_vector(home_local, "home local position", 3)
        origin = ned_to_geodetic(-home_local, home_geodetic)
        error = geodetic_to_ned(*home_geodetic, origin) - home_local
        return cls(scenario_origin, ned_to_geodetic(error, origin))  # moving the origin by e moves home by -e

    def position_to_scenario(self, local) -> np.ndarray:
        return geodetic_to_ned(*ned_to_geodetic(local, self.autopilot_origin), self.scenario_origin)

    def position_to_local(self, scenario) -> np.ndarray:
        return geodetic_to_ned(*ned_to_geodetic(scenario, self.scenario_origin), self.autopilot_origin)

    def vector_to_scenario(self, local) -> np.ndarray:
        return self._to_scenario @ as_vector(local, "local vector", 3)

    def vector_to_local(self, scenario) -> np.ndarray:
        return self._to_scenario.T @ as_vector(scenario, "scenario vector", 3)
