"""The fixed-wing kinematic model: constant airspeed and coordinated turns (``[vehicle] kind = "fixed_wing"``).

Frames, units and the orbit field are those of :mod:`agent.vehicles.base`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial

import numpy as np

from agent.vehicles.base import (
    GRAVITY,
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
    "airspeed": ConfigField("airspeed"),
    "max_bank_deg": ConfigField("max_bank", degrees=True, limit=89.0),
    "climb_rate": ConfigField("climb_rate"),
    "roll_rate_deg": ConfigField("roll_rate", degrees=True),
    "heading_gain": ConfigField("heading_gain"),
    "altitude_gain": ConfigField("altitude_gain"),
    "loiter_margin": ConfigField("loiter_margin"),
}


class FixedWingModel(KinematicModel):
    """Constant-airspeed coordinated-turn model (Dubins-like airplane with altitude hold).

    Turn rate ``omega = g tan(phi) / v`` (``v`` airspeed) with bank ``|phi| <= max_bank``, bank moving
    toward its command at most at ``roll_rate``. The bank command is
    ``atan(v (omega_ff + k_psi wrap(psi_d - psi)) / g)`` clipped to ``max_bank``: ``psi_d`` is the
    course of the Lawrence orbit field, ``omega_ff`` its rate of change along the current velocity
    (feed-forward, so that the orbit is held without a steady heading error).

    Depth: ``v_z = clip(k_z (z_sp - z), +-climb_rate)``; the airspeed stays ``v``, so the horizontal
    speed is ``sqrt(v^2 - v_z^2)``. ``pitch`` is the flight-path angle ``asin(-v_z / v)`` (no angle of
    attack is modelled), ``roll`` the bank, ``yaw`` the heading (no wind, so heading = course).

    An orbit setpoint is flown at ``max(radius, min_turn_radius)`` with ``min_turn_radius =
    v^2 / (g tan(max_bank))``. A position setpoint cannot be hovered at: the aircraft heads straight
    for it (so it overflies search waypoints and flies lawnmower legs along the lane) and, once
    arrived, loiters around it (clockwise) at ``loiter_radius = loiter_margin * min_turn_radius`` with
    the same vector field; the margin (chosen here) leaves bank authority to correct. A waypoint
    inside the turning circle may be missed by up to about ``min_turn_radius``, so a waypoint follower
    should accept at least that distance. The setpoint speed limit is ignored (constant airspeed).

    A position setpoint with a velocity feed-forward ``v_ff`` is a moving point to fly along (a planned path's
    set-point, :mod:`tasking.standoff`): the desired course is that of ``v_ff + (p_sp - p) / track_time`` —
    the path's own course on it, turning back onto it off it — and there is no arrival. An orbit's
    feed-forward is ignored (constant airspeed: the aircraft cannot add a centre's velocity to its own).
    """

    def __init__(
        self,
        initial_position,
        heading: float = 0.0,
        airspeed: float = 18.0,
        max_bank: float = math.radians(35.0),
        climb_rate: float = 3.0,
        *,
        roll_rate: float = math.radians(90.0),  # chosen here
        heading_gain: float = 1.0,  # 1/s, chosen here
        altitude_gain: float = 0.5,  # 1/s, chosen here
        loiter_margin: float = 1.2,  # chosen here
        track_time: float = 2.0,  # s, chosen here: the time to close the gap to a moving set-point
        t0: float = 0.0,
    ):
        self.airspeed = positive("airspeed", airspeed)
        self.max_bank = positive("max_bank", max_bank)
        if self.max_bank >= math.radians(89.0):
            raise ValueError(f"max_bank must be below 89 degrees, got {math.degrees(self.max_bank):.1f} degrees")
        self.climb_rate = positive("climb_rate", climb_rate)
        if self.climb_rate >= self.airspeed:
            raise ValueError(f"climb_rate ({self.climb_rate}) must be below the airspeed ({self.airspeed})")
        self.roll_rate = positive("roll_rate", roll_rate)
        self.heading_gain = positive("heading_gain", heading_gain)
        self.altitude_gain = positive("altitude_gain", altitude_gain)
        self.loiter_margin = positive("loiter_margin", loiter_margin)
        self.track_time = positive("track_time", track_time)
        if self.loiter_margin < 1.0:
            raise ValueError(f"loiter_margin must be at least 1, got {loiter_margin}")
        if not math.isfinite(heading):
            raise ValueError(f"heading must be finite, got {heading}")
        self._p = as_vector(initial_position, "initial_position", 3).copy()
        self._psi = wrap_angle(float(heading))
        self._phi = 0.0
        self._vz = 0.0
        self._t = float(t0)
        self._setpoint = Setpoint(self._p.copy())
        self._arrived_at: np.ndarray | None = None  # the position setpoint it is loitering around

    @property
    def max_turn_rate(self) -> float:
        return GRAVITY * math.tan(self.max_bank) / self.airspeed

    @property
    def min_turn_radius(self) -> float:
        return self.airspeed**2 / (GRAVITY * math.tan(self.max_bank))

    @property
    def loiter_radius(self) -> float:
        return self.loiter_margin * self.min_turn_radius

    def _horizontal_speed(self) -> float:
        return math.sqrt(self.airspeed**2 - self._vz**2)

    def state(self) -> VehicleState:
        vh = self._horizontal_speed()
        return VehicleState(
            t=self._t,
            position=self._p.copy(),
            velocity=np.array([vh * math.cos(self._psi), vh * math.sin(self._psi), self._vz]),
            yaw=self._psi,
            roll=self._phi,
            pitch=math.asin(-self._vz / self.airspeed),
        )

    def _guidance(self) -> Callable[[np.ndarray], np.ndarray]:
        """The desired-course field for the current setpoint, as a function of the position (north, east).

        Orbit setpoint: the Lawrence field. Moving point (position and velocity): ``v_ff + (p_sp - p) / track_time``.
        Position setpoint: head straight for the point until
        arrival, then the Lawrence field around it at ``loiter_radius``. Arrival (sticky while the
        setpoint stays within half a loiter radius of the arrival point) is declared at the closest
        approach inside the loiter radius — when the range starts to grow — or within 1 m.
        """
        sp = self._setpoint
        if sp.orbit is not None:
            center, radius, direction = sp.orbit
            radius = max(radius, self.min_turn_radius)
            return lambda p: orbit_vector_field(p - center, radius, direction, 1.0)
        point = sp.position[:2]
        if sp.velocity is not None:
            self._arrived_at = None
            return lambda p: sp.velocity + (point - p) / self.track_time
        if self._arrived_at is not None and np.linalg.norm(point - self._arrived_at) > 0.5 * self.loiter_radius:
            self._arrived_at = None  # a new point: fly to it
        if self._arrived_at is None:
            rel = self._p[:2] - point
            rho = float(np.linalg.norm(rel))
            closing = rel[0] * math.cos(self._psi) + rel[1] * math.sin(self._psi) < 0.0
            if rho < 1.0 or (rho <= self.loiter_radius and not closing):
                self._arrived_at = point.copy()
        if self._arrived_at is None:
            return lambda p: point - p
        self._arrived_at = point.copy()
        radius = self.loiter_radius
        return lambda p: orbit_vector_field(p - point, radius, 1, 1.0)

    def _substep(self, h: float) -> None:
        guidance = self._guidance()
        self._vz = max(
            -self.climb_rate, min(self.climb_rate, self.altitude_gain * (self._setpoint.position[2] - self._p[2]))
        )
        vh = self._horizontal_speed()
        course = np.array([math.cos(self._psi), math.sin(self._psi)])
        field = guidance(self._p[:2])
        psi_d = math.atan2(field[1], field[0])
        delta = 0.05  # s, finite-difference horizon for the feed-forward
        ahead = guidance(self._p[:2] + vh * delta * course)
        omega_ff = wrap_angle(math.atan2(ahead[1], ahead[0]) - psi_d) / delta
        omega_cmd = omega_ff + self.heading_gain * wrap_angle(psi_d - self._psi)
        phi_cmd = math.atan(self.airspeed * omega_cmd / GRAVITY)
        phi_cmd = max(-self.max_bank, min(self.max_bank, phi_cmd))
        self._phi += max(-self.roll_rate * h, min(self.roll_rate * h, phi_cmd - self._phi))
        omega = GRAVITY * math.tan(self._phi) / self.airspeed
        mid = self._psi + 0.5 * omega * h
        self._p += h * np.array([vh * math.cos(mid), vh * math.sin(mid), self._vz])
        self._psi = wrap_angle(self._psi + omega * h)


def from_config(params: dict, initial_position, initial_heading: float = 0.0) -> FixedWingModel:
    """A fixed wing from its ``[vehicle]`` parameters (:data:`CONFIG_FIELDS`); ``initial_heading`` (rad) is
    its heading. Raises ``ValueError`` naming the bad key."""
    build = partial(FixedWingModel, initial_position, heading=initial_heading)
    return kinematic_from_config("fixed_wing", params, CONFIG_FIELDS, build)
