"""Which of a peer's particle candidates is which of ours: candidate ids are local, so beliefs are matched
by where they put their mass (as :mod:`agent.beliefs.assignment` matches tracks by position).

Gate: the squared Mahalanobis distance of the two means under the sum of the covariances, Merino (3.65)
(the track-to-track test of :mod:`agent.beliefs.tracking`, here on the moments of a particle set and of a
mixture), at most ``gate``. Score of a gated pair: the log of the overlap ``∫ bel_i bel_j``, estimated on
our particles as ``log Σ_k w_k bel_j(x^(k))`` (the predictive likelihood the initiator uses for a bearing,
Merino (5.33)-(5.34)). Pairs are taken best score first, each candidate at most once; a peer's candidate
keeps its match (``labels``) while that pair still passes the gate.

**Ambiguity** (chosen here): two look-alike targets seen from nearly one plane give two rays of a peer that
both cross one ray of ours — at the target and at a ghost — with about the same overlap. Fusing either would
make a compact belief, wrong half of the time, that the agent's own bearings (all on its ray) never refute.
So a pair is fused only if its overlap beats every other gated pair of either candidate by ``AMBIGUITY``
(a likelihood ratio); otherwise both wait until their own bearings or a third agent's set them apart.
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from fusion.mixture import GaussianMixture
from fusion.particles import ParticleSet

TRACK_GATE = 16.27  # chi-square(3) 99.9 %: the tracker's track-to-track gate (TrackerConfig.track_gate)
AMBIGUITY = 10.0  # overlap ratio of the best pair to any rival pair needed to fuse it (chosen here)


def gate_distance(local: ParticleSet, remote: GaussianMixture) -> float:
    """``(μ_i - μ_j)ᵀ (Σ_i + Σ_j)⁻¹ (μ_i - μ_j)`` on the two beliefs' moments."""
    d = local.mean() - remote.mean()
    return float(d @ np.linalg.solve(local.cov() + remote.cov(), d))


def overlap(local: ParticleSet, remote: GaussianMixture) -> float:
    """``log Σ_k w_k bel_j(x^(k))``, the Monte Carlo estimate of ``log ∫ bel_i bel_j``."""
    with np.errstate(divide="ignore"):
        return float(logsumexp(np.log(local.weights) + remote.logpdf(local.states)))


def match(local: dict[int, ParticleSet], remote: dict[int, GaussianMixture], labels: dict[int, int],
          gate: float = TRACK_GATE) -> dict[int, int]:
    """Remote id -> local id for every remote candidate that matches one of ours (``labels``: the previous
    matches, remote id -> local id, kept when they still pass the gate)."""
    out: dict[int, int] = {}
    for rid, lid in labels.items():
        if rid in remote and lid in local and lid not in out.values() and \
                gate_distance(local[lid], remote[rid]) <= gate:
            out[rid] = lid
    pairs = []
    for rid, mixture in remote.items():
        if rid in out:
            continue
        for lid, particles in local.items():
            if lid not in out.values() and gate_distance(particles, mixture) <= gate:
                pairs.append((overlap(particles, mixture), rid, lid))
    margin = np.log(AMBIGUITY)
    for score, rid, lid in sorted(pairs, reverse=True):
        rivals = [s for s, r, lo in pairs if (r == rid) != (lo == lid)]
        if rid not in out and lid not in out.values() and all(score - s >= margin for s in rivals):
            out[rid] = lid
    return out
