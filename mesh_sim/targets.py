"""Ground-target truth models (spec 004 §4).

Every target is a frozen dataclass whose ``state(t)`` is a deterministic function of the simulation
time ``t`` [s], so any process can evaluate truth at any time. Targets move on the ground: the
model gives the horizontal track ``(n(t), e(t))`` and the terrain gives the height, so that in NED
(z down)

    ``z(t) = -h(n(t), e(t))``,   ``ż(t) = -(∂h/∂n ṅ + ∂h/∂e ė)``   (chain rule).

* :class:`StaticTarget` — spec 004 §4.3.
* :class:`ConstantVelocityTarget` — ``p(t) = p0 + v t``, spec 004 §4.2.
* :class:`Figure8Target` — ``p(t) = c + R(ψ) d [sin(4πωt), sin(2πωt)]``, spec 004 §4.1 (Eqs. 14-15,
  closed form; the peak speed is ``2πωd √5 ≈ 8.0`` m/s for ``d = 20`` m, ``ω = 0.0285`` Hz).
* :class:`SingerTarget` — "man-like" manoeuvring target, spec 004 §4.4 (Eqs. 16-17, Singer-type).
* :class:`DampedVelocityTarget` — an Ornstein-Uhlenbeck velocity: the trackers' own motion model, the truth
  a consistency (ANEES) test needs.

:mod:`mesh_sim.target_set` builds them from TOML-like tables and turns them into plain data for the wire.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Any, Protocol, runtime_checkable

import numpy as np

from perception.terrain import FlatTerrain, Terrain, terrain_gradient

__all__ = [
    "Target",
    "StaticTarget",
    "ConstantVelocityTarget",
    "Figure8Target",
    "SingerTarget",
    "DampedVelocityTarget",
]

#: The ground a target rides on when it is given no terrain: flat at 0 m.
FLAT_GROUND = FlatTerrain()


@runtime_checkable
class Target(Protocol):
    id: str

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """``(position_ned (3,), velocity_ned (3,))`` at time ``t``."""
        ...


# --------------------------------------------------------------------------------------- helpers


def _check_time(t: float) -> float:
    if isinstance(t, bool) or not isinstance(t, Real) or not math.isfinite(t):
        raise ValueError(f"time must be a finite number, got {t!r}")
    return float(t)


def _vec2(value: Any, name: str) -> tuple[float, float]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (2,):
        raise ValueError(f"{name} must have 2 entries (north, east), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    return float(arr[0]), float(arr[1])


def as_real(
    value: Any, name: str, *, positive: bool = False, non_negative: bool = False, allow_inf: bool = False
) -> float:
    """``value`` as a float: a real number (not a bool), finite (``+inf`` too with ``allow_inf``) and, if asked,
    positive or non-negative; ``ValueError`` naming ``name`` otherwise (for the models and the config parser)."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ValueError(f"{name} must be a number, got {value!r}")
    value = float(value)
    if math.isnan(value) or (math.isinf(value) and not (allow_inf and value > 0)):
        raise ValueError(f"{name} must be finite, got {value}")
    if positive and not value > 0:
        raise ValueError(f"{name} must be > 0, got {value}")
    if non_negative and not value >= 0:
        raise ValueError(f"{name} must be >= 0, got {value}")
    return value


def _seed(value: Any) -> int:
    """A pre-simulated target's seed: a non-negative integer (not a bool); ``ValueError`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, Integral) or value < 0:
        raise ValueError(f"seed must be a non-negative integer, got {value!r}")
    return int(value)


def _check_common(target: Any) -> None:
    if not isinstance(target.id, str) or not target.id:
        raise ValueError(f"target id must be a non-empty string, got {target.id!r}")
    if not callable(getattr(target.terrain, "height", None)):
        raise ValueError(f"target {target.id!r}: terrain must have a height(north, east) method")


def _on_terrain(terrain: Terrain, n: float, e: float, vn: float, ve: float) -> tuple[np.ndarray, np.ndarray]:
    """Lift a ground track point to NED: ``z = -h(n, e)``, ``ż = -∇h · (ṅ, ė)``."""
    h = float(terrain.height(n, e))
    gn, ge = terrain_gradient(terrain, n, e)
    vz = -(float(gn) * vn + float(ge) * ve)
    return np.array([n, e, 0.0 - h]), np.array([vn, ve, vz + 0.0])  # + 0.0: no -0.0 on the wire


# ---------------------------------------------------------------------------------------- models


@dataclass(frozen=True)
class StaticTarget:
    """A target fixed at ground position ``(n, e)`` (spec 004 §4.3)."""

    position: tuple[float, float]
    id: str = field(default="static", kw_only=True)
    terrain: Terrain = field(default=FLAT_GROUND, kw_only=True)

    def __post_init__(self):
        object.__setattr__(self, "position", _vec2(self.position, "position"))
        _check_common(self)

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        _check_time(t)
        return _on_terrain(self.terrain, *self.position, 0.0, 0.0)


@dataclass(frozen=True)
class ConstantVelocityTarget:
    """``(n, e)(t) = position + velocity t`` with a 2-D ground velocity (spec 004 §4.2)."""

    position: tuple[float, float]
    velocity: tuple[float, float]
    id: str = field(default="cv", kw_only=True)
    terrain: Terrain = field(default=FLAT_GROUND, kw_only=True)

    def __post_init__(self):
        object.__setattr__(self, "position", _vec2(self.position, "position"))
        object.__setattr__(self, "velocity", _vec2(self.velocity, "velocity"))
        _check_common(self)

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        t = _check_time(t)
        (n0, e0), (vn, ve) = self.position, self.velocity
        return _on_terrain(self.terrain, n0 + vn * t, e0 + ve * t, vn, ve)


@dataclass(frozen=True)
class Figure8Target:
    """Closed-form figure-8 (a 2:1 Lissajous), spec 004 §4.1 (Andreetto et al. Eqs. 14-15, with the
    minus sign and the initial velocity that make the ODE an exact figure-8):

        ``q(t) = d [sin(4πωt), sin(2πωt)]``,  ``q̇(t) = 2πωd [2 cos(4πωt), cos(2πωt)]``,
        ``(n, e)(t) = center + R(heading) q(t)``,  ``R(ψ) = [[cos ψ, -sin ψ], [sin ψ, cos ψ]]``.

    It passes through ``center`` at ``t = 0`` and ``t = 1/(2ω)``, repeats with period ``1/ω`` and its
    peak ground speed is ``2πωd √5`` (at ``t = 0``), 8.0 m/s for the defaults. ``heading`` [rad] turns
    the long (first) axis of the figure from north towards east."""

    center: tuple[float, float]
    d: float = 20.0
    omega: float = 0.0285
    heading: float = 0.0
    id: str = field(default="figure8", kw_only=True)
    terrain: Terrain = field(default=FLAT_GROUND, kw_only=True)

    def __post_init__(self):
        object.__setattr__(self, "center", _vec2(self.center, "center"))
        object.__setattr__(self, "d", as_real(self.d, "d", positive=True))
        object.__setattr__(self, "omega", as_real(self.omega, "omega", positive=True))
        object.__setattr__(self, "heading", as_real(self.heading, "heading"))
        _check_common(self)

    @property
    def period(self) -> float:
        return 1.0 / self.omega

    @property
    def peak_speed(self) -> float:
        return 2.0 * math.pi * self.omega * self.d * math.sqrt(5.0)

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        t = _check_time(t)
        w = 2.0 * math.pi * self.omega
        qx, qy = self.d * math.sin(2.0 * w * t), self.d * math.sin(w * t)
        vx, vy = 2.0 * w * self.d * math.cos(2.0 * w * t), w * self.d * math.cos(w * t)
        c, s = math.cos(self.heading), math.sin(self.heading)
        n = self.center[0] + c * qx - s * qy
        e = self.center[1] + s * qx + c * qy
        return _on_terrain(self.terrain, n, e, c * vx - s * vy, s * vx + c * vy)


class _Presimulated:
    """A target pre-simulated on the grid ``t_k = k dt`` in chunks of ``CHUNK_SECONDS`` (chunk ``j`` draws its
    noise from ``default_rng([seed, j])``), rows ``(n, e, vn, ve, ...)``; produced lazily as ``t`` grows, and
    never dependent on the order of the queries, so ``state(t)`` is a pure function of ``(parameters, t)``.
    Between grid points the velocity is linear and the position quadratic (the rows' positions integrate the
    velocity by the trapezoid rule), so ``state(t)`` is continuous and its velocity is exactly the derivative
    of its position. ``t`` must lie in ``[0, max_horizon]``. Not safe for concurrent first evaluation from
    threads. A subclass gives ``_start_row()`` and ``_simulate_chunk(j, start_row)``."""

    CHUNK_SECONDS = 60.0  # chosen here

    @property
    def _chunk_steps(self) -> int:
        return max(1, round(self.CHUNK_SECONDS / self.dt))

    def _ensure(self, t: float) -> None:
        if t < 0.0 or t > self.max_horizon:
            raise ValueError(f"target {self.id!r}: t = {t} is outside [0, max_horizon = {self.max_horizon}]")
        need = int(t / self.dt) // self._chunk_steps
        while len(self._chunks) <= need:
            j = len(self._chunks)
            start = self._start_row() if j == 0 else tuple(self._chunks[-1][-1])
            chunk = self._simulate_chunk(j, start)
            chunk.setflags(write=False)
            self._chunks.append(chunk)

    def _rows(self, t_end: float) -> tuple[np.ndarray, np.ndarray]:
        """Times ``(K+1,)`` and rows ``(K+1, columns)`` of the grid up to ``t_end``."""
        t_end = _check_time(t_end)
        self._ensure(t_end)
        k_end = int(math.floor(t_end / self.dt + 1e-9))
        rows = np.concatenate([self._chunks[0]] + [c[1:] for c in self._chunks[1:]])[: k_end + 1]
        return np.arange(k_end + 1) * self.dt, rows

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        t = _check_time(t)
        self._ensure(t)
        steps = self._chunk_steps
        k = int(math.floor(t / self.dt))
        j, i = divmod(k, steps)
        rows = self._chunks[j]
        s = t - (j * steps + i) * self.dt
        (pn, pe, vn, ve), (vn1, ve1) = rows[i, :4], rows[i + 1, 2:4]
        f = s / self.dt
        vn_t = vn + (vn1 - vn) * f
        ve_t = ve + (ve1 - ve) * f
        n = pn + vn * s + 0.5 * (vn1 - vn) * s * f
        e = pe + ve * s + 0.5 * (ve1 - ve) * s * f
        return _on_terrain(self.terrain, float(n), float(e), float(vn_t), float(ve_t))


@dataclass(frozen=True)
class SingerTarget(_Presimulated):
    """A "man-like" manoeuvring target (spec 004 §4.4, Singer-type): per ground axis

        ``ȧ = -α a + w``,  stationary ``std(a) = sigma`` [m/s²]  (``E[w w'] = 2 α sigma² δ``),

    sampled exactly on the grid ``t_k = k dt`` (Ornstein-Uhlenbeck transition):

        ``a_{k+1} = φ a_k + sigma √(1 - φ²) ξ_k``,  ``φ = exp(-α dt)``,  ``ξ_k ~ N(0, I₂)``.

    The velocity integrates the step-mean acceleration, ``v_{k+1} = v_k + dt (a_k + a_{k+1}) / 2``,
    and is then clipped to ``|v_{k+1}| <= max_speed`` (ground speed, 8 m/s by default: the top of
    the 0-8 m/s target range of spec 004); positions follow ``p_{k+1} = p_k + dt (v_k + v_{k+1}) / 2``.

    Pre-simulated on that grid as :class:`_Presimulated` says.

    ``sigma`` is the RMS acceleration, not the spectral density of spec 004's ``w`` (whose σ = 0.1
    m/s³ is ambiguous there): a white ``w`` of spectral density ``q`` gives ``sigma² = q / (2α)``.
    ``acceleration`` is the initial acceleration ``a_0`` (spec 004: ``[1, 1]``; default 0, chosen here)."""

    position: tuple[float, float]
    velocity: tuple[float, float]
    alpha: float
    sigma: float
    seed: int
    dt: float = 0.05  # spec 004 §3: the 0.05 s tracking time step
    max_speed: float = 8.0  # spec 004 §4.2: targets up to 8 m/s; math.inf disables the clip
    acceleration: tuple[float, float] = (0.0, 0.0)
    max_horizon: float = 86_400.0  # chosen here: a day of simulation time bounds the memory
    id: str = field(default="singer", kw_only=True)
    terrain: Terrain = field(default=FLAT_GROUND, kw_only=True)
    _chunks: list = field(init=False, repr=False, compare=False, default_factory=list)

    def __post_init__(self):
        object.__setattr__(self, "position", _vec2(self.position, "position"))
        object.__setattr__(self, "velocity", _vec2(self.velocity, "velocity"))
        object.__setattr__(self, "acceleration", _vec2(self.acceleration, "acceleration"))
        object.__setattr__(self, "alpha", as_real(self.alpha, "alpha", positive=True))
        object.__setattr__(self, "sigma", as_real(self.sigma, "sigma", non_negative=True))
        object.__setattr__(self, "dt", as_real(self.dt, "dt", positive=True))
        object.__setattr__(self, "max_speed", as_real(self.max_speed, "max_speed", positive=True, allow_inf=True))
        object.__setattr__(self, "max_horizon", as_real(self.max_horizon, "max_horizon", positive=True))
        object.__setattr__(self, "seed", _seed(self.seed))
        _check_common(self)
        if math.hypot(*self.velocity) > self.max_speed:
            raise ValueError(f"initial speed {math.hypot(*self.velocity):.3g} m/s exceeds max_speed {self.max_speed}")

    def _start_row(self) -> tuple:
        return (*self.position, *self.velocity, *self.acceleration)

    def _simulate_chunk(self, j: int, start: tuple) -> np.ndarray:
        """Rows ``k = 0..K`` of ``(n, e, vn, ve, an, ae)`` from the chunk's start row."""
        steps = self._chunk_steps
        phi = math.exp(-self.alpha * self.dt)
        gain = self.sigma * math.sqrt(-math.expm1(-2.0 * self.alpha * self.dt))
        xi = np.random.default_rng([self.seed, j]).standard_normal((steps, 2)) * gain
        out = np.empty((steps + 1, 6))
        pn, pe, vn, ve, an, ae = start
        vmax, half = self.max_speed, 0.5 * self.dt
        out[0] = start
        for k in range(steps):
            an1 = phi * an + xi[k, 0]
            ae1 = phi * ae + xi[k, 1]
            vn1 = vn + half * (an + an1)
            ve1 = ve + half * (ae + ae1)
            speed = math.hypot(vn1, ve1)
            if speed > vmax:
                vn1 *= vmax / speed
                ve1 *= vmax / speed
            pn += half * (vn + vn1)
            pe += half * (ve + ve1)
            vn, ve, an, ae = vn1, ve1, an1, ae1
            out[k + 1] = (pn, pe, vn, ve, an, ae)
        return out

    def grid(self, t_end: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The pre-simulated ground grid up to ``t_end``: ``times (K+1,)``, ground positions, ground
        velocities and the Singer accelerations ``a_k`` (each ``(K+1, 2)``)."""
        times, rows = self._rows(t_end)
        return times, rows[:, 0:2].copy(), rows[:, 2:4].copy(), rows[:, 4:6].copy()


@dataclass(frozen=True)
class DampedVelocityTarget(_Presimulated):
    """A ground target whose velocity is an Ornstein-Uhlenbeck process per ground axis — the truth the trackers'
    ``motion = "damped"`` model (:class:`fusion.motion.DampedVelocity`) assumes:

        ``dv = -v / tau dt + s dW``,  stationary ``std(v) = speed_std``  (``s² = 2 speed_std² / tau``),

    sampled exactly on the grid ``t_k = k dt``: ``v_{k+1} = φ v_k + speed_std √(1 - φ²) ξ_k``, ``φ = exp(-dt /
    tau)``, ``ξ_k ~ N(0, I₂)``; positions ``p_{k+1} = p_k + dt (v_k + v_{k+1}) / 2`` (the trapezoid's error,
    ``O(dt²)`` per step, is ~10⁻⁵ of the motion at dt = 0.05 s, tau = 10 s). Without ``velocity`` the start
    velocity is drawn from the stationary law ``N(0, speed_std² I₂)`` (``default_rng(seed)``), as the trackers'
    prior says. A filter's consistency (NEES inside its χ² interval) is defined against truth drawn from its own
    model (Bar-Shalom, Li & Kirubarajan 2001, §5.4.2): static or constant-velocity targets have a velocity the
    model would rarely draw and leave a consistent filter's NEES far below its interval. Pre-simulated as
    :class:`_Presimulated` says."""

    position: tuple[float, float]
    speed_std: float
    tau: float
    seed: int
    velocity: tuple[float, float] | None = None
    dt: float = 0.05  # spec 004 §3: the 0.05 s tracking time step
    max_horizon: float = 86_400.0  # chosen here: a day of simulation time bounds the memory
    id: str = field(default="damped", kw_only=True)
    terrain: Terrain = field(default=FLAT_GROUND, kw_only=True)
    _chunks: list = field(init=False, repr=False, compare=False, default_factory=list)

    def __post_init__(self):
        object.__setattr__(self, "position", _vec2(self.position, "position"))
        for name in ("speed_std", "tau", "dt", "max_horizon"):
            object.__setattr__(self, name, as_real(getattr(self, name), name, positive=True))
        object.__setattr__(self, "seed", _seed(self.seed))
        velocity = (self.speed_std * np.random.default_rng(self.seed).standard_normal(2) if self.velocity is None
                    else self.velocity)
        object.__setattr__(self, "velocity", _vec2(velocity, "velocity"))
        _check_common(self)

    def _start_row(self) -> tuple:
        return (*self.position, *self.velocity)

    def _simulate_chunk(self, j: int, start: tuple) -> np.ndarray:
        """Rows ``k = 0..K`` of ``(n, e, vn, ve)`` from the chunk's start row."""
        steps = self._chunk_steps
        phi = math.exp(-self.dt / self.tau)
        gain = self.speed_std * math.sqrt(-math.expm1(-2.0 * self.dt / self.tau))
        xi = np.random.default_rng([self.seed, j]).standard_normal((steps, 2)) * gain
        velocity = np.empty((steps + 1, 2))
        velocity[0] = start[2:4]
        for k in range(steps):
            velocity[k + 1] = phi * velocity[k] + xi[k]
        steps_moved = 0.5 * self.dt * (velocity[:-1] + velocity[1:])
        position = np.vstack([start[0:2], start[0:2] + np.cumsum(steps_moved, axis=0)])
        return np.hstack([position, velocity])
