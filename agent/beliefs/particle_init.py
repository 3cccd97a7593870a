"""Tracks that start as particles: a single ray is a banana, not an ellipse (Merino §5.3).

With ``[tracking] initiation = "particles"`` a detection outside every track's gate does not start a
track at the ground point of its ray (which needs the terrain, and a target on it). It starts a
*candidate*: a particle set spread along the viewing ray, the back-projection prior of Merino Alg. 5.4
with the bearing's own uncertainty in place of the pose sampling — directions drawn from ``N(azel, R)``,
ranges uniform in ``[depth_min, depth_max]``. Later unassociated bearings update the candidate they are
most likely under (the maximum-likelihood association of Merino (5.33)-(5.34), gated), by the SIR step
of §5.3.3 (:func:`fusion.particles.sir_update`: reweight, resample below ``N_eff < 0.3 N``, regularised
jitter). The bearing likelihood is ``exp(-d²/2)`` with ``d²`` the Mahalanobis distance of the predicted
azimuth/elevation (the camera model (5.31) expressed on the bearing, whose covariance already carries
the pixel and attitude noise).

Hand-over: once the set is one compact, Gaussian-like cloud (:meth:`fusion.particles.ParticleSet.is_unimodal`)
and its position standard deviation is below ``handover_std``, its moment-matched Gaussian becomes the
first position measurement of a trajectory track (Merino's suggestion of handing a converged particle
belief to the information filter), which is then shared and fused like any other. A candidate that has
not converged within ``candidate_lifetime`` seconds of its last update is dropped. With ``exchange = true``
the candidates are also shared with the neighbours and fused with theirs (:mod:`agent.beliefs.particles`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent.sensors.bearing import Bearing
from fusion.gaussian import Gaussian
from fusion.particles import ParticleSet, sir_update

MAX_CANDIDATES = 32  # candidates kept at once (chosen here: bounds the work under heavy clutter)
TELEMETRY_POINTS = 64  # particles per candidate in the telemetry, for the ground station (chosen here)


@dataclass(frozen=True)
class ParticleInitConfig:
    particles: int = 400  # per candidate (chosen here; Merino uses 200-500)
    depth_min: float = 5.0  # m, Alg. 5.4 d_min (chosen here)
    depth_max: float = 300.0  # m, Alg. 5.4 d_max (chosen here: beyond a small camera's detection range)
    gate: float = 9.0  # d² of the best particle for a bearing to update a candidate (Merino's (3.64) threshold)
    handover_std: float = 5.0  # m: largest position standard deviation handed over (chosen here)
    candidate_lifetime: float = 5.0  # s without an update before a candidate is dropped (chosen here)
    exchange: bool = False  # share candidates with the neighbours (agent.beliefs.particles, Merino §5.2)
    components: int = 6  # mixture components per shared candidate (chosen here: 480 bytes of numbers)
    exchange_period: float = 1.0  # s between candidate messages (chosen here: the track sending period)

    def __post_init__(self):
        if isinstance(self.particles, bool) or not isinstance(self.particles, int) or self.particles < 50:
            raise ValueError(f"tracking.particles must be an integer >= 50, got {self.particles!r}")
        if not (0.0 < self.depth_min < self.depth_max and np.isfinite(self.depth_max)):
            raise ValueError(f"need 0 < depth_min < depth_max, got {self.depth_min}, {self.depth_max}")
        if not isinstance(self.exchange, bool):
            raise ValueError(f"tracking.particle_init.exchange must be true or false, got {self.exchange!r}")
        if isinstance(self.components, bool) or not isinstance(self.components, int) or not 1 <= self.components <= 64:
            raise ValueError(f"tracking.particle_init.components must be an integer in 1..64, got {self.components!r}")
        for name in ("gate", "handover_std", "candidate_lifetime", "exchange_period"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"tracking.{name} must be positive, got {value!r}")


def bearing_mahalanobis(points: np.ndarray, bearing: Bearing) -> np.ndarray:
    """``d²`` of each point's azimuth/elevation seen from the bearing's sensor (azimuth wrapped)."""
    d = np.asarray(points, float) - bearing.sensor
    az = np.arctan2(d[:, 1], d[:, 0])
    el = np.arctan2(-d[:, 2], np.hypot(d[:, 0], d[:, 1]))
    r = np.stack([(bearing.azel[0] - az + np.pi) % (2 * np.pi) - np.pi, bearing.azel[1] - el], axis=1)
    return np.einsum("ni,ij,nj->n", r, np.linalg.inv(bearing.R), r)


def back_projection(bearing: Bearing, n: int, depth_min: float, depth_max: float,
                    rng: np.random.Generator) -> ParticleSet:
    """Merino Alg. 5.4 on a bearing: directions from ``N(azel, R)``, ranges uniform in the depth bounds."""
    azel = rng.multivariate_normal(bearing.azel, bearing.R, size=n)
    az, el = azel[:, 0], azel[:, 1]
    los = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)], axis=1)
    depth = rng.uniform(depth_min, depth_max, size=n)
    return ParticleSet.from_states(bearing.sensor + depth[:, None] * los)


@dataclass
class Candidate:
    id: int  # local: peers match candidates by their beliefs, not by id (agent.beliefs.particle_match)
    particles: ParticleSet
    last_update: float
    hits: int
    truth_id: str | None


@dataclass(frozen=True)
class Handover:
    position: Gaussian  # 3-D (north, east, down)
    hits: int
    last_measured: float
    truth_id: str | None


class ParticleInitiator:
    def __init__(self, config: ParticleInitConfig, seed: int):
        self.config = config
        self.rng = np.random.default_rng(seed)
        self._display_rng = np.random.default_rng(seed + 1)  # the telemetry's draws never shift the filter's
        self.candidates: list[Candidate] = []
        self.started = 0
        self.handed_over = 0
        self.expired = 0

    def offer(self, bearing: Bearing) -> None:
        """An unassociated bearing: update the candidate it is most likely under, or start one."""
        best, best_ll = None, -np.inf
        for candidate in self.candidates:
            d2 = bearing_mahalanobis(candidate.particles.states, bearing)
            if d2.min() > self.config.gate:
                continue
            predictive = np.log(np.sum(candidate.particles.weights * np.exp(-0.5 * (d2 - d2.min())))) - 0.5 * d2.min()
            if predictive > best_ll:
                best, best_ll = (candidate, d2), predictive
        if best is not None:
            candidate, d2 = best
            candidate.particles = sir_update(candidate.particles, -0.5 * d2, self.rng).particles
            candidate.last_update = max(candidate.last_update, bearing.t)
            candidate.hits += 1
            return
        if len(self.candidates) < MAX_CANDIDATES:
            c = self.config
            self.candidates.append(Candidate(self.started, back_projection(bearing, c.particles, c.depth_min,
                                                                           c.depth_max, self.rng),
                                             bearing.t, 1, bearing.truth_id))
            self.started += 1

    def ready(self, t: float) -> list[Handover]:
        """Candidates that converged (removed and returned) — expired ones are dropped."""
        out, keep = [], []
        for candidate in self.candidates:
            if self.converged(candidate.particles):
                out.append(Handover(candidate.particles.to_gaussian(), candidate.hits, candidate.last_update,
                                    candidate.truth_id))
            elif t - candidate.last_update > self.config.candidate_lifetime:
                self.expired += 1
            else:
                keep.append(candidate)
        self.candidates = keep
        self.handed_over += len(out)
        return out

    def converged(self, particles: ParticleSet) -> bool:
        if not particles.is_unimodal():
            return False
        return float(np.sqrt(np.max(np.linalg.eigvalsh(particles.cov())))) <= self.config.handover_std

    def points(self) -> np.ndarray:
        """Up to ``TELEMETRY_POINTS`` particles of every candidate, (k, 3), for the ground station."""
        chunks = [c.particles.resampled(self._display_rng, TELEMETRY_POINTS).states for c in self.candidates]
        return np.concatenate(chunks).astype(np.float32) if chunks else np.zeros((0, 3), np.float32)

    def metrics(self) -> dict:
        return {"candidates": len(self.candidates), "started": self.started, "handed_over": self.handed_over,
                "expired": self.expired}
