"""The sensor model of a certainty grid's camera, as plain settings: detection probabilities and pose noise.

:class:`DetectionModel` (Merino (4.9)-(4.15)) and :class:`PoseNoise` configure
:func:`perception.grid_likelihood.camera_cell_evidence` and :func:`perception.cell_projection.project_cells`;
they live here, without the image code (OpenCV), so that a scenario's ``[grid]`` settings are read
without loading it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Real

import numpy as np

__all__ = ["DetectionModel", "PoseNoise"]


def _probability(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not 0.0 < value < 1.0:
        raise ValueError(f"detection model: {name} must be a probability in (0, 1), got {value!r}")
    return float(value)


@dataclass(frozen=True)
class DetectionModel:
    """Per-pixel (or per-reading) detection probabilities and their range fall-off, Merino (4.9)-(4.15).
    The thesis gives no values: all defaults are chosen here."""

    pd: float = 0.9  # P_D = p(detect | fire) (chosen here; thesis gives none)
    pf: float = 0.05  # P_F = p(detect | no fire) (chosen here)
    d_max: float = 400.0  # m: range at which P_D = P_F = 0.5, (4.14)-(4.15) (chosen here)
    negative: bool = True  # non-detections are evidence (4.10)/(4.13); False = visual camera of §6.5

    def __post_init__(self):
        pd, pf = _probability(self.pd, "pd"), _probability(self.pf, "pf")
        if pd <= pf:
            raise ValueError(f"detection model: pd must exceed pf (an informative detector), got pd={pd}, pf={pf}")
        d_max = self.d_max
        if isinstance(d_max, bool) or not isinstance(d_max, Real) or not math.isfinite(d_max) or d_max <= 0:
            raise ValueError(f"detection model: d_max must be a finite range > 0 (m), got {d_max!r}")
        if not isinstance(self.negative, bool | np.bool_):
            raise ValueError(f"detection model: negative must be a bool, got {self.negative!r}")
        object.__setattr__(self, "pd", pd)
        object.__setattr__(self, "pf", pf)
        object.__setattr__(self, "d_max", float(d_max))
        object.__setattr__(self, "negative", bool(self.negative))

    def at_range(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(P_D(d), P_F(d))`` by (4.14)-(4.15), ``P [1 - ρ²] + 0.5 ρ²`` with ``ρ = min(d / d_max, 1)``:
        exactly 0.5 / 0.5 at and beyond ``d_max``. ``d`` must be finite and >= 0."""
        d = np.asarray(d, dtype=float)
        if not np.all(np.isfinite(d)) or np.any(d < 0):
            raise ValueError("range d must be finite and >= 0 (m)")
        rho2 = np.minimum(d / self.d_max, 1.0) ** 2
        return self.pd * (1.0 - rho2) + 0.5 * rho2, self.pf * (1.0 - rho2) + 0.5 * rho2


def _sigma(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value) or value < 0:
        raise ValueError(f"pose noise: {name} must be a finite number >= 0, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class PoseNoise:
    """Standard deviations of the camera pose error. Defaults chosen here (Merino gives none): a
    GPS-grade position and an AHRS-grade attitude, as :class:`perception.uncertainty.GeolocationNoise`."""

    position_sigma: float = 1.0  # m, per NED axis (chosen here)
    attitude_sigma: float = math.radians(1.0)  # rad, roll / pitch / yaw (chosen here)

    def __post_init__(self):
        object.__setattr__(self, "position_sigma", _sigma(self.position_sigma, "position_sigma"))
        object.__setattr__(self, "attitude_sigma", _sigma(self.attitude_sigma, "attitude_sigma"))
