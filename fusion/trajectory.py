"""Trajectory beliefs: the delayed-state information filter over a sliding window.

Merino §3.1.3 (Alg. 3.3) and §3.2.2: for a moving target, fusing filtered marginals is only
approximate because prediction is not linear in information form (Merino (2.22)). Keeping the joint
belief over the last ``window`` states makes prediction *additive*: advancing appends a state and adds
the process factor ``(I; -F^T) Q^-1 (I, -F)`` on the last two states (Merino (3.27)), a term that every
node adds identically. Channel filters over trajectories are therefore exact on trees (Merino
(3.41)-(3.42)).

States live on a uniform time grid ``t_k = k * step``; a belief's ``epoch`` is the index ``k`` of its
newest state. A belief always spans exactly ``window`` states (oldest first). The oldest state is
marginalised out with the Schur complement as the window slides (Merino (3.31)-(3.32)).

The prior of every trajectory is the *chain*: the process factors between consecutive states plus,
on the oldest state, the motion model's stationary information (``stationary_information()``; zero for
a constant-velocity model, the stationary velocity distribution for ``DampedVelocity``). Sliding the
window maps that chain onto itself — marginalising ``x_0`` leaves on ``x_1`` exactly the stationary
information again (nothing for constant velocity) — so two nodes that created a track at different
times still share exactly the same prior: the common information a channel filter starts from.

Measurements may update any state inside the window (``offset`` steps before the newest), so late
data are applied at the time they were taken, not as if current.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from fusion import lapack, validation
from fusion.covariance_intersection import fast_weights, optimal_weights
from fusion.gaussian import Gaussian, UninformativeBeliefError
from fusion.inverse_covariance_intersection import ici
from fusion.pair_weights import ici_weight


def grid_epoch(t: float, step: float) -> int:
    """The index of the newest time ``k * step`` not after ``t`` (1e-9 steps of slack for float rounding)."""
    return int(np.floor(t / step + 1e-9))


@dataclass(frozen=True)
class TrajectoryModel:
    """The grid (``step`` seconds), the window length and the motion model shared by a fleet."""

    motion: object
    step: float
    window: int = 10  # chosen here: 10 states; with 1 s steps this is half Merino's 20 s window

    F: np.ndarray = field(init=False, repr=False, compare=False)
    factor: np.ndarray = field(init=False, repr=False, compare=False)
    stationary: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        if not (np.isfinite(self.step) and self.step > 0):
            raise ValueError(f"step must be a positive number of seconds, got {self.step}")
        if int(self.window) != self.window or self.window < 2:
            raise ValueError(f"window must be an integer of at least 2 states, got {self.window}")
        F = self.motion.transition(self.step)
        Q = self.motion.noise(self.step)
        try:
            Q_inv = np.linalg.inv(validation.as_pd(Q, "process noise Q"))
        except ValueError:
            raise ValueError("a trajectory needs a motion model with positive-definite process noise") from None
        # Process factor on (x_{k-1}, x_k): -1/2 (x_k - F x_{k-1})^T Q^-1 (x_k - F x_{k-1}) (Merino (3.27)).
        upper = np.hstack([F.T @ Q_inv @ F, -F.T @ Q_inv])
        lower = np.hstack([-Q_inv @ F, Q_inv])
        object.__setattr__(self, "F", F)
        object.__setattr__(self, "factor", np.vstack([upper, lower]))
        stationary = getattr(self.motion, "stationary_information", None)
        object.__setattr__(self, "stationary", np.zeros_like(F) if stationary is None else stationary())

    @property
    def state_dim(self) -> int:
        return self.F.shape[0]

    @property
    def dim(self) -> int:
        return self.state_dim * self.window

    def epoch_of(self, t: float) -> int:
        return grid_epoch(t, self.step)


class Trajectory:
    """A Gaussian over the last ``model.window`` states in information form (oldest state first)."""

    __slots__ = ("y", "Y", "epoch", "model", "_states")

    def __init__(self, y: np.ndarray, Y: np.ndarray, epoch: int, model: TrajectoryModel):
        self.y = y
        self.Y = Y
        self.epoch = epoch
        self.model = model
        self._states: dict[int, Gaussian] = {}  # offset -> marginal, computed once: a belief is never changed

    @classmethod
    def prior(cls, model: TrajectoryModel, epoch: int) -> Trajectory:
        """The prior chain: the stationary information on the oldest state and the process factors
        (see the module docstring)."""
        n, L = model.state_dim, model.window
        Y = np.zeros((n * L, n * L))
        Y[:n, :n] = model.stationary
        for k in range(L - 1):
            Y[k * n : (k + 2) * n, k * n : (k + 2) * n] += model.factor
        return cls(np.zeros(n * L), Y, int(epoch), model)

    @classmethod
    def from_info(cls, y, Y, epoch: int, model: TrajectoryModel) -> Trajectory:
        """A validated trajectory belief (e.g. one decoded from the wire)."""
        y = validation.as_vector(y, "trajectory information vector", model.dim)
        Y = validation.as_psd(Y, "trajectory information matrix", model.dim)
        return cls(y, Y, int(epoch), model)

    @property
    def oldest(self) -> int:
        """The oldest epoch of the window (a measurement may be applied at any epoch ``oldest .. epoch``)."""
        return self.epoch - self.model.window + 1

    # -- time ------------------------------------------------------------------------------------
    def advanced_to(self, epoch: int) -> Trajectory:
        """Append states up to grid index ``epoch``, marginalising the oldest ones (Merino (3.27), (3.31)-(3.32))."""
        if epoch < self.epoch:
            raise ValueError(f"cannot advance a trajectory backwards (from epoch {self.epoch} to {epoch})")
        y, Y = self.y, self.Y
        n = self.model.state_dim
        for _ in range(epoch - self.epoch):
            y, Y = _slide(y, Y, n, self.model.factor)
        return Trajectory(y, Y, int(epoch), self.model)

    # -- measurements ----------------------------------------------------------------------------
    def update(self, H: np.ndarray, R_inv: np.ndarray, z, offset: int = 0) -> Trajectory:
        """Linear update of the state ``offset`` steps before the newest (Merino (3.29)-(3.30))."""
        block = self._block(offset)
        H, R_inv, z = validation.measurement_terms(H, R_inv, z, self.model.state_dim)
        HtRi = H.T @ R_inv
        y, Y = self.y.copy(), self.Y.copy()
        y[block] += HtRi @ z
        Y[block, block] += HtRi @ H
        return Trajectory(y, Y, self.epoch, self.model)

    def add_information(self, offsets, infos: np.ndarray, vectors: np.ndarray) -> Trajectory:
        """Several measurements at once, each on the state ``offsets[j]`` steps before the newest: ``Y_kk +=
        I_j``, ``y_k += i_j`` with ``I_j = H_j^T R_j^-1 H_j`` and ``i_j = H_j^T R_j^-1 z_j`` (Merino (3.29)-(3.30);
        for a linearised one ``z_j`` is ``z - h(mu) + H mu``, (3.52)). ``infos`` ``(m, p, p)`` and ``vectors``
        ``(m, p)`` cover the first ``p`` components of a state (a bearing sees only the position). One copy of
        the window for all of them; ``ValueError`` for an offset outside the window or a non-finite term."""
        n, L = self.model.state_dim, self.model.window
        offsets = np.asarray(offsets, int)
        m, p = vectors.shape
        if infos.shape != (m, p, p) or offsets.shape != (m,) or p > n:
            raise ValueError(f"{m} measurements need (m, p, p) information terms and m offsets, p <= {n}")
        if np.any((offsets < 0) | (offsets >= L)):
            raise ValueError(f"a state offset is outside the window of {L} states")
        if not (np.isfinite(infos).all() and np.isfinite(vectors).all()):
            raise ValueError("measurement information terms contain non-finite values")
        rows = ((L - 1 - offsets) * n)[:, None] + np.arange(p)  # (m, p): the rows of each state's first p entries
        y, Y = self.y.copy(), self.Y.copy()
        np.add.at(Y, (rows[:, :, None], rows[:, None, :]), infos)
        np.add.at(y, rows, vectors)
        return Trajectory(y, Y, self.epoch, self.model)

    def eif_update(self, model, z, offset: int = 0, linearization_point=None) -> Trajectory:
        """Extended information update of one state of the window (Merino (3.52))."""
        z = validation.as_vector(np.atleast_1d(np.asarray(z, dtype=float)), "measurement z", model.dim)
        mu = self.state(offset).mean if linearization_point is None else np.asarray(linearization_point, float)
        H = model.jacobian(mu)
        return self.update(H, model.R_inv, model.residual(z, model.h(mu)) + H @ mu, offset)

    def state(self, offset: int = 0) -> Gaussian:
        """The marginal belief on one state of the window (Merino App. A); ``offset=0`` is the newest. Each
        is computed once per belief (association and the update that follows ask for the same one)."""
        known = self._states.get(offset)
        if known is None:
            self._block(offset)  # ValueError outside the window
            known = self._states[offset] = self._marginal(self.model.window - 1 - offset)
        return known

    def current(self) -> Gaussian:
        """The marginal belief on the newest state."""
        return self.state(0)

    def _marginal(self, k: int) -> Gaussian:
        """The marginal belief on state ``k`` of the window (0 the oldest), by eliminating the other states
        (Merino (3.31)-(3.32): ``Y_k <- Y_kk - Y_k,r Y_rr^-1 Y_r,k``, ``y_k <- y_k - Y_k,r Y_rr^-1 y_r``).

        With the states ordered so that ``k`` comes last, ``Y = C C^T`` (Cholesky, ``C`` lower triangular)
        has ``C_kk C_kk^T`` equal to that Schur complement, and ``C_kk w_k``, with ``C w = y``, equal to the
        eliminated information vector: one LAPACK factorisation of the window (``potrf``) and one triangular
        solve (``trtrs``). A window whose information is singular somewhere (a track not yet observed in
        every direction) has no Cholesky factor; it is eliminated state by state instead (:meth:`_chain_marginal`)."""
        n, L = self.model.state_dim, self.model.window
        order = _last_state_order(n, L, k)
        Y, y = (self.Y, self.y) if order is None else (self.Y.take(order, 0).take(order, 1), self.y.take(order))
        factor = lapack.cholesky(Y)
        if factor is None:
            return self._chain_marginal(k)
        w = lapack.triangular_solve(factor, y)
        C_k = factor[-n:, -n:]
        return Gaussian(C_k @ w[-n:], C_k @ C_k.T)

    def _chain_marginal(self, k: int) -> Gaussian:
        """:meth:`_marginal` by eliminating one state at a time, which works on a singular window too.

        The information matrix is block-tridiagonal (the process factors couple consecutive states
        only, updates touch one block, and marginalising the oldest state keeps the structure), so the
        states older than ``k`` are eliminated oldest first and the newer ones newest first, each by
        Merino (3.31)-(3.32) with ``n x n`` blocks only — ``Y_jj <- Y_jj - Y_j,i Y_i^-1 Y_i,j`` for the
        neighbour ``i`` eliminated into ``j`` — which is O(L n^3), not O((L n)^3)."""
        L = self.model.window
        Y_k, y_k = self._chain(range(0, k + 1))
        if k < L - 1:  # the newer states' chain adds its own term to state k
            Y_right, y_right = self._chain(range(L - 1, k, -1))
            coupling = self._coupling(k, k + 1)
            sol = self._solve(Y_right, coupling.T, y_right, k + 1)
            Y_k = Y_k - coupling @ sol[:, :-1]
            y_k = y_k - coupling @ sol[:, -1]
        return Gaussian(y_k, 0.5 * (Y_k + Y_k.T))

    def _chain(self, order) -> tuple[np.ndarray, np.ndarray]:
        """Eliminate the states of ``order`` one after the other into the next; the last one's block then."""
        order = list(order)
        n = self.model.state_dim
        first = slice(order[0] * n, (order[0] + 1) * n)
        Y_prev, y_prev = self.Y[first, first], self.y[first]
        for prev, j in zip(order, order[1:], strict=False):
            cur = slice(j * n, (j + 1) * n)
            coupling = self._coupling(j, prev)
            sol = self._solve(Y_prev, coupling.T, y_prev, prev)
            Y_prev = self.Y[cur, cur] - coupling @ sol[:, :-1]
            y_prev = self.y[cur] - coupling @ sol[:, -1]
        return Y_prev, y_prev

    def _coupling(self, j: int, i: int) -> np.ndarray:
        """The off-diagonal block ``Y_j,i`` between states ``j`` and ``i`` of the window."""
        n = self.model.state_dim
        return self.Y[j * n : (j + 1) * n, i * n : (i + 1) * n]

    @staticmethod
    def _solve(Y_i: np.ndarray, coupling_t: np.ndarray, y_i: np.ndarray, i: int) -> np.ndarray:
        """``Y_i^-1 [Y_i,j | y_i]``; ``UninformativeBeliefError`` when state ``i`` carries singular information."""
        try:
            return lapack.solve(Y_i, np.concatenate([coupling_t, y_i[:, None]], axis=1))
        except np.linalg.LinAlgError:
            raise UninformativeBeliefError(f"state {i} of the window carries singular information") from None

    def _block(self, offset: int) -> slice:
        L, n = self.model.window, self.model.state_dim
        if not 0 <= offset < L:
            raise ValueError(f"state offset {offset} is outside the window of {L} states")
        k = L - 1 - offset
        return slice(k * n, (k + 1) * n)

    # -- the belief algebra ----------------------------------------------------------------------
    def fuse(self, other: Trajectory) -> Trajectory:
        self._check_aligned(other)
        return Trajectory(self.y + other.y, self.Y + other.Y, self.epoch, self.model)

    def remove(self, common: Trajectory) -> Trajectory:
        self._check_aligned(common)
        Y = self.Y - common.Y
        if not validation.is_psd(Y):
            raise ValueError("removing more information than the trajectory holds (result is indefinite)")
        return Trajectory(self.y - common.y, Y, self.epoch, self.model)

    def difference(self, other: Trajectory) -> Trajectory:
        """``remove`` without the positive semi-definite check, for channel-filter bookkeeping terms
        (:mod:`fusion.channel_filter`): after marginalisation they are only approximately valid beliefs."""
        self._check_aligned(other)
        return Trajectory(self.y - other.y, self.Y - other.Y, self.epoch, self.model)

    def intersect(self, other: Trajectory, omega: float) -> Trajectory:
        self._check_aligned(other)
        if not 0.0 <= omega <= 1.0:
            raise ValueError(f"omega must lie in [0, 1], got {omega}")
        return Trajectory(
            omega * self.y + (1 - omega) * other.y, omega * self.Y + (1 - omega) * other.Y, self.epoch, self.model
        )

    def scaled(self, weight: float) -> Trajectory:
        return Trajectory(weight * self.y, weight * self.Y, self.epoch, self.model)

    def with_information(self, y: np.ndarray, Y: np.ndarray) -> Trajectory:
        """The trajectory on this grid and window carrying ``(y, Y)`` (see ``Gaussian.with_information``)."""
        return Trajectory(y, Y, self.epoch, self.model)

    def _check_aligned(self, other) -> None:
        if not isinstance(other, Trajectory) or other.model != self.model:
            raise ValueError("trajectories must share one TrajectoryModel (grid, window and motion)")
        if other.epoch != self.epoch:
            raise ValueError(f"trajectories are not aligned: epoch {self.epoch} vs {other.epoch}")

    def allclose(self, other: Trajectory, rtol: float = 1e-9, atol: float = 0.0) -> bool:
        return (
            self.epoch == other.epoch
            and np.allclose(self.y, other.y, rtol=rtol, atol=atol)
            and np.allclose(self.Y, other.Y, rtol=rtol, atol=atol)
        )

    def __repr__(self) -> str:
        return f"Trajectory(epoch={self.epoch}, window={self.model.window}, state_dim={self.model.state_dim})"


@functools.cache
def _last_state_order(n: int, L: int, k: int) -> np.ndarray | None:
    """Indices of a window of ``L`` states of dimension ``n`` with state ``k`` moved last (``None``: it is)."""
    if k == L - 1:
        return None
    return np.r_[0 : k * n, (k + 1) * n : L * n, k * n : (k + 1) * n]


def _slide(y: np.ndarray, Y: np.ndarray, n: int, factor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Augment with one state (process factor on the last two) and marginalise the oldest state."""
    m = Y.shape[0]
    big = np.zeros((m + n, m + n))
    big[:m, :m] = Y
    big[m - n :, m - n :] += factor
    y_big = np.concatenate([y, np.zeros(n)])
    Y00, Y0r = big[:n, :n], big[:n, n:]
    try:
        sol = lapack.solve(Y00, np.concatenate([Y0r, y_big[:n, None]], axis=1))
    except np.linalg.LinAlgError:
        raise UninformativeBeliefError("cannot marginalise the oldest state: its information is singular") from None
    Yr = big[n:, n:] - Y0r.T @ sol[:, :-1]
    return y_big[n:] - Y0r.T @ sol[:, -1], 0.5 * (Yr + Yr.T)


#: The intersection rules :func:`intersect_on_newest` knows (``[tracking] intersection``).
INTERSECTION_RULES = ("ci", "fast_ci", "ici")


def intersect_on_newest(a: Trajectory, b: Trajectory, rule: str = "ci", objective: str = "det") -> Trajectory:
    """A conservative fusion of two trajectories whose weight ``omega`` is chosen on their newest-state
    marginals (``n x n``) rather than on the whole window (``Ln x Ln``):

    * ``"ci"``: covariance intersection (Merino (3.43)-(3.44)) with ``omega`` optimising ``objective``;
    * ``"fast_ci"``: covariance intersection with Niehsen's (2002) closed form ``omega ∝ 1 / tr(P)``;
    * ``"ici"``: inverse covariance intersection (Noack et al. 2017, :mod:`fusion.inverse_covariance_intersection`)
      with ``omega`` optimising ``objective``. ICI is not linear in the information, so its window is not
      block-tridiagonal: it is brought back onto the chain by :func:`chain_projection`, which keeps every
      single-state and consecutive-pair marginal — the newest state's estimate is exactly ICI's.

    Any ``omega`` in [0, 1] gives a consistent result (for ICI: when the correlation comes from common
    information); choosing it on the newest state makes the *current* estimate as tight as the rule allows, at
    a fraction of the cost."""
    if rule not in INTERSECTION_RULES:
        raise ValueError(f"intersection rule must be one of {', '.join(INTERSECTION_RULES)}, got {rule!r}")
    Ya, Yb = a.current().Y, b.current().Y
    if rule == "ici":
        omega = ici_weight(Ya, Yb, objective)
        return ici(a, b, omega) if omega in (0.0, 1.0) else chain_projection(ici(a, b, omega))
    omega = fast_weights([Ya, Yb]) if rule == "fast_ci" else optimal_weights([Ya, Yb], objective)
    return a.intersect(b, float(omega[0]))


def chain_projection(t: Trajectory) -> Trajectory:
    """The trajectory with a block-tridiagonal information matrix that has the same single-state and
    consecutive-pair marginals as ``t``.

    Among all Gaussians with those marginals it is the one of maximum entropy (Dempster, "Covariance selection",
    Biometrics 1972: the maximum-determinant completion of a banded covariance has a banded inverse), and for a
    chain its information is the junction-tree formula
    ``Y = sum_k E_k,k+1 P_k,k+1^-1 E_k,k+1^T - sum_{0<k<L-1} E_k P_k^-1 E_k^T``, ``y = Y mu``. A trajectory that
    is already a chain is returned unchanged (up to rounding). Needs a positive-definite ``t.Y``."""
    n, L = t.model.state_dim, t.model.window
    try:
        P = np.linalg.inv(np.linalg.cholesky(t.Y))
    except np.linalg.LinAlgError:
        raise UninformativeBeliefError("the trajectory's information matrix is singular: no chain projection") from None
    P = P.T @ P
    mean = P @ t.y
    pairs = np.linalg.inv(np.stack([P[k * n : (k + 2) * n, k * n : (k + 2) * n] for k in range(L - 1)]))
    singles = np.linalg.inv(np.stack([P[k * n : (k + 1) * n, k * n : (k + 1) * n] for k in range(1, L - 1)]))
    Y = np.zeros_like(t.Y)
    for k in range(L - 1):
        Y[k * n : (k + 2) * n, k * n : (k + 2) * n] += pairs[k]
    for k in range(1, L - 1):
        Y[k * n : (k + 1) * n, k * n : (k + 1) * n] -= singles[k - 1]
    Y = 0.5 * (Y + Y.T)
    return t.with_information(Y @ mean, Y)
