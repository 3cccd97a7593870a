"""Terrain height models and ray/terrain intersection.

A digital elevation model is assumed known to every agent (Merino §3.6), and the world uses the same
model as truth, so both import this module. Heights are metres above the NED origin, positive UP:
the NED ``z`` of a ground point is ``-height(north, east)`` (DESIGN.md §3, z down).

* :class:`FlatTerrain` — ``h(n, e) = h0`` (the flat plane of Ross et al. §VI.B, spec 002 §2.3).
* :class:`HillsTerrain` — a smooth analytic surface, a few sinusoidal ridges plus Gaussian bumps,
  deterministic for a seed, with known height bounds and a known slope bound.
* :func:`intersect_ray` — the first point where a camera ray meets the surface. Ross et al. (Eq. 1,
  spec 002 §2.3) intersect the ray with the plane of the three nearest DEM nodes and iterate; on an
  analytic surface the same georeferencing is a root search on the clearance ``f(λ)`` along the ray.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = [
    "Terrain",
    "FlatTerrain",
    "HillsTerrain",
    "terrain_from_config",
    "terrain_gradient",
    "intersect_ray",
    "unit_rays",
]


@runtime_checkable
class Terrain(Protocol):
    """Anything with a vectorised ``height(north, east)`` [m, positive up above the NED origin].

    Optional extras used when present: ``gradient(north, east) -> (dh/dn, dh/de)``,
    ``height_bounds -> (h_min, h_max)`` and ``max_slope`` (a Lipschitz bound on ``|∇h|``); they make
    :func:`intersect_ray` faster and exact about the first crossing."""

    def height(self, north: Any, east: Any) -> float | np.ndarray: ...


def _as_output(value: np.ndarray) -> float | np.ndarray:
    return float(value) if np.ndim(value) == 0 else value


class FlatTerrain:
    """A horizontal plane ``h(n, e) = height`` (Ross et al. HIL terrain, spec 002 §2.3).

    Immutable; the level is available as :attr:`level` (``height`` is the method)."""

    __slots__ = ("_level",)

    def __init__(self, height: float = 0.0):
        if isinstance(height, bool) or not isinstance(height, Real) or not math.isfinite(height):
            raise ValueError(f"flat terrain height must be a finite number, got {height!r}")
        object.__setattr__(self, "_level", float(height))

    def __setattr__(self, name, value):
        raise AttributeError("FlatTerrain is immutable")

    def __repr__(self) -> str:
        return f"FlatTerrain(height={self._level!r})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, FlatTerrain) and other._level == self._level

    def __hash__(self) -> int:
        return hash(("FlatTerrain", self._level))

    def __reduce__(self):
        return (FlatTerrain, (self._level,))

    @property
    def level(self) -> float:
        return self._level

    def height(self, north: Any, east: Any) -> float | np.ndarray:
        n, e = np.broadcast_arrays(np.asarray(north, dtype=float), np.asarray(east, dtype=float))
        return _as_output(np.full(n.shape, self._level))

    def gradient(self, north: Any, east: Any) -> tuple[float | np.ndarray, float | np.ndarray]:
        n, _ = np.broadcast_arrays(np.asarray(north, dtype=float), np.asarray(east, dtype=float))
        return _as_output(np.zeros(n.shape)), _as_output(np.zeros(n.shape))

    @property
    def height_bounds(self) -> tuple[float, float]:
        return self._level, self._level

    @property
    def max_slope(self) -> float:
        return 0.0


@dataclass(frozen=True)
class HillsTerrain:
    """Smooth hills, deterministic for ``seed``:

    ``h(n, e) = base + A [ Σ_i w_i cos(k_i·(n, e) + φ_i) + Σ_j b_j exp(-|(n, e) - c_j|² / (2 s_j²)) ]``

    with ``N_WAVES`` ridges (unit directions ``u_i`` uniform, ``|k_i| = 2π / λ_i``,
    ``λ_i ∈ [0.7, 1.4] wavelength``, weights ``w_i > 0`` summing to 1/2) and ``N_BUMPS`` Gaussian
    bumps (centres uniform in ``[-2, 2] wavelength`` around the origin, widths
    ``s_j ∈ [0.25, 0.5] wavelength``, signed heights ``b_j`` with ``Σ|b_j| = 1/2``, mostly hills).
    Hence ``|h - base| <= A`` everywhere and ``|∇h| <= A [Σ w_i |k_i| + Σ |b_j| e^{-1/2} / s_j]``.
    All shape constants are chosen here (no source gives a synthetic terrain)."""

    amplitude: float
    wavelength: float
    seed: int = 0
    base: float = 0.0
    _waves: np.ndarray = field(init=False, repr=False, compare=False)  # rows (k_n, k_e, phase, weight)
    _bumps: np.ndarray = field(init=False, repr=False, compare=False)  # rows (c_n, c_e, s, b)

    N_WAVES = 3  # chosen here
    N_BUMPS = 4  # chosen here

    def __post_init__(self):
        for name in ("amplitude", "wavelength", "base"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
                raise ValueError(f"hills terrain {name} must be a finite number, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.amplitude < 0:
            raise ValueError(f"hills terrain amplitude must be >= 0, got {self.amplitude}")
        if self.wavelength <= 0:
            raise ValueError(f"hills terrain wavelength must be > 0, got {self.wavelength}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, Integral) or self.seed < 0:
            raise ValueError(f"hills terrain seed must be a non-negative integer, got {self.seed!r}")
        object.__setattr__(self, "seed", int(self.seed))

        rng = np.random.default_rng(self.seed)
        heading = rng.uniform(0.0, 2.0 * np.pi, self.N_WAVES)
        lam = self.wavelength * rng.uniform(0.7, 1.4, self.N_WAVES)
        k = 2.0 * np.pi / lam
        phase = rng.uniform(0.0, 2.0 * np.pi, self.N_WAVES)
        w = rng.uniform(0.5, 1.0, self.N_WAVES)
        w = 0.5 * w / w.sum()
        waves = np.column_stack([k * np.cos(heading), k * np.sin(heading), phase, w])

        centres = rng.uniform(-2.0, 2.0, (self.N_BUMPS, 2)) * self.wavelength
        widths = rng.uniform(0.25, 0.5, self.N_BUMPS) * self.wavelength
        b = rng.uniform(0.5, 1.0, self.N_BUMPS) * np.where(rng.uniform(size=self.N_BUMPS) < 0.75, 1.0, -1.0)
        b = 0.5 * b / np.abs(b).sum()
        bumps = np.column_stack([centres, widths, b])
        waves.setflags(write=False)
        bumps.setflags(write=False)
        object.__setattr__(self, "_waves", waves)
        object.__setattr__(self, "_bumps", bumps)

    def height(self, north: Any, east: Any) -> float | np.ndarray:
        n, e = np.broadcast_arrays(np.asarray(north, dtype=float), np.asarray(east, dtype=float))
        h = np.zeros(n.shape)
        for kn, ke, phase, w in self._waves:
            h += w * np.cos(kn * n + ke * e + phase)
        for cn, ce, s, b in self._bumps:
            h += b * np.exp(-((n - cn) ** 2 + (e - ce) ** 2) / (2.0 * s * s))
        return _as_output(self.base + self.amplitude * h)

    def gradient(self, north: Any, east: Any) -> tuple[float | np.ndarray, float | np.ndarray]:
        """Analytic ``(∂h/∂n, ∂h/∂e)``."""
        n, e = np.broadcast_arrays(np.asarray(north, dtype=float), np.asarray(east, dtype=float))
        gn = np.zeros(n.shape)
        ge = np.zeros(n.shape)
        for kn, ke, phase, w in self._waves:
            s = -w * np.sin(kn * n + ke * e + phase)
            gn += s * kn
            ge += s * ke
        for cn, ce, s, b in self._bumps:
            g = b * np.exp(-((n - cn) ** 2 + (e - ce) ** 2) / (2.0 * s * s)) / (s * s)
            gn -= g * (n - cn)
            ge -= g * (e - ce)
        return _as_output(self.amplitude * gn), _as_output(self.amplitude * ge)

    @property
    def height_bounds(self) -> tuple[float, float]:
        """Guaranteed ``(h_min, h_max)``: the ridges span ``±Σw``, each bump adds ``[min(0,b), max(0,b)]``."""
        w = float(self._waves[:, 3].sum())
        b = self._bumps[:, 3]
        lo = self.base - self.amplitude * (w + float(-b[b < 0].sum()))
        hi = self.base + self.amplitude * (w + float(b[b > 0].sum()))
        return lo, hi

    @property
    def max_slope(self) -> float:
        """Lipschitz bound on ``|∇h|`` (a Gaussian bump's slope peaks at ``|b| e^{-1/2} / s``)."""
        k = np.hypot(self._waves[:, 0], self._waves[:, 1])
        ridges = float(np.sum(self._waves[:, 3] * k))
        bumps = float(np.sum(np.abs(self._bumps[:, 3]) * np.exp(-0.5) / self._bumps[:, 2]))
        return self.amplitude * (ridges + bumps)


def terrain_from_config(config: Mapping[str, Any]) -> Terrain:
    """Build a terrain from a TOML-like table.

    ``{"kind": "flat", "height": 0.0}`` or
    ``{"kind": "hills", "amplitude": 20.0, "wavelength": 300.0, "seed": 0, "base": 0.0}``
    (``height``, ``seed`` and ``base`` are optional). Unknown kinds or keys, missing keys and bad
    values raise :class:`ValueError` naming the offending key."""
    if not isinstance(config, Mapping):
        raise ValueError(f"terrain config must be a table, got {type(config).__name__}")
    kind = config.get("kind")
    specs: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
        "flat": ((), ("height",)),
        "hills": (("amplitude", "wavelength"), ("seed", "base")),
    }
    if kind not in specs:
        raise ValueError(f"terrain kind must be one of {sorted(specs)}, got {kind!r}")
    required, optional = specs[kind]
    unknown = sorted(set(config) - {"kind", *required, *optional})
    if unknown:
        raise ValueError(f"{kind} terrain: unknown key(s) {unknown}; allowed: {sorted({*required, *optional})}")
    missing = [key for key in required if key not in config]
    if missing:
        raise ValueError(f"{kind} terrain: missing key(s) {missing}")
    if kind == "flat":
        return FlatTerrain(config.get("height", 0.0))
    return HillsTerrain(
        amplitude=config["amplitude"],
        wavelength=config["wavelength"],
        seed=config.get("seed", 0),
        base=config.get("base", 0.0),
    )


def terrain_gradient(terrain: Terrain, north: Any, east: Any, step: float = 1e-2):
    """``(∂h/∂n, ∂h/∂e)``: the terrain's own ``gradient`` if it has one, else central differences
    ``(h(n + δ, e) - h(n - δ, e)) / 2δ`` (and likewise in east)."""
    gradient = getattr(terrain, "gradient", None)
    if callable(gradient):
        return gradient(north, east)
    n = np.asarray(north, dtype=float)
    e = np.asarray(east, dtype=float)
    gn = (np.asarray(terrain.height(n + step, e)) - np.asarray(terrain.height(n - step, e))) / (2.0 * step)
    ge = (np.asarray(terrain.height(n, e + step)) - np.asarray(terrain.height(n, e - step))) / (2.0 * step)
    return _as_output(gn), _as_output(ge)


def unit_rays(origins: Any, directions: Any) -> tuple[np.ndarray, np.ndarray]:
    """Rays as rows: their origins and unit directions, both ``(k, 3)`` floats. ``ValueError`` naming the fault
    for any other shape, a value that is not finite or a direction of zero length."""
    o = np.asarray(origins, dtype=float)
    d = np.asarray(directions, dtype=float)
    if o.ndim != 2 or o.shape[1:] != (3,) or d.shape != o.shape:
        raise ValueError(f"ray origins and directions must both have shape (k, 3), got {o.shape} and {d.shape}")
    if not (np.isfinite(o).all() and np.isfinite(d).all()):
        raise ValueError("ray origins and directions must be finite")
    norms = np.linalg.norm(d, axis=1)
    if np.any(norms == 0.0):
        raise ValueError("ray directions must be non-zero")
    return o, d / norms[:, None]


def intersect_ray(
    terrain: Terrain,
    origin_ned: Any,
    direction_ned: Any,
    max_range: float = 5000.0,
    tol: float = 1e-3,
    step: float = 1.0,
) -> np.ndarray | None:
    """First intersection of the ray ``r(λ) = o + λ d̂`` (``d̂ = d / |d|``, ``λ >= 0`` in metres) with
    the terrain surface, or ``None``.

    The clearance of the ray point above the ground is (NED, z down, heights up)

        ``f(λ) = -(o_z + λ d̂_z) - h(o_n + λ d̂_n, o_e + λ d̂_e)``,

    positive above the surface. The hit is the smallest ``λ* ∈ [0, max_range]`` with ``f(λ*) = 0``
    after ``f > 0``. On flat terrain ``h0`` it is ``λ* = (-h0 - o_z) / d̂_z`` (needs ``d̂_z > 0``, a ray
    pointing down).

    Search: (1) when the terrain reports ``height_bounds = (h_min, h_max)`` the ray is clipped to the
    slab ``h_min <= altitude <= h_max`` (a ray pointing level or up from above ``h_max`` never hits;
    a descending ray starts at the slab top and must hit by the slab bottom). (2) March: when the
    terrain reports ``max_slope = L``, ``f`` is Lipschitz with constant ``ρ = |d̂_z| + L |d̂_ne|``, so a
    step ``f(λ) / ρ`` cannot jump over a crossing (sphere tracing; steps never shorter than
    ``10 tol``, so only a dip below the surface shorter than that along the ray can be missed);
    otherwise fixed steps of ``step`` metres (which can miss features narrower than ``step``).
    (3) Bisection on the first sign change until the bracket is shorter than ``tol`` metres, then
    one secant step ``λ* = λ_lo + (λ_hi - λ_lo) f_lo / (f_lo - f_hi)``.

    Returns the hit point in NED (3,), ``None`` if the ray points away, leaves ``max_range`` first,
    or starts below the surface; a ray starting exactly on the surface returns its origin."""
    o = np.asarray(origin_ned, dtype=float)
    d = np.asarray(direction_ned, dtype=float)
    if o.shape != (3,) or d.shape != (3,):
        raise ValueError(f"origin and direction must have shape (3,), got {o.shape} and {d.shape}")
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))):
        raise ValueError("origin and direction must be finite")
    norm = float(np.linalg.norm(d))
    if norm == 0.0:
        raise ValueError("direction must be non-zero")
    if not (math.isfinite(max_range) and max_range > 0 and math.isfinite(tol) and tol > 0):
        raise ValueError(f"max_range and tol must be positive and finite, got {max_range} and {tol}")
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"step must be positive and finite, got {step}")
    d = d / norm
    on, oe, oz = (float(v) for v in o)
    dn, de, dz = (float(v) for v in d)

    def clearance(lam: float) -> float:
        return -(oz + lam * dz) - float(terrain.height(on + lam * dn, oe + lam * de))

    def point(lam: float) -> np.ndarray:
        return o + lam * d

    f0 = clearance(0.0)
    if f0 < 0.0:
        return None
    if f0 == 0.0:
        return o.copy()

    lo, hi_limit = 0.0, float(max_range)
    bounds = getattr(terrain, "height_bounds", None)
    if bounds is not None:
        h_min, h_max = (float(v) for v in bounds)
        altitude0 = -oz
        if altitude0 > h_max:
            if dz <= 0.0:  # level or climbing above every summit
                return None
            lo = (altitude0 - h_max) / dz
            if lo > max_range:
                return None
        if dz > 0.0:  # below h_min the ray is surely under the surface
            hi_limit = min(hi_limit, (altitude0 - h_min) / dz + tol)

    slope = getattr(terrain, "max_slope", None)
    rate = abs(dz) + float(slope) * math.hypot(dn, de) if slope is not None else None
    min_step = 10.0 * tol

    f_lo = clearance(lo) if lo > 0.0 else f0
    if f_lo <= 0.0:  # the slab top touches the surface (a summit exactly at h_max)
        if f_lo == 0.0:
            return point(lo)
        lo, f_lo = 0.0, f0  # cannot happen with correct bounds; fall back to marching from the origin
    while lo < hi_limit:
        if rate is not None and rate > 0.0:
            ds = max(f_lo / rate, min_step)
        else:
            ds = step
        hi = min(lo + ds, hi_limit)
        f_hi = clearance(hi)
        if f_hi <= 0.0:
            if f_hi == 0.0:
                return point(hi)
            while hi - lo > tol:
                mid = 0.5 * (lo + hi)
                f_mid = clearance(mid)
                if f_mid > 0.0:
                    lo, f_lo = mid, f_mid
                elif f_mid < 0.0:
                    hi, f_hi = mid, f_mid
                else:
                    return point(mid)
            lam = lo + (hi - lo) * f_lo / (f_lo - f_hi)
            return point(lam) if lam <= max_range else None
        lo, f_lo = hi, f_hi
    return None
