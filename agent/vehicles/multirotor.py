"""The multirotor kinematic model: an acceleration-limited point mass (``[vehicle] kind = "multirotor"``).

Frames, units and the orbit field are those of :mod:`agent.vehicles.base`.
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np

from agent.vehicles.base import (
    GRAVITY,
    ORBIT_ACCEL_SHARE,
    ConfigField,
    KinematicModel,
    Setpoint,
    VehicleState,
    kinematic_from_config,
    orbit_vector_field,
    positive,
    wrap_angle,
)
from fusion.validation import as_vector

#: ``[vehicle]`` keys (angles in degrees, named ``*_deg``; the others SI units).
CONFIG_FIELDS = {
    "max_speed": ConfigField("max_speed"),
    "max_accel": ConfigField("max_accel"),
    "max_climb": ConfigField("max_climb"),
    "yaw_rate_deg": ConfigField("yaw_rate", degrees=True),
    "position_gain": ConfigField("position_gain"),
}


def _approach_speed(distance: float, limit: float, gain: float, decel: float) -> float:
    """Speed command toward a point ``distance`` away: ``min(limit, gain d, sqrt(2 decel d))``."""
    return min(limit, gain * distance, math.sqrt(2.0 * decel * distance))


class MultirotorModel(KinematicModel):
    """Acceleration-limited point mass flying to a position setpoint or around an orbit.

    Position setpoint: the velocity command points at the target with speed
    ``min(v_max, k d, sqrt(2 a_dec d))`` (``d`` the 3-D distance, ``a_dec = a_max / 2``, ``k =
    position_gain``) — the square root is the braking profile that stops at the point, the linear
    term makes the last metres an exponential approach, so there is no overshoot. If the vertical
    part exceeds ``max_climb`` the whole command is scaled down, which keeps the path straight.

    Orbit setpoint: the horizontal command is the Lawrence vector field at cruise speed
    ``min(limit, sqrt(0.8 a_max r))`` (so that the centripetal acceleration ``v^2/r`` fits in the
    acceleration limit), the vertical command the same braking profile on the depth error.

    Velocity feed-forward (``Setpoint.velocity``, the point's or the centre's velocity ``v_ff``): the horizontal
    command is ``v_ff`` plus the command above (the guidance then acts in the frame moving with the point or
    the centre), scaled down so that the whole stays within ``max_speed``.

    The velocity follows the command as fast as ``max_accel`` allows (per sub-step the velocity
    change is clipped to ``a_max h``). Since the command lies in the convex set ``|v| <= v_max,
    |v_z| <= max_climb`` and the velocity moves on a straight segment towards it, the limits are never
    exceeded. Yaw turns toward the horizontal velocity (above 0.5 m/s) at most at ``yaw_rate``.
    Attitude from the applied acceleration ``a`` in the yaw-aligned frame (forward ``f``, right ``r``):
    ``pitch = -atan(a_f / g)``, ``roll = atan(a_r / g)`` — to first order the small-angle
    ``pitch = -a_f / g``, ``roll = a_r / g`` (accelerating forward needs nose down).
    """

    def __init__(
        self,
        initial_position,
        max_speed: float = 10.0,
        max_accel: float = 3.0,
        max_climb: float = 2.0,
        yaw_rate: float = math.radians(90.0),
        *,
        initial_yaw: float = 0.0,
        position_gain: float = 1.0,  # 1/s, chosen here
        t0: float = 0.0,
    ):
        self.max_speed = positive("max_speed", max_speed)
        self.max_accel = positive("max_accel", max_accel)
        self.max_climb = positive("max_climb", max_climb)
        self.yaw_rate = positive("yaw_rate", yaw_rate)
        self.position_gain = positive("position_gain", position_gain)
        if not math.isfinite(initial_yaw):
            raise ValueError(f"initial_yaw must be finite, got {initial_yaw}")
        self._p = as_vector(initial_position, "initial_position", 3).copy()
        self._v = np.zeros(3)
        self._a = np.zeros(3)
        self._yaw = wrap_angle(float(initial_yaw))
        self._t = float(t0)
        self._setpoint = Setpoint(self._p.copy())

    def state(self) -> VehicleState:
        c, s = math.cos(self._yaw), math.sin(self._yaw)
        a_fwd = c * self._a[0] + s * self._a[1]
        a_right = -s * self._a[0] + c * self._a[1]
        return VehicleState(
            t=self._t,
            position=self._p.copy(),
            velocity=self._v.copy(),
            yaw=self._yaw,
            roll=math.atan(a_right / GRAVITY),
            pitch=-math.atan(a_fwd / GRAVITY),
        )

    def _velocity_command(self) -> np.ndarray:
        sp = self._setpoint
        limit = self.max_speed if sp.speed is None else min(self.max_speed, sp.speed)
        decel = 0.5 * self.max_accel
        if sp.orbit is None:
            error = sp.position - self._p
            distance = float(np.linalg.norm(error))
            if distance < 1e-9:
                return np.zeros(3)
            command = error * (_approach_speed(distance, limit, self.position_gain, decel) / distance)
            if abs(command[2]) > self.max_climb:
                command *= self.max_climb / abs(command[2])
            return self._feed_forward(command)
        center, radius, direction = sp.orbit
        dz = float(sp.position[2] - self._p[2])
        vz = math.copysign(_approach_speed(abs(dz), min(self.max_climb, limit), self.position_gain, decel), dz)
        orbit_speed = math.sqrt(ORBIT_ACCEL_SHARE * self.max_accel * radius)  # v²/r within the share of a_max
        cruise = min(limit, orbit_speed, math.sqrt(max(limit**2 - vz**2, 0.0)))
        horizontal = orbit_vector_field(self._p[:2] - center, radius, direction, cruise)
        return self._feed_forward(np.array([horizontal[0], horizontal[1], vz]))

    def _feed_forward(self, command: np.ndarray) -> np.ndarray:
        """``command`` plus the setpoint's horizontal feed-forward, the horizontal part scaled so that the whole
        stays within ``max_speed``."""
        velocity = self._setpoint.velocity
        if velocity is None:
            return command
        horizontal = command[:2] + velocity
        speed, room = math.hypot(horizontal[0], horizontal[1]), math.sqrt(max(self.max_speed**2 - command[2]**2, 0.0))
        if speed > room:
            horizontal *= room / speed
        return np.array([horizontal[0], horizontal[1], command[2]])

    def _substep(self, h: float) -> None:
        dv = self._velocity_command() - self._v
        norm = float(np.linalg.norm(dv))
        if norm > self.max_accel * h:
            dv *= self.max_accel * h / norm
        v_new = self._v + dv
        self._p += 0.5 * (self._v + v_new) * h
        self._v = v_new
        self._a = dv / h
        if math.hypot(v_new[0], v_new[1]) > 0.5:
            error = wrap_angle(math.atan2(v_new[1], v_new[0]) - self._yaw)
            turn = max(-self.yaw_rate * h, min(self.yaw_rate * h, error))
            self._yaw = wrap_angle(self._yaw + turn)


def from_config(params: dict, initial_position, initial_heading: float = 0.0) -> MultirotorModel:
    """A multirotor from its ``[vehicle]`` parameters (:data:`CONFIG_FIELDS`); ``initial_heading`` (rad) is
    its initial yaw. Raises ``ValueError`` naming the bad key."""
    build = partial(MultirotorModel, initial_position, initial_yaw=initial_heading)
    return kinematic_from_config("multirotor", params, CONFIG_FIELDS, build)
