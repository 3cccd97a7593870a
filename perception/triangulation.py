"""Pseudo-intersection of several bearing rays and its covariance (thesis 000 §3.2, spec 000 §2.6.2).

Each measurement is a ray ``x_i + λ d_i`` (camera position, unit bearing) with a weight ``w_i``. The
point minimising ``E(q) = Σ w_i ||(I - d_i d_iᵀ)(q - x_i)||²`` (3.9)-(3.11) — the rays taken as full
lines, as in the thesis — solves

    A q* = b,   A = Σ w_i (I - d_i d_iᵀ)   (3.13),   b = Σ w_i (I - d_i d_iᵀ) x_i   (3.14).

Error propagation (3.15)-(3.26), with the estimate-plus-error model ``x = x̂ + δx``, ``d = d̂ + δd``,
``δdᵀ d̂ = 0``, to first order ``δq* = Σ_i (J_{x,i} δx_i + J_{d,i} δd_i)`` with ``r_i = q̂* - x̂_i``:

    J_{x,i} = w_i Â⁻¹ (I - d̂_i d̂_iᵀ),     J_{d,i} = w_i Â⁻¹ ((d̂_iᵀ r_i) I + d̂_i r_iᵀ)

(spec 000 §2.6.2 implementer aid), and for independent errors
``Cov(δq*) = Σ_i J_{x,i} Σ_{x,i} J_{x,i}ᵀ + J_{d,i} Σ_{d,i} J_{d,i}ᵀ`` with
``Σ_{d,i} = σ_θ² (I - d̂_i d̂_iᵀ)`` (angular noise σ_θ in radians, perpendicular to the bearing).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from perception.terrain import unit_rays

__all__ = [
    "PseudoIntersection",
    "pseudo_intersection",
    "pseudo_intersection_jacobians",
    "perturb_bearings",
    "batch_pseudo_intersection",
]

#: Smallest admissible ``λ_min(A) / λ_max(A)`` (chosen here). Below it the rays are (nearly)
#: parallel and the intersection is undetermined along their common direction.
MIN_CONDITION = 1e-10


@dataclass(frozen=True)
class PseudoIntersection:
    """The estimate ``point`` (3,), its covariance ``cov`` (3x3, or ``None`` if no noise was given),
    the weighted normal matrix ``A`` and the per-ray Jacobians ``J_x``, ``J_d`` (n, 3, 3)."""

    point: np.ndarray
    cov: np.ndarray | None
    A: np.ndarray
    J_x: np.ndarray
    J_d: np.ndarray


def _rays(origins, directions, weights):
    x, d = unit_rays(origins, directions)
    if x.shape[0] < 2:
        raise ValueError(f"a pseudo-intersection needs at least 2 rays, got {x.shape[0]} (A is singular for one)")
    n = x.shape[0]
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != (n,) or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise ValueError(f"weights must be {n} positive finite numbers, got {weights!r}")
    return x, d, w


def _solve(x, d, w):
    P = np.eye(3) - d[..., :, None] * d[..., None, :]  # (..., n, 3, 3) projectors I - d dᵀ
    A = np.einsum("...i,...ijk->...jk", w, P)
    b = np.einsum("...i,...ijk,...ik->...j", w, P, x)
    return P, A, b


def pseudo_intersection_jacobians(origins, directions, weights=None) -> PseudoIntersection:
    """``q̂* = Â⁻¹ b̂`` and the Jacobians ``J_x``, ``J_d`` (no covariance). Raises :class:`ValueError`
    for fewer than two rays, zero directions, bad weights or (nearly) parallel rays."""
    x, d, w = _rays(origins, directions, weights)
    P, A, b = _solve(x, d, w)
    eig = np.linalg.eigvalsh(A)
    if eig[0] <= MIN_CONDITION * eig[-1]:
        raise ValueError("the rays are (nearly) parallel: their pseudo-intersection is undetermined")
    A_inv = np.linalg.inv(A)
    q = A_inv @ b
    r = q - x
    J_x = w[:, None, None] * (A_inv @ P)
    dr = np.einsum("ij,ij->i", d, r)
    inner = dr[:, None, None] * np.eye(3) + d[:, :, None] * r[:, None, :]
    J_d = w[:, None, None] * (A_inv @ inner)
    return PseudoIntersection(q, None, A, J_x, J_d)


def pseudo_intersection(origins, directions, weights=None, position_cov=None, bearing_sigma=None) -> PseudoIntersection:
    """Pseudo-intersection of rays (n >= 2) and, when noise is given, its first-order covariance.

    ``position_cov``: the camera-position error covariance — a scalar variance, (n,) variances, a
    (3, 3) matrix shared by all rays or (n, 3, 3). ``bearing_sigma``: angular noise σ_θ (rad), a scalar
    or (n,), giving ``Σ_d = σ_θ² (I - d̂ d̂ᵀ)``. If either is given the other defaults to zero."""
    est = pseudo_intersection_jacobians(origins, directions, weights)
    if position_cov is None and bearing_sigma is None:
        return est
    n = est.J_x.shape[0]
    d = np.asarray(directions, dtype=float)
    d = d / np.linalg.norm(d, axis=1)[:, None]
    Sx = np.zeros((n, 3, 3)) if position_cov is None else np.asarray(position_cov, dtype=float)
    if Sx.ndim == 0 or Sx.shape == (n,):
        Sx = np.asarray(Sx)[..., None, None] * np.eye(3) * np.ones((n, 1, 1))
    elif Sx.shape == (3, 3):
        Sx = np.broadcast_to(Sx, (n, 3, 3))
    if Sx.shape != (n, 3, 3) or not np.all(np.isfinite(Sx)):
        raise ValueError(
            f"position_cov must be a variance, (n,), (3, 3) or (n, 3, 3), got shape {np.shape(position_cov)}"
        )
    if np.any(np.linalg.eigvalsh(0.5 * (Sx + np.swapaxes(Sx, 1, 2)))[:, 0] < -1e-12 * (1 + np.abs(Sx).max())):
        raise ValueError("position_cov must be positive semi-definite")
    sig = np.zeros(n) if bearing_sigma is None else np.broadcast_to(np.asarray(bearing_sigma, dtype=float), (n,))
    if not np.all(np.isfinite(sig)) or np.any(sig < 0):
        raise ValueError(f"bearing_sigma must be non-negative and finite, got {bearing_sigma!r}")
    Sd = sig[:, None, None] ** 2 * (np.eye(3) - d[:, :, None] * d[:, None, :])
    Jx, Jd = est.J_x, est.J_d
    cov = np.einsum("nij,njk,nlk->il", Jx, Sx, Jx) + np.einsum("nij,njk,nlk->il", Jd, Sd, Jd)
    return PseudoIntersection(est.point, 0.5 * (cov + cov.T), est.A, Jx, Jd)


def perturb_bearings(directions, sigma, rng: np.random.Generator, size: int) -> np.ndarray:
    """``size`` noisy copies (size, n, 3) of unit bearings: ``normalise(d + δd)`` with
    ``δd ~ N(0, σ² (I - d dᵀ))`` — the angular error model (3.4)-(3.5), for Monte Carlo checks."""
    d = np.asarray(directions, dtype=float)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    sigma = np.broadcast_to(np.asarray(sigma, dtype=float), d.shape[:-1])
    noise = rng.normal(size=(size,) + d.shape) * sigma[..., None]
    noise -= np.sum(noise * d, axis=-1, keepdims=True) * d
    out = d + noise
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def batch_pseudo_intersection(origins, directions, weights=None) -> np.ndarray:
    """``q*`` for a batch of ray sets: origins, directions (..., n, 3) -> (..., 3) (no checks beyond
    shapes; NaN where a set is degenerate). For Monte Carlo studies."""
    x = np.asarray(origins, dtype=float)
    d = np.asarray(directions, dtype=float)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    w = np.ones(d.shape[:-1]) if weights is None else np.broadcast_to(np.asarray(weights, dtype=float), d.shape[:-1])
    x = np.broadcast_to(x, d.shape)
    _, A, b = _solve(x, d, w)
    ok = np.abs(np.linalg.det(A)) > 0
    q = np.full(b.shape, np.nan)
    q[ok] = np.linalg.solve(A[ok], b[ok][..., None])[..., 0]
    return q
