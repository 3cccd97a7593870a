"""Particle beliefs and the SIR filter (Merino §5.1, §5.3.3, §5.3.5).

A belief is a set of ``N`` states ``x^(k)`` (rows of an ``(N, d)`` array) with normalised weights:

    bel(X) ≈ Σ_k w̃^(k) δ(X - x^(k)),   w̃^(k) = ω^(k) / Σ_j ω^(j)                Merino (5.6)-(5.7)

Operations (every one returns a new, immutable :class:`ParticleSet`):

* **reweighting** by a likelihood, the bootstrap filter (5.10): ``w̃_t^(k) ∝ w̃_{t-1}^(k) p(z_t | x_t^(k))``,
  done in the log domain. The sum of the unnormalised weights ``Σ_k w̃_{t-1}^(k) p(z_t | x^(k))`` is the
  Monte Carlo estimate of ``p(z_t | z^{t-1})`` used by the transmission trigger (5.35).
* **effective sample size** ``N_eff = [Σ_k (w̃^(k))²]^-1`` (§5.1; the thesis's "variance of the weights
  below a threshold" is read as "N_eff below a threshold", spec 001b §6 item 1).
* **low-variance (systematic) resampling** (Thrun et al. 2005, suggested in §5.1) and **jitter** after
  resampling (5.32), ``p_t^(k) = p_{t-1}^(k) + ν_t``, ``ν_t ~ N(0, R_t)``: the kernels are in
  :mod:`fusion.resampling`.
* **moments** ``μ = Σ w̃ x``, ``Σ̂ = Σ w̃ (x - μ)(x - μ)ᵀ`` and the moment-matched :class:`Gaussian`
  (the hand-over to the information filter that §5.5/§9 suggest once the belief is Gaussian).

The SIR step of §5.3.3 (:func:`sir_update`): reweight, then — only when ``N_eff < 0.3 N`` — resample and
jitter. ``R_t`` is not given by the thesis (spec 001b §6 item 5); by default (chosen here) the jitter is
the kernel of the density estimate (5.25), ``N(0, h² Σ̂)`` with the bandwidth ``h`` of (5.24) — the
regularised particle filter of Musso et al. (2001), whom the thesis cites for (5.19) — and the resampled
particles are first shrunk towards the mean by ``a = sqrt(1 - h²)`` (Liu & West 2001), so that jittering
keeps the weighted mean and covariance instead of inflating the covariance by ``1 + h²`` at every
resampling of a static state (:func:`fusion.resampling.kernel_jitter`). A fixed ``R_t`` can be configured
instead.

Transmission trigger (5.35): ``p(z^{t-k:t} | z^{t-k}) = Π_τ p(z_τ | z^{τ-1})``; a node transmits when the
product falls below a threshold (the data since the last transmission were informative), accumulated
in the log domain by :class:`InformationTrigger`. A likelihood is only defined up to a constant factor
(normalisation removes it), so the product is accumulated with every log-likelihood shifted to a maximum
of 0 over the particles (:attr:`SIRStep.log_relative_evidence`, chosen here): a constant (uninformative)
likelihood then contributes ``log 1 = 0`` and the threshold does not depend on the likelihood's units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fusion import validation
from fusion.gaussian import Gaussian
from fusion.resampling import (
    DegenerateWeightsError,
    as_raw_weights,
    gaussian_noise,
    kernel_jitter,
    optimal_bandwidth,
    positive_count,
    systematic_indices,
)

#: Merino §5.3.3: resample when the effective sample size drops below 30 % of N.
RESAMPLE_THRESHOLD = 0.3
#: Largest ``|Σ w - 1|`` accepted for weights given as normalised (the task's validation rule).
WEIGHT_SUM_TOL = 1e-9
#: Sarle's bimodality coefficient ``(skew² + 1) / kurtosis`` along every principal axis must stay at or
#: below this for :meth:`ParticleSet.is_unimodal`. A Gaussian has 1/3, a uniform segment (one viewing ray
#: with uniform depth, Alg. 5.4) 5/9, two equal separated modes 1. Chosen here: about 3 sampling standard
#: deviations above the Gaussian value for N_eff = 200, well below the uniform segment's 0.556 (measured on
#: Gaussian clouds: 0.2 % (2-D) and 0.7 % (3-D) wrongly rejected at N = 200, none at N = 500, ~10 % at N = 100).
UNIMODAL_MAX_BIMODALITY = 0.45
#: Fewer effective particles than this are too few to judge the shape: :meth:`ParticleSet.is_unimodal`
#: says False (chosen here: the sampling spread of the kurtosis is ~sqrt(24 / N_eff)).
UNIMODAL_MIN_N_EFF = 30.0
#: Principal axes with a variance below this fraction of the largest (or below the rounding level of the
#: states' magnitude) are treated as exactly flat: a point mass along them for the shape test, a singular
#: covariance for the Gaussian hand-over (chosen here).
FLAT_AXIS_RTOL = 1e-12
#: Default threshold of the information trigger, in nats: transmit once the accumulated relative evidence
#: has dropped below log(0.1) (chosen here; the thesis gives no value, spec 001b §6 item 5).
DEFAULT_LOG_THRESHOLD = math.log(0.1)


# -- validation --------------------------------------------------------------------------------------
def _as_states(states) -> np.ndarray:
    arr = np.array(states, dtype=float)  # a copy: the set owns its arrays
    if arr.ndim != 2:
        raise ValueError(f"particle states must have shape (N, d), got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError("a particle set needs at least one particle (N = 0)")
    if arr.shape[1] == 0:
        raise ValueError("particle states must have at least one dimension (d = 0)")
    if not np.all(np.isfinite(arr)):
        raise ValueError("particle states contain non-finite values (NaN or inf)")
    return arr


def _as_normalised_weights(weights, n: int) -> np.ndarray:
    arr = as_raw_weights(weights, n)
    total = float(arr.sum())
    if total == 0.0:
        raise DegenerateWeightsError("weights are all zero")
    if abs(total - 1.0) > WEIGHT_SUM_TOL:
        raise ValueError(f"weights must sum to one (within {WEIGHT_SUM_TOL:g}), got {total!r}")
    return arr  # kept bit for bit (dividing by a sum of 1 ± ulp again would change them at every copy)


def _readonly(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


# -- the particle set ---------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ParticleSet:
    """States ``(N, d)`` float64 and normalised weights ``(N,)``; both read-only copies.

    The constructor validates: a 2-D finite state array with ``N >= 1`` and ``d >= 1``, and finite,
    non-negative weights summing to one within :data:`WEIGHT_SUM_TOL` (all-zero weights raise
    :class:`DegenerateWeightsError`). Use :meth:`from_states` for equal weights,
    :meth:`from_unnormalised` or :meth:`from_log_weights` for weights that still need normalising."""

    states: np.ndarray
    weights: np.ndarray

    def __post_init__(self):
        states = _as_states(self.states)
        weights = _as_normalised_weights(self.weights, states.shape[0])
        object.__setattr__(self, "states", _readonly(states))
        object.__setattr__(self, "weights", _readonly(weights))

    # -- construction ---------------------------------------------------------------------------
    @classmethod
    def from_states(cls, states, weights=None) -> ParticleSet:
        """From states and normalised weights (equal weights ``1/N`` when ``weights`` is None)."""
        states = _as_states(states)
        if weights is None:
            weights = np.full(states.shape[0], 1.0 / states.shape[0])
        return cls(states, weights)

    @classmethod
    def from_unnormalised(cls, states, weights) -> ParticleSet:
        """From non-negative weights of any positive total (normalised here, Merino (5.6))."""
        states = _as_states(states)
        w = as_raw_weights(weights, states.shape[0])
        total = float(w.sum())
        if total == 0.0:
            raise DegenerateWeightsError("weights are all zero")
        return cls(states, w / total)

    @classmethod
    def from_log_weights(cls, states, log_weights) -> ParticleSet:
        """From log weights (``-inf`` allowed, NaN and ``+inf`` not), normalised stably."""
        states = _as_states(states)
        normalised, _ = _normalise_log(np.asarray(log_weights, dtype=float), states.shape[0], "log weights")
        return cls(states, normalised)

    # -- accessors ------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        return self.states.shape[0]

    @property
    def dim(self) -> int:
        return self.states.shape[1]

    def n_eff(self) -> float:
        """Effective sample size ``[Σ_k w̃_k²]^-1`` (Merino §5.1), between 1 and N."""
        return float(1.0 / np.dot(self.weights, self.weights))

    def mean(self) -> np.ndarray:
        """Weighted mean ``Σ_k w̃_k x^(k)`` (the estimate (5.5) of ``E[X]``)."""
        return self.weights @ self.states

    def cov(self) -> np.ndarray:
        """Weighted covariance ``Σ_k w̃_k (x^(k) - μ)(x^(k) - μ)ᵀ`` (the moments of the empirical belief
        (5.7), without a small-sample correction: it is what moment matching to a Gaussian needs)."""
        d = self.states - self.mean()
        c = (self.weights[:, None] * d).T @ d
        return 0.5 * (c + c.T)

    # -- the filter operations --------------------------------------------------------------------
    def reweighted(self, log_likelihood) -> tuple[ParticleSet, float]:
        """Bootstrap update (5.10) ``w̃_k ∝ w̃_k p(z | x^(k))`` from ``log p(z | x^(k))`` (N,).

        Returns the normalised set and ``log Σ_k w̃_k p(z | x^(k))``, the estimate of ``log p(z_t | z^{t-1})``
        (the weight sum of (5.35)). ``-inf`` entries (zero likelihood) are allowed; NaN, ``+inf`` and a
        wrong shape raise ``ValueError``; all-zero resulting weights raise :class:`DegenerateWeightsError`."""
        ll = np.asarray(log_likelihood, dtype=float)
        with np.errstate(divide="ignore"):
            log_w = np.log(self.weights)
        if ll.shape != (self.n,):
            raise ValueError(f"log-likelihood must have shape ({self.n},), got {ll.shape}")
        _check_log(ll, "log-likelihood")
        normalised, log_sum = _normalise_log(log_w + ll, self.n, "log-likelihood")
        return ParticleSet(self.states, normalised), log_sum

    def resampled(self, rng: np.random.Generator, n: int | None = None) -> ParticleSet:
        """Low-variance (systematic) resampling to ``n`` (default ``N``) equally weighted particles."""
        n = self.n if n is None else positive_count(n, "number of resampled particles")
        idx = systematic_indices(self.weights, n, rng)
        return ParticleSet(self.states[idx], np.full(n, 1.0 / n))

    def jittered(self, rng: np.random.Generator, cov) -> ParticleSet:
        """Every state plus independent ``N(0, cov)`` noise (Merino (5.32)); ``cov`` is d x d PSD."""
        cov = validation.as_psd(cov, "jitter covariance", self.dim)
        return ParticleSet(self.states + gaussian_noise(rng, cov, self.n), self.weights)

    def kernel_jittered(
        self, rng: np.random.Generator, bandwidth: float | None = None, shrink: bool = True
    ) -> ParticleSet:
        """Jitter with the kernel of (5.25), ``N(0, h² Σ̂)`` (``h`` from (5.24) with ``N_eff`` by default).

        With ``shrink`` the states first move to ``a x + (1 - a) μ``, ``a = sqrt(1 - h²)`` (Liu & West
        2001): the weighted mean and covariance are then unchanged in expectation (``a² Σ̂ + h² Σ̂ = Σ̂``).
        ``h`` is capped at 1 (``a = 0``: a fresh Gaussian sample) when ``N_eff`` is tiny."""
        h = optimal_bandwidth(self.n_eff(), self.dim) if bandwidth is None else _bandwidth(bandwidth)
        return ParticleSet(kernel_jitter(self.states, rng, h, shrink, self.mean(), self.cov()), self.weights)

    # -- Gaussian hand-over -----------------------------------------------------------------------
    def to_gaussian(self) -> Gaussian:
        """Moment matching: ``N(μ, Σ̂)`` as a :class:`Gaussian`. Raises ``ValueError`` when ``Σ̂`` is
        singular (e.g. fewer distinct particles than dimensions after resampling without jitter)."""
        cov = self.cov()
        vals = np.linalg.eigvalsh(cov)
        if vals[0] <= _flat_tolerance(vals[::-1], self.states):
            raise ValueError("cannot hand the particle set over to a Gaussian: its covariance is singular")
        return Gaussian.from_moments(self.mean(), cov)

    def bimodality_coefficients(self) -> np.ndarray:
        """Sarle's bimodality coefficient ``(γ² + 1) / κ`` of the weighted set projected on each principal
        axis of ``Σ̂`` (``γ`` skewness, ``κ`` kurtosis of the standardised projection), largest variance
        first. Exactly flat axes (see :data:`FLAT_AXIS_RTOL`) are left out."""
        vals, vecs = np.linalg.eigh(self.cov())
        order = np.argsort(vals)[::-1]
        vals, vecs = vals[order], vecs[:, order]
        keep = vals > _flat_tolerance(vals, self.states)
        if not np.any(keep):
            return np.zeros(0)
        z = (self.states - self.mean()) @ vecs[:, keep] / np.sqrt(vals[keep])
        w = self.weights[:, None]
        skew = np.sum(w * z**3, axis=0)
        kurt = np.sum(w * z**4, axis=0)
        return (skew**2 + 1.0) / kurt

    def is_unimodal(
        self, max_bimodality: float = UNIMODAL_MAX_BIMODALITY, min_n_eff: float = UNIMODAL_MIN_N_EFF
    ) -> bool:
        """Whether the set is one compact, Gaussian-like cloud that a Gaussian may replace (chosen here).

        Criterion: ``N_eff >= min_n_eff`` and, along every principal axis of ``Σ̂``, the bimodality
        coefficient (:meth:`bimodality_coefficients`) is at most ``max_bimodality``. Two or more modes
        give a low kurtosis or a strong skew along the axis that joins them; a single viewing ray with
        uniform depth (a line or a "banana", Alg. 5.4) is flat along the ray (coefficient 5/9); a Gaussian
        cloud has 1/3. A point mass (all axes flat) counts as unimodal."""
        if not 0.0 < max_bimodality <= 1.0:
            raise ValueError(f"max_bimodality must lie in (0, 1], got {max_bimodality!r}")
        if self.n_eff() < min_n_eff:
            return False
        return bool(np.all(self.bimodality_coefficients() <= max_bimodality))

    def __repr__(self) -> str:
        return f"ParticleSet(n={self.n}, dim={self.dim}, n_eff={self.n_eff():.1f})"


def _flat_tolerance(vals_descending: np.ndarray, states: np.ndarray) -> float:
    """Variance at or below which a principal axis counts as flat: relative to the largest variance, and
    never below the rounding level of moments of states of this magnitude."""
    scale = max(1.0, float(np.max(np.abs(states))))
    return max(FLAT_AXIS_RTOL * max(float(vals_descending[0]), 0.0), (FLAT_AXIS_RTOL * scale) ** 2)


def _bandwidth(h) -> float:
    h = float(h)
    if not math.isfinite(h) or h <= 0.0:
        raise ValueError(f"bandwidth must be a positive finite number, got {h!r}")
    return h


def _check_log(values: np.ndarray, name: str) -> None:
    if np.any(np.isnan(values)):
        raise ValueError(f"{name} contains NaN")
    if np.any(values == np.inf):
        raise ValueError(f"{name} contains +inf")


def _normalise_log(log_w: np.ndarray, n: int, name: str) -> tuple[np.ndarray, float]:
    """Normalised weights from log weights, and ``log Σ exp(log_w)``."""
    if log_w.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {log_w.shape}")
    _check_log(log_w, name)
    top = float(np.max(log_w))
    if top == -np.inf:
        raise DegenerateWeightsError(f"every weight is zero ({name} all -inf)")
    w = np.exp(log_w - top)
    total = float(w.sum())
    return w / total, top + math.log(total)


# -- the SIR step -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SIRConfig:
    """Settings of :func:`sir_update`.

    ``resample_threshold``: resample when ``N_eff < threshold * N`` (Merino §5.3.3: 0.3).
    ``jitter_cov``: a fixed ``R_t`` of (5.32) (d x d PSD), or None for the kernel jitter ``N(0, h² Σ̂)``
    (chosen here, see the module docstring); ``shrink`` applies to the kernel jitter only."""

    resample_threshold: float = RESAMPLE_THRESHOLD
    jitter_cov: np.ndarray | None = None
    shrink: bool = True

    def __post_init__(self):
        t = float(self.resample_threshold)
        if not 0.0 < t <= 1.0:
            raise ValueError(f"resample_threshold must lie in (0, 1], got {self.resample_threshold!r}")
        object.__setattr__(self, "resample_threshold", t)
        if self.jitter_cov is not None:
            cov = _readonly(validation.as_psd(self.jitter_cov, "jitter covariance R_t").copy())
            object.__setattr__(self, "jitter_cov", cov)


@dataclass(frozen=True)
class SIRStep:
    """The outcome of one SIR step: the new set, ``log Σ_k w̃_k p(z | x^(k))`` (``log_evidence``), the
    same with the log-likelihood shifted to a maximum of 0 (``log_relative_evidence``, for the trigger),
    ``N_eff`` after reweighting and whether the set was resampled and jittered."""

    particles: ParticleSet
    log_evidence: float
    log_relative_evidence: float
    n_eff: float
    resampled: bool


def sir_update(
    particles: ParticleSet, log_likelihood, rng: np.random.Generator, config: SIRConfig | None = None
) -> SIRStep:
    """One step of the static-state SIR filter (Merino Alg. 5.1 with §5.3.3): reweight by the likelihood,
    then, only if ``N_eff < 0.3 N``, resample ``N`` particles (systematic) and jitter them (5.32)."""
    config = SIRConfig() if config is None else config
    ll = np.asarray(log_likelihood, dtype=float)
    updated, log_evidence = particles.reweighted(ll)
    finite = ll[np.isfinite(ll)]
    log_relative = log_evidence - float(finite.max()) if finite.size else -math.inf
    n_eff = updated.n_eff()
    resample = n_eff < config.resample_threshold * updated.n
    if resample:
        if config.jitter_cov is None:
            # kernel and shrinkage from the weighted set before resampling (its moments are the better
            # estimate: resampling only adds noise to them)
            h = optimal_bandwidth(n_eff, updated.dim)
            mu, cov = updated.mean(), updated.cov()
            resampled = updated.resampled(rng)
            updated = ParticleSet(kernel_jitter(resampled.states, rng, h, config.shrink, mu, cov), resampled.weights)
        else:
            if config.jitter_cov.shape != (updated.dim, updated.dim):
                raise ValueError(
                    f"jitter covariance must be {updated.dim}x{updated.dim}, got {config.jitter_cov.shape}"
                )
            updated = updated.resampled(rng).jittered(rng, config.jitter_cov)
    return SIRStep(updated, log_evidence, log_relative, n_eff, resample)


@dataclass
class InformationTrigger:
    """Information-triggered transmission (Merino (5.35)), in the log domain.

    :meth:`add` accumulates ``log p(z_τ | z^{τ-1})`` terms (use :attr:`SIRStep.log_relative_evidence`,
    which is 0 for an uninformative likelihood); :meth:`due` says whether the accumulated product has
    fallen below ``exp(log_threshold)`` — the data since the last transmission were informative;
    :meth:`reset` starts afresh after a transmission."""

    log_product: float = 0.0
    steps: int = field(default=0)

    def add(self, log_weight_sum: float) -> None:
        value = float(log_weight_sum)
        if math.isnan(value) or value == math.inf:
            raise ValueError(f"log weight sum must be a number below +inf, got {log_weight_sum!r}")
        self.log_product += value
        self.steps += 1

    def due(self, log_threshold: float = DEFAULT_LOG_THRESHOLD) -> bool:
        threshold = float(log_threshold)
        if not math.isfinite(threshold):
            raise ValueError(f"log threshold must be finite, got {log_threshold!r}")
        return self.log_product < threshold

    def reset(self) -> None:
        self.log_product = 0.0
        self.steps = 0
