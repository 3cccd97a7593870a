"""Where a grid cell falls in an image, and how much fire the image shows there (Merino §4.2.1, (4.11), (4.31)).

**Projection** (:func:`project_cells`). Merino §4.2.1, step 4: the pixel of cell ``k`` seen by camera ``j`` is
``M_k = f(Q_j, r_k)``, the pin-hole projection (3.57) ``s m = A (R_t  -t_t) p`` (plus lens distortion,
:meth:`perception.camera.Intrinsics.project`). The pose ``Q_j`` is uncertain, and so is where inside its square
the evidence of a cell lies (grid resolution); both are propagated with the unscented transform (Merino
Alg. 3.5, :func:`fusion.unscented.sigma_points`) to ``p(M_k) ~ N(m_k, Σ_k)``, the ellipse of Merino Fig. 4.3.
The error state is 8-D, ``δ = (δn, δe, δd, δφ, δθ, δψ, δc_n, δc_e)``, zero mean, diagonal covariance:

* ``δn, δe, δd`` — camera position error (NED, m), ``σ = position_sigma`` per axis;
* ``δφ, δθ, δψ`` — attitude error (rad), ``σ = attitude_sigma`` for roll, pitch and yaw, applied as the error
  rotation ``R_δ = R_z(δψ) R_y(δθ) R_x(δφ)`` on the world side, ``R' = R_δ R_world_from_cam``. With one σ for
  the three angles the error rotation is isotropic to first order, so this is equivalent to perturbing the
  vehicle's Euler angles whatever its attitude, gimbal or mount (``R_δ R = R R_δ'``, ``δ' = Rᵀ δ`` identically
  distributed): a :class:`~perception.pose.CameraPose` suffices;
* ``δc_n, δc_e`` — the position of the evidence inside the square cell of side ``c``: uniform over the cell,
  so zero mean and variance ``c²/12`` per horizontal axis (the height of a cell is its centre's).

Sigma points: ``2·8 + 1 = 17`` with ``κ = max(3 - n, 0) = 0`` (:func:`fusion.unscented.default_kappa`):
non-negative weights, so the pixel covariance is always positive semi-definite. They are common to all cells
(the pose error is shared), so all ``K`` cells are projected at once as ``(17, K, 3)`` camera-frame points.
The mean is accumulated as ``m = Y_0 + Σ_s W_s (Y_s - Y_0)``: with zero noise and ``c = 0`` it is exactly the
projection of the centre (:func:`perception.projection.world_to_pixel`).

**Expectation over the ellipse** (:func:`mask_expectation`), ``E[I(M_k)] = Σ_M I(M) p(M)`` of (4.11) and
(4.31) for a binary segmentation ``I``. The spec leaves the region extent and the renormalisation [unclear].
Chosen here: the region is the whole image, the weights are the Gaussian density at the pixel centres,
renormalised over the pixels inside the image (pixels outside the image are unobserved, not background):

    E[I(M)] = Σ_q I(q) N(q; m, Σ) / Σ_{q in image} N(q; m, Σ).

It is computed with a fixed Gauss-Hermite stencil (:data:`GH_NODES_MAJOR` x :data:`GH_NODES_MINOR` nodes,
oriented along the eigenvectors of the covariance and scaled by the square roots of its eigenvalues, which,
unlike a Cholesky factor, also exists for a singular covariance). Point samples of a binary image are a poor
quadrature, though (a node on an edge counts fully or not at all: 0.2-0.45 from the exact sum, measured), so
the Gaussian is split, ``N_Σ = N_{s² I} * N_R`` with ``R = Σ - s² I`` and ``s² <= λ_min(Σ)`` from a ladder of
levels: the mask is blurred by ``N_{s² I}`` (separable, once per level used, each level from the previous
one), and the stencil over ``N_R`` integrates the now smooth image with bilinear interpolation. The in-image
indicator is blurred and integrated in the same way (it is separable: two 1-D profiles), and ``E`` is the
ratio of the two integrals — "nodes outside the image dropped and the weights renormalised", done exactly.
Small ellipses (both variances <= :data:`EXACT_MAX_VARIANCE`, where one blur level is a large part of the
ellipse) are summed exactly over a window instead. Measured against the brute-force sum over every pixel
(pixel-noise, blob and rectangle masks, 3000 random ellipses of 0.01-150 px² with an axis ratio up to 3): at
most 0.019 off, 0.0002 on average (the default pose noise gives 9-40 px² and axis ratios below 3 for 5 m cells
seen from 80 m). Needle-thin ellipses are worse: up to ~0.15 at an axis ratio of 20 (2 x 40 px²).
"""

from __future__ import annotations

import math
from numbers import Real

import cv2
import numpy as np

from fusion.unscented import default_kappa, sigma_points
from perception.camera import Intrinsics
from perception.grid_sensor_model import PoseNoise
from perception.pose import CameraPose
from perception.rotations import rotation_from_euler

__all__ = ["PoseNoise", "UT_DIM", "UT_KAPPA", "check_cells", "check_pose", "project_cells", "mask_expectation"]

#: Dimension of the error state: position 3 + roll/pitch/yaw 3 + cell north/east 2.
UT_DIM = 8
#: κ of the unscented transform (chosen here: fusion's default ``max(3 - n, 0) = 0`` keeps every weight >= 0).
UT_KAPPA = default_kappa(UT_DIM)


#: Gauss-Hermite nodes along the major / minor axis of the residual ellipse (chosen here: 5 x 5, exact for
#: polynomials up to degree 9 along each axis).
GH_NODES_MAJOR = 5
GH_NODES_MINOR = 5
#: Blur levels ``s = BLUR_MIN_SIGMA · BLUR_LEVEL_RATIO^j <= BLUR_MAX_SIGMA`` (px) plus ``s = 0`` (chosen here: a
#: quarter octave keeps the residual ``Σ - s² I`` small; 32 px is far beyond the 3-6 px of a 5 m cell at 80 m).
BLUR_MIN_SIGMA = 0.5
BLUR_LEVEL_RATIO = 2.0**0.25
BLUR_MAX_SIGMA = 32.0
#: Small ellipses, both variances <= ``(EXACT_WINDOW / 3)²`` px² (3σ within the window), are summed exactly over
#: the pixels within ``EXACT_WINDOW`` px of the nearest one; ``EXACT_JITTER`` (px²) regularises a zero
#: covariance, which then picks the nearest pixel (chosen here: blur + stencil is least accurate below ~2 px²).
EXACT_WINDOW = 6
EXACT_MAX_VARIANCE = (EXACT_WINDOW / 3.0) ** 2
EXACT_JITTER = 1e-9
#: In-image stencil weight below which the stencil is taken to have missed the image (chosen here).
_MIN_INSIDE_WEIGHT = 1e-6

_LEVELS = np.array([0.0] + [BLUR_MIN_SIGMA * BLUR_LEVEL_RATIO**j for j in range(64)])
_LEVELS = _LEVELS[_LEVELS <= BLUR_MAX_SIGMA * (1 + 1e-12)]


def _gauss_hermite(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of the ``n``-point rule for ``E[g(X)]``, ``X ~ N(0, 1)``."""
    x, w = np.polynomial.hermite.hermgauss(n)
    return x * math.sqrt(2.0), w / math.sqrt(math.pi)


def _stencil() -> tuple[np.ndarray, np.ndarray]:
    """Product stencil: nodes (N, 2) as (minor, major) coefficients and weights (N,), summing to 1."""
    x_minor, w_minor = _gauss_hermite(GH_NODES_MINOR)
    x_major, w_major = _gauss_hermite(GH_NODES_MAJOR)
    a, b = np.meshgrid(x_minor, x_major, indexing="ij")
    return np.stack([a.ravel(), b.ravel()], axis=-1), np.outer(w_minor, w_major).ravel()


_NODES, _WEIGHTS = _stencil()


def check_cells(cells_ned: np.ndarray, cell_size: float | None = None) -> np.ndarray:
    """``cells_ned`` as a finite ``(K, 3)`` float array (and ``cell_size`` finite >= 0 when given; 0 means
    point cells, the evidence exactly at the centre)."""
    cells = np.asarray(cells_ned, dtype=float) if not isinstance(cells_ned, np.ndarray) else cells_ned
    if cells.ndim != 2 or cells.shape[1] != 3:
        raise ValueError(f"cells_ned must have shape (K, 3) (NED cell centres), got {np.shape(cells_ned)}")
    if not np.issubdtype(cells.dtype, np.number) or np.issubdtype(cells.dtype, np.complexfloating):
        raise ValueError(f"cells_ned must be real numbers, got dtype {cells.dtype}")
    cells = cells.astype(float, copy=False)
    if not np.all(np.isfinite(cells)):
        raise ValueError("cells_ned contains non-finite values (NaN or inf)")
    if cell_size is not None and (
        isinstance(cell_size, bool) or not isinstance(cell_size, Real) or not math.isfinite(cell_size) or cell_size < 0
    ):
        raise ValueError(f"cell_size must be a finite number >= 0 (m), got {cell_size!r}")
    return cells


def check_pose(pose: CameraPose, intrinsics: Intrinsics) -> None:
    """``pose`` must be a finite :class:`CameraPose` and ``intrinsics`` an :class:`Intrinsics`."""
    if not isinstance(pose, CameraPose):
        raise ValueError(f"pose must be a CameraPose, got {type(pose).__name__}")
    if not (np.all(np.isfinite(pose.R_world_from_cam)) and np.all(np.isfinite(pose.centre))):
        raise ValueError("pose contains non-finite values (NaN or inf) in its rotation or centre")
    if not isinstance(intrinsics, Intrinsics):
        raise ValueError(f"intrinsics must be an Intrinsics, got {type(intrinsics).__name__}")


def project_cells(
    cells_ned: np.ndarray, cell_size: float, pose: CameraPose, intrinsics: Intrinsics, noise: PoseNoise
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unscented transform (Merino Alg. 3.5) of the pixel of every cell centre over the pose error and the
    position of the evidence inside the cell (module docstring), all cells at once.

    Returns ``(mean (K, 2), cov (K, 2, 2), valid (K,))``: ``valid`` is False for a cell with any sigma
    point on or behind the plane of the optical centre (or beyond the lens-distortion fold), and its
    mean and covariance are NaN. A valid cell may still project outside the image."""
    cells = check_cells(cells_ned, cell_size)
    check_pose(pose, intrinsics)
    if not isinstance(noise, PoseNoise):
        raise ValueError(f"noise must be a PoseNoise, got {type(noise).__name__}")
    variances = np.array(
        [noise.position_sigma**2] * 3 + [noise.attitude_sigma**2] * 3 + [float(cell_size) ** 2 / 12.0] * 2
    )
    deltas, weights = sigma_points(np.zeros(UT_DIM), np.diag(variances), UT_KAPPA)  # (17, 8), (17,)
    # Per sigma point: world->camera rotation R_δ R and centre; the cell offset (north, east, 0).
    R = pose.R_world_from_cam
    R_err = rotation_from_euler(deltas[:, 3], deltas[:, 4], deltas[:, 5])  # (17, 3, 3)
    shift = -(pose.centre + deltas[:, :3])  # cell offset (north, east, 0) minus the camera centre
    shift[:, :2] += deltas[:, 6:8]
    diff = np.empty((len(deltas), len(cells), 3))  # (17, K, 3) points relative to the camera centre
    for axis in range(3):  # filled per axis: far faster than a broadcast over a trailing axis of 3
        diff[:, :, axis] = cells[:, axis] + shift[:, axis, None]
    # (p - c) @ R_δ @ R; the second product is one 2-D matrix product, as in CameraPose.world_to_camera.
    Y = intrinsics.project((diff @ R_err).reshape(-1, 3) @ R).reshape(len(deltas), len(cells), 2)  # (17, K, 2)
    u, v = Y[..., 0], Y[..., 1]
    mean = np.stack([u[0] + weights @ (u - u[0]), v[0] + weights @ (v - v[0])], axis=-1)
    du, dv = u - mean[:, 0], v - mean[:, 1]
    cov = np.empty((len(cells), 2, 2))
    cov[:, 0, 0] = weights @ (du * du)
    cov[:, 1, 1] = weights @ (dv * dv)
    cov[:, 0, 1] = cov[:, 1, 0] = weights @ (du * dv)
    # A NaN sigma point (behind the camera, beyond the distortion fold) makes its cell's sums NaN (W_0 = 0
    # included: 0 · NaN = NaN), so the sums themselves say which cells are valid.
    valid = np.isfinite(mean[:, 0]) & np.isfinite(mean[:, 1]) & np.isfinite(cov[:, 0, 0] + cov[:, 1, 1])
    mean[~valid] = np.nan
    cov[~valid] = np.nan
    return mean, cov, valid


def mask_expectation(mask: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``E[I(M)] = Σ_q I(q) N(q; m, Σ) / Σ_{q in image} N(q; m, Σ)`` for each of ``K`` pixel Gaussians,
    by the blurred Gauss-Hermite stencil (module docstring). ``mask`` (H, W) bool, ``mean`` (K, 2)
    finite ``(u, v)`` inside the image, ``cov`` (K, 2, 2) symmetric positive semi-definite. Returns (K,)."""
    if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.ndim != 2:
        raise ValueError(f"mask must be a 2-D boolean numpy array, got {getattr(mask, 'dtype', type(mask))}")
    mean, cov = np.asarray(mean, dtype=float), np.asarray(cov, dtype=float)
    if mean.ndim != 2 or mean.shape[1] != 2 or cov.shape != (len(mean), 2, 2):
        raise ValueError(f"mean must be (K, 2) and cov (K, 2, 2), got {mean.shape} and {cov.shape}")
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
        raise ValueError("pixel mean and covariance must be finite")
    height, width = mask.shape
    if np.any((mean < -0.5) | (mean > [width - 0.5, height - 0.5])):
        raise ValueError("pixel means must lie inside the image")
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    eig, vec = _eigen_2x2(cov)
    if np.any(eig[:, 0] < -1e-9 * np.maximum(1.0, eig[:, 1])):
        raise ValueError("pixel covariances must be positive semi-definite")
    out = np.full(len(mean), np.nan)
    level = np.searchsorted(_LEVELS**2, eig[:, 0], side="right") - 1
    small = eig[:, 1] <= EXACT_MAX_VARIANCE
    if np.any(small):
        out[small] = _window_expectation(mask, mean[small], cov[small])
    stencil = np.flatnonzero(~small)
    residual = np.clip(eig[stencil] - (_LEVELS[level[stencil]] ** 2)[:, None], 0.0, None)
    factor = vec[stencil] * np.sqrt(residual)[:, None, :]  # columns: minor, major axis x sqrt(eigenvalue)
    points = mean[stencil, None, :] + _NODES @ np.swapaxes(factor, 1, 2)  # (K', N, 2)
    used = np.unique(level[stencil])
    pad = math.ceil(4.0 * float(_LEVELS[used].max())) + 2 if len(used) else 0  # the kernels reach 4 s
    canvas = np.zeros((height + 2 * pad, width + 2 * pad), np.float32)
    canvas[pad : pad + height, pad : pad + width] = mask
    # The in-image indicator is separable: blur its two 1-D profiles; their outer product is the blurred image.
    rows, cols = np.zeros(height + 2 * pad, np.float32), np.zeros(width + 2 * pad, np.float32)
    rows[pad : pad + height], cols[pad : pad + width] = 1.0, 1.0
    previous = 0.0
    for j in used:  # ascending: each level blurs the previous one by the missing variance
        s = float(_LEVELS[j])
        if s > previous:
            step = math.sqrt(s * s - previous * previous)
            kernel = cv2.getGaussianKernel(2 * math.ceil(4.0 * step) + 1, step, cv2.CV_32F)
            canvas = cv2.sepFilter2D(canvas, cv2.CV_32F, kernel, kernel, borderType=cv2.BORDER_CONSTANT)
            rows = np.convolve(rows, kernel[:, 0], "same").astype(np.float32)
            cols = np.convolve(cols, kernel[:, 0], "same").astype(np.float32)
            previous = s
        sel = level[stencil] == j
        maps = (points[sel] + pad).astype(np.float32)
        # Needle-thin ellipses (s = 0) sample the raw mask at the nearest pixel; the others interpolate.
        interpolation = cv2.INTER_LINEAR if s > 0 else cv2.INTER_NEAREST
        both = cv2.merge([canvas, np.outer(rows, cols)])  # (fire, in image)
        sampled = cv2.remap(both, maps[..., 0], maps[..., 1], interpolation, borderMode=cv2.BORDER_CONSTANT)
        num, den = sampled[..., 0] @ _WEIGHTS, sampled[..., 1] @ _WEIGHTS
        inside = den > _MIN_INSIDE_WEIGHT
        out[stencil[sel]] = np.where(inside, num / np.where(inside, den, 1.0), np.nan)
    lost = np.isnan(out)  # every node off the image (a thin ellipse along the border): the nearest pixel
    if np.any(lost):
        u = np.clip(np.rint(mean[lost, 0]), 0, width - 1).astype(int)
        v = np.clip(np.rint(mean[lost, 1]), 0, height - 1).astype(int)
        out[lost] = mask[v, u]
    return np.clip(out, 0.0, 1.0)


def _eigen_2x2(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (K, 2) ascending and eigenvectors (K, 2, 2) as columns (minor, major) of symmetric 2x2
    matrices, in closed form: ``λ = (a + c)/2 ± √(((a - c)/2)² + b²)``, major axis at ``½ atan2(2b, a - c)``."""
    a, b, c = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    mid, rad = 0.5 * (a + c), np.hypot(0.5 * (a - c), b)
    theta = 0.5 * np.arctan2(2.0 * b, a - c)
    cos, sin = np.cos(theta), np.sin(theta)
    vec = np.stack([np.stack([-sin, cos], axis=-1), np.stack([cos, sin], axis=-1)], axis=-1)
    return np.stack([mid - rad, mid + rad], axis=-1), vec


def _window_expectation(mask: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """The defining sum itself over the pixels within ``EXACT_WINDOW`` of the nearest pixel (enough for
    ``3σ <= EXACT_WINDOW``), with the covariance regularised by ``EXACT_JITTER`` (so a zero covariance picks
    the nearest pixel centre)."""
    height, width = mask.shape
    r = EXACT_WINDOW
    offsets = np.stack(np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1), indexing="xy"), -1).reshape(-1, 2)
    pixels = np.rint(mean).astype(int)[:, None, :] + offsets  # (K, (2r+1)², 2) integer (u, v)
    d = pixels - mean[:, None, :]
    info = np.linalg.inv(cov + EXACT_JITTER * np.eye(2))
    maha = np.einsum("kni,kij,knj->kn", d, info, d)
    weight = np.exp(-0.5 * (maha - maha.min(axis=1, keepdims=True)))
    inside = (pixels[..., 0] >= 0) & (pixels[..., 0] < width) & (pixels[..., 1] >= 0) & (pixels[..., 1] < height)
    weight *= inside
    fire = mask[np.clip(pixels[..., 1], 0, height - 1), np.clip(pixels[..., 0], 0, width - 1)]
    return np.sum(weight * fire, axis=1) / np.sum(weight, axis=1)
