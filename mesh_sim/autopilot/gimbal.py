"""A two-axis camera gimbal driven by the MAVLink gimbal protocol v2.

The autopilot acts as the gimbal manager (PX4 ``gimbal`` module, https://mavlink.io/en/services/gimbal_v2.html):
MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW (angles in degrees) and GIMBAL_MANAGER_SET_PITCHYAW (radians) set the
target pitch and yaw (yaw relative to the vehicle's heading); a NaN angle leaves that axis where it is.
The device slews towards the targets at ``SLEW_RATE`` and reports its attitude in
GIMBAL_DEVICE_ATTITUDE_STATUS (id 285, MAVLink 2 only). Limits are those of a typical camera gimbal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

PITCH_LIMITS = (math.radians(-90.0), math.radians(30.0))  # chosen here
YAW_LIMITS = (math.radians(-180.0), math.radians(180.0))
SLEW_RATE = math.radians(90.0)  # rad/s; chosen here


def _clip(value: float, limits: tuple[float, float]) -> float:
    return min(max(value, limits[0]), limits[1])


@dataclass
class Gimbal:
    pitch: float = 0.0  # rad, positive up
    yaw: float = 0.0  # rad, relative to the vehicle heading
    target_pitch: float = 0.0
    target_yaw: float = 0.0

    def point(self, pitch: float, yaw: float) -> None:
        """New targets (radians); NaN keeps an axis's target, other values are clipped to the limits."""
        if math.isfinite(pitch):
            self.target_pitch = _clip(pitch, PITCH_LIMITS)
        if math.isfinite(yaw):
            self.target_yaw = _clip(yaw, YAW_LIMITS)

    def step(self, dt: float) -> None:
        limit = SLEW_RATE * dt
        self.pitch += _clip(self.target_pitch - self.pitch, (-limit, limit))
        self.yaw += _clip(self.target_yaw - self.yaw, (-limit, limit))
