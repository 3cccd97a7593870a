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
centralized oracle and agents under ``flood``, which fuse no beliefs (see ``fusion.imm_window``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fusion import validation
from fusion.gaussian import Gaussian


@dataclass(frozen=True)
class ImmModel:
    """The motion models and their Markov switching matrix ``switch[i, j] = p_ij`` (rows sum to 1)."""

    motions: tuple
    switch: np.ndarray
    _terms: dict = field(default_factory=dict, init=False, repr=False, compare=False)  # dt -> terms(dt)

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

    def terms(self, dt: float) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
        """``(F_j, Q_j)`` of every mode over ``dt`` seconds, computed once per ``dt`` (a tracker predicts on one
        grid step)."""
        known = self._terms.get(dt)
        if known is None:
            known = self._terms[dt] = tuple((m.transition(dt), m.noise(dt)) for m in self.motions)
        return known

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
        for j, (F, Q) in enumerate(model.terms(dt)):
            x0, P0 = _moments(self.means, self.covs, weights[:, j])
            means.append(F @ x0)
            covs.append(_symmetric(F @ P0 @ F.T + Q))
        return ImmBelief(np.array(means), np.array(covs), c)

    def update(self, measurement, z) -> ImmBelief:
        """EKF update of every mode with one measurement (a ``fusion.measurement`` model with ``R``), and the
        mode probabilities by their innovation likelihoods (step 3 above)."""
        z = np.asarray(z, float)
        R = measurement.R
        terms = [measurement.linearize(x) for x in self.means]  # (z_hat_j, H_j): the geometry of each mode
        H = np.array([h for _, h in terms])  # (r, m, n); every mode at once below
        nu = np.array([measurement.residual(z, z_hat) for z_hat, _ in terms])  # (r, m)
        PHt = self.covs @ H.transpose(0, 2, 1)  # (r, n, m)
        S = _symmetric(H @ PHt + R)
        K = np.linalg.solve(S, PHt.transpose(0, 2, 1)).transpose(0, 2, 1)  # K_j = P_j H_j^T S_j^-1
        means = self.means + np.einsum("rnm,rm->rn", K, nu)
        A = np.eye(self.means.shape[1]) - K @ H
        covs = _symmetric(A @ self.covs @ A.transpose(0, 2, 1) + K @ R @ K.transpose(0, 2, 1))  # Joseph form
        _, logdet = np.linalg.slogdet(2.0 * np.pi * S)
        mahalanobis = np.einsum("rm,rm->r", nu, np.linalg.solve(S, nu[:, :, None])[:, :, 0])
        log_post = np.log(np.maximum(self.probs, 1e-300)) - 0.5 * (mahalanobis + logdet)
        probs = np.exp(log_post - log_post.max())
        return ImmBelief(means, covs, probs / probs.sum())

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
    """``(a + a^T) / 2`` of a matrix, or of each matrix of a stack."""
    return 0.5 * (a + np.swapaxes(a, -1, -2))
