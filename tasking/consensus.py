"""Distributed estimation of Andreetto et al. (Electronics 2018; spec 004 §2.3, §2.6): consensus WLS with
Metropolis weights and a Kalman-consensus filter.

**Metropolis weights** on an undirected graph with degrees ``d_i = |N_i|`` (spec 004 §2.3):

    ``W_ij = 1 / (1 + max(d_i, d_j))`` for ``{i, j} ∈ E``,  ``W_ii = 1 - Σ_{j∈N_i} W_ij``,  0 otherwise.

``W`` is symmetric and doubly stochastic, so on a connected graph ``W^k → 11ᵀ/n``.

**Consensus WLS** (Xiao, Boyd and Lall, IPSN 2005, as spec 004 §2.3 transcribes it): node ``i`` with a
measurement ``y_i = A_i x + v_i``, ``v_i ~ N(0, Σ_i)`` starts from

    ``P_i(0) = A_iᵀ Σ_i⁻¹ A_i``,  ``q_i(0) = A_iᵀ Σ_i⁻¹ y_i``  (both 0 without a measurement)

and iterates ``P_i(k+1) = Σ_j W_ij P_j(k)``, ``q_i(k+1) = Σ_j W_ij q_j(k)``, with the estimate
``x̂_i(k) = P_i(k)⁻¹ q_i(k)``. Both sums are preserved, so on a connected graph every ``x̂_i(k)`` tends to the
centralized WLS ``(Σ A_iᵀΣ_i⁻¹A_i)⁻¹ Σ A_iᵀΣ_i⁻¹y_i``; an intermediate ``x̂_i(k)`` is itself a weighted WLS of
the measurements, hence unbiased. In Andreetto et al. ``A_i = I_2`` and ``y_i = m_i`` (Eq. (2)); the static
algorithm runs ``f`` iterations per step, the tracking stage one (spec 004 §2.7 steps 2 and 4).

**Lost messages** (not in the paper, which assumes none, spec 004 §6; chosen here). In a round in which node ``i``
did not receive ``j``'s message, ``i`` keeps ``W_ij`` on itself (:func:`lossy_weights`):

    ``W'_ij = W_ij`` if ``i`` received ``j``'s message, else 0;  ``W'_ii = 1 - Σ_{j≠i} W'_ij``.

The receiver alone decides, from what it heard: no acknowledgement, so still one message per node and round (the
paper's budget of 3 per step). ``W'`` is non-negative and row-stochastic but, unlike ``W``, not symmetric: every
``(P_i, q_i)`` stays ``Σ_j c_ij (P_j(0), q_j(0))`` with one set of coefficients ``c_ij >= 0`` (products of the
rounds' ``W'``), so ``x̂_i`` is still a WLS of the measurements with weights ``c_ij Σ_j⁻¹`` — unbiased, the paper's
"even the intermediate estimates ... are unbiased" — and a node that hears nobody keeps its own information (the
"number of UAVs that contributes to the estimate changes in time"). What is lost is the conservation of
``Σ_i P_i``: the limit is a consensus on a weighted WLS rather than on the centralized one, and the variance is
somewhat higher. The alternative, dropping a link for both ends when either direction is lost, keeps ``W``
doubly stochastic but needs each sender to learn whether its message arrived (an acknowledgement round).
The Kalman-consensus filter sums what node ``i`` received (``received`` in place of the undirected ``N_i``).

**Kalman-consensus filter** (Olfati-Saber, CDC 2009, Algorithm 1, as spec 004 §2.6 transcribes it): node ``i``
with prior ``(x̄_i, P_i)`` and measurement ``z_i = H x + v_i``, ``v_i ~ N(0, R)``:

    ``u_i = Hᵀ R⁻¹ z_i``,  ``U_i = Hᵀ R⁻¹ H``               (both 0 without a measurement)
    ``y_i = Σ_{j∈N_i∪{i}} u_j``,  ``S_i = Σ_{j∈N_i∪{i}} U_j``
    ``M_i = (P_i⁻¹ + S_i)⁻¹``
    ``x̂_i = x̄_i + M_i (y_i - S_i x̄_i) + γ_i M_i Σ_{j∈N_i} (x̄_j - x̄_i)``,  ``γ_i = ε / (1 + ‖M_i‖_F)``
    ``P_i ← A M_i Aᵀ + Q``,  ``x̄_i ← A x̂_i``

with the double integrator of spec 004 §2.6: ``x = [p; ṗ]``, ``A = [[I, Δt I], [0, I]]``, ``H = [I 0]`` and the
acceleration entering through ``G = [Δt²/2 I; Δt I]``, ``Q = σ_a² G Gᵀ`` (G is not in the paper; this is the
discrete white-noise acceleration model, chosen here), ``σ_a = 0.01 m/s²`` (004 Sec. 6.1).

Every function takes arrays with any leading batch shape (e.g. one graph per Monte Carlo run): nodes are the
axis before the state axes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.sparse.csgraph import connected_components

from fusion.motion import ConstantVelocity

#: 004 Sec. 6.1: the standard deviation of the KF acceleration noise [m/s²].
SIGMA_A = 0.01


# -------------------------------------------------------------------------------------------- graphs
def check_adjacency(adjacency, symmetric: bool = True) -> np.ndarray:
    """``adjacency (..., n, n)`` as a boolean array; ValueError unless it has an empty diagonal and, with
    ``symmetric``, is symmetric (``symmetric=False``: ``adjacency[i, j]`` says node ``i`` received ``j``'s message)."""
    adj = np.asarray(adjacency)
    if adj.ndim < 2 or adj.shape[-1] != adj.shape[-2]:
        raise ValueError(f"adjacency must be (..., n, n), got shape {adj.shape}")
    if adj.dtype != bool:
        if not np.all(np.isin(adj, (0, 1))):
            raise ValueError("adjacency must hold only 0/1 (or booleans)")
        adj = adj.astype(bool)
    if symmetric and np.any(adj != np.swapaxes(adj, -1, -2)):
        raise ValueError("adjacency must be symmetric (the communication graph is undirected)")
    if np.any(np.diagonal(adj, axis1=-2, axis2=-1)):
        raise ValueError("adjacency must have an empty diagonal (no self-loops)")
    return adj


def components(weights_or_adjacency) -> list[list[int]]:
    """The connected components (sorted node lists) of one graph given by a weight or adjacency matrix."""
    mat = np.asarray(weights_or_adjacency)
    if mat.ndim != 2:
        raise ValueError(f"components needs one (n, n) matrix, got shape {mat.shape}")
    links = (mat != 0) & ~np.eye(mat.shape[0], dtype=bool)
    count, labels = connected_components(links, directed=False)
    return [np.flatnonzero(labels == c).tolist() for c in range(count)]


def metropolis_weights(adjacency) -> np.ndarray:
    """Metropolis weights ``W (..., n, n)`` of undirected graphs (spec 004 §2.3)."""
    adj = check_adjacency(adjacency)
    degree = adj.sum(axis=-1)
    pair_max = np.maximum(degree[..., :, None], degree[..., None, :])
    W = np.where(adj, 1.0 / (1.0 + pair_max), 0.0)  # W_ij = 1 / (1 + max(d_i, d_j)) on edges
    n = adj.shape[-1]
    W[..., np.arange(n), np.arange(n)] = 1.0 - W.sum(axis=-1)  # W_ii = 1 - Σ_j W_ij
    return W


def lossy_weights(weights, received) -> np.ndarray:
    """One round's weights when messages were lost (module docstring): ``W'_ij = W_ij`` where node ``i`` received
    ``j``'s message (``received[..., i, j]``), 0 elsewhere off the diagonal, and ``W'_ii = 1 - Σ_{j≠i} W'_ij``."""
    W = np.asarray(weights, dtype=float)
    heard = check_adjacency(received, symmetric=False)
    if heard.shape != W.shape:
        raise ValueError(f"received must have the weights' shape {W.shape}, got {heard.shape}")
    kept = np.where(heard, W, 0.0)
    n = W.shape[-1]
    kept[..., np.arange(n), np.arange(n)] = 1.0 - kept.sum(axis=-1)  # the lost weight stays on the receiver
    return kept


def check_weights(weights, require_connected: bool = False) -> np.ndarray:
    """``weights (..., n, n)``: finite, non-negative, symmetric, rows summing to 1 (doubly stochastic); with
    ``require_connected`` every graph must be connected (needed for convergence to the centralized WLS)."""
    W = np.asarray(weights, dtype=float)
    if W.ndim < 2 or W.shape[-1] != W.shape[-2]:
        raise ValueError(f"weights must be (..., n, n), got shape {W.shape}")
    if not np.all(np.isfinite(W)) or np.any(W < 0):
        raise ValueError("weights must be finite and non-negative")
    if not np.allclose(W, np.swapaxes(W, -1, -2), atol=1e-12):
        raise ValueError("weights must be symmetric (undirected graph)")
    row_sums = W.sum(axis=-1)
    if not np.allclose(row_sums, 1.0, atol=1e-9):
        raise ValueError(f"weights rows must sum to 1, got row sums {row_sums.ravel()[:5]}")
    if require_connected:
        for graph in W.reshape(-1, W.shape[-1], W.shape[-1]):
            parts = components(graph)
            if len(parts) > 1:
                raise ValueError(f"weights describe a disconnected graph with components {parts}")
    return W


# ---------------------------------------------------------------------------------- consensus WLS
def wls_information(measurements, information, valid=None) -> tuple[np.ndarray, np.ndarray]:
    """Xiao's initial ``(P_i(0), q_i(0))`` for ``A_i = I``: ``P = Σ⁻¹``, ``q = Σ⁻¹ y`` where ``valid``, 0 elsewhere.

    ``measurements (..., n, d)``; ``information`` ``Σ_i⁻¹`` as ``(d, d)`` (shared) or ``(..., n, d, d)``;
    ``valid (..., n)`` booleans (default: all). Invalid rows may hold anything finite or not."""
    y = np.asarray(measurements, dtype=float)
    d = y.shape[-1]
    mask = np.ones(y.shape[:-1], dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    if mask.shape != y.shape[:-1]:
        raise ValueError(f"valid must have shape {y.shape[:-1]}, got {mask.shape}")
    if not np.all(np.isfinite(y[mask])):
        raise ValueError("valid measurements must be finite (NaN or inf found)")
    info = np.broadcast_to(np.asarray(information, dtype=float), y.shape[:-1] + (d, d))
    if not np.all(np.isfinite(info[mask])):
        raise ValueError("information matrices must be finite")
    P = np.where(mask[..., None, None], info, 0.0)  # P_i(0) = A_iᵀ Σ_i⁻¹ A_i
    q = (P @ np.where(mask[..., None], y, 0.0)[..., None])[..., 0]  # q_i(0) = A_iᵀ Σ_i⁻¹ y_i
    return P, q


def consensus_round(weights, P, q) -> tuple[np.ndarray, np.ndarray]:
    """One Xiao–Boyd–Lall iteration: ``P_i ← Σ_j W_ij P_j``, ``q_i ← Σ_j W_ij q_j`` (one message per node)."""
    W, P = np.asarray(weights, dtype=float), np.asarray(P, dtype=float)
    flat = P.reshape(*P.shape[:-2], -1)  # the matrices as rows, so one batched matmul does Σ_j W_ij P_j
    return (W @ flat).reshape(P.shape), W @ np.asarray(q, dtype=float)


def wls_consensus(weights, P, q, iterations: int, require_connected: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``iterations`` consensus rounds (``f`` of spec 004 §2.3; 1 is the tracking stage's one-step WLS)."""
    if isinstance(iterations, bool) or int(iterations) != iterations or iterations < 0:
        raise ValueError(f"iterations must be a non-negative integer, got {iterations}")
    W = check_weights(weights, require_connected)
    P, q = np.asarray(P, dtype=float), np.asarray(q, dtype=float)
    for _ in range(int(iterations)):
        P, q = consensus_round(W, P, q)
    return P, q


def wls_estimate(P, q, fallback) -> tuple[np.ndarray, np.ndarray]:
    """``x̂_i = P_i⁻¹ q_i`` where node ``i`` holds information (``tr P_i > 0``), else ``fallback``; also returns
    that mask. A node without information keeps its previous value (spec 004 §8: keep the previous centre)."""
    P, q = np.asarray(P, dtype=float), np.asarray(q, dtype=float)
    informed = np.trace(P, axis1=-2, axis2=-1) > 0
    eye = np.eye(P.shape[-1])
    safe_P = np.where(informed[..., None, None], P, eye)
    x = np.linalg.solve(safe_P, q[..., None])[..., 0]  # x̂_i = P_i⁻¹ q_i
    return np.where(informed[..., None], x, np.asarray(fallback, dtype=float)), informed


# ------------------------------------------------------------------------ Kalman-consensus filter
@dataclass(frozen=True)
class DoubleIntegrator:
    """The KCF target model of spec 004 §2.6 on the plane: ``x = [p; ṗ]`` (4,), ``A``, ``H``, ``Q = σ_a² G Gᵀ``."""

    dt: float
    sigma_a: float = SIGMA_A

    def __post_init__(self):
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a positive time step, got {self.dt}")
        if not (math.isfinite(self.sigma_a) and self.sigma_a >= 0):
            raise ValueError(f"sigma_a must be a non-negative acceleration std, got {self.sigma_a}")

    @cached_property
    def A(self) -> np.ndarray:
        return ConstantVelocity(spatial_dims=2).transition(self.dt)  # [[I, Δt I], [0, I]]

    @cached_property
    def H(self) -> np.ndarray:
        return np.hstack([np.eye(2), np.zeros((2, 2))])  # z = [I 0] x

    @cached_property
    def Q(self) -> np.ndarray:
        G = np.vstack([0.5 * self.dt**2 * np.eye(2), self.dt * np.eye(2)])  # G = [Δt²/2 I; Δt I]
        return self.sigma_a**2 * G @ G.T  # Q = σ_a² G Gᵀ


@dataclass(frozen=True)
class KCFStep:
    """One KCF step's result: posterior means ``(..., n, 4)`` and covariances ``M (..., n, 4, 4)``, and the
    priors for the next step."""

    mean: np.ndarray
    cov: np.ndarray
    next_mean: np.ndarray
    next_cov: np.ndarray


def kcf_step(
    model: DoubleIntegrator,
    prior_mean,
    prior_cov,
    adjacency,
    z,
    has_z,
    R,
    epsilon: float,
) -> KCFStep:
    """One step of the Kalman-consensus filter (Olfati-Saber 2009, Algorithm 1) at every node.

    ``prior_mean (..., n, 4)``, ``prior_cov (..., n, 4, 4)``, ``adjacency (..., n, n)`` (the nodes that run the
    filter and exchange ``(u_i, U_i, x̄_i)``; one message per node; ``adjacency[..., i, j]``: ``i`` received ``j``'s
    message, which need not be symmetric when messages are lost), ``z (..., n, 2)`` with ``has_z (..., n)``,
    ``R`` the (2, 2) measurement covariance, ``epsilon`` the consensus gain ``ε >= 0``."""
    if not (math.isfinite(epsilon) and epsilon >= 0):
        raise ValueError(f"epsilon must be a non-negative consensus gain, got {epsilon}")
    R = np.asarray(R, dtype=float)
    if R.shape != (2, 2) or not np.all(np.isfinite(R)) or np.any(np.linalg.eigvalsh(0.5 * (R + R.T)) <= 0):
        raise ValueError(f"R must be a (2, 2) positive-definite covariance, got {R.tolist()}")
    adj = check_adjacency(adjacency, symmetric=False).astype(float)
    x_bar, P = np.asarray(prior_mean, dtype=float), np.asarray(prior_cov, dtype=float)
    mask = np.asarray(has_z, dtype=bool)
    z = np.where(mask[..., None], np.asarray(z, dtype=float), 0.0)
    if not np.all(np.isfinite(z)):
        raise ValueError("measurements z must be finite where has_z")
    H, A = model.H, model.A
    HtRinv = H.T @ np.linalg.inv(R)
    u = np.where(mask[..., None], z @ HtRinv.T, 0.0)  # u_i = Hᵀ R⁻¹ z_i
    U = np.where(mask[..., None, None], HtRinv @ H, 0.0)  # U_i = Hᵀ R⁻¹ H
    closed = adj + np.eye(adj.shape[-1])
    y = closed @ u  # y_i = Σ_{j∈N_i∪{i}} u_j
    S = (closed @ U.reshape(*U.shape[:-2], -1)).reshape(U.shape)  # S_i = Σ_{j∈N_i∪{i}} U_j
    M = np.linalg.inv(np.linalg.inv(P) + S)  # M_i = (P_i⁻¹ + S_i)⁻¹
    disagreement = adj @ x_bar - adj.sum(axis=-1)[..., None] * x_bar  # Σ_{j∈N_i} (x̄_j - x̄_i)
    gamma = epsilon / (1.0 + np.linalg.norm(M, ord="fro", axis=(-2, -1)))  # γ_i = ε / (1 + ‖M_i‖_F)
    innovation = y - (S @ x_bar[..., None])[..., 0]  # y_i - S_i x̄_i
    x_hat = x_bar + (M @ (innovation + gamma[..., None] * disagreement)[..., None])[..., 0]
    next_cov = A @ M @ A.T + model.Q  # P_i ← A M_i Aᵀ + Q
    next_mean = x_hat @ A.T  # x̄_i ← A x̂_i
    return KCFStep(x_hat, M, next_mean, next_cov)
