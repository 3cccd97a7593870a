"""Per-cell evidence of one camera frame or one fire-sensor reading for a certainty grid (Merino §4.2.1, §4.5, §6.5).

**Camera** (:func:`camera_cell_evidence`). The segmentation is a binary image ``I`` (1 = fire). The pixel of
cell ``k`` is uncertain, ``p(M_k) ~ N(m_k, Σ_k)`` from the unscented transform of the pose and the cell
extent (:func:`perception.cell_projection.project_cells`, Merino §4.2.1 step 4). Given the pixel, a fire
pixel has ``p(z|x_k) = P_D`` (4.9), ``p(z|x̄_k) = P_F`` (4.12), a background pixel ``1 - P_D`` (4.10) and
``1 - P_F`` (4.13). Summing over the pixel, (4.11) ``p(z|x_k) = Σ_M p(I(M)|x_k) p(M)``, gives with
``p = E[I(M_k)] = Σ_M I(M) p(M)`` (``p_fire``)

    p(z|x_k) = p P_D + (1 - p)(1 - P_D),     p(z|x̄_k) = p P_F + (1 - p)(1 - P_F),

and ``llr = log p(z|x_k) - log p(z|x̄_k)`` (the increment of Merino Alg. 4.2). ``P_D``, ``P_F`` fall off with
the distance ``d`` from the mean camera position to the cell (4.14)-(4.15):

    P(d) = P [1 - (d/d_max)²] + 0.5 (d/d_max)²,   clamped to 0.5 for d >= d_max (ratio 1: no update).

With ``negative=False`` (the visual camera of Merino §6.5, no negative information) the background term of
both hypotheses is 0.5, ``p(z|x_k) = p P_D + (1 - p)/2`` and ``p(z|x̄_k) = p P_F + (1 - p)/2``, so that pure
background gives ratio 1. Beta pseudo-counts (4.31): ``m = Σ_M I(M) p(M) = p`` and
``n = Σ_M (1 - I(M)) p(M) = 1 - p``; with ``negative=False`` background is not evidence and ``n = 0``.
A cell is evaluated only if all its sigma points are in front of the camera, its pixel mean is inside the
image and ``d < d_max``; all other cells get no evidence (``m = n = 0``, Alg. 4.4).

The expectation ``p = Σ_M I(M) p(M)`` over the cell's pixel ellipse is
:func:`perception.cell_projection.mask_expectation` (a Gauss-Hermite stencil over a pre-blurred mask; the
region is the whole image, renormalised over the pixels inside it — see there for the choice and its accuracy).

**Fire sensor** (:func:`fire_sensor_evidence`): see its docstring, (4.16)-(4.19) and (4.32)-(4.33).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Real

import numpy as np

from perception.camera import Intrinsics
from perception.cell_projection import check_cells, check_pose, mask_expectation, project_cells
from perception.grid_sensor_model import DetectionModel, PoseNoise
from perception.pose import CameraPose

__all__ = [
    "DetectionModel",
    "PoseNoise",
    "CellEvidence",
    "project_cells",
    "mask_expectation",
    "camera_likelihoods",
    "camera_cell_evidence",
    "fire_sensor_evidence",
    "DEFAULT_MODEL",
    "DEFAULT_NOISE",
]

#: Likelihood of either hypothesis on a background pixel for a camera without negative information
#: (Merino §6.5: "p(z|F_k) = 0.5 for both hypotheses").
NO_NEGATIVE_LIKELIHOOD = 0.5


#: Default detection model and pose noise of :func:`camera_cell_evidence`.
DEFAULT_MODEL = DetectionModel()
DEFAULT_NOISE = PoseNoise()


@dataclass(frozen=True)
class CellEvidence:
    """What one frame (or one sensor reading) says about the cells it covers, ``M`` of them.

    ``index`` (M,) flat indices into the cell array; ``p_fire`` (M,) ``E[I(M_k)]``, the Gaussian-weighted
    fraction of fire pixels (4.11); ``llr`` (M,) ``log p(z|x_k) - log p(z|x̄_k)``; ``m``, ``n`` (M,) Beta
    pseudo-counts of detections and non-detections (4.31)-(4.33); ``pixel_mean`` (M, 2) and ``pixel_cov``
    (M, 2, 2) the cell's pixel Gaussian (NaN for a sensor without an image)."""

    index: np.ndarray
    p_fire: np.ndarray
    llr: np.ndarray
    m: np.ndarray
    n: np.ndarray
    pixel_mean: np.ndarray
    pixel_cov: np.ndarray

    def __post_init__(self):
        size = len(self.index)
        shapes = {"p_fire": (size,), "llr": (size,), "m": (size,), "n": (size,)}
        shapes |= {"pixel_mean": (size, 2), "pixel_cov": (size, 2, 2)}
        for name, shape in shapes.items():
            if np.shape(getattr(self, name)) != shape:
                raise ValueError(f"cell evidence: {name} must have shape {shape}, got {np.shape(getattr(self, name))}")

    def __len__(self) -> int:
        return len(self.index)


def _check_mask(mask, intrinsics: Intrinsics) -> np.ndarray:
    if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_:
        dtype = getattr(mask, "dtype", type(mask).__name__)
        raise ValueError(f"mask must be a boolean numpy array (segmentation), got {dtype}")
    if mask.shape != (intrinsics.height, intrinsics.width):
        raise ValueError(
            f"mask shape {mask.shape} does not match the intrinsics (height, width) "
            f"= ({intrinsics.height}, {intrinsics.width})"
        )
    return mask


def camera_likelihoods(
    p_fire: np.ndarray | float, pd: np.ndarray | float, pf: np.ndarray | float, negative: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """``(p(z|x_k), p(z|x̄_k))`` from the fire fraction and the (range-dependent) ``P_D``, ``P_F``:
    (4.9)-(4.13) mixed over the pixel (4.11); background term 0.5 for both if not ``negative`` (§6.5)."""
    p = np.asarray(p_fire, dtype=float)
    pd, pf = np.asarray(pd, dtype=float), np.asarray(pf, dtype=float)
    if negative:
        return p * pd + (1.0 - p) * (1.0 - pd), p * pf + (1.0 - p) * (1.0 - pf)
    return p * pd + (1.0 - p) * NO_NEGATIVE_LIKELIHOOD, p * pf + (1.0 - p) * NO_NEGATIVE_LIKELIHOOD


def camera_cell_evidence(
    mask: np.ndarray,
    cells_ned: np.ndarray,
    cell_size: float,
    pose: CameraPose,
    intrinsics: Intrinsics,
    model: DetectionModel = DEFAULT_MODEL,
    noise: PoseNoise = DEFAULT_NOISE,
) -> CellEvidence:
    """Evidence of one segmented frame for every cell it sees (module docstring). ``mask`` (H, W) bool must
    match ``intrinsics``; ``cells_ned`` (K, 3) are the cell centres (row-major grid order), ``cell_size`` the
    cell side (m, >= 0). Cells behind the camera, outside the image or at ``d >= d_max`` are left out."""
    check_pose(pose, intrinsics)
    mask = _check_mask(mask, intrinsics)
    if not isinstance(model, DetectionModel):
        raise ValueError(f"model must be a DetectionModel, got {type(model).__name__}")
    cells = check_cells(cells_ned, cell_size)
    mean, cov, valid = project_cells(cells, cell_size, pose, intrinsics, noise)
    dist = np.linalg.norm(cells - pose.centre, axis=1)
    seen = valid & np.asarray(intrinsics.contains(mean), dtype=bool)
    index = np.flatnonzero(seen & (dist < model.d_max))
    mean, cov = mean[index], cov[index]
    p_fire = mask_expectation(mask, mean, cov)
    pd, pf = model.at_range(dist[index])
    like_fire, like_clear = camera_likelihoods(p_fire, pd, pf, model.negative)
    llr = np.log(like_fire) - np.log(like_clear)
    n = 1.0 - p_fire if model.negative else np.zeros_like(p_fire)
    return CellEvidence(index, p_fire, llr, p_fire.copy(), n, mean, cov)


def fire_sensor_evidence(
    detected: bool,
    cells_ned: np.ndarray,
    sensor_position: np.ndarray,
    axis: np.ndarray,
    half_angle: float,
    model: DetectionModel,
) -> CellEvidence:
    """Evidence of one reading of a binary fire sensor with a cone field of view (Merino Fig. 4.4-4.5).

    Cells in the cone, angle to ``axis`` ``α < half_angle`` (rad, in ``(0, π]``) and ``d < d_max``, get
    ``p(z|x_k) = P_D(d, α)``, ``p(z|x̄_k) = P_F(d, α)`` on detection (4.16)-(4.17) and ``1 - P_D``, ``1 - P_F``
    otherwise (4.18)-(4.19). The angular fall-off is only plotted in the thesis; chosen here: the same form
    as (4.14) applied on top of the range term, ``P(d, α) = P g + 0.5 (1 - g)`` with
    ``g = [1 - (d/d_max)²] [1 - (α/half_angle)²]`` (so P -> 0.5 at the cone edge and at ``d_max``).
    Beta counts (4.32)-(4.33): a detection shares one count over the ``S`` cells in view, ``m = 1/S``,
    ``n = 0``; no detection gives ``m = 0``, ``n = 1``. With ``model.negative = False`` a non-detection is
    not evidence (llr 0, ``n = 0``). ``p_fire`` is the reading (1 or 0); the pixel fields are NaN."""
    if not isinstance(detected, bool | np.bool_):
        raise ValueError(f"detected must be a bool, got {detected!r}")
    if not isinstance(model, DetectionModel):
        raise ValueError(f"model must be a DetectionModel, got {type(model).__name__}")
    cells = check_cells(cells_ned)
    position = np.asarray(sensor_position, dtype=float)
    direction = np.asarray(axis, dtype=float)
    if position.shape != (3,) or not np.all(np.isfinite(position)):
        raise ValueError(f"sensor_position must be a finite 3-vector (NED, m), got {sensor_position!r}")
    if direction.shape != (3,) or not np.all(np.isfinite(direction)) or not np.any(direction):
        raise ValueError(f"axis must be a finite non-zero 3-vector, got {axis!r}")
    if isinstance(half_angle, bool) or not isinstance(half_angle, Real) or not 0.0 < half_angle <= math.pi:
        raise ValueError(f"half_angle must be in (0, π] radians, got {half_angle!r}")
    rel = cells - position
    dist = np.linalg.norm(rel, axis=1)
    unit = direction / np.linalg.norm(direction)
    angle = np.arctan2(np.linalg.norm(np.cross(rel, unit), axis=1), rel @ unit)
    index = np.flatnonzero((angle < half_angle) & (dist < model.d_max))
    gain = (1.0 - (dist[index] / model.d_max) ** 2) * (1.0 - (angle[index] / half_angle) ** 2)
    pd = model.pd * gain + 0.5 * (1.0 - gain)
    pf = model.pf * gain + 0.5 * (1.0 - gain)
    size = len(index)
    zeros = np.zeros(size)
    if detected:
        llr, m, n = np.log(pd) - np.log(pf), np.full(size, 1.0 / max(size, 1)), zeros
    elif model.negative:
        llr, m, n = np.log1p(-pd) - np.log1p(-pf), zeros, np.ones(size)
    else:
        llr, m, n = zeros, zeros, zeros.copy()
    p_fire = np.full(size, 1.0 if detected else 0.0)
    return CellEvidence(index, p_fire, llr, m, n, np.full((size, 2), np.nan), np.full((size, 2, 2), np.nan))
