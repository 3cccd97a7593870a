"""Interacting multiple model (IMM) filter in moment form (Blom & Bar-Shalom, 1988).

A target follows one of ``r`` linear motion models (``fusion.motion``) and switches between them as a
Markov chain, ``p_ij = P(mode j at k | mode i at k-1)``. One cycle (Bar-Shalom, Li & Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, §11.6.6):

1. **interaction** (11.6.6-6 to -9): ``c_j = sum_i p_ij mu_i``, ``mu_i|j = p_ij mu_i / c_j``,
   ``x0_j = sum_i mu_i|j x_i``, ``P0_j = sum_i mu_i|j (P_i + (x_i - x0_j)(x_i - x0_j)^T)``;
2. **mode-matched prediction**: ``x_j = F_j x0_j``, ``P_j = F_j P0_j F_j^T + Q_j``; the predicted mode
   probabilities are ``c_j``;
3. **mode-matched update** (extended Kalman filter for a nonlinear measurement) with likelihood
   ``Lambda_j = N(nu_j; 0, S_j)`` (11.6.6-10 to -12), then ``mu_j ∝ Lambda_j c_j`` (11.6.6-13 to -15);
4. **combination** (11.6.6-16 to -17): the moment-matched Gaussian of the mixture.

Several measurements of one time are applied one after the other (each multiplies the mode likelihoods):
given the mode they are independent, so this is the exact mode posterior.

A mixture is not a Gaussian in information form: two IMM beliefs cannot be fused by adding information, so
channel filters cannot remove common information from them exactly. The IMM therefore serves the
centralized oracle, which fuses nothing (see ``mesh_sim.imm_oracle``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion import validation
from fusion.gaussian import Gaussian


@dataclass(frozen=True)
class ImmModel:
    """The motion models and their Markov switching matrix ``switch[i, j] = p_ij`` (rows sum to 1)."""

    motions: tuple
    switch: np.ndarray

    def __post_init__(self):
        r = len(self.motions)
        if r < 1:
            raise ValueError("an IMM needs at least one motion model")
        dims = {m.dim for m in self.motions}
        if len(dims) != 1:
            raise ValueError(f"every IMM motion model must have the same state dimension, got {sorted(dims)}")
        switch = validation.shaped(self.switch, "IMM switching matrix", (r, r))
        if np.any(switch < 0) or not np.allclose(switch.sum(axis=1), 1.0):
            raise ValueError("the IMM switching matrix must be non-negative with rows summing to 1")
        object.__setattr__(self, "switch", switch)

    @property
    def dim(self) -> int:
        return self.motions[0].dim

    @classmethod
    def two_modes(cls, quiet, manoeuvre, stay: float) -> ImmModel:
        """A quiet and a manoeuvring model, each kept with probability ``stay`` per step."""
        if not 0.0 < stay <= 1.0:
            raise ValueError(f"the probability of staying in a mode must be in (0, 1], got {stay}")
        return cls((quiet, manoeuvre), np.array([[stay, 1.0 - stay], [1.0 - stay, stay]]))


@dataclass(frozen=True)
class ImmBelief:
    """Mode-conditioned means ``(r, n)``, covariances ``(r, n, n)`` and mode probabilities ``(r,)``."""

    means: np.ndarray
    covs: np.ndarray
    probs: np.ndarray

    @classmethod
    def start(cls, mean, cov, probs) -> ImmBelief:
        """Every mode starts from the same Gaussian ``N(mean, cov)`` with prior probabilities ``probs``."""
        mean = validation.as_vector(mean, "IMM initial mean")
        cov = validation.as_pd(cov, "IMM initial covariance", mean.size)
        probs = validation.as_vector(probs, "IMM mode probabilities")
        if np.any(probs < 0) or not np.isclose(probs.sum(), 1.0):
            raise ValueError(f"IMM mode probabilities must be non-negative and sum to 1, got {probs}")
        r = probs.size
        return cls(np.tile(mean, (r, 1)), np.tile(cov, (r, 1, 1)), probs)

    def predict(self, model: ImmModel, dt: float) -> ImmBelief:
        """Interaction then mode-matched prediction over ``dt`` seconds (steps 1-2 above)."""
        c = self.probs @ model.switch  # c_j = sum_i p_ij mu_i
        weights = model.switch * self.probs[:, None] / np.where(c > 0, c, 1.0)[None, :]  # mu_i|j in column j
        means, covs = [], []
        for j, motion in enumerate(model.motions):
            x0, P0 = _moments(self.means, self.covs, weights[:, j])
            F = motion.transition(dt)
            means.append(F @ x0)
            covs.append(_symmetric(F @ P0 @ F.T + motion.noise(dt)))
        return ImmBelief(np.array(means), np.array(covs), c)

    def update(self, measurement, z) -> ImmBelief:
        """EKF update of every mode with one measurement (a ``fusion.measurement`` model with ``R``), and the
        mode probabilities by their innovation likelihoods (step 3 above)."""
        z = np.asarray(z, float)
        means, covs, log_like = [], [], []
        for x, P in zip(self.means, self.covs, strict=True):
            z_hat, H = measurement.linearize(x)
            nu = measurement.residual(z, z_hat)
            S = _symmetric(H @ P @ H.T + measurement.R)
            PHt = P @ H.T
            K = np.linalg.solve(S, PHt.T).T
            means.append(x + K @ nu)
            A = np.eye(x.size) - K @ H
            covs.append(_symmetric(A @ P @ A.T + K @ measurement.R @ K.T))  # Joseph form
            _, logdet = np.linalg.slogdet(2.0 * np.pi * S)
            log_like.append(-0.5 * (float(nu @ np.linalg.solve(S, nu)) + logdet))
        log_post = np.log(np.maximum(self.probs, 1e-300)) + np.array(log_like)
        probs = np.exp(log_post - log_post.max())
        return ImmBelief(np.array(means), np.array(covs), probs / probs.sum())

    def combined(self) -> Gaussian:
        """The mixture's moment-matched Gaussian (step 4 above)."""
        return Gaussian.from_moments(*_moments(self.means, self.covs, self.probs))


def _moments(means: np.ndarray, covs: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of the mixture ``sum_i w_i N(means_i, covs_i)`` (weights summing to 1)."""
    mean = weights @ means
    spread = means - mean
    cov = np.einsum("i,ijk->jk", weights, covs) + (spread.T * weights) @ spread
    return mean, _symmetric(cov)


def _symmetric(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + a.T)
