"""Gaussian mixtures: the functional belief behind particle fusion (Merino §5.2.1, (5.18)-(5.25)).

A mixture ``bel(X) = Σ_k α_k N(X; μ_k, Σ_k)``, ``Σ α_k = 1`` (Merino (5.18)).

**Density estimate of a particle set** (``Approximate_belief`` of Alg. 5.2). The Gaussian kernel density
estimate (5.19)-(5.23) with the kernel covariance scaled by the bandwidth, in the corrected form of
spec 001b §6 item 2 (the thesis's (5.25) prints ``(1/h^d) N(x^(k), h Σ)``, inconsistent with its own
kernel (5.23), whose ``(2π)^{d/2}`` is also missing):

    bel(X) = Σ_k w̃^(k) N(X; x^(k), h² Σ̂)                                   corrected (5.25)
    h_opt  = (4 / (d + 2))^{1/(d+4)} N^{-1/(d+4)}                             (5.24)

with ``Σ̂`` the weighted covariance of the set. ``N`` in (5.24) is taken as the effective sample size
``N_eff`` (equal to N for the equally weighted sets the thesis uses; chosen here for weighted sets).
Being a convolution of the empirical belief with the kernel (5.22), its covariance is exactly
``(1 + h²) Σ̂``. With ``shrink=True`` (Liu & West 2001, chosen here as an option) the component means are
moved to ``a x^(k) + (1 - a) μ̂``, ``a = sqrt(1 - h²)``, and the mixture keeps the set's mean and
covariance exactly.

**Compression** (the thesis mentions k-means reduction after Sheng et al. 2005 without specifying it):
weighted k-means (k-means++ seeding, Lloyd iterations) on the component means, in coordinates whitened by
the mixture's covariance, then moment matching inside every cluster (chosen here):

    α_c = Σ_{i∈c} α_i,  μ_c = Σ α_i μ_i / α_c,  Σ_c = Σ α_i (Σ_i + (μ_i - μ_c)(μ_i - μ_c)ᵀ) / α_c

which preserves the mixture's mean and covariance exactly (law of total covariance).

``logpdf`` is vectorised: one Cholesky factor per component (one for all components when they share a
covariance, as a density estimate does), squared Mahalanobis distances by ``scipy.spatial.distance.cdist``
on whitened points, and ``scipy.special.logsumexp`` over components; points are processed in chunks so
that memory stays bounded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular
from scipy.spatial.distance import cdist
from scipy.special import logsumexp

from fusion.particles import WEIGHT_SUM_TOL, ParticleSet
from fusion.resampling import optimal_bandwidth

#: Largest number of (point, component) pairs evaluated at once by :meth:`GaussianMixture.logpdf`
#: (chosen here: ~16 MB of float64 per chunk).
LOGPDF_CHUNK = 1 << 21
#: Lloyd iterations of the weighted k-means at most (chosen here; it usually stops after a few).
KMEANS_MAX_ITER = 50
#: Relative tolerance of the symmetry check of component covariances (chosen here).
SYMMETRY_RTOL = 1e-9
_LOG_2PI = math.log(2.0 * math.pi)


def _readonly(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class GaussianMixture:
    """Weights ``(K,)`` (non-negative, summing to one within ``WEIGHT_SUM_TOL``), means ``(K, d)`` and
    symmetric positive-definite covariances ``(K, d, d)``; validated on construction, read-only."""

    weights: np.ndarray
    means: np.ndarray
    covs: np.ndarray

    def __post_init__(self):
        w = np.array(self.weights, dtype=float)
        if w.ndim != 1 or w.size == 0:
            raise ValueError(f"mixture weights must be a non-empty vector, got shape {w.shape}")
        k = w.size
        if not np.all(np.isfinite(w)):
            raise ValueError("mixture weights contain non-finite values (NaN or inf)")
        if np.any(w < 0.0):
            raise ValueError(f"mixture weights must be non-negative, got minimum {w.min():.3g}")
        total = float(w.sum())
        if total == 0.0:
            raise ValueError("mixture weights are all zero")
        if abs(total - 1.0) > WEIGHT_SUM_TOL:
            raise ValueError(f"mixture weights must sum to one (within {WEIGHT_SUM_TOL:g}), got {total!r}")
        m = np.array(self.means, dtype=float)
        if m.ndim != 2 or m.shape[0] != k or m.shape[1] == 0:
            raise ValueError(f"mixture means must have shape ({k}, d) with d >= 1, got {m.shape}")
        if not np.all(np.isfinite(m)):
            raise ValueError("mixture means contain non-finite values (NaN or inf)")
        d = m.shape[1]
        c = np.asarray(self.covs, dtype=float)
        if c.shape != (k, d, d):
            raise ValueError(f"mixture covariances must have shape ({k}, {d}, {d}), got {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError("mixture covariances contain non-finite values (NaN or inf)")
        shared = bool(np.all(c == c[0]))
        unique = c[:1] if shared else c
        scale = np.maximum(1.0, np.max(np.abs(unique), axis=(1, 2)))
        if np.any(np.max(np.abs(unique - unique.transpose(0, 2, 1)), axis=(1, 2)) > SYMMETRY_RTOL * scale):
            raise ValueError("mixture covariances are not symmetric")
        unique = 0.5 * (unique + unique.transpose(0, 2, 1))
        try:
            chol = np.linalg.cholesky(unique)
        except np.linalg.LinAlgError:
            bad = [i for i in range(unique.shape[0]) if not _is_pd(unique[i])]
            which = bad[0] if bad else "?"
            raise ValueError(f"mixture covariance of component {which} is not positive definite") from None
        covs = np.broadcast_to(unique[0], (k, d, d)) if shared else unique
        with np.errstate(divide="ignore"):
            log_w = np.log(w)
        half_logdet = np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)
        object.__setattr__(self, "weights", _readonly(w))  # as given: a round trip stays bit-exact
        object.__setattr__(self, "means", _readonly(m))
        object.__setattr__(self, "covs", _readonly(covs if shared else covs.copy()))
        object.__setattr__(self, "_shared", shared)
        object.__setattr__(self, "_chol", chol)
        object.__setattr__(self, "_log_norm", log_w - 0.5 * d * _LOG_2PI - half_logdet)

    # -- construction ---------------------------------------------------------------------------
    @classmethod
    def kde(cls, particles: ParticleSet, bandwidth: float | None = None, shrink: bool = False) -> GaussianMixture:
        """The kernel density estimate of a particle set, corrected (5.25): ``Σ_k w̃_k N(x^(k), h² Σ̂)``.

        ``bandwidth`` defaults to (5.24) with ``N_eff``; it must be positive and finite (and below 1 with
        ``shrink``). Zero-weight particles are left out. Raises ``ValueError`` if ``Σ̂`` is singular."""
        if not isinstance(particles, ParticleSet):
            raise ValueError(f"expected a ParticleSet, got {type(particles).__name__}")
        h = optimal_bandwidth(particles.n_eff(), particles.dim) if bandwidth is None else float(bandwidth)
        if not math.isfinite(h) or h <= 0.0:
            raise ValueError(f"bandwidth must be a positive finite number, got {bandwidth!r}")
        if shrink and h >= 1.0:
            raise ValueError(f"a shrunk density estimate needs a bandwidth below 1, got {h!r}")
        cov = particles.cov()
        if not _is_pd(cov):
            raise ValueError(
                "the particle covariance is singular: no kernel density estimate (too few distinct particles)"
            )
        keep = particles.weights > 0.0
        w, x = particles.weights[keep], particles.states[keep]
        if shrink:
            a = math.sqrt(1.0 - h * h)
            x = a * x + (1.0 - a) * particles.mean()
        kernel = h * h * cov
        return cls(w, x, np.broadcast_to(kernel, (w.size,) + kernel.shape))  # dropping zeros keeps the sum

    @classmethod
    def from_particles(
        cls, particles: ParticleSet, k: int, rng: np.random.Generator, bandwidth: float | None = None
    ) -> GaussianMixture:
        """At most ``k`` components that keep the set's weighted mean and covariance exactly: the shrunk
        density estimate, compressed (:meth:`compressed`)."""
        return cls.kde(particles, bandwidth, shrink=True).compressed(k, rng)

    # -- accessors ------------------------------------------------------------------------------
    @property
    def k(self) -> int:
        return self.weights.shape[0]

    @property
    def dim(self) -> int:
        return self.means.shape[1]

    @property
    def shared_covariance(self) -> bool:
        """True when every component has the same covariance (a density estimate)."""
        return self._shared

    def mean(self) -> np.ndarray:
        """``Σ_k α_k μ_k``."""
        return self.weights @ self.means

    def cov(self) -> np.ndarray:
        """``Σ_k α_k (Σ_k + (μ_k - μ)(μ_k - μ)ᵀ)``."""
        d = self.means - self.mean()
        spread = (self.weights[:, None] * d).T @ d
        within = self.covs[0] if self._shared else np.einsum("k,kij->ij", self.weights, self.covs)
        c = within + spread
        return 0.5 * (c + c.T)

    # -- densities ------------------------------------------------------------------------------
    def logpdf(self, x) -> np.ndarray:
        """``log Σ_k α_k N(x; μ_k, Σ_k)`` for points ``x`` (M, d) -> (M,)."""
        pts = as_points(x, self.dim)
        out = np.empty(pts.shape[0])
        if self._shared:
            centre = self.mean()
            L = self._chol[0]
            zm = solve_triangular(L, (self.means - centre).T, lower=True).T
            step = max(1, LOGPDF_CHUNK // self.k)
            for s in range(0, pts.shape[0], step):
                zx = solve_triangular(L, (pts[s : s + step] - centre).T, lower=True).T
                out[s : s + step] = logsumexp(self._log_norm - 0.5 * cdist(zx, zm, "sqeuclidean"), axis=1)
            return out
        inv = np.linalg.inv(self._chol)  # (K, d, d) lower-triangular inverses
        step = max(1, LOGPDF_CHUNK // (self.k * self.dim))
        for s in range(0, pts.shape[0], step):
            diff = pts[s : s + step, None, :] - self.means[None, :, :]
            z = np.einsum("kij,mkj->mki", inv, diff)
            out[s : s + step] = logsumexp(self._log_norm - 0.5 * np.sum(z * z, axis=2), axis=1)
        return out

    def pdf(self, x) -> np.ndarray:
        return np.exp(self.logpdf(x))

    def sample(self, rng: np.random.Generator, n: int) -> ParticleSet:
        """``n`` equally weighted particles drawn from the mixture."""
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
            raise ValueError(f"number of samples must be a positive integer, got {n!r}")
        idx = rng.choice(self.k, size=int(n), p=self.weights)
        z = rng.standard_normal((int(n), self.dim))
        L = np.broadcast_to(self._chol[0], (int(n), self.dim, self.dim)) if self._shared else self._chol[idx]
        return ParticleSet.from_states(self.means[idx] + np.einsum("nij,nj->ni", L, z))

    # -- compression ----------------------------------------------------------------------------
    def compressed(self, k: int, rng: np.random.Generator, max_iter: int = KMEANS_MAX_ITER) -> GaussianMixture:
        """At most ``k`` components by weighted k-means on the means and moment matching per cluster;
        the mixture's mean and covariance are preserved exactly. ``k >= K`` returns ``self``."""
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1:
            raise ValueError(f"number of components k must be a positive integer, got {k!r}")
        if isinstance(max_iter, bool) or not isinstance(max_iter, int | np.integer) or max_iter < 1:
            raise ValueError(f"max_iter must be a positive integer, got {max_iter!r}")
        live = np.flatnonzero(self.weights > 0.0)
        if k >= live.size:
            return self
        w, mu = self.weights[live], self.means[live]
        labels = _weighted_kmeans(_whiten(mu, self.cov()), w, int(k), rng, int(max_iter))
        weights, means, covs = [], [], []
        for c in range(int(k)):
            members = np.flatnonzero(labels == c)
            if members.size == 0:
                continue
            wc = w[members]
            alpha = float(wc.sum())
            mean = wc @ mu[members] / alpha
            d = mu[members] - mean
            if self._shared:
                within = self.covs[0].copy()
            else:
                within = np.einsum("k,kij->ij", wc, self.covs[live][members]) / alpha
            cov = within + (wc[:, None] * d).T @ d / alpha
            weights.append(alpha)
            means.append(mean)
            covs.append(0.5 * (cov + cov.T))
        weights = np.array(weights)
        return GaussianMixture(weights / weights.sum(), np.array(means), np.array(covs))

    def __repr__(self) -> str:
        return f"GaussianMixture(k={self.k}, dim={self.dim})"


def _is_pd(matrix: np.ndarray) -> bool:
    try:
        np.linalg.cholesky(matrix)
        return True
    except np.linalg.LinAlgError:
        return False


def _whiten(points: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Points in coordinates where ``cov`` is the identity (so that k-means weighs all axes alike)."""
    try:
        L = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        return points
    return solve_triangular(L, (points - points.mean(axis=0)).T, lower=True).T


def _weighted_kmeans(x: np.ndarray, w: np.ndarray, k: int, rng: np.random.Generator, max_iter: int) -> np.ndarray:
    """Labels (n,) of a weighted k-means: k-means++ seeding with probabilities ``∝ w D²``, Lloyd iterations
    until the labels stop changing; an empty cluster is re-seeded at the point that costs most."""
    n = x.shape[0]
    centres = np.empty((k, x.shape[1]))
    centres[0] = x[rng.choice(n, p=w / w.sum())]
    d2 = np.sum((x - centres[0]) ** 2, axis=1)
    for c in range(1, k):
        p = w * d2
        total = p.sum()
        centres[c] = x[rng.choice(n, p=p / total)] if total > 0 else x[rng.integers(n)]
        d2 = np.minimum(d2, np.sum((x - centres[c]) ** 2, axis=1))
    labels = np.full(n, -1)
    for _ in range(max_iter):
        dist = cdist(x, centres, "sqeuclidean")
        new = np.argmin(dist, axis=1)
        counts = np.bincount(new, weights=w, minlength=k)
        for c in np.flatnonzero(counts == 0):
            cost = w * dist[np.arange(n), new]
            far = int(np.argmax(cost))
            new[far] = c
            dist[far] = 0.0
            counts = np.bincount(new, weights=w, minlength=k)
        if np.array_equal(new, labels):
            break
        labels = new
        sums = np.zeros_like(centres)
        np.add.at(sums, labels, w[:, None] * x)
        nonempty = counts > 0
        centres[nonempty] = sums[nonempty] / counts[nonempty, None]
    return labels


def as_points(x, dim: int) -> np.ndarray:
    """Finite points ``(M, dim)`` at which a density is evaluated; ``ValueError`` otherwise."""
    pts = np.asarray(x, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != dim:
        raise ValueError(f"points must have shape (M, {dim}), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points contain non-finite values (NaN or inf)")
    return pts
