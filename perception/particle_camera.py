"""Camera model of the particle filter for bearing-only localisation of a static point (Merino §5.3).

A particle is a 3-D point ``p^(k)`` (NED, m). A detection is the pixel ``m_j`` of the object (5.28) seen by
a camera whose pose ``Q_j`` is uncertain.

**Pose uncertainty** (chosen here: the thesis leaves the parametrisation open). ``δq = (δc, δθ)`` with
``δc`` the error of the optical centre (NED, m) and ``δθ`` a rotation vector (rad) about world axes:
``R = Exp(δθ) R̄``, ``c = c̄ + δc``, ``δq ~ N(0, Σ_q)`` (6 x 6).

**Likelihood** (5.30)-(5.31): ``m = f(p, Q) + ε``, ``ε ~ N(0, S)``, with ``f`` the pin-hole model (3.57)
(:meth:`perception.camera.Intrinsics.project` of the camera-frame point ``Rᵀ (p - c)``). The pose
uncertainty is pushed through ``f`` by the unscented transform (Merino Alg. 3.5, :mod:`fusion.unscented`)
for every particle, giving a pixel mean ``m^(k)`` and covariance ``Σ^(k)``, and

    p(m_j | p^(k)) = 1 / (2π sqrt|Σ^(k) + S|) exp(-½ (m_j - m^(k))ᵀ (Σ^(k) + S)^-1 (m_j - m^(k)))   (5.31)

Vectorised over particles: the ``2n + 1 = 13`` sigma-point poses are built once and every particle is
projected through all of them in one array operation. A particle behind the camera for any sigma point
(or beyond the distortion fold) cannot have produced the detection: its log-likelihood is ``-inf``.

**Back-projection prior**, Alg. 5.4 ``prior_camera(m_{j,0}, μ_q, Σ_q)``: for every particle sample a pose
``q^(k) ~ N(μ_q, Σ_q)``, take the viewing ray ``v^(k)`` of the pixel from that pose (the inverse of
(3.57), :meth:`Intrinsics.ray`), a range ``d^(k) ~ U(d_min, d_max)`` along the unit ray, and
``p^(k) = c^(k) + d^(k) v^(k)`` with weight ``1/N``. ``d_min``, ``d_max`` are not given by the thesis.

**Scan-to-track association** (5.33)-(5.34): ``p(z_p | H_p) ≈ Σ_k w^(k) p(m_p | p^(k))``; the detection with
the largest value is the track's (no clutter model or gate in the thesis; none added).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.special import logsumexp

from fusion import validation
from fusion.particles import ParticleSet
from fusion.unscented import sigma_points
from perception.camera import Intrinsics
from perception.pose import CameraPose

__all__ = [
    "DEFAULT_D_MIN",
    "DEFAULT_D_MAX",
    "DEFAULT_PIXEL_SIGMA",
    "UncertainPose",
    "CameraDetection",
    "association_log_likelihoods",
    "associate",
]

#: Range interval of the back-projection prior (m). Chosen here: from just outside the airframe to beyond
#: the useful detection range of a small UAV camera (the thesis gives none, spec 001b §6 item 5).
DEFAULT_D_MIN = 2.0
DEFAULT_D_MAX = 500.0
#: Standard deviation of the image-processing error ``S = σ² I`` (px). Chosen here (thesis: not given).
DEFAULT_PIXEL_SIGMA = 2.0


@dataclass(frozen=True, eq=False)
class UncertainPose:
    """A camera pose ``pose`` (the mean ``μ_q``) and the 6 x 6 covariance ``cov`` of ``δq = (δc, δθ)``
    (optical-centre error in NED metres, then a world-frame rotation vector in radians)."""

    pose: CameraPose
    cov: np.ndarray

    def __post_init__(self):
        if not isinstance(self.pose, CameraPose):
            raise ValueError(f"pose must be a CameraPose, got {type(self.pose).__name__}")
        cov = validation.as_psd(self.cov, "pose covariance", 6).copy()
        cov.setflags(write=False)
        object.__setattr__(self, "cov", cov)

    @classmethod
    def from_sigmas(cls, pose: CameraPose, position_sigma: float, attitude_sigma: float) -> UncertainPose:
        """Independent errors: ``position_sigma`` (m) per NED axis, ``attitude_sigma`` (rad) per world axis."""
        for name, value in (("position_sigma", position_sigma), ("attitude_sigma", attitude_sigma)):
            if not math.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be a non-negative finite number, got {value!r}")
        return cls(pose, np.diag([position_sigma**2] * 3 + [attitude_sigma**2] * 3))

    def perturbed(self, delta) -> tuple[np.ndarray, np.ndarray]:
        """Rotations ``R_world_from_cam`` (M, 3, 3) and centres (M, 3) for pose errors ``delta`` (M, 6)."""
        delta = np.asarray(delta, dtype=float)
        if delta.ndim != 2 or delta.shape[1] != 6:
            raise ValueError(f"pose errors must have shape (M, 6), got {delta.shape}")
        R = Rotation.from_rotvec(delta[:, 3:]).as_matrix() @ self.pose.R_world_from_cam
        return R, self.pose.centre + delta[:, :3]

    def sample(self, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
        """``n`` poses ``q ~ N(μ_q, Σ_q)``: rotations (n, 3, 3) and centres (n, 3)."""
        try:
            root = np.linalg.cholesky(self.cov)
        except np.linalg.LinAlgError:
            vals, vecs = np.linalg.eigh(self.cov)
            root = vecs * np.sqrt(np.clip(vals, 0.0, None))
        return self.perturbed(rng.standard_normal((n, 6)) @ root.T)


def _positive_count(n, name: str) -> int:
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"{name} must be a positive integer, got {n!r}")
    return int(n)


@dataclass(frozen=True, eq=False)
class CameraDetection:
    """One detection: the pixel ``m_j`` (2,), the camera's intrinsics and uncertain pose, the pixel noise
    covariance ``S`` (2 x 2, positive definite; default ``DEFAULT_PIXEL_SIGMA² I``) and the UT ``kappa``
    (None: :func:`fusion.unscented.default_kappa`)."""

    pixel: np.ndarray
    intrinsics: Intrinsics
    pose: UncertainPose
    pixel_cov: np.ndarray | None = None
    kappa: float | None = None

    def __post_init__(self):
        pixel = validation.as_vector(self.pixel, "detection pixel", 2).copy()
        pixel.setflags(write=False)
        object.__setattr__(self, "pixel", pixel)
        if not isinstance(self.intrinsics, Intrinsics):
            raise ValueError(f"intrinsics must be an Intrinsics, got {type(self.intrinsics).__name__}")
        if not isinstance(self.pose, UncertainPose):
            raise ValueError(f"pose must be an UncertainPose, got {type(self.pose).__name__}")
        S = DEFAULT_PIXEL_SIGMA**2 * np.eye(2) if self.pixel_cov is None else self.pixel_cov
        S = validation.as_pd(S, "pixel noise covariance S", 2).copy()
        S.setflags(write=False)
        object.__setattr__(self, "pixel_cov", S)
        points, weights = sigma_points(np.zeros(6), self.pose.cov, self.kappa)
        R, c = self.pose.perturbed(points)
        object.__setattr__(self, "_sigma_R", R)
        object.__setattr__(self, "_sigma_c", c)
        object.__setattr__(self, "_sigma_w", weights)

    # -- (5.31) -----------------------------------------------------------------------------------
    def pixel_moments(self, points) -> tuple[np.ndarray, np.ndarray]:
        """UT pixel mean (N, 2) and covariance (N, 2, 2) of every point under the pose uncertainty.
        Rows are NaN for a point behind the camera (or beyond the distortion fold) at any sigma point."""
        p = _points(points)
        cam = np.einsum("sji,snj->sni", self._sigma_R, p[None, :, :] - self._sigma_c[:, None, :])
        pix = self.intrinsics.project(cam)  # (S, N, 2)
        w = self._sigma_w
        mean = np.einsum("s,snk->nk", w, pix)
        d = pix - mean
        cov = np.einsum("s,snk,snl->nkl", w, d, d)
        return mean, 0.5 * (cov + cov.transpose(0, 2, 1))

    def log_likelihood(self, points) -> np.ndarray:
        """``log p(m_j | p^(k))`` (5.31) for every point (N, 3) -> (N,); ``-inf`` where undefined."""
        mean, cov = self.pixel_moments(points)
        C = cov + self.pixel_cov
        a, b, d = C[:, 0, 0], C[:, 0, 1], C[:, 1, 1]
        det = a * d - b * b
        r = self.pixel - mean
        with np.errstate(invalid="ignore", divide="ignore"):
            quad = (d * r[:, 0] ** 2 - 2.0 * b * r[:, 0] * r[:, 1] + a * r[:, 1] ** 2) / det
            ll = -math.log(2.0 * math.pi) - 0.5 * np.log(det) - 0.5 * quad
        return np.where(np.isfinite(ll), ll, -np.inf)

    # -- Alg. 5.4 -----------------------------------------------------------------------------------
    def back_projection_prior(
        self, n: int, rng: np.random.Generator, d_min: float = DEFAULT_D_MIN, d_max: float = DEFAULT_D_MAX
    ) -> ParticleSet:
        """Merino Alg. 5.4: ``n`` equally weighted points ``c^(k) + d^(k) v^(k)``, poses sampled from
        ``N(μ_q, Σ_q)`` and ranges ``d^(k) ~ U(d_min, d_max)`` along the unit viewing ray."""
        n = _positive_count(n, "number of particles")
        d_min, d_max = float(d_min), float(d_max)
        if not (math.isfinite(d_min) and math.isfinite(d_max)) or d_min < 0.0 or d_max <= d_min:
            raise ValueError(f"the range interval must satisfy 0 <= d_min < d_max < inf, got [{d_min}, {d_max}]")
        R, c = self.pose.sample(rng, n)
        ray_cam = self.intrinsics.ray(self.pixel)
        v = R @ ray_cam
        d = rng.uniform(d_min, d_max, size=n)
        return ParticleSet.from_states(c + d[:, None] * v)


def _points(points) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"particle states must be 3-D points of shape (N, 3), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("particle states contain non-finite values (NaN or inf)")
    return p


def association_log_likelihoods(particles: ParticleSet, detections: Sequence[CameraDetection]) -> np.ndarray:
    """``log Σ_k w^(k) p(m_p | p^(k))`` (5.34) for every candidate detection ``p`` -> (P,)."""
    if not isinstance(particles, ParticleSet):
        raise ValueError(f"expected a ParticleSet, got {type(particles).__name__}")
    if len(detections) == 0:
        raise ValueError("association needs at least one candidate detection")
    with np.errstate(divide="ignore"):
        log_w = np.log(particles.weights)
    return np.array([logsumexp(log_w + det.log_likelihood(particles.states)) for det in detections])


def associate(particles: ParticleSet, detections: Sequence[CameraDetection]) -> int:
    """Index of the maximum-likelihood detection (5.34) among ``detections``."""
    return int(np.argmax(association_log_likelihoods(particles, detections)))
