"""Gaussian beliefs in information (canonical) form.

A Gaussian ``N(mu, P)`` is stored as the information vector ``y = P^-1 mu`` and information matrix
``Y = P^-1`` (Merino (3.7)-(3.9)). Zero information (``Y = 0``) is a legal belief: it says that nothing
is known yet, which is how every decentralized filter starts (Merino Alg. 3.4, line 1).

The belief algebra of DESIGN.md §2:

* ``fuse``      ``(y_a + y_b, Y_a + Y_b)``                independent evidence (Merino (3.34)-(3.35))
* ``remove``    ``(y_a - y_c, Y_a - Y_c)``                common information (Merino (3.36))
* ``intersect`` ``(w y_a + (1-w) y_b, w Y_a + (1-w) Y_b)`` covariance intersection (Merino (3.43)-(3.44))
* ``predict``   information-filter prediction            (Merino Alg. 3.2, lines 1-3)

Gaussians are immutable: every operation returns a new belief.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fusion import lapack, validation

_sum = np.add.reduce  # without ndarray.sum's Python wrapper: it runs on every predict and update


class UninformativeBeliefError(ValueError):
    """The belief has no (or not enough) information to define a mean or a covariance."""


class Gaussian:
    """A Gaussian belief ``(y, Y)`` in information form. Construct with :meth:`from_moments`,
    :meth:`from_info` or :meth:`zeros`; the constructor itself trusts its arguments."""

    __slots__ = ("y", "Y", "_mean", "_cov", "_factor")
    epoch = None  # a timeless belief: it never needs aligning before the algebra (see ChannelFilter)

    def __init__(self, y: np.ndarray, Y: np.ndarray):
        self.y = y
        self.Y = Y
        self._mean = self._cov = None  # the moments, computed once (a belief is immutable): copies are handed out
        self._factor = None  # the Cholesky factor of Y, shared by the mean and the covariance

    # -- construction ---------------------------------------------------------------------------
    @classmethod
    def from_moments(cls, mean, cov) -> Gaussian:
        """From a mean and a positive-definite covariance: ``Y = P^-1``, ``y = P^-1 mu`` (3.7)-(3.8)."""
        mean = validation.as_vector(mean, "mean")
        cov = validation.as_pd(cov, "covariance", mean.shape[0])
        Y = lapack.spd_inverse(cov)
        return cls(Y @ mean, Y)

    @classmethod
    def from_info(cls, y, Y) -> Gaussian:
        """From an information vector and a symmetric positive semi-definite information matrix."""
        y = validation.as_vector(y, "information vector")
        Y = validation.as_psd(Y, "information matrix", y.shape[0])
        return cls(y, Y)

    @classmethod
    def zeros(cls, dim: int) -> Gaussian:
        """The belief that carries no information (Merino Alg. 3.4: ``Omega_0 = 0, xi_0 = 0``)."""
        if dim < 1:
            raise ValueError(f"dimension must be positive, got {dim}")
        return cls(np.zeros(dim), np.zeros((dim, dim)))

    # -- moments ----------------------------------------------------------------------------------
    @property
    def dim(self) -> int:
        return self.y.shape[0]

    @property
    def has_information(self) -> bool:
        return bool(np.any(self.Y))

    @property
    def mean(self) -> np.ndarray:
        """``mu = Y^-1 y``; raises :class:`UninformativeBeliefError` if ``Y`` is singular."""
        if self._mean is None:
            self._mean = self._solve(self.y)
        return self._mean.copy()

    @property
    def cov(self) -> np.ndarray:
        """``P = Y^-1``; raises :class:`UninformativeBeliefError` if ``Y`` is singular."""
        if self._cov is None:
            P = self._solve(np.eye(self.dim))
            self._cov = 0.5 * (P + P.T)
        return self._cov.copy()

    def _solve(self, rhs: np.ndarray) -> np.ndarray:
        """``Y^-1 rhs`` by Cholesky (:mod:`fusion.lapack`: scipy's wrappers cost ten times more than the
        arithmetic on a 6x6 matrix)."""
        if self._factor is None:
            self._factor = lapack.cholesky(self.Y)
        factor = self._factor
        if factor is None:
            if not self.has_information:
                raise UninformativeBeliefError("the belief has no information yet: mean and covariance are undefined")
            raise UninformativeBeliefError(
                "the information matrix is singular: some direction of the state is unobserved"
            )
        return lapack.cholesky_solve(factor, rhs)

    # -- the belief algebra -----------------------------------------------------------------------
    def fuse(self, other: Gaussian) -> Gaussian:
        """Add independent evidence: ``(y_a + y_b, Y_a + Y_b)`` (Merino (3.34)-(3.35))."""
        self._check_compatible(other)
        return Gaussian(self.y + other.y, self.Y + other.Y)

    def remove(self, common: Gaussian) -> Gaussian:
        """Remove common information: ``(y_a - y_c, Y_a - Y_c)`` (Merino (3.36)).

        Raises ``ValueError`` if the result is not positive semi-definite, i.e. if ``common`` holds
        information that this belief does not."""
        self._check_compatible(common)
        Y = self.Y - common.Y
        if not validation.is_psd(Y):
            raise ValueError("removing more information than the belief holds (result is indefinite)")
        return Gaussian(self.y - common.y, Y)

    def intersect(self, other: Gaussian, omega: float) -> Gaussian:
        """Covariance intersection with weight ``omega`` on this belief (Merino (3.43)-(3.44))."""
        self._check_compatible(other)
        if not 0.0 <= omega <= 1.0:
            raise ValueError(f"omega must lie in [0, 1], got {omega}")
        return Gaussian(omega * self.y + (1.0 - omega) * other.y, omega * self.Y + (1.0 - omega) * other.Y)

    def scaled(self, weight: float) -> Gaussian:
        """The belief raised to a power: ``(w y, w Y)`` (one term of a weighted exponential product)."""
        return Gaussian(weight * self.y, weight * self.Y)

    def with_information(self, y: np.ndarray, Y: np.ndarray) -> Gaussian:
        """A belief of the same kind carrying ``(y, Y)`` (for rules such as inverse covariance intersection that
        compute the information pair themselves); trusted, like the constructor."""
        return Gaussian(y, Y)

    def predict(self, F: np.ndarray, Q: np.ndarray, F_inv: np.ndarray | None = None) -> Gaussian:
        """Information-filter prediction through ``x' = F x + w``, ``w ~ N(0, Q)`` (Merino Alg. 3.2).

        With ``Psi = F^-T Y F^-1`` (3.11), Merino's (3.12) ``Psi - Psi (Q^-1 + Psi)^-1 Psi`` equals
        ``(I + Psi Q)^-1 Psi``, and (3.13) equals ``(I + Psi Q)^-1 F^-T y``. This form needs neither
        ``Q`` nor ``Y`` to be invertible, so zero information and a static model (``Q = 0``) work."""
        n = self.dim
        F = validation.shaped(F, "transition matrix F", (n, n))
        Q = validation.shaped(Q, "process noise Q", (n, n))
        if F_inv is None:
            F_inv = np.linalg.inv(F)
        else:
            F_inv = validation.shaped(F_inv, "inverse transition", (n, n))
            if not math.isfinite(float(F.sum())):  # F itself is not used below: check it here
                raise ValueError("non-finite result of the prediction (F contains NaN or inf)")
        psi = F_inv.T @ self.Y @ F_inv
        gain = psi @ Q
        gain.flat[:: n + 1] += 1.0
        rhs = np.concatenate([psi, (F_inv.T @ self.y)[:, None]], axis=1)
        sol = np.linalg.solve(gain, rhs)
        if not math.isfinite(float(_sum(sol, axis=None))):  # y and Y in one reduction
            raise ValueError("non-finite result of the prediction (F, F^-1 or Q contains NaN or inf)")
        Y = sol[:, :-1]
        return Gaussian(sol[:, -1], 0.5 * (Y + Y.T))

    def update(self, H: np.ndarray, R_inv: np.ndarray, z: np.ndarray) -> Gaussian:
        """Linear measurement update ``Y + H^T R^-1 H``, ``y + H^T R^-1 z`` (Merino (3.17)-(3.18))."""
        H = validation.shaped(H, "measurement matrix H", (None, self.dim))
        m = H.shape[0]
        R_inv = validation.shaped(R_inv, "inverse measurement noise R^-1", (m, m))
        z = validation.shaped(z, "measurement z", (m,))
        # Both increments in one product, [H^T R^-1 H | H^T R^-1 z], checked in one reduction: a NaN or inf
        # in H, R^-1 or z propagates into its sum.
        increment = H.T @ R_inv @ np.concatenate([H, z[:, None]], axis=1)
        if not math.isfinite(float(_sum(increment, axis=None))):
            raise ValueError("non-finite result of the update (H, R^-1 or the measurement z contains NaN or inf)")
        return Gaussian(self.y + increment[:, -1], self.Y + increment[:, :-1])

    # -- marginals, conditionals, divergences -----------------------------------------------------
    def marginal(self, keep: Sequence[int]) -> Gaussian:
        """Marginal over ``keep`` in information form (Merino App. A):
        ``Y_aa - Y_ab Y_bb^-1 Y_ba``, ``y_a - Y_ab Y_bb^-1 y_b``."""
        a, b = self._split(keep)
        if b.size == 0:
            return Gaussian(self.y[a].copy(), self.Y[np.ix_(a, a)].copy())
        Y_ab = self.Y[np.ix_(a, b)]
        Y_bb = self.Y[np.ix_(b, b)]
        try:
            sol = np.linalg.solve(Y_bb, np.concatenate([Y_ab.T, self.y[b][:, None]], axis=1))
        except np.linalg.LinAlgError:
            raise UninformativeBeliefError(
                "cannot marginalise: the information on the removed variables is singular"
            ) from None
        Y = self.Y[np.ix_(a, a)] - Y_ab @ sol[:, :-1]
        return Gaussian(self.y[a] - Y_ab @ sol[:, -1], 0.5 * (Y + Y.T))

    def condition(self, keep: Sequence[int], values) -> Gaussian:
        """Conditional of ``x_keep`` given the other variables equal ``values`` (Merino App. A):
        ``Y_{a|b} = Y_aa``, ``y_{a|b} = y_a - Y_ab b``. (The thesis's table prints ``+``; the
        sign is corrected here: from ``-1/2 x^T Y x + x^T y`` the cross term contributes ``-Y_ab b``.)"""
        a, b = self._split(keep)
        values = validation.as_vector(values, "conditioning values", b.size)
        return Gaussian(self.y[a] - self.Y[np.ix_(a, b)] @ values, self.Y[np.ix_(a, a)].copy())

    def kl_divergence(self, other: Gaussian) -> float:
        """``D_KL(self || other)`` (Merino (A.6)):
        ``1/2 [tr(P_q^-1 P_p) + log|P_q| - log|P_p| + (mu_q - mu_p)^T P_q^-1 (mu_q - mu_p) - N]``."""
        self._check_compatible(other)
        P_p = self.cov
        d = other.mean - self.mean
        _, logdet_Yq = np.linalg.slogdet(other.Y)
        _, logdet_Yp = np.linalg.slogdet(self.Y)
        quad = float(d @ other.Y @ d)
        return 0.5 * (float(np.trace(other.Y @ P_p)) - logdet_Yq + logdet_Yp + quad - self.dim)

    def nees(self, truth) -> float:
        """Normalised estimation error squared ``(x - mu)^T P^-1 (x - mu)`` against a true state."""
        err = validation.as_vector(truth, "true state", self.dim) - self.mean
        return float(err @ self.Y @ err)

    # -- helpers ----------------------------------------------------------------------------------
    def advanced_to(self, epoch) -> Gaussian:
        """A timeless belief is the same at every epoch (see ``fusion.channel_filter``)."""
        return self

    def _split(self, keep: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        a = np.asarray(keep, dtype=int)
        if a.ndim != 1 or a.size == 0 or np.any(a < 0) or np.any(a >= self.dim) or np.unique(a).size != a.size:
            raise ValueError(f"indices {list(keep)} are not distinct indices of a {self.dim}-D state")
        return a, np.setdiff1d(np.arange(self.dim), a)

    def _check_compatible(self, other) -> None:
        if not isinstance(other, Gaussian):
            raise ValueError(f"expected a Gaussian, got {type(other).__name__}")
        if other.dim != self.dim:
            raise ValueError(f"dimension mismatch: {self.dim} vs {other.dim}")

    def allclose(self, other: Gaussian, rtol: float = 1e-9, atol: float = 0.0) -> bool:
        return np.allclose(self.y, other.y, rtol=rtol, atol=atol) and np.allclose(
            self.Y, other.Y, rtol=rtol, atol=atol
        )

    def __repr__(self) -> str:
        return f"Gaussian(dim={self.dim}, trace(Y)={np.trace(self.Y):.4g})"
