"""A :class:`agent.vehicles.base.Setpoint` as the position and velocity that SET_POSITION_TARGET_LOCAL_NED
carries (scenario frame; :mod:`agent.vehicles.mavlink.frames` takes them to the autopilot's).

PX4's multicopter position controller (and ArduCopter's in GUIDED) uses a velocity given together with a
position as a feed-forward: ``v_cmd = v_ff + K_p (p_sp - p)``. So the pair describes the motion wanted now:

* **point** setpoint: ``p_sp`` = the point, ``v_ff`` toward it at ``min(limit, d / settle_time)`` — the
  speed that would reach it in ``settle_time``, so the feed-forward fades to zero on arrival and the
  position loop finishes the approach;
* **orbit** setpoint: ``v_ff`` = the Lawrence orbit field (:func:`agent.vehicles.base.orbit_vector_field`)
  at the vehicle's position at speed ``limit``, the same guidance the kinematic models fly; ``p_sp`` = the
  carrot, the point of the circle nearest the vehicle at the orbit's depth — on the circle the position
  error is zero and the feed-forward alone carries the vehicle round, off it the position loop pulls it in
  along the radius as the field does.

``limit`` is the setpoint's speed, or the vehicle's cruise speed when it has none.
"""

from __future__ import annotations

import math

import numpy as np

from agent.vehicles.base import Setpoint, orbit_vector_field

SETTLE_TIME = 2.0  # s: a point setpoint's feed-forward is the speed that reaches it in this time (chosen here)


def setpoint_motion(setpoint: Setpoint, position: np.ndarray, cruise_speed: float) -> tuple[np.ndarray, np.ndarray]:
    """(position, velocity feed-forward) (3,) each, NED, for ``setpoint`` flown from ``position``."""
    limit = cruise_speed if setpoint.speed is None else min(cruise_speed, setpoint.speed)
    position = np.asarray(position, float)
    if setpoint.orbit is None:
        error = setpoint.position - position
        distance = float(np.linalg.norm(error))
        if distance < 1e-9:
            return setpoint.position.copy(), np.zeros(3)
        return setpoint.position.copy(), error * (min(limit, distance / SETTLE_TIME) / distance)
    center, radius, direction = setpoint.orbit
    relative = position[:2] - center
    rho = math.hypot(*relative)
    radial = relative / rho if rho > 1e-9 else np.array([1.0, 0.0])  # at the centre: leave northwards
    carrot = np.array([*(center + radius * radial), setpoint.position[2]])
    horizontal = orbit_vector_field(relative, radius, direction, limit)
    return carrot, np.array([horizontal[0], horizontal[1], 0.0])
