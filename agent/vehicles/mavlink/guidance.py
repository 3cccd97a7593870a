"""A :class:`agent.vehicles.base.Setpoint` as the moving reference that SET_POSITION_TARGET_LOCAL_NED carries:
a position and its velocity (scenario frame; :mod:`agent.vehicles.mavlink.frames` takes them to the
autopilot's).

The reference is a virtual vehicle that flies the setpoint exactly, and the real one tracks it. PX4's multicopter
position controller uses a velocity given with a position as a feed-forward, ``v_cmd = v_ff + K_p (p_sp - p)``
(``PositionControl::_positionControl``), and ArduCopter's GUIDED moves its position target along the velocity
(``set_pos_vel_accel``): both follow a position that moves with its velocity without lag, and a position that
jumps would be flown toward at whatever speed the position loop gives. So at each stream tick, ``dt`` after
the last, the reference moves ``p_ref += v_ref dt`` (the midpoint rule: Euler's drifts off a circle), with

* a **point** setpoint: ``v_ref`` toward it at ``min(limit, d / SETTLE_TIME)`` — the setpoint's speed limit on
  the way, slowing down on arrival (``d`` the reference's distance to the point);
* an **orbit** setpoint: horizontally the Lawrence orbit field (:func:`agent.vehicles.base.orbit_vector_field`)
  at the reference, at speed ``limit`` — the guidance the kinematic models fly — and vertically the point law
  toward the orbit's depth.

A setpoint's velocity feed-forward (``Setpoint.velocity``: the point's or the orbit centre's own motion) is added
horizontally to either, as the kinematic multirotor adds it: the guidance then acts in the frame moving with the
point or the centre, and the autopilot's own limits bound the sum.

``limit`` is the setpoint's speed, or the vehicle's cruise speed when it has none; on an orbit of radius ``r`` at
most ``sqrt(0.8 a_max r)``, the kinematic multirotor's cruise (the centripetal ``v²/r`` within the acceleration the
vehicle is asked for, ``max_accel``). The reference starts at the
vehicle, and starts there again whenever the vehicle is more than ``LEASH_TIME · limit`` from it (the
autopilot could not follow: it was held, or slower than asked), so it never runs away. A new setpoint takes
the reference on from where it is, so the commanded motion has no jump.
"""

from __future__ import annotations

import numpy as np

from agent.vehicles.base import ORBIT_ACCEL_SHARE, Setpoint, orbit_vector_field

SETTLE_TIME = 1.0  # s: a point is approached at d / SETTLE_TIME (the kinematic multirotor's position_gain, 1/s)
LEASH_TIME = 2.0  # s of flight at the speed limit: farther from the vehicle, the reference restarts there (chosen here)
MIN_LEASH = 5.0  # m: the smallest leash (chosen here: a GPS position's few metres must not restart it)


def _approach(error: np.ndarray, limit: float) -> np.ndarray:
    """Velocity along ``error`` at ``min(limit, |error| / SETTLE_TIME)``."""
    distance = float(np.linalg.norm(error))
    if distance < 1e-9:
        return np.zeros_like(error)
    return error * (min(limit, distance / SETTLE_TIME) / distance)


def speed_limit(setpoint: Setpoint, cruise_speed: float) -> float:
    return cruise_speed if setpoint.speed is None else min(cruise_speed, setpoint.speed)


def reference_velocity(setpoint: Setpoint, position: np.ndarray, limit: float, max_accel: float = np.inf
                       ) -> np.ndarray:
    """The velocity (3,) the setpoint asks for at ``position`` (module docstring)."""
    if setpoint.orbit is None:
        velocity = _approach(setpoint.position - position, limit)
    else:
        center, radius, direction = setpoint.orbit
        cruise = min(limit, float(np.sqrt(ORBIT_ACCEL_SHARE * max_accel * radius)))  # v²/r <= share · a_max
        horizontal = orbit_vector_field(position[:2] - center, radius, direction, cruise)
        vertical = _approach(np.array([setpoint.position[2] - position[2]]), limit)
        velocity = np.array([horizontal[0], horizontal[1], vertical[0]])
    if setpoint.velocity is not None:
        velocity[:2] += setpoint.velocity
    return velocity


class Reference:
    """The moving reference of the module docstring; :meth:`advance` once per streamed setpoint."""

    def __init__(self, cruise_speed: float, max_accel: float = np.inf):
        self.cruise_speed, self.max_accel = cruise_speed, max_accel
        self.position: np.ndarray | None = None  # scenario NED [m]
        self.velocity = np.zeros(3)
        self.restarts = 0  # times the vehicle was out of the leash

    def advance(self, setpoint: Setpoint, vehicle_position: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Move the reference ``dt`` (>= 0) seconds along ``setpoint``'s guidance; its (position, velocity there)."""
        limit = speed_limit(setpoint, self.cruise_speed)
        vehicle_position = np.asarray(vehicle_position, float)
        leash = max(MIN_LEASH, LEASH_TIME * limit)
        if self.position is None or np.linalg.norm(self.position - vehicle_position) > leash:
            self.position, self.restarts = vehicle_position.copy(), self.restarts + (self.position is not None)
        half = self.position + reference_velocity(setpoint, self.position, limit, self.max_accel) * (dt / 2)
        self.position = self.position + reference_velocity(setpoint, half, limit, self.max_accel) * dt  # midpoint
        self.velocity = reference_velocity(setpoint, self.position, limit, self.max_accel)
        return self.position.copy(), self.velocity.copy()
