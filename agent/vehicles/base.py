"""The vehicle interface, and what the kinematic models share (orbit guidance, sub-stepping, config keys).

An agent reads the vehicle state, and sends it a setpoint, every cycle (DESIGN §4). The kinematic
models (:mod:`agent.vehicles.multirotor`, :mod:`agent.vehicles.fixed_wing`) simulate a vehicle; the MAVLink
vehicle (:mod:`agent.vehicles.mavlink`) implements the same :class:`Vehicle` protocol for a real autopilot
(its ``step`` does not wait: the real vehicle moves on its own clock). A real vehicle can lose its
autopilot: its state then says the pose is stale (``fresh``) and the vehicle itself that it is not
``healthy``; a simulated one is always both.

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
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

from fusion.validation import as_vector, positive
from tasking.orbit import Goal

GRAVITY = 9.80665  # m/s^2

#: Share of the acceleration limit an orbit's centripetal acceleration may use: orbits are flown at most at
#: ``sqrt(ORBIT_ACCEL_SHARE a_max r)`` (chosen here, leaving the rest to correct the radius).
ORBIT_ACCEL_SHARE = 0.8

#: Integration sub-step (s), chosen here: a 5 Hz agent step is integrated in >= 10 sub-steps.
MAX_SUBSTEP = 0.02


def wrap_angle(angle: float) -> float:
    """Wrap to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class VehicleState:
    """Vehicle state at time ``t``: NED ``position`` and ``velocity`` (3,), ``yaw``, ``roll``, ``pitch`` (rad).
    ``fresh``: the pose is current (``False``: the vehicle lost its autopilot and this is the last pose it had,
    which must not georeference a measurement)."""

    t: float
    position: np.ndarray
    velocity: np.ndarray
    yaw: float
    roll: float
    pitch: float
    fresh: bool = True


@dataclass(frozen=True)
class Setpoint:
    """A vehicle setpoint.

    ``position`` (3,) NED: the point to fly to. ``speed``: optional speed limit (m/s). ``orbit``:
    optional ``(center (north, east), radius, direction)`` meaning "circle this point" at the depth
    ``position[2]``; the horizontal part of ``position`` is then ignored. ``velocity``: optional horizontal
    feed-forward (north, east) [m/s], the velocity of the point (or of the orbit's centre) — MAVLink's
    SET_POSITION_TARGET_LOCAL_NED carries the same pair.
    """

    position: np.ndarray
    speed: float | None = None
    orbit: tuple[np.ndarray, float, int] | None = None
    velocity: np.ndarray | None = None

    def __post_init__(self):
        object.__setattr__(self, "position", as_vector(self.position, "setpoint position", 3))
        if self.speed is not None:
            positive("speed", self.speed)
            object.__setattr__(self, "speed", float(self.speed))
        if self.orbit is not None:
            try:
                center, radius, direction = self.orbit
            except (TypeError, ValueError):
                raise ValueError("orbit must be (center (2,), radius, direction)") from None
            center = as_vector(center, "orbit center", 2)
            positive("orbit radius", radius)
            if direction not in (1, -1):
                raise ValueError(f"orbit direction must be +1 or -1, got {direction}")
            object.__setattr__(self, "orbit", (center, float(radius), int(direction)))
        if self.velocity is not None:
            object.__setattr__(self, "velocity", as_vector(self.velocity, "setpoint velocity", 2))


class VehicleError(RuntimeError):
    """A real vehicle cannot be reached or refuses what it is asked (the MAVLink vehicle's errors derive from it):
    ``python -m agent`` stops with exit code 2 before the agent runs."""


@runtime_checkable
class Vehicle(Protocol):
    """What the agent needs from a vehicle (kinematic model or MAVLink).

    ``healthy``: flying the agent's setpoints (``False``: the autopilot is lost, took over, or the battery is
    low; tasking then gives its tasks to others). ``battery``: remaining charge 0-1, ``None`` when unknown (a
    simulated vehicle: the health model's fuel stands in). ``failed``: the vehicle reports a failure.
    ``point(look_at)``: the planner's gimbal command (``Goal.look_at``, NED, or ``None``), as the sensors get it:
    a real vehicle's gimbal points there; a simulated one has none (a camera sensor steers its own)."""

    healthy: bool
    battery: float | None
    failed: bool

    def state(self) -> VehicleState: ...

    def point(self, look_at) -> None: ...

    def set_setpoint(self, setpoint: Setpoint) -> None: ...

    def step(self, dt: float) -> None: ...

    def close(self) -> None: ...


def goal_to_setpoint(goal: Goal) -> Setpoint:
    """Turn tasking's :class:`tasking.orbit.Goal` into a vehicle :class:`Setpoint`."""
    orbit = None
    if goal.orbit_center is not None:
        orbit = (goal.orbit_center, goal.orbit_radius, goal.orbit_direction)
    return Setpoint(position=goal.position, speed=goal.speed, orbit=orbit, velocity=goal.velocity)


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


def _check_dt(dt) -> float:
    if not (isinstance(dt, int | float | np.integer | np.floating) and math.isfinite(dt) and dt >= 0):
        raise ValueError(f"dt must be a non-negative finite number of seconds, got {dt!r}")
    return float(dt)


class KinematicModel(ABC):
    """A simulated vehicle: it keeps the last setpoint (``_setpoint``) and its clock (``_t``), and
    integrates ``step(dt)`` in ``ceil(dt / MAX_SUBSTEP)`` equal sub-steps (:meth:`_substep`)."""

    _setpoint: Setpoint
    _t: float
    healthy = True  # a simulated vehicle never loses its autopilot
    battery = None  # nor reports a battery (the health model's fuel stands in)
    failed = False

    def point(self, look_at) -> None:  # noqa: B027 - no gimbal: a simulated camera steers itself (Sensor.point)
        """No gimbal on a kinematic model."""

    @property
    def setpoint(self) -> Setpoint:
        return self._setpoint

    def close(self) -> None:  # noqa: B027 - a simulated vehicle holds nothing to release
        """Nothing to release."""

    @abstractmethod
    def state(self) -> VehicleState: ...

    def set_setpoint(self, setpoint: Setpoint) -> None:
        if not isinstance(setpoint, Setpoint):
            raise TypeError(f"setpoint must be a Setpoint, got {type(setpoint).__name__}")
        self._setpoint = setpoint

    @abstractmethod
    def _substep(self, h: float) -> None: ...

    def step(self, dt: float) -> None:
        dt = _check_dt(dt)
        if dt == 0.0:
            return
        n = max(1, math.ceil(dt / MAX_SUBSTEP - 1e-9))
        for _ in range(n):
            self._substep(dt / n)
        self._t += dt


class ConfigField(NamedTuple):
    """A ``[vehicle]`` key of a kinematic model: the constructor ``argument`` it sets, whether the config
    gives it in degrees (converted to radians), and an exclusive upper ``limit`` in config units."""

    argument: str
    degrees: bool = False
    limit: float | None = None


def kinematic_from_config(
    kind: str, params: dict, fields: dict[str, ConfigField], build: Callable[..., KinematicModel]
) -> KinematicModel:
    """``build(**arguments)`` from the ``[vehicle]`` parameters (``kind`` removed) of a kinematic model.

    Every key must be one of ``fields`` and its value a positive finite number (below the field's
    ``limit`` if it has one). Missing keys take the model defaults. Raises ``ValueError`` naming the key,
    or naming the kind for a value the model itself rejects.
    """
    kwargs = {}
    for key, value in params.items():
        if key not in fields:
            raise ValueError(f"{key}: unknown {kind} parameter, expected some of {sorted(fields)}")
        field = fields[key]
        try:
            value = positive(key, value)
        except ValueError as error:
            raise ValueError(f"{key}: {error}") from None
        if field.limit is not None and value >= field.limit:
            unit = " degrees" if field.degrees else ""
            raise ValueError(f"{key}: must be below {field.limit:g}{unit}, got {value!r}")
        kwargs[field.argument] = math.radians(value) if field.degrees else value
    try:
        return build(**kwargs)
    except ValueError as error:
        raise ValueError(f"vehicle config ({kind}): {error}") from None
