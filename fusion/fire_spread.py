"""Fire prediction on a grid: the two-layer fire/burnt belief of Merino §6.3 (6.1)-(6.6).

Each cell ``k`` holds ``f_k = p(F_k = 1)`` (burning) and ``q_k = p(Q_k = 1)`` (completely burnt), estimated
by two independent Bernoulli grids (6.1). The transition model:

* (6.5) persistence: a burning cell stays burning unless it was burnt; a burnt cell never burns again;
* (6.6) spread: a burning neighbour ``q in R(k)`` ignites an unburnt cell with probability ``omega_q``;
* (6.4) burn-out: a cell burning at ``t`` becomes burnt with probability ``beta``; burnt stays burnt.

The thesis does not say how (6.5) and (6.6) combine; independent causes give the noisy-OR
(001b §2.6.2):

    f' = (1 - q) [1 - (1 - f) prod_{n in R(k)} (1 - omega_n f_n)]
    q' = q + beta f'

``q'`` deserves a note: (6.3) sums ``p(Q_t | F_t, Q_{t-1}) p(F_t)`` as if ``F_t`` were independent of
``Q_{t-1}``, which gives ``q + (1 - q) beta f'``. But ``F_t = 1`` implies ``Q_{t-1} = 0`` under (6.5), so
``p(Q_{t-1} = 0, F_t = 1) = f'`` and the exact one-step marginal is ``q + beta f'`` (checked by Monte Carlo
in the tests; the two agree whenever ``q`` is 0 or 1). From independent cells, one step gives the exact marginals
``f'`` and ``q'``; over several steps the cells are re-factorised after each step (mean field, as (6.1) does).

Unspecified in the thesis, chosen here: ``beta``, ``omega``, ``R(k)`` (4 or 8 neighbours, same ``omega``
for each), the initial "small value" of ``f`` and ``q`` (001b §2.6.3), and an optional wind bias: the
neighbour in unit direction ``d`` (from the burning neighbour towards the cell, (north, east)) ignites with
``omega * max(0, 1 + wind . d)``; ``wind`` points where the wind blows *to*.

The prediction is nonlinear in the log-odds evidence, so channel-filter exactness holds only for the
static (and linear decay) models; :meth:`FireBelief.predict` is for a local or centralized belief.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import logit

from fusion.grid import LogOddsGrid
from fusion.grid_geometry import GridGeometry

#: Per-step probability that a burning cell becomes completely burnt, beta in (6.4) (chosen here).
BURN = 0.05
#: Per-step ignition probability from one burning neighbour, omega_q in (6.6) (chosen here).
SPREAD = 0.02
#: Initial fire and burnt probabilities, "a small value" (001b §2.6.3; chosen here).
FIRE_PRIOR = 0.01
BURNT_PRIOR = 0.01

_OFFSETS = {
    4: ((-1, 0), (1, 0), (0, -1), (0, 1)),
    8: ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)),
}


def _probability(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.number) or not 0.0 <= value <= 1.0:
        raise ValueError(f"{name} must be a probability in [0, 1], got {value!r}")
    return float(value)


@dataclass(frozen=True)
class FireSpreadModel:
    """The fire/burnt transition of Merino (6.2)-(6.6), combined by noisy-OR (module docstring)."""

    burn: float = BURN  # beta in (6.4)
    spread: float = SPREAD  # omega_q in (6.6)
    neighbourhood: int = 8  # R(k): 4 or 8
    wind: tuple[float, float] = (0.0, 0.0)  # (north, east) bias, see the module docstring

    def __post_init__(self):
        object.__setattr__(self, "burn", _probability(self.burn, "burn probability"))
        object.__setattr__(self, "spread", _probability(self.spread, "spread probability"))
        if isinstance(self.neighbourhood, bool) or self.neighbourhood not in _OFFSETS:
            raise ValueError(f"neighbourhood must be 4 or 8, got {self.neighbourhood!r}")
        wind = self.wind
        if not isinstance(wind, list | tuple | np.ndarray) or len(wind) != 2:
            raise ValueError(f"wind must be a (north, east) pair, got {wind!r}")
        if not all(isinstance(v, int | float | np.number) and not isinstance(v, bool) and math.isfinite(v)
                   for v in wind):
            raise ValueError(f"wind must be two finite numbers, got {wind!r}")
        object.__setattr__(self, "wind", (float(wind[0]), float(wind[1])))
        worst = max(p for _, _, p in self.neighbour_probabilities())
        if worst > 1.0:
            raise ValueError(f"spread * (1 + wind . d) reaches {worst:.3g} > 1: reduce the spread or the wind")

    def neighbour_probabilities(self) -> list[tuple[int, int, float]]:
        """``(dr, dc, omega)``: the neighbour at row/col offset ``(dr, dc)`` from a cell ignites it with
        probability ``omega = spread * max(0, 1 + wind . d)``, ``d`` the unit vector from neighbour to cell."""
        out = []
        for dr, dc in _OFFSETS[self.neighbourhood]:
            d = np.array([-dr, -dc], dtype=float) / math.hypot(dr, dc)
            out.append((dr, dc, self.spread * max(0.0, 1.0 + float(np.dot(self.wind, d)))))
        return out

    def predict(self, fire: np.ndarray, burnt: np.ndarray, steps: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """``steps`` applications of the noisy-OR transition to the cell probabilities ``(f, q)``."""
        f, q = _layer(fire, "fire"), _layer(burnt, "burnt")
        if f.shape != q.shape:
            raise ValueError(f"fire and burnt layers differ in shape: {f.shape} vs {q.shape}")
        if isinstance(steps, bool) or not isinstance(steps, int | np.integer) or steps < 0:
            raise ValueError(f"steps must be a non-negative integer, got {steps!r}")
        rows, cols = f.shape
        neighbours = self.neighbour_probabilities()
        for _ in range(int(steps)):
            padded = np.pad(f, 1)
            no_ignition = 1.0 - f  # (6.5): a burning cell keeps burning
            for dr, dc, omega in neighbours:
                no_ignition = no_ignition * (1.0 - omega * padded[1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols])
            f = (1.0 - q) * (1.0 - no_ignition)  # (6.5)-(6.6): nothing burns in a burnt cell
            q = q + self.burn * f  # (6.4); see the module docstring for why not (1 - q) beta f
            np.clip(f, 0.0, 1.0, out=f)
            np.clip(q, 0.0, 1.0, out=q)
        return f, q


def _layer(value, name: str) -> np.ndarray:
    arr = np.array(value, dtype=float)
    if arr.ndim != 2 or arr.size == 0:
        raise ValueError(f"{name} must be a non-empty 2-D array of cell probabilities, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} contains non-finite values (NaN or inf)")
    if arr.min() < 0.0 or arr.max() > 1.0:
        raise ValueError(f"{name} probabilities must lie in [0, 1], got range [{arr.min()}, {arr.max()}]")
    return arr


@dataclass(frozen=True, eq=False)
class FireBelief:
    """The two-layer belief of Merino (6.1): fire and burnt as two :class:`~fusion.grid.LogOddsGrid`."""

    fire: LogOddsGrid
    burnt: LogOddsGrid

    def __post_init__(self):
        for name in ("fire", "burnt"):
            if not isinstance(getattr(self, name), LogOddsGrid):
                raise ValueError(f"{name} layer must be a LogOddsGrid, got {type(getattr(self, name)).__name__}")
        self.fire.geometry.check_same(self.burnt.geometry)

    @classmethod
    def uniform(cls, geometry: GridGeometry, fire_prior: float = FIRE_PRIOR, burnt_prior: float = BURNT_PRIOR
                ) -> FireBelief:
        return cls(LogOddsGrid.uniform(geometry, fire_prior), LogOddsGrid.uniform(geometry, burnt_prior))

    @property
    def geometry(self) -> GridGeometry:
        return self.fire.geometry

    def predict(self, model: FireSpreadModel, steps: int = 1) -> FireBelief:
        """Read both layers as (clamped) probabilities, apply ``model.predict``, store back as evidence."""
        if not isinstance(model, FireSpreadModel):
            raise ValueError(f"model must be a FireSpreadModel, got {type(model).__name__}")
        f, q = model.predict(self.fire.probability(), self.burnt.probability(), steps)
        return FireBelief(_to_grid(self.fire, f), _to_grid(self.burnt, q))

    def update_fire(self, llr: np.ndarray) -> FireBelief:
        """Alg. 4.2 on the fire layer (Merino §6.5 likelihoods)."""
        return FireBelief(self.fire.update(llr), self.burnt)

    def update_burnt(self, llr: np.ndarray) -> FireBelief:
        """Alg. 4.2 on the burnt layer."""
        return FireBelief(self.fire, self.burnt.update(llr))


def _to_grid(like: LogOddsGrid, p: np.ndarray) -> LogOddsGrid:
    """Probabilities back to evidence ``logit(p) - l0``, within the layer's clamp (so the log-odds stay finite)."""
    p = np.clip(p, 1.0 - like.clamp, like.clamp)
    return LogOddsGrid(like.geometry, logit(p) - logit(like.prior), like.prior, like.clamp)
