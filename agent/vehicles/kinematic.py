"""The vehicle interface and two kinematic models (multirotor, fixed wing).

An agent reads the vehicle state, and sends it a setpoint, every cycle (DESIGN §4). The kinematic
models here stand in for the MAVLink vehicle, which will implement the same :class:`Vehicle` protocol
(its ``step`` will only poll the link: the real vehicle moves on its own clock).

Frames and units (DESIGN §3): local NED, x north, y east, z **down**, metres, seconds, radians.
``yaw`` is the heading from north towards east; ``roll`` and ``pitch`` are FRD body angles (roll
positive right wing down, pitch positive nose up). An orbit direction ``+1`` is clockwise seen from
above (a right turn, positive yaw rate), ``-1`` anticlockwise.

Orbit guidance uses the Lyapunov vector field of Lawrence, Frew & Pisano (2008), relative position
``(x, y)`` to the centre, ``rho = |(x, y)|``, radius ``r``, speed ``v0``, direction ``s``::

    [x', y'] = -v0 / (rho (rho^2 + r^2)) * [x (rho^2 - r^2) + s y 2 rho r,  y (rho^2 - r^2) - s x 2 rho r]

Its magnitude is ``v0`` everywhere; on the circle it is tangent, outside it spirals in, inside out.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from fusion.validation import as_vector
from tasking.orbit import Goal

GRAVITY = 9.80665  # m/s^2

#: Integration sub-step (s), chosen here: a 5 Hz agent step is integrated in >= 10 sub-steps.
MAX_SUBSTEP = 0.02


def wrap_angle(angle: float) -> float:
    """Wrap to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class VehicleState:
    """Vehicle state at time ``t``: NED ``position`` and ``velocity`` (3,), ``yaw``, ``roll``, ``pitch`` (rad)."""

    t: float
    position: np.ndarray
    velocity: np.ndarray
    yaw: float
    roll: float
    pitch: float


@dataclass(frozen=True)
class Setpoint:
    """A vehicle setpoint.

    ``position`` (3,) NED: the point to fly to. ``speed``: optional speed limit (m/s). ``orbit``:
    optional ``(center (north, east), radius, direction)`` meaning "circle this point" at the depth
    ``position[2]``; the horizontal part of ``position`` is then ignored.
    """

    position: np.ndarray
    speed: float | None = None
    orbit: tuple[np.ndarray, float, int] | None = None

    def __post_init__(self):
        object.__setattr__(self, "position", as_vector(self.position, "setpoint position", 3))
        if self.speed is not None:
            _positive("speed", self.speed)
            object.__setattr__(self, "speed", float(self.speed))
        if self.orbit is not None:
            try:
                center, radius, direction = self.orbit
            except (TypeError, ValueError):
                raise ValueError("orbit must be (center (2,), radius, direction)") from None
            center = as_vector(center, "orbit center", 2)
            _positive("orbit radius", radius)
            if direction not in (1, -1):
                raise ValueError(f"orbit direction must be +1 or -1, got {direction}")
            object.__setattr__(self, "orbit", (center, float(radius), int(direction)))


@runtime_checkable
class Vehicle(Protocol):
    """What the agent needs from a vehicle (kinematic model or MAVLink)."""

    def state(self) -> VehicleState: ...

    def set_setpoint(self, setpoint: Setpoint) -> None: ...

    def step(self, dt: float) -> None: ...


def goal_to_setpoint(goal: Goal) -> Setpoint:
    """Turn tasking's :class:`tasking.orbit.Goal` into a vehicle :class:`Setpoint`."""
    orbit = None
    if goal.orbit_center is not None:
        orbit = (goal.orbit_center, goal.orbit_radius, goal.orbit_direction)
    return Setpoint(position=goal.position, speed=goal.speed, orbit=orbit)


def orbit_vector_field(rel_ne: np.ndarray, radius: float, direction: int, speed: float) -> np.ndarray:
    """Desired horizontal velocity (north, east) of the Lawrence orbit field (see the module docstring)."""
    x, y = float(rel_ne[0]), float(rel_ne[1])
    rho = math.hypot(x, y)
    if rho < 1e-9:  # the field is undefined at the centre: leave northwards
        return np.array([speed, 0.0])
    r = radius
    k = -speed / (rho * (rho * rho + r * r))
    d = rho * rho - r * r
    return np.array([k * (x * d + direction * y * 2.0 * rho * r), k * (y * d - direction * x * 2.0 * rho * r)])


def _positive(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"{name} must be a number, got {value!r}")
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


def _check_dt(dt) -> float:
    if not (isinstance(dt, int | float | np.integer | np.floating) and math.isfinite(dt) and dt >= 0):
        raise ValueError(f"dt must be a non-negative finite number of seconds, got {dt!r}")
    return float(dt)


def _approach_speed(distance: float, limit: float, gain: float, decel: float) -> float:
    """Speed command toward a point ``distance`` away: ``min(limit, gain d, sqrt(2 decel d))``."""
    return min(limit, gain * distance, math.sqrt(2.0 * decel * distance))


class MultirotorModel:
    """Acceleration-limited point mass flying to a position setpoint or around an orbit.

    Position setpoint: the velocity command points at the target with speed
    ``min(v_max, k d, sqrt(2 a_dec d))`` (``d`` the 3-D distance, ``a_dec = a_max / 2``, ``k =
    position_gain``) — the square root is the braking profile that stops at the point, the linear
    term makes the last metres an exponential approach, so there is no overshoot. If the vertical
    part exceeds ``max_climb`` the whole command is scaled down, which keeps the path straight.

    Orbit setpoint: the horizontal command is the Lawrence vector field at cruise speed
    ``min(limit, sqrt(0.8 a_max r))`` (so that the centripetal acceleration ``v^2/r`` fits in the
    acceleration limit), the vertical command the same braking profile on the depth error.

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
        self.max_speed = _positive("max_speed", max_speed)
        self.max_accel = _positive("max_accel", max_accel)
        self.max_climb = _positive("max_climb", max_climb)
        self.yaw_rate = _positive("yaw_rate", yaw_rate)
        self.position_gain = _positive("position_gain", position_gain)
        if not math.isfinite(initial_yaw):
            raise ValueError(f"initial_yaw must be finite, got {initial_yaw}")
        self._p = as_vector(initial_position, "initial_position", 3).copy()
        self._v = np.zeros(3)
        self._a = np.zeros(3)
        self._yaw = wrap_angle(float(initial_yaw))
        self._t = float(t0)
        self._setpoint = Setpoint(self._p.copy())

    @property
    def setpoint(self) -> Setpoint:
        return self._setpoint

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

    def set_setpoint(self, setpoint: Setpoint) -> None:
        if not isinstance(setpoint, Setpoint):
            raise TypeError(f"setpoint must be a Setpoint, got {type(setpoint).__name__}")
        self._setpoint = setpoint

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
            return command
        center, radius, direction = sp.orbit
        dz = float(sp.position[2] - self._p[2])
        vz = math.copysign(_approach_speed(abs(dz), min(self.max_climb, limit), self.position_gain, decel), dz)
        cruise = min(limit, math.sqrt(0.8 * self.max_accel * radius), math.sqrt(max(limit**2 - vz**2, 0.0)))
        horizontal = orbit_vector_field(self._p[:2] - center, radius, direction, cruise)
        return np.array([horizontal[0], horizontal[1], vz])

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

    def step(self, dt: float) -> None:
        dt = _check_dt(dt)
        if dt == 0.0:
            return
        n = max(1, math.ceil(dt / MAX_SUBSTEP - 1e-9))
        for _ in range(n):
            self._substep(dt / n)
        self._t += dt


class FixedWingModel:
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
        t0: float = 0.0,
    ):
        self.airspeed = _positive("airspeed", airspeed)
        self.max_bank = _positive("max_bank", max_bank)
        if self.max_bank >= math.radians(89.0):
            raise ValueError(f"max_bank must be below 89 degrees, got {math.degrees(self.max_bank):.1f} degrees")
        self.climb_rate = _positive("climb_rate", climb_rate)
        if self.climb_rate >= self.airspeed:
            raise ValueError(f"climb_rate ({self.climb_rate}) must be below the airspeed ({self.airspeed})")
        self.roll_rate = _positive("roll_rate", roll_rate)
        self.heading_gain = _positive("heading_gain", heading_gain)
        self.altitude_gain = _positive("altitude_gain", altitude_gain)
        self.loiter_margin = _positive("loiter_margin", loiter_margin)
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
    def setpoint(self) -> Setpoint:
        return self._setpoint

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

    def set_setpoint(self, setpoint: Setpoint) -> None:
        if not isinstance(setpoint, Setpoint):
            raise TypeError(f"setpoint must be a Setpoint, got {type(setpoint).__name__}")
        self._setpoint = setpoint

    def _guidance(self) -> Callable[[np.ndarray], np.ndarray]:
        """The desired-course field for the current setpoint, as a function of the position (north, east).

        Orbit setpoint: the Lawrence field. Position setpoint: head straight for the point until
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

    def step(self, dt: float) -> None:
        dt = _check_dt(dt)
        if dt == 0.0:
            return
        n = max(1, math.ceil(dt / MAX_SUBSTEP - 1e-9))
        for _ in range(n):
            self._substep(dt / n)
        self._t += dt


# Config keys per kind: config name -> (constructor argument, converts degrees to radians).
_CONFIG_FIELDS = {
    "multirotor": {
        "max_speed": ("max_speed", False),
        "max_accel": ("max_accel", False),
        "max_climb": ("max_climb", False),
        "yaw_rate_deg": ("yaw_rate", True),
        "position_gain": ("position_gain", False),
    },
    "fixed_wing": {
        "airspeed": ("airspeed", False),
        "max_bank_deg": ("max_bank", True),
        "climb_rate": ("climb_rate", False),
        "roll_rate_deg": ("roll_rate", True),
        "heading_gain": ("heading_gain", False),
        "altitude_gain": ("altitude_gain", False),
        "loiter_margin": ("loiter_margin", False),
    },
}


def vehicle_from_config(
    config: dict, initial_position, initial_heading: float = 0.0
) -> MultirotorModel | FixedWingModel:
    """Build a kinematic vehicle from ``{"kind": "multirotor" | "fixed_wing", ...}``.

    Angles are in degrees in the config (DESIGN §3: degrees only at the edges) and say so in their
    names: ``yaw_rate_deg``, ``max_bank_deg``, ``roll_rate_deg``. Other keys are SI units
    (``max_speed``, ``max_accel``, ``max_climb``, ``position_gain`` for a multirotor; ``airspeed``,
    ``climb_rate``, ``heading_gain``, ``altitude_gain``, ``loiter_margin`` for a fixed wing). Missing
    keys take the model defaults. ``initial_heading`` (rad) is the multirotor's initial yaw or the
    fixed wing's heading. Raises ``ValueError`` naming the field for an unknown kind, an unknown key or
    a bad value.
    """
    if not isinstance(config, dict):
        raise ValueError(f"vehicle config must be a dict, got {type(config).__name__}")
    kind = config.get("kind")
    if kind not in _CONFIG_FIELDS:
        raise ValueError(f"kind: unknown vehicle kind {kind!r}, expected one of {sorted(_CONFIG_FIELDS)}")
    fields = _CONFIG_FIELDS[kind]
    kwargs = {}
    for key, value in config.items():
        if key == "kind":
            continue
        if key not in fields:
            raise ValueError(f"{key}: unknown {kind} parameter, expected some of {sorted(fields)}")
        argument, degrees = fields[key]
        try:
            value = _positive(key, value)
        except ValueError as error:
            raise ValueError(f"{key}: {error}") from None
        if key == "max_bank_deg" and value >= 89.0:
            raise ValueError(f"{key}: must be below 89 degrees, got {value!r}")
        kwargs[argument] = math.radians(value) if degrees else value
    try:
        if kind == "multirotor":
            return MultirotorModel(initial_position, initial_yaw=initial_heading, **kwargs)
        return FixedWingModel(initial_position, heading=initial_heading, **kwargs)
    except ValueError as error:
        raise ValueError(f"vehicle config ({kind}): {error}") from None
