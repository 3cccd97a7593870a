"""The "man-like" target of Andreetto et al. (Electronics 2018; spec 004 §4.4, Eqs. (16)-(17)), discretised
exactly, for the rendezvous experiment E4 (:mod:`mesh_sim.orbit_experiments`).

Per ground axis the state is ``s = [p, ṗ, p̈]`` and (Eq. (16)-(17), reconstructed in spec 004 §4.4)

    ``ṡ = F s + L w``,  ``F = [[0, 1, 0], [0, 0, 1], [0, 0, -α̃]]``,  ``L = [0, 0, 1]ᵀ``,

a Singer model: the acceleration is an Ornstein-Uhlenbeck process. ``w`` is white with spectral density
``q = σ_w²`` (the paper's "standard deviation of w_5(t) and w_6(t) ... 0.1 m/s³", read as a density: chosen here,
the paper does not say), so the stationary acceleration variance is ``q / (2 α̃)``. ``α̃ = 10²`` (the exponent's
sign was lost in extraction; ``10⁻²`` gives 64 m/s after 100 s, ``10²`` a walking 1.4 m/s: spec 004 §4.4) and
``x(0) = [0, 0, 1, 1, 1, 1]``.

At the rendezvous step of 1 s, ``α̃ Δt = 100``: forward Euler is unstable (``|1 - α̃ Δt| = 99``) and a trapezoidal
velocity update turns the initial 1 m/s² into +0.5 m/s instead of the exact ``1/α̃ = 0.01`` m/s. The exact
discretisation is used instead. With ``g(τ) = exp(F τ) L = [(α̃τ - 1 + e^{-α̃τ}) / α̃², (1 - e^{-α̃τ}) / α̃, e^{-α̃τ}]``
(the input column of the transition, closed form),

    ``Φ = exp(F Δt) = [[1, Δt, g₁(Δt)], [0, 1, g₂(Δt)], [0, 0, g₃(Δt)]]``,  ``Q = q ∫₀^Δt g(τ) g(τ)ᵀ dτ``,
    ``s_{k+1} = Φ s_k + N(0, Q)``,

``Q`` by adaptive quadrature of the closed-form integrand (Van Loan's matrix exponential loses every digit here:
it holds ``e^{+α̃Δt} = e^{100}``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import quad_vec

MAN_LIKE_ALPHA = 100.0  # α̃ = 10² (spec 004 §4.4: the man-like reading of the lost exponent)
MAN_LIKE_SIGMA_W = 0.1  # σ(w_5) = σ(w_6) = 0.1 m/s³ (004 §6.2.2), a white-noise density here
MAN_LIKE_START = ((0.0, 0.0), (1.0, 1.0), (1.0, 1.0))  # x(0) = [0, 0, 1, 1, 1, 1]: position, velocity, acceleration


def singer_discretisation(alpha: float, q: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Φ, Q)`` (3, 3) of one axis of the Singer model over ``dt`` (module docstring)."""
    for name, value in (("alpha", alpha), ("dt", dt)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be positive, got {value}")
    if not (math.isfinite(q) and q >= 0):
        raise ValueError(f"q must be a non-negative noise density, got {q}")
    Phi = np.eye(3)
    Phi[0, 1] = dt
    Phi[:, 2] = _input_column(alpha, dt)
    Q = q * quad_vec(lambda tau: np.outer(*(2 * [_input_column(alpha, tau)])), 0.0, dt, epsrel=1e-12)[0]
    return Phi, Q


def _input_column(alpha: float, tau: float) -> np.ndarray:
    """``g(τ) = exp(F τ) L`` (module docstring)."""
    decay = -math.expm1(-alpha * tau)  # 1 - e^{-α̃τ}
    return np.array([(alpha * tau - decay) / alpha**2, decay / alpha, 1.0 - decay])


def man_like_paths(
    runs: int,
    times: np.ndarray,
    seed: int,
    alpha: float = MAN_LIKE_ALPHA,
    sigma_w: float = MAN_LIKE_SIGMA_W,
    start=MAN_LIKE_START,
) -> np.ndarray:
    """Ground positions ``(R, T, 2)`` of ``runs`` independent man-like targets at ``times`` (evenly spaced, from
    ``t = 0``), both axes driven by independent noise; ``start`` is ``(p(0), ṗ(0), p̈(0))``."""
    times = np.asarray(times, dtype=float)
    dt = float(times[1] - times[0]) if times.size > 1 else 1.0
    Phi, Q = singer_discretisation(alpha, sigma_w**2, dt)
    eigenvalues, vectors = np.linalg.eigh(Q)
    root = vectors * np.sqrt(np.clip(eigenvalues, 0.0, None))  # Q = root rootᵀ (Q may be numerically singular)
    rng = np.random.default_rng(seed)
    state = np.broadcast_to(np.asarray(start, dtype=float).T, (runs, 2, 3)).copy()  # (R, axis, [p, ṗ, p̈])
    paths = np.empty((runs, times.size, 2))
    paths[:, 0] = state[..., 0]
    for k in range(1, times.size):
        state = state @ Phi.T + rng.standard_normal((runs, 2, 3)) @ root.T  # s_{k+1} = Φ s_k + N(0, Q)
        paths[:, k] = state[..., 0]
    return paths
