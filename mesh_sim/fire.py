"""The true fire: a stochastic two-layer cellular fire on its own truth grid.

State per cell k: 0 unburnt, 1 burning, 2 burnt — the binary truth behind Merino's two layers
``F_k`` (fire in the cell) and ``Q_k`` (cell completely burnt), §6.3 (spec 001b §2.6.1). Each step
of ``dt = step`` seconds applies Merino's prediction model (6.4)-(6.6) as a *generative* model,
all transitions drawn from the state at the start of the step:

* burn-out, (6.4) with ``β = 1 - exp(-dt / burn_time)``: a burning cell becomes burnt with
  probability β (a constant hazard ``1 / burn_time``; ``burn_time = inf``: cells never burn out);
* persistence, (6.5): a burning cell that does not burn out stays burning; a burnt cell never
  burns again;
* spread, (6.6) with ``ω_q = p_q``: an unburnt cell k ignites with the noisy-OR over its burning
  8-neighbours q (the spec's combination of (6.5)-(6.6)):

      ``P(ignite_k) = 1 - Π_q (1 - p_q)``,  ``p_q = 1 - exp(-dt · rate · w_qk · s_qk)``,

  so ``P(ignite_k) = 1 - exp(-dt · rate · Σ_q w_qk s_qk)`` (computed in that form);
* wind (chosen here): ``w_qk = exp(wind_gain · v · u_qk)`` with ``v`` the (north, east) wind [m/s]
  and ``u_qk`` the unit vector from q to k: spread downwind is faster, upwind slower, and
  ``w = 1`` without wind;
* slope (chosen here): ``s_qk = exp(slope_gain · atan((h_k - h_q) / |r_k - r_q|))`` with terrain
  heights ``h`` at the cell centres: spread uphill is faster.

Merino stresses that his model is not a fire-spread model (§6.3.1: it only adds memory and spatial
smoothing to the filter) and gives no values for β, ω_q or the neighbourhood. The exponential wind
and slope factors follow the common cellular-automaton practice (e.g. Alexandridis et al., 2008:
ignition probability of a neighbour scaled by ``exp(c V)``-type wind and ``exp(a θ_slope)`` slope
factors); every constant here is chosen here. Cells listed as firebreaks never ignite.

Reproducibility: step k draws its uniforms from ``default_rng([seed, k])`` over the bounding box of
the burning cells (grown by one cell), so ``state_at(t)`` is a pure function of (config, terrain,
seed, t) whatever the order of the queries. The latest state is cached (stepping forward is
incremental) and a compressed checkpoint is kept every ``CHECKPOINT_STEPS`` steps (stepping back
restarts from the nearest one). Once no cell can change any more the state is final.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from numbers import Integral, Real
from typing import Any

import numpy as np
import scipy.ndimage

from agent.net.fire_truth import BURNING, BURNT, MAX_FIRE_CELLS, UNBURNT, encode_fire
from perception.terrain import FlatTerrain

__all__ = ["FireConfig", "FireWorld", "NEIGHBOURS"]

WIND_GAIN = 0.3  # s/m, chosen here: a 5 m/s wind multiplies the downwind hazard by e^1.5 ≈ 4.5
SLOPE_GAIN = 4.0  # per radian, chosen here: a 10° upslope multiplies the hazard by ≈ 2
CHECKPOINT_STEPS = 64  # chosen here
MAX_HORIZON_S = 86_400.0  # chosen here: a day of simulation time bounds the work of one query
_EDGE_TOL = 1e-9  # relative slack for cell counts and step indices (floating-point edges)

#: The 8-neighbourhood (Merino's R(k), spec 001b §2.6.2: 8-connected chosen here), (d_row, d_col).
NEIGHBOURS: tuple[tuple[int, int], ...] = tuple((di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj)


# ----------------------------------------------------------------------------------------- config


def _real(value: Any, name: str, *, positive=False, non_negative=False, allow_inf=False) -> float:
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ValueError(f"fire {name} must be a number, got {value!r}")
    value = float(value)
    if math.isnan(value) or (math.isinf(value) and not (allow_inf and value > 0)):
        raise ValueError(f"fire {name} must be finite, got {value}")
    if positive and not value > 0:
        raise ValueError(f"fire {name} must be > 0, got {value}")
    if non_negative and not value >= 0:
        raise ValueError(f"fire {name} must be >= 0, got {value}")
    return value


def _tuple(value: Any, size: int, name: str) -> tuple[float, ...]:
    if isinstance(value, str | bytes) or not isinstance(value, Sequence | np.ndarray) or len(value) != size:
        raise ValueError(f"fire {name} must be a list of {size} numbers, got {value!r}")
    return tuple(_real(v, f"{name}[{i}]") for i, v in enumerate(value))


def _rectangle(value: Any, name: str) -> tuple[float, float, float, float]:
    n0, n1, e0, e1 = _tuple(value, 4, name)
    if not (n0 < n1 and e0 < e1):
        raise ValueError(f"fire {name} must be [north_min, north_max, east_min, east_max] with min < max, got {value}")
    return n0, n1, e0, e1


def _list(value: Any, name: str) -> Sequence:
    if isinstance(value, str | bytes) or not isinstance(value, Sequence | np.ndarray):
        raise ValueError(f"fire {name} must be a list, got {value!r}")
    return value


@dataclass(frozen=True)
class FireConfig:
    """The scenario's ``[fire]`` table. ``ignitions``: (north, east) points burning at t = 0 (at least
    one); ``area``: (north_min, north_max, east_min, east_max) covered by the truth grid (default: the
    scenario area); ``cell``: truth cell side [m]; ``rate``: ignition hazard per burning neighbour
    [1/s]; ``burn_time``: mean burning time of a cell [s] (``inf`` allowed); ``wind``: (north, east)
    [m/s]; ``step``: the internal time step [s]; ``temperature_K``: flame temperature for the thermal
    camera; ``firebreaks``: rectangles like ``area`` whose cells never burn; ``wind_gain`` [s/m] and
    ``slope_gain`` [1/rad]: see the module docstring. The seed comes from the caller (the scenario)."""

    ignitions: tuple[tuple[float, float], ...]
    area: tuple[float, float, float, float]
    cell: float = 5.0  # m, chosen here
    rate: float = 0.02  # 1/s, chosen here: calm-air fronts of about 0.55 m/s with 5 m cells (measured)
    burn_time: float = 120.0  # s, chosen here
    wind: tuple[float, float] = (0.0, 0.0)
    step: float = 1.0  # s, chosen here
    temperature_K: float = 800.0  # chosen here
    firebreaks: tuple[tuple[float, float, float, float], ...] = ()
    wind_gain: float = WIND_GAIN
    slope_gain: float = SLOPE_GAIN

    def __post_init__(self):
        area = _rectangle(self.area, "area")
        ignitions = tuple(_tuple(p, 2, f"ignitions[{i}]") for i, p in enumerate(_list(self.ignitions, "ignitions")))
        if not ignitions:
            raise ValueError("fire ignitions must list at least one (north, east) point")
        for i, (n, e) in enumerate(ignitions):
            if not (area[0] <= n <= area[1] and area[2] <= e <= area[3]):
                raise ValueError(f"fire ignitions[{i}] = ({n}, {e}) is outside the area {area}")
        breaks = tuple(_rectangle(r, f"firebreaks[{i}]") for i, r in enumerate(_list(self.firebreaks, "firebreaks")))
        for i, (n0, n1, e0, e1) in enumerate(breaks):
            if n1 <= area[0] or n0 >= area[1] or e1 <= area[2] or e0 >= area[3]:
                raise ValueError(f"fire firebreaks[{i}] = {(n0, n1, e0, e1)} does not overlap the area {area}")
        values = {
            "cell": _real(self.cell, "cell", positive=True),
            "rate": _real(self.rate, "rate", non_negative=True),
            "burn_time": _real(self.burn_time, "burn_time", positive=True, allow_inf=True),
            "step": _real(self.step, "step", positive=True),
            "temperature_K": _real(self.temperature_K, "temperature_K", positive=True),
            "wind_gain": _real(self.wind_gain, "wind_gain", non_negative=True),
            "slope_gain": _real(self.slope_gain, "slope_gain", non_negative=True),
        }
        for name, value in {"area": area, "ignitions": ignitions, "firebreaks": breaks,
                            "wind": _tuple(self.wind, 2, "wind"), **values}.items():
            object.__setattr__(self, name, value)
        rows, cols = self.shape
        if rows * cols > MAX_FIRE_CELLS:
            raise ValueError(f"fire grid of {rows}x{cols} cells exceeds {MAX_FIRE_CELLS}: use a larger cell")
        cells = [self.cell_of(n, e) for n, e in ignitions]
        for i, rect in enumerate(breaks):
            blocked = set(_rect_cells(rect, self.origin, self.cell, self.shape))
            hit = [k for k, c in enumerate(cells) if c in blocked]
            if hit:
                raise ValueError(f"fire ignitions[{hit[0]}] lies in a cell of firebreaks[{i}]")

    @classmethod
    def from_dict(cls, d: Mapping, area: tuple[float, float, float, float]) -> FireConfig:
        """Build from the ``[fire]`` table; ``area`` (the scenario's) is used unless the table has its
        own. Unknown keys, a missing ``ignitions`` and bad values raise ``ValueError`` naming the key."""
        if not isinstance(d, Mapping):
            raise ValueError(f"fire config must be a table, got {type(d).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"fire: unknown key(s) {unknown}; allowed: {sorted(known)}")
        if "ignitions" not in d:
            raise ValueError("fire: missing key 'ignitions' (a list of [north, east] points)")
        return cls(**{"area": area, **dict(d)})

    @property
    def origin(self) -> tuple[float, float]:
        """(north, east) of the corner of cell (0, 0)."""
        return self.area[0], self.area[2]

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) = ceil(extent / cell): the grid covers the area (its last cells may overhang it)."""
        rows = math.ceil((self.area[1] - self.area[0]) / self.cell - _EDGE_TOL)
        cols = math.ceil((self.area[3] - self.area[2]) / self.cell - _EDGE_TOL)
        return max(1, rows), max(1, cols)

    def cell_of(self, north: float, east: float) -> tuple[int, int]:
        """The (row, col) holding a point of the area (the area's far edges belong to the last cells)."""
        rows, cols = self.shape
        i = min(int(math.floor((north - self.area[0]) / self.cell)), rows - 1)
        j = min(int(math.floor((east - self.area[2]) / self.cell)), cols - 1)
        return max(i, 0), max(j, 0)


def _rect_cells(rect, origin, cell, shape) -> list[tuple[int, int]]:
    """Cells overlapping the rectangle with positive area."""
    (n0, n1, e0, e1), (rows, cols) = rect, shape
    i = np.arange(rows)
    j = np.arange(cols)
    rows_in = i[(origin[0] + (i + 1) * cell > n0) & (origin[0] + i * cell < n1)]
    cols_in = j[(origin[1] + (j + 1) * cell > e0) & (origin[1] + j * cell < e1)]
    return [(int(a), int(b)) for a in rows_in for b in cols_in]


# ------------------------------------------------------------------------------------------ world


def _overlap(lo_a: np.ndarray, width_a: float, lo_b: np.ndarray, width_b: float) -> np.ndarray:
    """``[len(lo_a), len(lo_b)]`` lengths of the overlaps of the intervals ``[lo, lo + width)``."""
    lo = np.maximum(lo_a[:, None], lo_b[None, :])
    hi = np.minimum(lo_a[:, None] + width_a, lo_b[None, :] + width_b)
    return np.maximum(hi - lo, 0.0)


class FireWorld:
    """The fire of one run: ``state_at(t)`` and what is derived from it (see the module docstring)."""

    def __init__(self, config: FireConfig, terrain=None, seed: int = 0):
        if not isinstance(config, FireConfig):
            raise ValueError(f"config must be a FireConfig, got {type(config).__name__}")
        if isinstance(seed, bool) or not isinstance(seed, Integral) or seed < 0:
            raise ValueError(f"fire seed must be a non-negative integer, got {seed!r}")
        terrain = FlatTerrain() if terrain is None else terrain
        if not callable(getattr(terrain, "height", None)):
            raise ValueError("terrain must have a height(north, east) method")
        self.config = config
        self.terrain = terrain
        self.seed = int(seed)
        self.shape = config.shape
        self.origin = config.origin
        rows, cols = self.shape
        n = self.origin[0] + (np.arange(rows) + 0.5) * config.cell
        e = self.origin[1] + (np.arange(cols) + 0.5) * config.cell
        nn, ee = np.meshgrid(n, e, indexing="ij")
        self.centres = np.stack([nn, ee], axis=-1)
        self.heights = np.broadcast_to(np.asarray(terrain.height(nn, ee), dtype=float), self.shape).copy()
        if not np.all(np.isfinite(self.heights)):
            raise ValueError("terrain heights at the fire cells are not finite")
        self.firebreak = np.zeros(self.shape, bool)
        for rect in config.firebreaks:
            for i, j in _rect_cells(rect, self.origin, config.cell, self.shape):
                self.firebreak[i, j] = True
        for array in (self.centres, self.heights, self.firebreak):
            array.setflags(write=False)
        self._hazard = self._hazards()
        self._p_burnout = -math.expm1(-config.step / config.burn_time)
        initial = np.zeros(self.shape, np.int8)
        for point in config.ignitions:
            initial[config.cell_of(*point)] = BURNING
        self._k, self._state = 0, initial
        self._checkpoints: dict[int, bytes] = {0: zlib.compress(initial.tobytes())}
        self._final_step: int | None = None  # first step from which the state never changes

    def _hazards(self) -> list[tuple[int, int, np.ndarray]]:
        """Per direction (di, dj): ``dt · rate · w · s`` at each *source* cell q, toward k = q + (di, dj);
        zero where k is outside the grid or a firebreak."""
        c = self.config
        rows, cols = self.shape
        wind = np.asarray(c.wind)
        out = []
        for di, dj in NEIGHBOURS:
            distance = c.cell * math.hypot(di, dj)
            x = np.zeros(self.shape)
            src = (slice(max(-di, 0), rows - max(di, 0)), slice(max(-dj, 0), cols - max(dj, 0)))
            dst = (slice(max(di, 0), rows + min(di, 0)), slice(max(dj, 0), cols + min(dj, 0)))
            rise = self.heights[dst] - self.heights[src]
            w = math.exp(c.wind_gain * float(wind @ np.array([di, dj]) / math.hypot(di, dj)))
            x[src] = c.step * c.rate * w * np.exp(c.slope_gain * np.arctan(rise / distance))
            x[src] *= ~self.firebreak[dst]
            x.setflags(write=False)
            out.append((di, dj, x))
        return out

    # -- stepping

    def _step_of(self, t: float) -> int:
        if isinstance(t, bool) or not isinstance(t, Real) or not math.isfinite(t):
            raise ValueError(f"time must be a finite number, got {t!r}")
        if not 0.0 <= t <= MAX_HORIZON_S:
            raise ValueError(f"fire time t = {t} is outside [0, {MAX_HORIZON_S}] s")
        return int(math.floor(float(t) / self.config.step + _EDGE_TOL))

    def ignition_probability(self, state: np.ndarray) -> np.ndarray:
        """(rows, cols) probability that each cell ignites during the next step from ``state``:
        ``1 - exp(-Σ_q dt rate w_qk s_qk)`` over burning neighbours q for unburnt, non-firebreak
        cells; 0 elsewhere."""
        state = np.asarray(state)
        if state.shape != self.shape:
            raise ValueError(f"state must have shape {self.shape}, got {state.shape}")
        burning = (state == BURNING).astype(float)
        total = np.zeros(self.shape)
        rows, cols = self.shape
        for di, dj, x in self._hazard:
            src = (slice(max(-di, 0), rows - max(di, 0)), slice(max(-dj, 0), cols - max(dj, 0)))
            dst = (slice(max(di, 0), rows + min(di, 0)), slice(max(dj, 0), cols + min(dj, 0)))
            total[dst] += burning[src] * x[src]
        return np.where(state == UNBURNT, -np.expm1(-total), 0.0)

    def _advance(self, state: np.ndarray, k: int) -> tuple[np.ndarray, bool]:
        """State at step k + 1 from the state at step k, and whether nothing can change any more."""
        burning = state == BURNING
        rows_on = np.flatnonzero(burning.any(axis=1))
        if rows_on.size == 0:
            return state, True
        cols_on = np.flatnonzero(burning.any(axis=0))
        r0, r1 = max(rows_on[0] - 1, 0), min(rows_on[-1] + 2, self.shape[0])
        c0, c1 = max(cols_on[0] - 1, 0), min(cols_on[-1] + 2, self.shape[1])
        box = state[r0:r1, c0:c1]
        b = burning[r0:r1, c0:c1].astype(float)
        h, w = box.shape
        total = np.zeros(box.shape)
        for di, dj, x in self._hazard:  # every burning source and its neighbours lie inside the box
            xb = x[r0:r1, c0:c1]
            src = (slice(max(-di, 0), h - max(di, 0)), slice(max(-dj, 0), w - max(dj, 0)))
            dst = (slice(max(di, 0), h + min(di, 0)), slice(max(dj, 0), w + min(dj, 0)))
            total[dst] += b[src] * xb[src]
        u = np.random.default_rng([self.seed, k]).random(box.shape)
        unburnt = box == UNBURNT
        ignite = unburnt & (u < -np.expm1(-total))
        burnout = (b > 0) & (u < self._p_burnout)
        new = state.copy()
        new_box = new[r0:r1, c0:c1]
        new_box[ignite] = BURNING
        new_box[burnout] = BURNT
        frozen = self._p_burnout == 0.0 and not np.any(total[unburnt] > 0.0)
        return new, frozen

    def state_at(self, t: float) -> np.ndarray:
        """(rows, cols) int8 at time t: 0 unburnt, 1 burning, 2 burnt (the state after
        ``floor(t / step)`` steps). A fresh copy."""
        k = self._step_of(t)
        if self._final_step is not None and k >= self._final_step:
            k = self._final_step
        if k < self._k:
            start = max(s for s in self._checkpoints if s <= k)
            self._k = start
            self._state = np.frombuffer(zlib.decompress(self._checkpoints[start]), np.int8).reshape(self.shape).copy()
        while self._k < k:
            new, frozen = self._advance(self._state, self._k)
            if frozen:
                self._final_step = self._k
                break
            self._state, self._k = new, self._k + 1
            if self._k % CHECKPOINT_STEPS == 0:
                self._checkpoints[self._k] = zlib.compress(self._state.tobytes())
        return self._state.copy()

    # -- derived truth

    def burning_cells(self, t: float) -> np.ndarray:
        """(k, 3) NED centres of the burning cells, on the terrain (``z = -h``)."""
        on = self.state_at(t) == BURNING
        ne = self.centres[on]
        return np.column_stack([ne, -self.heights[on] + 0.0])

    def payload(self, t: float) -> dict:
        """The compact truth for the wire (:func:`agent.net.fire_truth.encode_fire`, decoded by
        :func:`agent.net.fire_truth.decode_fire`)."""
        return encode_fire(self.origin, self.config.cell, self.state_at(t), self.config.temperature_K)

    def coverage(self, geometry_origin, cell: float, shape, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Fractions of each cell of another axis-aligned grid (corner ``geometry_origin`` (north,
        east), side ``cell``, ``shape`` (rows, cols)) that are burning and burnt at ``t``. Exact areas:
        the overlap of two axis-aligned squares is separable, so with ``A_n[a, i]`` (``A_e[b, j]``)
        the length shared by row a of the other grid and truth row i (columns likewise),

            ``burning[a, b] = Σ_ij A_n[a, i] [state_ij = 1] A_e[b, j] / cell²``

        (``A_n @ mask @ A_e.T``). Parts of a cell outside the truth grid count as unburnt."""
        origin = np.asarray(geometry_origin, dtype=float)
        if origin.shape != (2,) or not np.all(np.isfinite(origin)):
            raise ValueError(f"geometry_origin must be 2 finite numbers (north, east), got {geometry_origin!r}")
        cell = _real(cell, "coverage cell", positive=True)
        if isinstance(shape, str | bytes) or not isinstance(shape, Sequence | np.ndarray) or len(shape) != 2 or any(
                isinstance(v, bool) or not isinstance(v, Integral) or v < 1 for v in shape):
            raise ValueError(f"shape must be 2 positive integers (rows, cols), got {shape!r}")
        rows, cols = int(shape[0]), int(shape[1])
        state = self.state_at(t)
        c = self.config.cell
        a_n = _overlap(origin[0] + np.arange(rows) * cell, cell, self.origin[0] + np.arange(self.shape[0]) * c, c)
        a_e = _overlap(origin[1] + np.arange(cols) * cell, cell, self.origin[1] + np.arange(self.shape[1]) * c, c)
        area = cell * cell
        burning = a_n @ (state == BURNING).astype(float) @ a_e.T / area
        burnt = a_n @ (state == BURNT).astype(float) @ a_e.T / area
        return np.clip(burning, 0.0, 1.0), np.clip(burnt, 0.0, 1.0)

    def fire_regions(self, t: float) -> list[dict]:
        """Connected burning regions (8-connectivity) at ``t``, in label order: ``{"centroid": (n, e)``
        (mean of the cell centres), ``"cells": k, "area_m2": k cell²}`` — the true alarms."""
        labels, count = scipy.ndimage.label(self.state_at(t) == BURNING, structure=np.ones((3, 3), int))
        out = []
        for label in range(1, count + 1):
            ne = self.centres[labels == label]
            out.append({"centroid": (float(ne[:, 0].mean()), float(ne[:, 1].mean())), "cells": int(len(ne)),
                        "area_m2": float(len(ne) * self.config.cell**2)})
        return out
