"""Linear motion models ``x_t = F(dt) x_{t-1} + w``, ``w ~ N(0, Q(dt))``.

State ordering follows Merino (3.54): all positions, then all velocities (then all accelerations),
e.g. ``(x, y, z, vx, vy, vz)`` for a 3-D constant-velocity target.

* :class:`ConstantVelocity` — discretised white-noise acceleration, Merino (3.58)-(3.59).
* :class:`Static` — ``F = I``, ``Q = 0`` (Merino §3.2.1).
* :class:`Singer` — exponentially correlated acceleration (Singer, 1970), discretised exactly with
  Van Loan's matrix exponential (Van Loan, 1978), which also serves as the independent check of the
  constant-velocity closed form in the tests.
* :class:`DampedVelocity` — integrated Ornstein–Uhlenbeck velocity: a target whose speed stays bounded
  in distribution. Its stationary velocity distribution is a prior every node shares by construction.

A model may define ``stationary_information()``: the information matrix of its stationary distribution
on one state (zero along directions, such as position, that have none). Trajectory priors use it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg


@dataclass(frozen=True)
class ConstantVelocity:
    """White-noise acceleration with power spectral density ``q`` [m^2/s^3] per axis.

    ``F = [[I, dt I], [0, I]]`` (3.58) and ``Q = [[dt^3/3 D, dt^2/2 D], [dt^2/2 D, dt D]]`` (3.59) with
    ``D = q I`` — or, when ``vertical_q`` is given, ``D = diag(q, ..., q, vertical_q)``: a ground target
    accelerates freely on the ground but hardly up or down (the last axis is "down" in NED).
    """

    spatial_dims: int = 3
    q: float = 0.1  # chosen here: a walking-pace target (about 0.3 m/s of velocity change per sqrt(s))
    vertical_q: float | None = None

    def __post_init__(self):
        _check_positive(self.spatial_dims, "spatial_dims")
        for name in ("q", "vertical_q"):
            value = getattr(self, name)
            if value is not None and (not np.isfinite(value) or value < 0):
                raise ValueError(f"{name} must be a finite non-negative spectral density, got {value}")

    @property
    def dim(self) -> int:
        return 2 * self.spatial_dims

    def transition(self, dt: float) -> np.ndarray:
        return np.kron(np.array([[1.0, dt], [0.0, 1.0]]), np.eye(self.spatial_dims))

    def inverse_transition(self, dt: float) -> np.ndarray:
        return self.transition(-dt)

    def noise(self, dt: float) -> np.ndarray:
        _check_dt(dt)
        block = np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
        density = np.full(self.spatial_dims, float(self.q))
        if self.vertical_q is not None:
            density[-1] = self.vertical_q
        return np.kron(block, np.diag(density))


@dataclass(frozen=True)
class Static:
    """A state that does not move: ``F = I``, ``Q = 0`` (Merino §3.2.1)."""

    dim: int = 3

    def __post_init__(self):
        _check_positive(self.dim, "dim")

    def transition(self, dt: float) -> np.ndarray:
        return np.eye(self.dim)

    def inverse_transition(self, dt: float) -> np.ndarray:
        return np.eye(self.dim)

    def noise(self, dt: float) -> np.ndarray:
        return np.zeros((self.dim, self.dim))


@dataclass(frozen=True)
class Singer:
    """Singer manoeuvring model: per axis ``da/dt = -alpha a + w``, ``E[w w] = 2 alpha sigma_m^2``.

    ``alpha`` is the inverse manoeuvre time constant [1/s] and ``sigma_m`` the RMS acceleration
    [m/s^2]; both defaults are chosen here (a ground vehicle turning every ~10 s at ~1 m/s^2)."""

    spatial_dims: int = 3
    alpha: float = 0.1
    sigma_m: float = 1.0

    def __post_init__(self):
        _check_positive(self.spatial_dims, "spatial_dims")
        if not (np.isfinite(self.alpha) and self.alpha > 0):
            raise ValueError(f"alpha must be positive, got {self.alpha}")
        if not (np.isfinite(self.sigma_m) and self.sigma_m >= 0):
            raise ValueError(f"sigma_m must be non-negative, got {self.sigma_m}")

    @property
    def dim(self) -> int:
        return 3 * self.spatial_dims

    def _continuous(self) -> tuple[np.ndarray, np.ndarray]:
        A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -self.alpha]])
        Qc = np.zeros((3, 3))
        Qc[2, 2] = 2.0 * self.alpha * self.sigma_m**2
        return A, Qc

    def transition(self, dt: float) -> np.ndarray:
        A, _ = self._continuous()
        return np.kron(scipy.linalg.expm(A * dt), np.eye(self.spatial_dims))

    def inverse_transition(self, dt: float) -> np.ndarray:
        return self.transition(-dt)

    def noise(self, dt: float) -> np.ndarray:
        _check_dt(dt)
        A, Qc = self._continuous()
        _, Q1 = van_loan(A, Qc, dt)
        return np.kron(Q1, np.eye(self.spatial_dims))


@dataclass(frozen=True)
class DampedVelocity:
    """Integrated Ornstein–Uhlenbeck velocity per axis: ``dp = v dt``, ``dv = -v / tau dt + s dW``.

    The velocity is stationary with variance ``speed_std^2`` (so ``s^2 = 2 speed_std^2 / tau``); the
    position is a random walk with no stationary distribution. ``vertical_speed_std`` (last axis, "down"
    in NED) lets ground targets hardly climb. Discretised exactly with Van Loan's method. Defaults are
    chosen here: ground vehicles up to ~10 m/s, changing velocity over ~10 s."""

    spatial_dims: int = 3
    speed_std: float = 5.0  # stationary horizontal velocity standard deviation [m/s]
    tau: float = 10.0  # velocity correlation time [s]
    vertical_speed_std: float | None = None

    def __post_init__(self):
        _check_positive(self.spatial_dims, "spatial_dims")
        for name in ("speed_std", "tau", "vertical_speed_std"):
            value = getattr(self, name)
            if value is not None and not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")

    @property
    def dim(self) -> int:
        return 2 * self.spatial_dims

    def _axis_stds(self) -> np.ndarray:
        stds = np.full(self.spatial_dims, float(self.speed_std))
        if self.vertical_speed_std is not None:
            stds[-1] = self.vertical_speed_std
        return stds

    def _discrete(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        _check_dt(dt)
        A = np.array([[0.0, 1.0], [0.0, -1.0 / self.tau]])
        F = np.zeros((self.dim, self.dim))
        Q = np.zeros((self.dim, self.dim))
        d = self.spatial_dims
        for axis, std in enumerate(self._axis_stds()):
            F1, Q1 = van_loan(A, np.diag([0.0, 2.0 * std**2 / self.tau]), dt)
            idx = [axis, d + axis]
            F[np.ix_(idx, idx)] = F1
            Q[np.ix_(idx, idx)] = Q1
        return F, Q

    def transition(self, dt: float) -> np.ndarray:
        return self._discrete(dt)[0]

    def inverse_transition(self, dt: float) -> np.ndarray:
        return np.linalg.inv(self.transition(dt))

    def noise(self, dt: float) -> np.ndarray:
        return self._discrete(dt)[1]

    def stationary_information(self) -> np.ndarray:
        """``diag(0 (positions), 1 / speed_std^2 (velocities))``: what every node knows before any data."""
        d = self.spatial_dims
        info = np.zeros((self.dim, self.dim))
        info[d:, d:] = np.diag(1.0 / self._axis_stds() ** 2)
        return info


def van_loan(A: np.ndarray, Qc: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact discretisation of ``dx = A x dt + dW``, ``E[dW dW^T] = Qc dt`` (Van Loan, 1978).

    ``expm([[-A, Qc], [0, A^T]] dt) = [[., F^-1 Q], [0, F^T]]``, hence ``F`` and ``Q``.

    The block exponential contains ``expm(-A dt)``, which grows like ``e^{alpha dt}`` for a decaying
    mode (Singer), and ``Q = F (F^-1 Q)`` then cancels catastrophically (garbage, even an indefinite
    ``Q``, from ``alpha dt ~ 20``). So the block formula is applied only over ``h = dt / 2^k`` with
    ``||A|| h <= 1``, and the step is doubled ``k`` times: ``Q(2h) = F(h) Q(h) F(h)^T + Q(h)``,
    ``F(2h) = F(h)^2`` (exact, and a sum of PSD terms)."""
    n = A.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -A
    M[:n, n:] = Qc
    M[n:, n:] = A.T
    span = float(np.linalg.norm(A, 1)) * abs(dt)
    k = int(np.ceil(np.log2(span))) if span > 1.0 else 0
    E = scipy.linalg.expm(M * (dt / 2**k))
    F = E[n:, n:].T
    Q = F @ E[:n, n:]
    for _ in range(k):
        Q = F @ Q @ F.T + Q
        F = F @ F
    return F, 0.5 * (Q + Q.T)


def _check_positive(value: int, name: str) -> None:
    if int(value) != value or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value}")


def _check_dt(dt: float) -> None:
    if not np.isfinite(dt) or dt < 0:
        raise ValueError(f"time step must be finite and non-negative, got {dt}")
