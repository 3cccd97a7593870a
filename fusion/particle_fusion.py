"""Decentralized fusion of particle beliefs (Merino §5.2: Alg. 5.2, Alg. 5.3, (2.26)-(2.28)).

**Bayesian fusion** at node ``i`` of a set received from neighbour ``j`` (5.15):

    bel_{i,m}(X) = η bel_i(X) bel_j(X) / bel_ij(X)

with ``bel_ij`` what the two nodes already share. Both sets are importance samples of ``bel_{i,m}``
after re-weighting (5.16)-(5.17):

    received x_j^(k):  ω = N_j w_j^(k) bel_i(x_j^(k)) / bel_ij(x_j^(k))
    local    x_i^(k):  ω = N_i w_i^(k) bel_j(x_i^(k)) / bel_ij(x_i^(k))

where ``bel_i``, ``bel_j`` are the density estimates of the sets (:meth:`GaussianMixture.kde`,
``Approximate_belief``). For the thesis's equally weighted sets ``N w = 1`` and these are exactly the
weights of Alg. 5.2; for weighted sets the factor ``N w`` keeps both halves of the pool on the same scale
(each half's mean weight estimates ``1/η``). The ``N_i + N_j`` weights are normalised together and ``N_i``
particles are resampled from the pool (Alg. 5.2, lines 6-7). Computed in the log domain.

``bel_ij = None`` means a flat common belief (nothing shared yet, no common prior): the ratio uses
``bel_i`` (or ``bel_j``) only. A :class:`UniformBox` is a common uniform prior over a box (chosen here as
the thesis leaves the initial ``bel_ij`` open, spec 001b §6 item 3): inside the box it cancels like a
constant; a particle outside the box gets weight 0, because the fused belief contains the common prior
and is zero there.

**Common-information bookkeeping** (:class:`ParticleChannelFilter`, after Bourgault & Durrant-Whyte 2004):
on receiving from ``j``, ``bel_ij ← bel_j`` (2.27) (Alg. 5.2, line 5); on sending to ``j``,
``bel_ij ← bel_i`` (2.28). ``bel_ij`` is stored as a Gaussian mixture (the density estimate of the set,
optionally compressed to ``k`` components). This removes the common information exactly only on tree
(acyclic) topologies and when messages do not cross; the state is static, so ``bel_ij`` needs no
prediction (spec 001b §2.2).

**Linear opinion pool** (5.26)-(5.27), Alg. 5.3: received particles get weight ``α_j w_j^(k)`` and local
ones ``α_i w_i^(k)`` (``α_i + α_j = 1``; ``α_j / N_j`` for the thesis's equally weighted sets), then ``N_i``
particles are resampled (line 11 of the algorithm: immediately). ``α`` is not given by the thesis; the
default ``α_i = 0.5`` is chosen here (spec 001b §2.4).
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from fusion.mixture import GaussianMixture, as_points
from fusion.particles import ParticleSet

#: Default weight of the local belief in the linear opinion pool (chosen here; Merino gives no value).
DEFAULT_ALPHA_LOCAL = 0.5
METHODS = ("bayes", "lop")


class Density(Protocol):
    """Anything with a dimension and a vectorised ``logpdf`` (M, d) -> (M,): a common belief ``bel_ij``."""

    @property
    def dim(self) -> int: ...

    def logpdf(self, x) -> np.ndarray: ...


@dataclass(frozen=True)
class UniformBox:
    """The uniform density over the axis-aligned box ``[lower, upper]`` (a common uniform prior)."""

    lower: np.ndarray
    upper: np.ndarray

    def __post_init__(self):
        lo, hi = np.array(self.lower, dtype=float), np.array(self.upper, dtype=float)
        if lo.ndim != 1 or lo.size == 0 or hi.shape != lo.shape:
            raise ValueError(f"box bounds must be two vectors of the same length, got {lo.shape} and {hi.shape}")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError("box bounds contain non-finite values (NaN or inf)")
        if np.any(hi <= lo):
            raise ValueError("box upper bounds must exceed the lower bounds on every axis")
        lo.setflags(write=False)
        hi.setflags(write=False)
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)

    @property
    def dim(self) -> int:
        return self.lower.size

    def logpdf(self, x) -> np.ndarray:
        """``-log(volume)`` inside the box (boundary included), ``-inf`` outside."""
        pts = as_points(x, self.dim)
        inside = np.all((pts >= self.lower) & (pts <= self.upper), axis=1)
        return np.where(inside, -float(np.sum(np.log(self.upper - self.lower))), -np.inf)

    def sample(self, rng: np.random.Generator, n: int) -> ParticleSet:
        """``n`` equally weighted particles drawn uniformly from the box."""
        return ParticleSet.from_states(rng.uniform(self.lower, self.upper, size=(int(n), self.dim)))


# -- fusion rules --------------------------------------------------------------------------------------
def _check_sets(local, received, common=None) -> None:
    for name, s in (("local", local), ("received", received)):
        if not isinstance(s, ParticleSet):
            raise ValueError(f"{name} belief must be a ParticleSet, got {type(s).__name__}")
    if received.dim != local.dim:
        raise ValueError(f"dimension mismatch: local {local.dim}-D, received {received.dim}-D")
    if common is not None:
        if not callable(getattr(common, "logpdf", None)):
            raise ValueError(f"common belief must have a logpdf (a GaussianMixture or UniformBox), got {common!r}")
        if common.dim != local.dim:
            raise ValueError(f"dimension mismatch: particles {local.dim}-D, common belief {common.dim}-D")


def _size(n, default: int) -> int:
    if n is None:
        return default
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"number of fused particles must be a positive integer, got {n!r}")
    return int(n)


def _finish(states, log_w, n: int, rng, resample: bool) -> ParticleSet:
    pool = ParticleSet.from_log_weights(states, log_w)
    if not resample:
        return pool
    if rng is None:
        raise ValueError("resampling the fused pool needs a random generator (rng)")
    return pool.resampled(rng, n)


def _log_ratio(numerator: np.ndarray, common: np.ndarray) -> np.ndarray:
    """``log bel / bel_ij``, and ``-inf`` (weight 0) where the common belief is zero: outside its support."""
    out = np.full(numerator.shape, -np.inf)
    ok = common > -np.inf
    out[ok] = numerator[ok] - common[ok]
    return out


@dataclass(frozen=True)
class BayesFusion:
    """Alg. 5.2 with its intermediate products: the fused set and the two density estimates."""

    fused: ParticleSet
    local_belief: GaussianMixture
    received_belief: GaussianMixture


def fuse_bayes_detailed(
    local: ParticleSet,
    received: ParticleSet,
    common: Density | None,
    rng: np.random.Generator | None,
    *,
    n: int | None = None,
    bandwidth: float | None = None,
    shrink: bool = False,
    resample: bool = True,
    received_belief: GaussianMixture | None = None,
) -> BayesFusion:
    """:func:`fuse_bayes`, also returning ``bel_i`` and ``bel_j`` (the channel filter stores ``bel_j``).
    ``received_belief`` reuses an already computed density estimate of ``received``."""
    _check_sets(local, received, common)
    n = _size(n, local.n)
    bel_i = GaussianMixture.kde(local, bandwidth, shrink)
    bel_j = GaussianMixture.kde(received, bandwidth, shrink) if received_belief is None else received_belief
    if bel_j.dim != local.dim:
        raise ValueError(f"dimension mismatch: received belief {bel_j.dim}-D, particles {local.dim}-D")
    with np.errstate(divide="ignore"):
        log_nw_j = np.log(received.n * received.weights)
        log_nw_i = np.log(local.n * local.weights)
    log_i_at_j = bel_i.logpdf(received.states)
    log_j_at_i = bel_j.logpdf(local.states)
    if common is None:
        w_j, w_i = log_nw_j + log_i_at_j, log_nw_i + log_j_at_i
    else:
        c = common.logpdf(np.concatenate([received.states, local.states]))
        w_j = log_nw_j + _log_ratio(log_i_at_j, c[: received.n])
        w_i = log_nw_i + _log_ratio(log_j_at_i, c[received.n :])
    fused = _finish(np.concatenate([received.states, local.states]), np.concatenate([w_j, w_i]), n, rng, resample)
    return BayesFusion(fused, bel_i, bel_j)


def fuse_bayes(
    local: ParticleSet,
    received: ParticleSet,
    common: Density | None,
    rng: np.random.Generator | None,
    *,
    n: int | None = None,
    bandwidth: float | None = None,
    shrink: bool = False,
    resample: bool = True,
) -> ParticleSet:
    """Merino Alg. 5.2: ``bel_i bel_j / bel_ij`` by re-weighting the union of both sets.

    ``common`` is ``bel_ij`` (a :class:`GaussianMixture`, a :class:`UniformBox` or None for flat);
    ``bandwidth``/``shrink`` configure the density estimates (default (5.24), unshrunk as in the thesis);
    ``n`` particles (default ``local.n``) are resampled from the pool, or with ``resample=False`` the
    weighted pool of ``N_i + N_j`` particles is returned. Raises ``ValueError`` on mismatched dimensions,
    and :class:`~fusion.resampling.DegenerateWeightsError` when every pooled weight is zero."""
    return fuse_bayes_detailed(
        local, received, common, rng, n=n, bandwidth=bandwidth, shrink=shrink, resample=resample
    ).fused


def fuse_lop(
    local: ParticleSet,
    received: ParticleSet,
    alpha_local: float = DEFAULT_ALPHA_LOCAL,
    rng: np.random.Generator | None = None,
    *,
    n: int | None = None,
    resample: bool = True,
) -> ParticleSet:
    """Merino Alg. 5.3, the linear opinion pool ``α_i bel_i + (1 - α_i) bel_j`` (5.26)-(5.27).

    ``alpha_local`` must lie in [0, 1]. ``n`` particles (default ``local.n``) are resampled; with
    ``resample=False`` the weighted union is returned (``rng`` may then be None)."""
    _check_sets(local, received)
    a = float(alpha_local)
    if not 0.0 <= a <= 1.0:
        raise ValueError(f"alpha_local must lie in [0, 1], got {alpha_local!r}")
    n = _size(n, local.n)
    w = np.concatenate([a * local.weights, (1.0 - a) * received.weights])
    pool = ParticleSet.from_unnormalised(np.concatenate([local.states, received.states]), w)
    if not resample:
        return pool
    if rng is None:
        raise ValueError("resampling the fused pool needs a random generator (rng)")
    return pool.resampled(rng, n)


# -- the channel filter ----------------------------------------------------------------------------------
class ParticleChannelFilter:
    """Per-neighbour common beliefs ``bel_ij`` of one node, and fusion through them.

    ``initial_common`` is ``bel_ij`` before any exchange: None (flat), a :class:`UniformBox` (a common
    uniform prior) or any density with ``logpdf`` (e.g. a Gaussian prior as a one-component mixture).
    ``method`` ("bayes" or "lop") and ``alpha_local`` are the defaults of :meth:`on_receive`;
    ``bandwidth``/``shrink`` configure the density estimates; ``common_components`` compresses each
    stored ``bel_ij`` to at most that many components (None: keep the full density estimate)."""

    def __init__(
        self,
        initial_common: Density | None = None,
        *,
        method: str = "bayes",
        alpha_local: float = DEFAULT_ALPHA_LOCAL,
        bandwidth: float | None = None,
        shrink: bool = False,
        common_components: int | None = None,
    ):
        if initial_common is not None and not callable(getattr(initial_common, "logpdf", None)):
            raise ValueError(f"initial common belief must have a logpdf, got {initial_common!r}")
        self.initial_common = initial_common
        self.method = _method(method)
        if not 0.0 <= float(alpha_local) <= 1.0:
            raise ValueError(f"alpha_local must lie in [0, 1], got {alpha_local!r}")
        self.alpha_local = float(alpha_local)
        if bandwidth is not None and (not math.isfinite(float(bandwidth)) or float(bandwidth) <= 0.0):
            raise ValueError(f"bandwidth must be a positive finite number, got {bandwidth!r}")
        self.bandwidth = bandwidth
        self.shrink = bool(shrink)
        if common_components is not None and (
            isinstance(common_components, bool) or not isinstance(common_components, int) or common_components < 1
        ):
            raise ValueError(f"common_components must be a positive integer or None, got {common_components!r}")
        self.common_components = common_components
        self._common: dict[Hashable, Density | None] = {}

    def neighbours(self) -> list:
        return list(self._common)

    def common(self, neighbour: Hashable) -> Density | None:
        """``bel_ij`` for ``neighbour`` (the initial common belief for a neighbour not seen yet)."""
        return self._common.get(neighbour, self.initial_common)

    def add_neighbour(self, neighbour: Hashable) -> None:
        """Open a channel (with the initial common belief) if there is none yet."""
        self._common.setdefault(neighbour, self.initial_common)

    def reset(self, neighbour: Hashable) -> None:
        """Back to the initial common belief (a neighbour that restarted and holds nothing of ours)."""
        self._common[neighbour] = self.initial_common

    def _store(self, belief: GaussianMixture, rng) -> GaussianMixture:
        if self.common_components is None or belief.k <= self.common_components:
            return belief
        if rng is None:
            raise ValueError("compressing the common belief needs a random generator (rng)")
        return belief.compressed(self.common_components, rng)

    def on_send(
        self, local: ParticleSet, neighbours: Iterable[Hashable] | None = None, rng: np.random.Generator | None = None,
        *, sent: GaussianMixture | None = None,
    ) -> None:
        """Record ``bel_ij ← bel_i`` (2.28) for the neighbours the set is sent to (default: every open
        channel). ``sent``: the belief as it went on the wire when that is not the set itself (a compressed
        mixture, what the neighbour will hold): recorded as it is. ``rng`` is needed only when
        ``common_components`` compresses the stored belief."""
        if not isinstance(local, ParticleSet):
            raise ValueError(f"local belief must be a ParticleSet, got {type(local).__name__}")
        if sent is not None and (not isinstance(sent, GaussianMixture) or sent.dim != local.dim):
            raise ValueError(f"the sent belief must be a {local.dim}-D GaussianMixture, got {sent!r}")
        targets = list(self._common) if neighbours is None else list(neighbours)
        if not targets:
            return
        belief = self._store(GaussianMixture.kde(local, self.bandwidth, self.shrink) if sent is None else sent, rng)
        for nb in targets:
            self._common[nb] = belief

    def on_receive(
        self,
        neighbour: Hashable,
        local: ParticleSet,
        received: ParticleSet,
        rng: np.random.Generator,
        method: str | None = None,
        alpha_local: float | None = None,
        received_belief: GaussianMixture | None = None,
        resample: bool = True,
    ) -> ParticleSet:
        """Fuse ``received`` from ``neighbour`` into ``local`` (Alg. 5.2 or Alg. 5.3) and record
        ``bel_ij ← bel_j`` (2.27). The record is updated whatever the method, so that a later Bayesian
        fusion divides by what the neighbour sent last. ``received_belief``: the neighbour's belief as a
        density when it came as one (a compressed mixture, ``received`` then samples of it): used as
        ``bel_j`` instead of the density estimate of ``received``. ``resample=False`` returns the weighted
        pool of both sets (e.g. to regularise it from its weighted moments before resampling)."""
        method = self.method if method is None else _method(method)
        _check_sets(local, received)
        if method == "bayes":
            result = fuse_bayes_detailed(
                local, received, self.common(neighbour), rng, bandwidth=self.bandwidth, shrink=self.shrink,
                received_belief=received_belief, resample=resample,
            )
            fused, bel_j = result.fused, result.received_belief
        else:
            a = self.alpha_local if alpha_local is None else alpha_local
            fused = fuse_lop(local, received, a, rng, resample=resample)
            bel_j = GaussianMixture.kde(received, self.bandwidth, self.shrink) if received_belief is None \
                else received_belief
        self._common[neighbour] = self._store(bel_j, rng)
        return fused


def _method(method) -> str:
    if method not in METHODS:
        raise ValueError(f"fusion method must be one of {METHODS}, got {method!r}")
    return method
