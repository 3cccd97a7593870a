"""Resampling and regularisation kernels of particle filtering (Merino §5.1, (5.24), (5.25), (5.32)).

Array-level operations on weighted particle states, used by :class:`fusion.particles.ParticleSet` and by
the SIR step (:func:`fusion.particles.sir_update`):

* **low-variance (systematic) resampling** (Thrun et al. 2005, suggested in §5.1): one uniform draw
  ``u ~ U[0, 1/N)`` and the points ``u + k/N``; particle ``k`` is copied ``floor(N w̃_k)`` or
  ``ceil(N w̃_k)`` times (:func:`systematic_indices`).
* **jitter** after resampling (5.32): ``p_t^(k) = p_{t-1}^(k) + ν_t``, ``ν_t ~ N(0, R_t)``
  (:func:`gaussian_noise`).
* the **bandwidth** of the density estimate, ``h_opt`` of (5.24) (:func:`optimal_bandwidth`), and the
  **kernel jitter** ``N(0, h² Σ̂)`` with the kernel of (5.25) — the regularised particle filter of Musso
  et al. (2001), whom the thesis cites for (5.19) — after shrinking the states towards the mean by
  ``a = sqrt(1 - h²)`` (Liu & West 2001), so that jittering keeps the weighted mean and covariance
  instead of inflating the covariance by ``1 + h²`` at every resampling of a static state
  (:func:`kernel_jitter`).
"""

from __future__ import annotations

import math

import numpy as np


class DegenerateWeightsError(ValueError):
    """Every weight is zero (all particles have zero likelihood): the set cannot be normalised."""


# -- validation --------------------------------------------------------------------------------------
def as_raw_weights(weights, n: int, name: str = "weights") -> np.ndarray:
    """``weights`` as a float64 copy of shape ``(n,)``: finite and non-negative, not necessarily normalised."""
    arr = np.array(weights, dtype=float)
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},) to match the states, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contain non-finite values (NaN or inf)")
    if np.any(arr < 0.0):
        raise ValueError(f"{name} must be non-negative, got minimum {arr.min():.3g}")
    return arr


def positive_count(n, name: str) -> int:
    """``n`` as an ``int`` if it is a positive integer (not a bool), else ``ValueError`` naming ``name``."""
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"{name} must be a positive integer, got {n!r}")
    return int(n)


# -- the bandwidth of the density estimate ------------------------------------------------------------
def optimal_bandwidth(n: float, dim: int) -> float:
    """``h_opt = (4 / (d + 2))^{1/(d+4)} N^{-1/(d+4)}`` (Merino (5.24), Silverman's rule for a Gaussian
    kernel). ``n`` may be fractional (an effective sample size)."""
    if isinstance(dim, bool) or not isinstance(dim, int | np.integer) or dim < 1:
        raise ValueError(f"dimension must be a positive integer, got {dim!r}")
    n = float(n)
    if not math.isfinite(n) or n < 1.0:
        raise ValueError(f"the number of particles for the bandwidth must be >= 1, got {n!r}")
    return (4.0 / (dim + 2)) ** (1.0 / (dim + 4)) * n ** (-1.0 / (dim + 4))


def systematic_indices(weights, n: int, rng: np.random.Generator) -> np.ndarray:
    """Indices drawn by low-variance (systematic) resampling: ``u ~ U[0, 1)``, points ``(u + k) / n``
    against the cumulative weights. Index ``k`` appears ``floor(n w_k)`` or ``ceil(n w_k)`` times;
    zero-weight entries never appear."""
    n = positive_count(n, "number of resampled particles")
    if np.ndim(weights) != 1 or np.shape(weights)[0] == 0:
        raise ValueError(f"weights must be a non-empty vector, got shape {np.shape(weights)}")
    w = as_raw_weights(weights, np.shape(weights)[0])
    cumulative = np.cumsum(w)
    if cumulative[-1] <= 0.0:
        raise DegenerateWeightsError("weights are all zero")
    cumulative /= cumulative[-1]
    cumulative[-1] = 1.0  # the points are < 1, so every one finds a particle
    points = (rng.random() + np.arange(n)) / n
    return np.searchsorted(cumulative, points, side="right")


def gaussian_noise(rng: np.random.Generator, cov: np.ndarray, size: int) -> np.ndarray:
    """``size`` draws of ``N(0, cov)`` for a PSD ``cov`` (Cholesky, or the symmetric root if singular)."""
    try:
        root = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        vals, vecs = np.linalg.eigh(cov)
        root = vecs * np.sqrt(np.clip(vals, 0.0, None))
    return rng.standard_normal((size, cov.shape[0])) @ root.T


def kernel_jitter(
    states: np.ndarray, rng: np.random.Generator, h: float, shrink: bool, mu: np.ndarray, cov: np.ndarray
) -> np.ndarray:
    """The states ``(N, d)`` jittered with the kernel of (5.25), ``N(0, h² cov)``, for the bandwidth ``h``
    and the weighted mean ``mu`` and covariance ``cov`` of the set.

    With ``shrink`` the states first move to ``a x + (1 - a) μ``, ``a = sqrt(1 - h²)`` (Liu & West
    2001), ``h`` capped at 1 (``a = 0``: a fresh Gaussian sample), so that the weighted mean and
    covariance are unchanged in expectation (``a² Σ̂ + h² Σ̂ = Σ̂``)."""
    if shrink:
        h = min(h, 1.0)
        a = math.sqrt(1.0 - h * h)
        states = a * states + (1.0 - a) * mu
    return states + gaussian_noise(rng, h * h * cov, states.shape[0])
