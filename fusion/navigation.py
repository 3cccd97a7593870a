"""The cascaded dead-reckoning / GPS navigation filter: position and velocity.

Lee, Kaminer, Dobrokhodov and Jones (NPS, 2010), spec 003 §2.6-§2.7, Eqs. 18-39. Frames: NED position
``p^n``, body FRD velocity ``v^b``; the attitude comes from an (external) attitude filter as a scalar-last
quaternion ``q = [ϱ; q4]`` with the DCM (spec 003 [NOT IN PAPER]; the active Hamilton matrix of
:mod:`perception.rotations`, not normalised, so that the Jacobian below is exact for it)

    C_b^n(q) = (q4² - ϱᵀϱ) I + 2 ϱϱᵀ + 2 q4 [ϱ×]

Position filter (``v^b = [V, 0, 0]``: no sideslip or angle of attack, Eq. 19):

    p̂_{k+1|k} = p̂_{k|k} + Δt C_b^n(q̂_k) v^b                                   (Eq. 20)
    P^p_{k+1|k} = P^p_{k|k} + F_2 𝒫^u F_2ᵀ,   F_2 = ∂(Δt C_b^n(q) v^b)/∂[q; v^b] (3x7)   (Eqs. 22-25)

Velocity filter (Coriolis, Earth rate and centripetal terms neglected):

    v̂_{k+1|k} = v̂_{k|k} + Δt C_b^n(q̂_k) f^b + g^n Δt,   g^n = [0, 0, g]       (Eqs. 31-34)
    P^v_{k+1|k} = P^v_{k|k} + F_2^v 𝒫^v F_2^vᵀ,  F_2^v = ∂(Δt C_b^n(q) f^b)/∂[q; f^b]   (Eqs. 35-37)

or, with ``velocity_covariance="eq38"``, the paper's heuristic ``P^v_{k+1|k} = (1/Δt) F_2 [𝒫^u + Δt 𝒫^v] F_2ᵀ``
(Eq. 38, which drops the prior ``P^v_{k|k}``; spec 003 ⚠). The paper's claim ``F_2^v = F_2^p`` holds in
structure only, so each Jacobian is taken at its own vector.

GPS position and velocity updates (``H = I``), Eqs. 26-30 and 39:

    ν = ỹ - ŷ,   P^νν = H P Hᵀ + R,   K = P Hᵀ (P^νν)⁻¹,   x̂ += K ν,   P -= K P^νν Kᵀ

each optionally gated by the χ² test of :mod:`fusion.navigation_faults` (Eqs. 40-44). With several GPS
receivers, :class:`GpsFaultIsolation` tests each receiver against a filter that never used it (a bank of
observers, [NOT IN PAPER]), so that a drifting receiver is isolated and the filter continues on the others.

``𝒫^u`` (Eq. 25) and ``𝒫^v`` (Eq. 37) share the quaternion block ``𝒫_q`` and are constant (the attitude filter
is in steady state); their values are tuning choices (:class:`NavigationNoise`). The multi-rate GPS of Eq. 26 is the
caller's business: call :meth:`NavigationFilter.predict` at the dead-reckoning rate and the updates whenever a
GPS datum arrives.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import block_diag

from fusion import lapack
from fusion.navigation_faults import InnovationTest, SensorMonitor, innovation_test
from fusion.validation import as_pd, as_vector

#: Standard gravity (m/s²), as in agent.vehicles.base (fusion imports nothing above it).
GRAVITY = 9.80665
VELOCITY_COVARIANCES = ("eq35", "eq38")


def _skew(v: np.ndarray) -> np.ndarray:
    """``[v×]``: ``[v×] w = v × w``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _quaternion(q) -> np.ndarray:
    q = as_vector(q, "attitude quaternion (x, y, z, w)", 4)
    if not np.any(q):
        raise ValueError("attitude quaternion is zero")
    return q


def _dcm(rho: np.ndarray, q4: float) -> np.ndarray:
    rr = rho @ rho
    return (q4 * q4 - rr) * np.eye(3) + 2.0 * np.outer(rho, rho) + 2.0 * q4 * _skew(rho)


def _jacobian(rho: np.ndarray, q4: float, C: np.ndarray, x: np.ndarray, dt: float) -> np.ndarray:
    d_rho = -2.0 * np.outer(x, rho) + 2.0 * (rho @ x) * np.eye(3) + 2.0 * np.outer(rho, x) - 2.0 * q4 * _skew(x)
    d_q4 = 2.0 * q4 * x + 2.0 * _skew(rho) @ x
    return dt * np.column_stack([d_rho, d_q4, C])


def dcm_from_quaternion(q) -> np.ndarray:
    """``C_b^n = (q4² - ϱᵀϱ) I + 2 ϱϱᵀ + 2 q4 [ϱ×]`` for ``q = (ϱ, q4)`` (scalar last; not normalised)."""
    q = _quaternion(q)
    return _dcm(q[:3], q[3])


def dcm_jacobian(q, vector, dt: float) -> np.ndarray:
    """``F_2 = ∂(Δt C_b^n(q) x)/∂[q; x]`` (3x7, Eqs. 23 and 36) at ``q`` and the body vector ``x``.

    With ``C x = (q4² - ϱᵀϱ) x + 2 ϱ (ϱᵀx) + 2 q4 (ϱ × x)``: ``∂/∂ϱ = -2 x ϱᵀ + 2 (ϱᵀx) I + 2 ϱ xᵀ - 2 q4 [x×]``,
    ``∂/∂q4 = 2 q4 x + 2 ϱ × x`` and ``∂/∂x = C``."""
    q = _quaternion(q)
    return _jacobian(q[:3], q[3], _dcm(q[:3], q[3]), as_vector(vector, "body vector", 3), dt)


@dataclass(frozen=True)
class NavigationNoise:
    """The constant input covariances: ``quaternion`` 𝒫_q (4x4), ``body_velocity`` 𝒫_v^p (3x3, the speed and the
    neglected sideslip/angle-of-attack velocities) and ``specific_force`` 𝒫_a (3x3); ``𝒫^u = diag(𝒫_q, 𝒫_v^p)``
    (Eq. 25) and ``𝒫^v = diag(𝒫_q, 𝒫_a)`` (Eq. 37). Defaults: :meth:`from_std` with its defaults."""

    quaternion: np.ndarray
    body_velocity: np.ndarray
    specific_force: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "quaternion", as_pd(self.quaternion, "quaternion covariance", 4))
        object.__setattr__(self, "body_velocity", as_pd(self.body_velocity, "body velocity covariance", 3))
        object.__setattr__(self, "specific_force", as_pd(self.specific_force, "specific force covariance", 3))

    @classmethod
    def from_std(
        cls,
        attitude: float = math.radians(0.5),
        speed: float = 0.5,
        cross_speed: float = 0.2,
        specific_force: float = 0.05,
    ) -> NavigationNoise:
        """From standard deviations (chosen here): attitude error (rad) -> ``𝒫_q = (σ/2)² I₄`` (a small rotation
        δθ moves a unit quaternion by ``½ Ξ(q) δθ``, whose covariance ``(σ/2)² (I - q qᵀ)`` this bounds), speed
        and cross-axis velocity (m/s), specific force per axis (m/s²)."""
        for name, value in (("attitude", attitude), ("speed", speed), ("cross_speed", cross_speed),
                            ("specific_force", specific_force)):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} standard deviation must be positive, got {value}")
        return cls(
            (0.5 * attitude) ** 2 * np.eye(4),
            np.diag([speed**2, cross_speed**2, cross_speed**2]),
            specific_force**2 * np.eye(3),
        )

    @property
    def position_inputs(self) -> np.ndarray:
        """``𝒫^u = diag(𝒫_q, 𝒫_v^p)`` (Eq. 25), 7x7."""
        return block_diag(self.quaternion, self.body_velocity)

    @property
    def velocity_inputs(self) -> np.ndarray:
        """``𝒫^v = diag(𝒫_q, 𝒫_a)`` (Eq. 37), 7x7."""
        return block_diag(self.quaternion, self.specific_force)


def _kalman_update(mean: np.ndarray, cov: np.ndarray, z: np.ndarray, R: np.ndarray):
    """Eqs. 27-30 with ``H = I``: the posterior and the innovation ``(ν, P^νν)``."""
    nu = z - mean  # ν = ỹ - ŷ
    S = cov + R  # P^νν = H P Hᵀ + R (Eq. 27)
    K = lapack.solve(S, cov).T  # K = P Hᵀ (P^νν)⁻¹ (Eq. 28; S and P symmetric)
    new_cov = cov - K @ S @ K.T  # P -= K P^νν Kᵀ (Eq. 30)
    return mean + K @ nu, 0.5 * (new_cov + new_cov.T), nu, S  # x̂ += K ν (Eq. 29)


class NavigationFilter:
    """The cascaded position and velocity filters (module docstring). Plain state: ``position``,
    ``position_cov``, ``velocity``, ``velocity_cov`` (NED, m and m/s)."""

    def __init__(
        self,
        position,
        position_cov,
        velocity,
        velocity_cov,
        noise: NavigationNoise | None = None,
        velocity_covariance: str = "eq35",
    ):
        self.position = as_vector(position, "initial position", 3).copy()
        self.position_cov = as_pd(position_cov, "initial position covariance", 3).copy()
        self.velocity = as_vector(velocity, "initial velocity", 3).copy()
        self.velocity_cov = as_pd(velocity_cov, "initial velocity covariance", 3).copy()
        self.noise = NavigationNoise.from_std() if noise is None else noise
        if velocity_covariance not in VELOCITY_COVARIANCES:
            raise ValueError(f"velocity_covariance must be one of {VELOCITY_COVARIANCES}, got {velocity_covariance!r}")
        self.velocity_covariance = velocity_covariance
        self._P_u, self._P_v = self.noise.position_inputs, self.noise.velocity_inputs

    def predict(self, q, speed: float, specific_force, dt: float) -> None:
        """Dead-reckon both filters over ``dt`` from the attitude ``q`` (scalar last), the speed ``V`` (m/s) and the
        body specific force ``f^b`` (m/s²): Eqs. 20, 24, 34 and 35 (or 38)."""
        q, C = self._attitude(q, dt)
        F2p = self._predict_position(q, C, speed, dt)
        f_body = as_vector(specific_force, "specific force (body)", 3)
        self.velocity = self.velocity + dt * C @ f_body + np.array([0.0, 0.0, GRAVITY * dt])  # Eq. 34
        if self.velocity_covariance == "eq35":
            F2v = _jacobian(q[:3], q[3], C, f_body, dt)
            self.velocity_cov = self.velocity_cov + F2v @ self._P_v @ F2v.T  # Eq. 35
        else:
            self.velocity_cov = F2p @ (self._P_u + dt * self._P_v) @ F2p.T / dt  # Eq. 38

    def predict_position(self, q, speed: float, dt: float) -> None:
        """Dead-reckon the position filter alone (Eqs. 20 and 24)."""
        q, C = self._attitude(q, dt)
        self._predict_position(q, C, speed, dt)

    @staticmethod
    def _attitude(q, dt: float) -> tuple[np.ndarray, np.ndarray]:
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt}")
        q = _quaternion(q)
        return q, _dcm(q[:3], q[3])

    def _predict_position(self, q: np.ndarray, C: np.ndarray, speed: float, dt: float) -> np.ndarray:
        if not math.isfinite(speed):
            raise ValueError(f"speed must be finite, got {speed}")
        v_body = np.array([float(speed), 0.0, 0.0])  # v^b = [V, 0, 0]
        F2p = _jacobian(q[:3], q[3], C, v_body, dt)
        self.position = self.position + dt * C @ v_body  # p̂ += Δt C_b^n v^b (Eq. 20)
        self.position_cov = self.position_cov + F2p @ self._P_u @ F2p.T  # Eq. 24
        return F2p

    def _update(self, which: str, z, R, monitor: SensorMonitor | None, t: float) -> InnovationTest | None:
        if monitor is not None and monitor.isolated:
            return None
        z = as_vector(z, f"GPS {which}", 3)
        R = as_pd(R, f"GPS {which} noise R", 3)
        mean, cov = getattr(self, which), getattr(self, f"{which}_cov")
        new_mean, new_cov, nu, S = _kalman_update(mean, cov, z, R)
        test = innovation_test(nu, S)  # d², χ² (Eqs. 43-44)
        if monitor is None or monitor.admit(test, t):
            setattr(self, which, new_mean)
            setattr(self, f"{which}_cov", new_cov)
        return test

    def update_position(self, z, R, monitor: SensorMonitor | None = None, t: float = math.nan) -> InnovationTest | None:
        """GPS position update (Eqs. 26-30). With a ``monitor`` the datum is used only if it passes the χ² gate and
        the sensor is not isolated (Eq. 44); returns the test, or ``None`` for an isolated sensor."""
        return self._update("position", z, R, monitor, t)

    def update_velocity(self, z, R, monitor: SensorMonitor | None = None, t: float = math.nan) -> InnovationTest | None:
        """GPS velocity update (Eq. 39 with Eqs. 27-30), gated like :meth:`update_position`."""
        return self._update("velocity", z, R, monitor, t)


class GpsFaultIsolation:
    """Isolation of faulty GPS receivers by a bank of observers (the "generalised observer scheme", Frank, 1990;
    [NOT IN PAPER]: the paper's Eq. 44 tests each datum against the one filter that every receiver feeds).

    ``filter`` uses every healthy receiver. For each receiver ``i`` a copy of it uses every healthy receiver
    *but* ``i``, and receiver ``i``'s datum is tested (Eqs. 43-44) against that copy's prediction. A receiver
    whose error grows slowly (a drift) therefore cannot drag its own reference along, and a healthy receiver
    is not blamed for the fix a faulty one pulled away; with a single receiver the reference is dead reckoning.
    A datum that passes updates the filter and every copy but its own; a
    :class:`~fusion.navigation_faults.SensorMonitor` per receiver turns failures into isolation (``k`` of the last
    ``n``), after which the receiver is ignored.

    Limitation: with exactly two receivers a *slow* drift cannot be attributed, since each receiver's reference
    is fed by the other one and follows it; either may be isolated. One receiver (tested against dead reckoning)
    or three and more (a majority) isolate the drifting one. A step larger than the gate is isolated in every
    case, before the filter has moved."""

    def __init__(self, nav: NavigationFilter, receivers, probability: float = 0.99, k: int = 3, n: int = 5):
        names = list(receivers)
        if not names or len(set(names)) != len(names):
            raise ValueError(f"receivers must be distinct names, at least one, got {receivers!r}")
        self.filter = nav
        self.monitors = {name: SensorMonitor(name, 3, probability, k, n) for name in names}
        self._without = {name: copy.deepcopy(nav) for name in names}  # filter i: every receiver but i

    def predict(self, q, speed: float, specific_force, dt: float) -> None:
        """:meth:`NavigationFilter.predict` on the filter, and its position part on every copy."""
        self.filter.predict(q, speed, specific_force, dt)
        for nav in self._without.values():
            nav.predict_position(q, speed, dt)

    def update_position(self, receiver: str, z, R, t: float) -> InnovationTest | None:
        """Test receiver ``receiver``'s fix against the filter that excludes it; use it if it passes and the receiver
        is healthy. Returns the test, or ``None`` once the receiver is isolated."""
        if receiver not in self.monitors:
            raise ValueError(f"unknown receiver {receiver!r}; known: {sorted(self.monitors)}")
        monitor = self.monitors[receiver]
        if monitor.isolated:
            return None
        reference = self._without[receiver]
        z = as_vector(z, "GPS position", 3)
        test = innovation_test(z - reference.position, reference.position_cov + as_pd(R, "GPS position noise R", 3))
        if monitor.admit(test, t):
            for name, nav in (("", self.filter), *self._without.items()):
                if name != receiver:
                    nav.update_position(z, R)
        return test

    def update_velocity(self, z, R, monitor: SensorMonitor | None = None, t: float = math.nan) -> InnovationTest | None:
        """GPS velocity update of the filter (the copies only serve position tests)."""
        return self.filter.update_velocity(z, R, monitor, t)

    @property
    def isolated(self) -> list[str]:
        return [name for name, m in self.monitors.items() if m.isolated]
