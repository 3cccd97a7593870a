"""Observability-aware receding-horizon path planning by direct collocation (spec 002 §2.7; Ross, Geiger,
Sinsley, Horn, Long & Niessner, Sec. V, Eqs. (8)-(9); collocation of Hargraves & Paris 1987).

Model, Ross (8) with the target's states replaced by its known constant-velocity prediction. State
``x = (n, e, ψ, V)`` (north, east [m], heading [rad], airspeed [m/s]), control ``u = (a, ω)``
(longitudinal acceleration [m/s^2], turn rate [rad/s]; Ross's bank command ``φ`` is ``atan(ω V / g)``)::

    ṅ = V cos ψ + w_n,   ė = V sin ψ + w_e,   ψ̇ = ω,   V̇ = a                                   (8)

``w`` is the wind, the velocity of the air mass (Ross et al. subtract it: their convention is "wind from").

Collocation (Hermite–Simpson, spec 002 §2.7): ``M`` nodes ``t_k = t0 + k τ`` over the horizon ``T``
(``τ = T / (M - 1)``; "7 nodes, 20 s" gives 6 segments of 3.33 s), states cubic Hermite and controls linear
between nodes. With ``f_k = f(x_k, u_k)`` the midpoint of segment ``k`` and its defect are::

    x_c = (x_k + x_k+1) / 2 + τ/8 (f_k - f_k+1),    u_c = (u_k + u_k+1) / 2
    ẋ_c = -3/(2τ) (x_k - x_k+1) - (f_k + f_k+1) / 4,       Δ_k = f(x_c, u_c) - ẋ_c = 0

The decision variables are ``x_1..x_M-1`` and ``u_0..u_M-1`` (``x_0`` is the measured state); ``Δ = 0`` are
equality constraints. Limits at the nodes (Ross) and, for speed and lateral acceleration, also at the
midpoints (chosen here: the speed is quadratic between nodes and would otherwise overshoot its band):
``V_min <= V <= V_max``, ``|a| <= a_max``, ``|ω| <= ω_max`` and the lateral acceleration ``|ω| V <= a_lat`` —
for a fixed wing ``a_lat = g tan φ_max`` (turn rate ``ω = g tan φ / V``), for a multirotor its acceleration
limit. Solved by SLSQP (scipy) instead of SNOPT, with analytic gradients, on variables scaled to natural
units (:meth:`CollocationProblem.variable_scale`). SLSQP's subproblem calls BLAS: an agent process should
run scipy's OpenBLAS on one thread (``OPENBLAS_NUM_THREADS=1``); its worker threads on a shared machine
were measured to cost 5-10x per solve.

Objective (replaces Ross (9), whose ``J_tiv`` and weights are not given; form chosen here), integrated by
Simpson's rule on the nodes and Hermite midpoints, per target ``j`` predicted at ``p_j(t) = m_j + v_j t``,
``Δ = p_j - (n, e)``, ``ρ = |Δ|``, ``r^2 = ρ^2 + h^2`` (``h`` the height above the target)::

    J = - Σ_j log det I_j  +  (w_fp / T) Σ_j ∫ ((ρ - r_fp)_+ / r_fp)^2 dt  +  (w_u / T) ∫ (a/a_max)^2 + (ω/ω_max)^2 dt
    I_j = λ ∫ B(Δ) dt,     B(Δ) = (1 / (σ^2 r^2)) (I - Δ Δᵀ / r^2)

``B`` is the Fisher information, about the target's ground position, of one bearing (unit line of sight)
with isotropic angular noise ``σ`` from the slant range ``r``, at measurement rate ``λ``. Its eigenvalues
are ``1 / (σ^2 r^2)`` across the line of sight and ``h^2 / (σ^2 r^4)`` along it; for ``h = 0`` it is the
2-D bearing information ``(1 / (σ^2 ρ^2)) u⊥ u⊥ᵀ``. ``-log det`` rewards both closeness and diverse viewing
directions (an orbit rather than a fly-over); the footprint term keeps the target within the camera
footprint radius ``r_fp``; ``w_u`` is a small control effort.

Receding horizon (spec 002 §2.7, 2 s update): :class:`RecedingHorizonPlanner` replans every
``replan_period`` from the measured state, warm-started from its previous plan shifted in time and, as a
second start, from a circle about the target (the problem is not convex); it keeps the better plan, keeps
the previous plan when every solve fails, and returns the plan's set-point at the current time.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from numbers import Real

import numpy as np
from scipy.optimize import minimize

from fusion.validation import as_vector, positive

GRAVITY = 9.80665  # m/s^2
#: The default wind: still air (read-only).
NO_WIND = np.zeros(2)
NO_WIND.flags.writeable = False
#: A solve is accepted if its largest defect is below this (m/s or rad/s); chosen here.
DEFECT_TOL = 1e-4



@dataclass(frozen=True)
class VehicleLimits:
    """Node limits: airspeed band [m/s], ``|a| <= max_accel`` [m/s^2], ``|ω| <= max_turn_rate`` [rad/s] and
    ``|ω| V <= max_lateral_accel`` [m/s^2]."""

    min_speed: float
    max_speed: float
    max_accel: float
    max_turn_rate: float
    max_lateral_accel: float

    def __post_init__(self):
        if not (isinstance(self.min_speed, Real) and math.isfinite(self.min_speed) and self.min_speed >= 0):
            raise ValueError(f"min_speed must be a non-negative finite number, got {self.min_speed!r}")
        if positive("max_speed", self.max_speed) <= self.min_speed:
            raise ValueError(f"max_speed ({self.max_speed}) must exceed min_speed ({self.min_speed})")
        for name in ("max_accel", "max_turn_rate", "max_lateral_accel"):
            positive(name, getattr(self, name))

    @classmethod
    def fixed_wing(cls, airspeed: float = 18.0, max_bank: float = math.radians(35.0), speed_band: float = 0.2,
                   max_accel: float = 1.0) -> VehicleLimits:
        """A fixed wing (defaults of ``agent.vehicles.fixed_wing``): airspeed ``airspeed (1 ± speed_band)``,
        bank ``|φ| <= max_bank`` i.e. ``|ω| V <= g tan φ_max``; the band and ``max_accel`` are chosen here."""
        airspeed, max_bank = positive("airspeed", airspeed), positive("max_bank", max_bank)
        if max_bank >= math.pi / 2:
            raise ValueError(f"max_bank must be below 90 degrees, got {math.degrees(max_bank):.1f}")
        if not 0 < speed_band < 1:
            raise ValueError(f"speed_band must be in (0, 1), got {speed_band!r}")
        lateral = GRAVITY * math.tan(max_bank)  # ω V = g tan φ
        min_speed = airspeed * (1 - speed_band)
        return cls(min_speed, airspeed * (1 + speed_band), max_accel, lateral / min_speed, lateral)

    @classmethod
    def multirotor(cls, max_speed: float = 10.0, max_accel: float = 3.0,
                   yaw_rate: float = math.radians(90.0)) -> VehicleLimits:
        """A multirotor (defaults of ``agent.vehicles.multirotor``): it may hover (``V_min = 0``); its
        acceleration limit bounds both ``|a|`` and the centripetal ``ω V``."""
        return cls(0.0, max_speed, max_accel, yaw_rate, max_accel)


@dataclass(frozen=True)
class PlannerConfig:
    """Horizon and objective settings; the horizon and node count are Ross's (Sec. VI.D), the rest chosen here."""

    horizon: float = 20.0  # T [s], Ross
    nodes: int = 7  # M, Ross ("7 nodes": 6 segments)
    altitude: float = 60.0  # h, height above the target [m]
    footprint_radius: float = 60.0  # r_fp [m]: a nadir camera with a 90° field of view at 60 m
    bearing_sigma: float = 0.01  # σ [rad]
    measurement_rate: float = 4.0  # λ [Hz], Ross's 4 Hz localizer
    footprint_weight: float = 10.0  # w_fp
    control_weight: float = 0.01  # w_u
    max_iterations: int = 100
    tolerance: float = 1e-5  # SLSQP ftol

    def __post_init__(self):
        for name in ("horizon", "altitude", "footprint_radius", "bearing_sigma", "measurement_rate",
                     "footprint_weight", "control_weight", "tolerance"):
            positive(name, getattr(self, name))
        for name, least in (("nodes", 2), ("max_iterations", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise ValueError(f"{name} must be an integer >= {least}, got {value!r}")

    @property
    def step(self) -> float:
        """τ = T / (M - 1)."""
        return self.horizon / (self.nodes - 1)


# -- model and collocation ----------------------------------------------------------------------------------
def dynamics(states: np.ndarray, controls: np.ndarray, wind: np.ndarray = NO_WIND) -> np.ndarray:
    """Ross (8): ``f(x, u)`` row-wise for states (..., 4) and controls (..., 2)."""
    psi, speed = states[..., 2], states[..., 3]
    return np.stack([speed * np.cos(psi) + wind[0], speed * np.sin(psi) + wind[1],  # ṅ, ė = V (cos ψ, sin ψ) + w
                     controls[..., 1], controls[..., 0]], axis=-1)  # ψ̇ = ω, V̇ = a


def _state_jacobian(states: np.ndarray) -> np.ndarray:
    """``∂f/∂x`` (..., 4, 4)."""
    psi, speed = states[..., 2], states[..., 3]
    a = np.zeros((*states.shape[:-1], 4, 4))
    a[..., 0, 2], a[..., 0, 3] = -speed * np.sin(psi), np.cos(psi)
    a[..., 1, 2], a[..., 1, 3] = speed * np.cos(psi), np.sin(psi)
    return a


#: ``∂f/∂u``: ψ̇ = ω, V̇ = a.
_B = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 1.0], [1.0, 0.0]])


def hermite_midpoints(states, controls, step: float, wind=NO_WIND):
    """``(x_c, u_c, ẋ_c)`` of every segment (module docstring)."""
    f = dynamics(states, controls, wind)
    x_c = 0.5 * (states[:-1] + states[1:]) + step / 8 * (f[:-1] - f[1:])  # x_c = (x_k + x_k+1)/2 + τ/8 (f_k - f_k+1)
    u_c = 0.5 * (controls[:-1] + controls[1:])  # u_c = (u_k + u_k+1)/2
    xdot_c = -1.5 / step * (states[:-1] - states[1:]) - 0.25 * (f[:-1] + f[1:])  # ẋ_c = -3/(2τ)(x_k - x_k+1) - ...
    return x_c, u_c, xdot_c


def hermite_simpson_defects(states, controls, step: float, wind=NO_WIND) -> np.ndarray:
    """``Δ_k = f(x_c, u_c) - ẋ_c`` per segment, (M - 1, 4)."""
    x_c, u_c, xdot_c = hermite_midpoints(np.asarray(states, float), np.asarray(controls, float), step, wind)
    return dynamics(x_c, u_c, wind) - xdot_c


def bearing_information(vehicle_ne, target_ne, sigma: float, altitude: float) -> np.ndarray:
    """``B(Δ) = (1 / (σ^2 r^2)) (I - Δ Δᵀ / r^2)``, ``Δ = target - vehicle``, ``r^2 = |Δ|^2 + h^2`` (..., 2, 2)."""
    delta = np.asarray(target_ne, float) - np.asarray(vehicle_ne, float)
    r2 = np.sum(delta * delta, axis=-1) + altitude**2
    outer = delta[..., :, None] * delta[..., None, :]
    return (np.eye(2) - outer / r2[..., None, None]) / (sigma**2 * r2[..., None, None])


def accumulated_information(vehicle_ne, target_ne, dt: float, config: PlannerConfig = PlannerConfig()) -> np.ndarray:
    """``λ Δt Σ_t B(Δ_t)`` (2, 2): the bearing information gathered along a sampled path (T, 2) about a target
    at ``target_ne`` ((2,) or (T, 2)), one sample every ``dt`` s (rectangle rule)."""
    path = np.asarray(vehicle_ne, dtype=float)
    if path.ndim != 2 or path.shape[1] != 2 or not np.all(np.isfinite(path)):
        raise ValueError(f"vehicle_ne must be a finite (T, 2) array, got shape {path.shape}")
    dt = positive("dt", dt)
    b = bearing_information(path, target_ne, config.bearing_sigma, config.altitude)
    return config.measurement_rate * dt * b.sum(axis=0)


class CollocationProblem:
    """One NLP: the objective, defects and lateral-acceleration constraints as functions of the decision
    vector ``z = (x_1..x_M-1, u_0..u_M-1)``, each with its analytic gradient / Jacobian."""

    def __init__(self, initial_state, target_mean, target_velocity, limits: VehicleLimits,
                 config: PlannerConfig = PlannerConfig(), wind=(0.0, 0.0)):
        self.limits, self.config = limits, config
        self.x0 = as_vector(initial_state, "initial_state (north, east, heading, speed)", 4).copy()
        self.x0[3] = min(max(self.x0[3], limits.min_speed), limits.max_speed)  # a measured speed outside the band
        means = _targets(target_mean, "target_mean")
        velocities = _targets(target_velocity, "target_velocity")
        if velocities.shape != means.shape:
            raise ValueError(f"target_velocity {velocities.shape} must match target_mean {means.shape}")
        self.wind = as_vector(wind, "wind", 2)
        m, tau = config.nodes, config.step
        self.tau = tau
        # Simpson points: the M nodes, then the M - 1 midpoints, their times and weights τ/6 (1 4 1)
        self.times = np.concatenate([np.arange(m) * tau, (np.arange(m - 1) + 0.5) * tau])
        self.weights = np.concatenate([np.full(m, tau / 3), np.full(m - 1, 2 * tau / 3)])
        self.weights[[0, m - 1]] = tau / 6
        self.targets = means[:, None, :] + velocities[:, None, :] * self.times[None, :, None]  # (K, Q, 2)
        self._effort_scale = config.control_weight / config.horizon / np.array(
            [limits.max_accel, limits.max_turn_rate]) ** 2  # w_u / (T u_max^2)
        self._speed_map, self._speed_offset, self._turn_map = self._limit_maps()

    # -- decision vector --------------------------------------------------------------------------------------
    def pack(self, states: np.ndarray, controls: np.ndarray) -> np.ndarray:
        return np.concatenate([states[1:].ravel(), controls.ravel()])

    def unpack(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = self.config.nodes
        states = np.vstack([self.x0, z[: 4 * (m - 1)].reshape(m - 1, 4)])
        return states, z[4 * (m - 1):].reshape(m, 2)

    def bounds(self) -> list[tuple[float | None, float | None]]:
        lim, m = self.limits, self.config.nodes
        state = [(None, None), (None, None), (None, None), (lim.min_speed, lim.max_speed)]
        control = [(-lim.max_accel, lim.max_accel), (-lim.max_turn_rate, lim.max_turn_rate)]
        return state * (m - 1) + control * m

    # -- objective ------------------------------------------------------------------------------------------
    def objective(self, z: np.ndarray) -> tuple[float, np.ndarray]:
        """``J(z)`` and ``∂J/∂z``."""
        m, tau = self.config.nodes, self.tau
        states, controls = self.unpack(z)
        x_c, u_c, _ = hermite_midpoints(states, controls, tau, self.wind)
        points = np.concatenate([states[:, :2], x_c[:, :2]])  # (Q, 2) vehicle (n, e) at the Simpson points
        delta = self.targets - points  # (K, Q, 2) target - vehicle
        info_value, info_grad = self._information(delta)
        fp_value, fp_grad = self._footprint(delta)
        effort = controls[:-1] ** 2 + 4 * u_c**2 + controls[1:] ** 2  # Simpson of u^2 per segment (times τ/6)
        value = info_value + fp_value + tau / 6 * float(np.sum(effort @ self._effort_scale))
        g_points = info_grad + fp_grad  # ∂J/∂(n, e) at each Simpson point
        g_mid = g_points[m:]
        # midpoint (n, e): ∂x_c/∂x_k = I/2 + τ/8 A_k, ∂x_c/∂x_k+1 = I/2 - τ/8 A_k+1 (controls do not enter);
        # g A_k[:2] = (0, 0, V (g_e cos ψ - g_n sin ψ), g_n cos ψ + g_e sin ψ) at node k
        cos, sin, speed = np.cos(states[:, 2]), np.sin(states[:, 2]), states[:, 3]
        g_states = np.zeros((m, 4))
        g_states[:, :2] = g_points[:m]
        g_states[:-1, :2] += 0.5 * g_mid
        g_states[1:, :2] += 0.5 * g_mid
        for nodes, sign in ((slice(None, -1), tau / 8), (slice(1, None), -tau / 8)):
            g_states[nodes, 2] += sign * speed[nodes] * (g_mid[:, 1] * cos[nodes] - g_mid[:, 0] * sin[nodes])
            g_states[nodes, 3] += sign * (g_mid[:, 0] * cos[nodes] + g_mid[:, 1] * sin[nodes])
        g_controls = np.zeros((m, 2))
        g_controls[:-1] += tau / 6 * (2 * controls[:-1] + 4 * u_c) * self._effort_scale  # ∂/∂u_k, u_c = (u_k + u_k+1)/2
        g_controls[1:] += tau / 6 * (2 * controls[1:] + 4 * u_c) * self._effort_scale
        return value, self.pack(g_states, g_controls)

    def _information(self, delta: np.ndarray) -> tuple[float, np.ndarray]:
        """``-Σ_j log det I_j`` and its gradient per Simpson point (Q, 2), from ``Δ`` (K, Q, 2)."""
        cfg = self.config
        dn, de = delta[..., 0], delta[..., 1]
        r2 = dn * dn + de * de + cfg.altitude**2  # r^2 = ρ^2 + h^2
        c = (cfg.measurement_rate / cfg.bearing_sigma**2) * self.weights / r2  # λ w_q / (σ^2 r^2)
        i_nn = np.sum(c * (1 - dn * dn / r2), axis=1)  # I_j = λ Σ_q w_q B(Δ_jq), B = (I - Δ Δᵀ / r^2) / (σ^2 r^2)
        i_ee = np.sum(c * (1 - de * de / r2), axis=1)
        i_ne = -np.sum(c * dn * de / r2, axis=1)
        det = i_nn * i_ee - i_ne**2
        s_nn, s_ee, s_ne = (i_ee / det)[:, None], (i_nn / det)[:, None], (-i_ne / det)[:, None]  # S_j = I_j^-1
        # ∂(-log det I_j)/∂p_q = λ w_q ∇_Δ φ, φ(Δ) = tr(S B(Δ)) = (tr S / r^2 - Δᵀ S Δ / r^4) / σ^2:
        # ∇_Δ φ = (-2 (tr(S) Δ + S Δ) / r^4 + 4 (Δᵀ S Δ) Δ / r^6) / σ^2
        sd_n, sd_e = s_nn * dn + s_ne * de, s_ne * dn + s_ee * de
        quad = dn * sd_n + de * sd_e
        trace = s_nn + s_ee
        k = (cfg.measurement_rate / cfg.bearing_sigma**2) * self.weights / r2**2
        g_n = k * (-2 * (trace * dn + sd_n) + 4 * quad * dn / r2)
        g_e = k * (-2 * (trace * de + sd_e) + 4 * quad * de / r2)
        return float(-np.sum(np.log(det))), np.stack([g_n.sum(axis=0), g_e.sum(axis=0)], axis=1)

    def _footprint(self, delta: np.ndarray) -> tuple[float, np.ndarray]:
        """``(w_fp / T) Σ_j Σ_q w_q ((ρ - r_fp)_+ / r_fp)^2`` and its gradient per point (Q, 2)."""
        cfg = self.config
        rho = np.sqrt(np.sum(delta * delta, axis=-1))
        excess = np.maximum(rho - cfg.footprint_radius, 0.0) / cfg.footprint_radius  # (ρ - r_fp)_+ / r_fp
        scale = cfg.footprint_weight / cfg.horizon * self.weights
        value = float(np.sum(scale * excess**2))
        d_rho = 2 * scale * excess / (cfg.footprint_radius * np.where(rho > 0, rho, 1.0))  # ∂/∂ρ / ρ; ∂ρ/∂p = -Δ/ρ
        return value, -np.sum(d_rho[..., None] * delta, axis=0)

    # -- constraints -------------------------------------------------------------------------------------------
    def defects(self, z: np.ndarray) -> np.ndarray:
        states, controls = self.unpack(z)
        return hermite_simpson_defects(states, controls, self.tau, self.wind).ravel()

    def defects_jacobian(self, z: np.ndarray) -> np.ndarray:
        """``∂Δ/∂z``, ((M-1) 4, len(z)), by the chain rule through ``x_c``, ``u_c`` and ``ẋ_c``:
        ``∂Δ/∂x_k = A_c (I/2 + τ/8 A_k) + 3/(2τ) I + A_k/4``, ``∂Δ/∂u_k = τ/8 A_c B + B/2 + B/4`` and
        mirrored for ``k + 1``; ``A_c A_k = 0`` here (positions never enter ``f``), so ``A_c (I/2 + ...) = A_c/2``."""
        m, tau = self.config.nodes, self.tau
        states, controls = self.unpack(z)
        x_c, _, _ = hermite_midpoints(states, controls, tau, self.wind)
        a, a_c = _state_jacobian(states), _state_jacobian(x_c)
        eye = 1.5 / tau * np.eye(4)
        a_c_b = tau / 8 * (a_c @ _B)
        jac = np.zeros((m - 1, 4, m, 6))
        seg = np.arange(m - 1)
        jac[seg, :, seg, :4] = 0.5 * a_c + 0.25 * a[:-1] + eye  # ∂Δ/∂x_k
        jac[seg, :, seg + 1, :4] = 0.5 * a_c + 0.25 * a[1:] - eye  # ∂Δ/∂x_k+1
        jac[seg, :, seg, 4:] = a_c_b + 0.75 * _B  # ∂Δ/∂u_k
        jac[seg, :, seg + 1, 4:] = -a_c_b + 0.75 * _B  # ∂Δ/∂u_k+1
        jac = jac.reshape(4 * (m - 1), m, 6)
        return np.concatenate([jac[:, 1:, :4].reshape(4 * (m - 1), -1), jac[:, :, 4:].reshape(4 * (m - 1), -1)], 1)

    def _limit_maps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Speed and turn rate at the Simpson points (nodes, then midpoints) are linear in ``z``:
        ``V = P_V z + V_offset``, ``ω = P_ω z`` with ``V_c = (V_k + V_k+1)/2 + τ/8 (a_k - a_k+1)`` and
        ``ω_c = (ω_k + ω_k+1)/2``; ``V_offset`` carries the fixed ``V_0``."""
        m, tau = self.config.nodes, self.tau
        speed = np.zeros((2 * m - 1, m, 6))  # per point: coefficients of (x_k, u_k) of every node
        turn = np.zeros((2 * m - 1, m, 6))
        nodes, seg = np.arange(m), np.arange(m - 1)
        speed[nodes, nodes, 3] = 1.0
        turn[nodes, nodes, 5] = 1.0
        speed[m + seg, seg, 3] = speed[m + seg, seg + 1, 3] = 0.5
        speed[m + seg, seg, 4], speed[m + seg, seg + 1, 4] = tau / 8, -tau / 8
        turn[m + seg, seg, 5] = turn[m + seg, seg + 1, 5] = 0.5
        offset = speed[:, 0, 3] * self.x0[3]

        def as_z(coefficients: np.ndarray) -> np.ndarray:
            return np.concatenate([coefficients[:, 1:, :4].reshape(2 * m - 1, -1),
                                   coefficients[:, :, 4:].reshape(2 * m - 1, -1)], axis=1)

        return as_z(speed), offset, as_z(turn)

    def limit_margins(self, z: np.ndarray) -> np.ndarray:
        """Inequalities ``>= 0``: ``a_lat ∓ ω V`` at the nodes and midpoints, and ``V_c - V_min``,
        ``V_max - V_c`` at the midpoints (the nodes' speeds are bounds); (4 M - 2 + 2 (M - 1),)."""
        m, lim = self.config.nodes, self.limits
        speed = self._speed_map @ z + self._speed_offset
        lateral = (self._turn_map @ z) * speed  # ω V
        mid = speed[m:]
        return np.concatenate([lim.max_lateral_accel - lateral, lim.max_lateral_accel + lateral,
                               mid - lim.min_speed, lim.max_speed - mid])

    def limit_margins_jacobian(self, z: np.ndarray) -> np.ndarray:
        m = self.config.nodes
        speed = self._speed_map @ z + self._speed_offset
        turn = self._turn_map @ z
        d_lateral = turn[:, None] * self._speed_map + speed[:, None] * self._turn_map  # ∂(ω V) = ω ∂V + V ∂ω
        d_mid = self._speed_map[m:]
        return np.vstack([-d_lateral, d_lateral, d_mid, -d_mid])

    def variable_scale(self) -> np.ndarray:
        """Natural units of the decision variables, chosen here (SLSQP works on ``z / scale``): half a segment's
        flight ``V_max τ / 2`` for positions, 1 rad, ``V_max / 4``, ``a_max`` and ``ω_max``."""
        lim, m = self.limits, self.config.nodes
        state = [0.5 * lim.max_speed * self.tau] * 2 + [1.0, 0.25 * lim.max_speed]
        return np.array(state * (m - 1) + [lim.max_accel, lim.max_turn_rate] * m)

    def solve(self, z0: np.ndarray):
        """SLSQP from ``z0`` on the scaled variables; returns scipy's result with ``x`` in physical units."""
        cfg, scale = self.config, self.variable_scale()

        def objective(y):
            value, grad = self.objective(y * scale)
            return value, grad * scale

        constraints = [
            {"type": "eq", "fun": lambda y: self.defects(y * scale),
             "jac": lambda y: self.defects_jacobian(y * scale) * scale},
            {"type": "ineq", "fun": lambda y: self.limit_margins(y * scale),
             "jac": lambda y: self.limit_margins_jacobian(y * scale) * scale},
        ]
        bounds = [(None if lo is None else lo / s, None if hi is None else hi / s)
                  for (lo, hi), s in zip(self.bounds(), scale, strict=True)]
        result = minimize(objective, z0 / scale, jac=True, method="SLSQP", bounds=bounds, constraints=constraints,
                          options={"maxiter": cfg.max_iterations, "ftol": cfg.tolerance})
        result.x = result.x * scale
        return result


def _targets(value, name: str) -> np.ndarray:
    """One (2,) or several (K, 2) target vectors as a finite (K, 2) array."""
    arr = np.asarray(value, dtype=float)
    arr = arr[None] if arr.ndim == 1 else arr
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
        raise ValueError(f"{name} must be (north, east) or (K, 2), got shape {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains non-finite values (NaN or inf)")
    return arr


# -- plans ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Plan:
    """A solved horizon: node ``states`` (M, 4) and ``controls`` (M, 2) from time ``t0`` every ``step`` s, and
    how the solve went (``objective``, SLSQP ``iterations``, wall ``solve_time`` [s], ``max_defect``)."""

    t0: float
    step: float
    states: np.ndarray
    controls: np.ndarray
    wind: np.ndarray = field(default_factory=lambda: np.zeros(2))
    objective: float = math.nan
    iterations: int = 0
    solve_time: float = 0.0
    success: bool = False
    message: str = ""
    max_defect: float = math.nan

    @property
    def times(self) -> np.ndarray:
        return self.t0 + self.step * np.arange(len(self.states))

    @property
    def end(self) -> float:
        return self.t0 + self.step * (len(self.states) - 1)

    def sample(self, t) -> np.ndarray:
        """The cubic Hermite state at time(s) ``t`` (clamped to the horizon), (..., 4)."""
        t = np.clip(np.asarray(t, dtype=float), self.t0, self.end)
        k = np.minimum(((t - self.t0) / self.step).astype(int), len(self.states) - 2)
        s = (t - self.t0) / self.step - k
        f = dynamics(self.states, self.controls, self.wind)
        h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s  # cubic Hermite basis
        h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
        return (h00[..., None] * self.states[k] + h10[..., None] * self.step * f[k]
                + h01[..., None] * self.states[k + 1] + h11[..., None] * self.step * f[k + 1])

    def control(self, t) -> np.ndarray:
        """The linearly interpolated control at time(s) ``t`` (clamped), (..., 2)."""
        t = np.asarray(t, dtype=float)
        times = self.times
        return np.stack([np.interp(t, times, self.controls[:, i]) for i in range(2)], axis=-1)


#: The cold start's turn rate as a share of ``ω_max``, chosen here (see :func:`cold_guess`).
COLD_TURN_SHARE = 0.05


def cold_guess(state: np.ndarray, limits: VehicleLimits, config: PlannerConfig,
               wind=NO_WIND) -> tuple[np.ndarray, np.ndarray]:
    """Cold start: fly on at the current speed on a gentle right turn, ``ω = COLD_TURN_SHARE ω_max``, sampled
    exactly at the nodes. The turn breaks the mirror symmetry of a vehicle heading straight at the target,
    whose straight path is a stationary point of the objective."""
    omega = COLD_TURN_SHARE * limits.max_turn_rate
    t = config.step * np.arange(config.nodes)
    psi0, speed = state[2], state[3]
    states = np.repeat(state[None], config.nodes, axis=0)
    states[:, 2] = psi0 + omega * t
    states[:, 0] += speed / omega * (np.sin(states[:, 2]) - math.sin(psi0)) + wind[0] * t  # constant-turn arc
    states[:, 1] -= speed / omega * (np.cos(states[:, 2]) - math.cos(psi0)) - wind[1] * t
    controls = np.zeros((config.nodes, 2))
    controls[:, 1] = omega
    return states, controls


def shifted_guess(previous: Plan, t: float, state: np.ndarray, config: PlannerConfig) -> tuple[np.ndarray, np.ndarray]:
    """Warm start: the previous plan sampled at ``t + k τ``; past its end the last state is flown on along
    its heading. The headings are shifted by the multiple of 2π nearest the measured heading."""
    times = t + config.step * np.arange(config.nodes)
    states = previous.sample(times)
    beyond = times > previous.end
    if np.any(beyond):
        last = previous.states[-1]
        velocity = last[3] * np.array([math.cos(last[2]), math.sin(last[2])]) + previous.wind
        states[beyond] = last
        states[beyond, :2] += (times[beyond] - previous.end)[:, None] * velocity
    states[:, 2] += 2 * math.pi * round((state[2] - states[0, 2]) / (2 * math.pi))
    controls = previous.control(times)
    controls[beyond] = 0.0
    return states, controls


def orbit_guess(state: np.ndarray, target_mean, target_velocity, limits: VehicleLimits,
                config: PlannerConfig) -> tuple[np.ndarray, np.ndarray]:
    """A second start: nodes 1..M-1 on a circle about the (first) predicted target, in the vehicle's current
    sense of rotation about it, at radius ``max(1.2 V_min^2 / a_lat, r_fp / 2)`` and speed ``V_min`` (a
    hovering-capable vehicle: mid-band speed); chosen here. Node 0 stays the measured state."""
    target = _targets(target_mean, "target_mean")[0]
    velocity = _targets(target_velocity, "target_velocity")[0]
    radius = max(1.2 * limits.min_speed**2 / limits.max_lateral_accel, 0.5 * config.footprint_radius)
    speed = limits.min_speed if limits.min_speed > 0 else 0.5 * limits.max_speed
    rel = state[:2] - target
    own_velocity = state[3] * np.array([math.cos(state[2]), math.sin(state[2])])
    sense = 1.0 if rel[0] * own_velocity[1] - rel[1] * own_velocity[0] >= 0 else -1.0  # +1: clockwise from above
    t = config.step * np.arange(config.nodes)
    angle = math.atan2(rel[1], rel[0]) + sense * speed / radius * t
    states = np.column_stack([target[0] + velocity[0] * t + radius * np.cos(angle),
                              target[1] + velocity[1] * t + radius * np.sin(angle),
                              angle + sense * math.pi / 2, np.full(config.nodes, speed)])
    states[0] = state
    states[:, 2] = np.unwrap(states[:, 2])  # headings continuous from the measured one
    controls = np.zeros((config.nodes, 2))
    controls[:, 1] = sense * speed / radius
    return states, controls


def plan(state, target_mean, target_velocity, limits: VehicleLimits, config: PlannerConfig = PlannerConfig(), *,
         t0: float = 0.0, wind=(0.0, 0.0), initial_guess: tuple[np.ndarray, np.ndarray] | None = None) -> Plan:
    """One collocation solve from ``state = (north, east, heading, speed)`` at time ``t0``, for the target(s)
    at ``target_mean`` (2,) or (K, 2) at ``t0`` moving at ``target_velocity``. ``initial_guess``: node
    ``(states, controls)``, by default :func:`cold_guess` (its first state is replaced by ``state``)."""
    if not (isinstance(t0, Real) and math.isfinite(t0)):
        raise ValueError(f"t0 must be a finite time in seconds, got {t0!r}")
    problem = CollocationProblem(state, target_mean, target_velocity, limits, config, wind)
    guess_states, guess_controls = initial_guess if initial_guess is not None else cold_guess(
        problem.x0, limits, config, problem.wind)
    z0 = problem.pack(np.asarray(guess_states, float), np.asarray(guess_controls, float))
    lower, upper = np.array([(-np.inf if lo is None else lo, np.inf if hi is None else hi)
                             for lo, hi in problem.bounds()]).T
    started = time.perf_counter()
    result = problem.solve(np.clip(z0, lower, upper))
    elapsed = time.perf_counter() - started
    states, controls = problem.unpack(result.x)
    defect = float(np.max(np.abs(problem.defects(result.x))))
    return Plan(float(t0), config.step, states, controls.copy(), problem.wind, float(result.fun), int(result.nit),
                elapsed, bool(result.success) and defect < DEFECT_TOL, str(result.message), defect)


# -- receding horizon -----------------------------------------------------------------------------------------
def unicycle_state(position, velocity, yaw: float) -> np.ndarray:
    """``(north, east, heading, speed)`` from a vehicle's NED ``position`` and ``velocity``: the course of the
    horizontal velocity, or ``yaw`` below 0.5 m/s (a hovering multirotor has no course)."""
    p, v = as_vector(position, "position"), as_vector(velocity, "velocity")
    if not (isinstance(yaw, Real) and math.isfinite(yaw)):
        raise ValueError(f"yaw must be a finite angle in radians, got {yaw!r}")
    speed = math.hypot(v[0], v[1])
    heading = math.atan2(v[1], v[0]) if speed >= 0.5 else float(yaw)
    return np.array([p[0], p[1], heading, speed])


@dataclass(frozen=True)
class Replanning:
    """One replanning at time ``t``: its ``solves`` and their wall and thread-CPU times [s]."""

    t: float
    solves: tuple[Plan, ...]
    wall: float
    cpu: float


@dataclass(frozen=True)
class PlanSetpoint:
    """The plan at time ``t``: NED ``position`` (3,) (depth ``-altitude``: the target on the origin's ground
    plane), NED ground ``velocity`` (3,) (level), ``heading`` [rad] and airspeed ``speed`` [m/s]."""

    t: float
    position: np.ndarray
    velocity: np.ndarray
    heading: float
    speed: float


class RecedingHorizonPlanner:
    """Ross's receding horizon (spec 002 §2.7): replan every ``replan_period`` s (2 s) from the measured state.

    Each replanning solves from the previous plan shifted in time (:func:`shifted_guess`; the first time
    :func:`cold_guess`) and, if ``orbit_start``, also from :func:`orbit_guess`, and keeps the successful
    plan of lower objective: the problem is not convex, and a fixed wing warm-started from its own plans
    alone can settle on a wide circle with the target outside the footprint. ``orbit_start=None`` (chosen
    here) means "if the vehicle cannot hover" (``min_speed > 0``): a hovering vehicle's optimum is to hold
    still over the target, which the warm start finds alone. When every
    solve fails the previous plan is kept while it still covers the current time. :meth:`setpoint` is the
    call a planner makes every cycle."""

    def __init__(self, limits: VehicleLimits, config: PlannerConfig = PlannerConfig(), replan_period: float = 2.0,
                 wind=(0.0, 0.0), orbit_start: bool | None = None):
        self.limits, self.config = limits, config
        self.replan_period = positive("replan_period", replan_period)
        if self.replan_period > config.horizon:
            raise ValueError(f"replan_period ({replan_period}) must not exceed the horizon ({config.horizon})")
        self.wind = as_vector(wind, "wind", 2)
        self.orbit_start = limits.min_speed > 0 if orbit_start is None else bool(orbit_start)
        self.plan: Plan | None = None
        self.solves: list[Plan] = []  # every solve, kept or not (timing and iteration statistics)
        self.replan_times: list[float] = []  # wall time of each replanning (all its solves) [s]

    def setpoint(self, t: float, state, target_mean, target_velocity) -> PlanSetpoint:
        """The set-point at time ``t`` given the vehicle ``state`` (north, east, heading, speed) (see
        :func:`unicycle_state`) and the target estimate (mean at ``t`` and velocity, (2,) or (K, 2))."""
        if not (isinstance(t, Real) and math.isfinite(t)):
            raise ValueError(f"t must be a finite time in seconds, got {t!r}")
        state = as_vector(state, "state (north, east, heading, speed)", 4)
        current = self.plan
        if current is None or t < current.t0 or t - current.t0 >= self.replan_period:
            self._replan(float(t), state, target_mean, target_velocity)
        return self._sample(float(t))

    def _replan(self, t: float, state: np.ndarray, target_mean, target_velocity) -> None:
        self.adopt(self.solve(t, state, target_mean, target_velocity, self.plan))

    def solve(self, t: float, state, target_mean, target_velocity, previous: Plan | None) -> Replanning:
        """The solves of one replanning at ``t`` from ``previous`` (warm start) and, if ``orbit_start``, the orbit
        guess. Reads only this planner's immutable settings and its arguments, so it may run on another thread
        (:mod:`tasking.standoff`) while :meth:`adopt` and :meth:`sample` run on the caller's."""
        started, cpu = time.perf_counter(), time.thread_time()
        state = as_vector(state, "state (north, east, heading, speed)", 4)
        guesses = [None if previous is None else shifted_guess(previous, t, state, self.config)]
        if self.orbit_start:
            guesses.append(orbit_guess(state, target_mean, target_velocity, self.limits, self.config))
        solved = [plan(state, target_mean, target_velocity, self.limits, self.config, t0=t, wind=self.wind,
                       initial_guess=guess) for guess in guesses]
        return Replanning(float(t), tuple(solved), time.perf_counter() - started, time.thread_time() - cpu)

    def adopt(self, replanning: Replanning) -> bool:
        """Take a replanning's successful plan of lowest objective; with none, keep the previous plan while it
        covers the replanning's time (else take the first solve). ``True`` if a successful plan was taken."""
        self.solves.extend(replanning.solves)
        self.replan_times.append(replanning.wall)
        good = [p for p in replanning.solves if p.success]
        if good:
            self.plan = min(good, key=lambda p: p.objective)
        elif self.plan is None or replanning.t > self.plan.end:
            self.plan = replanning.solves[0]
        return bool(good)

    def sample(self, t: float) -> PlanSetpoint:
        """The current plan's set-point at ``t`` (clamped to its horizon); a plan must have been adopted."""
        if self.plan is None:
            raise ValueError("no plan yet: adopt a replanning first")
        return self._sample(float(t))

    def _sample(self, t: float) -> PlanSetpoint:
        n, e, heading, speed = self.plan.sample(t)
        velocity = speed * np.array([math.cos(heading), math.sin(heading)]) + self.wind
        return PlanSetpoint(t, np.array([n, e, -self.config.altitude]), np.array([*velocity, 0.0]),
                            float(heading), float(speed))
