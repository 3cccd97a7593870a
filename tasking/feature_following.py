"""Feature following: the pointing geometry, the UAV flight-path optimisation and the guidance set-points.

Lee, Kaminer, Dobrokhodov and Jones, "Autonomous Feature Following for Visual Surveillance Using a Small
Unmanned Aerial Vehicle with Gimbaled Camera System" (NPS, 2010), spec 003 §2.3-§2.5.

Pointing geometry (Eqs. 10-13), pinned down here because the paper leaves the frame open (spec 003 §2.3 ⚠).
Resolve the line of sight ``ℓ = p_T(τ) - p_UAV(τ)`` (UAV to feature; Eq. 11 uses its negative, which leaves
the ratio unchanged) in the UAV *path frame*: x along the horizontal track, y to the right, z down. Then

    λ = atan2(ℓ_y, ℓ_z)                                                              (Eqs. 10-11)

is the LOS angle from the local vertical in the lateral plane, positive when the feature is to the right
(the paper's ``φ_T`` is the same line measured from the horizon, ``φ_T = π/2 - |λ|``). A roll ``φ``
(FRD: right wing down) turns the body-down axis to ``-φ``; a lateral gimbal angle ``φ_G`` (from body down,
positive right) turns the optical axis to ``φ_G - φ``. The feature is at the image centre iff

    e = λ - (φ_G - φ_UAV) = 0                  (Eq. 12; the paper's φ_T = π/2 - (φ_UAV + φ_G) with its
                                                bank measured positive towards the feature)
    |e| <= ε < θ/2                             (Eq. 13; θ the camera field of view, the OCR's "9/2")

and the centring gimbal command is ``φ_G = λ + φ_UAV`` (spec 003 [DERIVED]).

Flight-path optimisation (Eqs. 14-17):

    min ε  subject to  |φ_UAV| <= φ_max,  |φ̇_UAV| <= φ̇_max,  |e(τ)| <= ε < θ/2,
                       v_min <= v <= v_max,  a_p(τ) <= a_max

with φ_UAV, φ̇_UAV, a_p from Eqs. 5, 7, 9 on the UAV path. Choices made here (spec 003 §2.4 ⚠):

* the UAV path is the feature offset sideways by a constant ``d`` (positive to the right of the feature's
  direction) at a constant altitude, built as Eq.-2 quintics through the exact offset's ``p, p', p''`` at
  the feature's knots (:func:`offset_path`); the decision variables are ``(v, d)`` (``τ_f`` is fixed by
  the operator's feature);
* the gimbal's lateral angle is limited to ``look_range`` (default 10°-80° to the right: the camera looks
  out of the right side, at least 10° off nadir where a pan/tilt gimbal has its singularity; equal bounds
  model a fixed camera). Where ``λ + φ_UAV`` is out of range the gimbal stops at the limit and ``e ≠ 0``;
* constraints are enforced on a τ grid; the solver is a grid search over ``(v, d)`` refined once around the
  best offset. Among candidates whose ε is within :data:`EPSILON_TIE` of the least, the smallest ``|d|``
  (closest feature, finest ground resolution) wins, then the speed nearest ``preferred_speed``.

Guidance (spec 003 §2.5: the paper defers the path-following law to its ref. [2]; a substitute, [NOT IN
PAPER]): :class:`PathFollower` turns the UAV path into :class:`tasking.orbit.Goal` set-points by a
vector field (Nelson et al., 2007): the desired course ``χ_d = χ_path - χ_∞ (2/π) atan(k e_y)`` with ``e_y``
the signed cross-track error, expressed as a carrot point ``carrot_distance`` ahead along ``χ_d``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tasking.feature_path import (
    PolynomialPath,
    bank_angle,
    lateral_acceleration,
    roll_rate,
)
from tasking.orbit import Goal, orbit_setpoint

#: ε values within this of the least are ties (rad), broken by the offset and then the speed. Chosen here.
EPSILON_TIE = 1e-3

_RIGHT = np.array([[0.0, -1.0], [1.0, 0.0]])  # rotates a horizontal (north, east) direction 90° to the right


# -- geometry ----------------------------------------------------------------------------------------------
def _right_normal_and_derivatives(d1: np.ndarray, d2: np.ndarray, d3: np.ndarray):
    """The horizontal right normal ``n = J u / s`` (``u = (x', y')``, ``s = ‖u‖``) and ``n'``, ``n''``."""
    u, u1, u2 = d1[..., :2], d2[..., :2], d3[..., :2]
    s = np.linalg.norm(u, axis=-1, keepdims=True)
    s1 = np.sum(u * u1, axis=-1, keepdims=True) / s  # s' = u·u'/s
    s2 = (np.sum(u1 * u1, axis=-1, keepdims=True) + np.sum(u * u2, axis=-1, keepdims=True)) / s - s1**2 / s
    Ju, Ju1, Ju2 = u @ _RIGHT.T, u1 @ _RIGHT.T, u2 @ _RIGHT.T
    n = Ju / s
    n1 = Ju1 / s - Ju * s1 / s**2
    n2 = Ju2 / s - 2.0 * Ju1 * s1 / s**2 - Ju * s2 / s**2 + 2.0 * Ju * s1**2 / s**3
    return n, n1, n2


def offset_path(feature: PolynomialPath, offset: float, down: float) -> PolynomialPath:
    """The feature shifted ``offset`` metres to the right of its direction (left if negative), at depth ``down``.

    Knot conditions ``p + d n``, ``p' + d n'``, ``p'' + d n''`` (``n`` the horizontal right normal) are exact;
    each segment is the Eq.-2 quintic through them. Raises ``ValueError`` when the offset exceeds the radius
    of curvature on the inside of a turn at a knot (the offset curve would reverse: a cusp)."""
    if not (math.isfinite(offset) and math.isfinite(down)):
        raise ValueError(f"offset and down must be finite, got offset={offset}, down={down}")
    d1, d2, d3 = (feature.derivative(feature.knots, r) for r in (1, 2, 3))
    n, n1, n2 = _right_normal_and_derivatives(d1, d2, d3)
    cond = np.zeros((feature.knots.size, 3, 3))
    cond[:, 0, :2] = feature.position(feature.knots)[:, :2] + offset * n
    cond[:, 1, :2] = d1[:, :2] + offset * n1
    cond[:, 2, :2] = d2[:, :2] + offset * n2
    cond[:, 0, 2] = down
    if np.any(np.sum(cond[:, 1, :2] * d1[:, :2], axis=1) <= 0.0):
        raise ValueError(f"offset {offset} m exceeds the feature's radius of curvature inside a turn (cusp)")
    return PolynomialPath.from_knot_conditions(feature.knots, cond)


def lateral_los_angle(uav_path: PolynomialPath, feature: PolynomialPath, tau) -> np.ndarray:
    """``λ = atan2(ℓ_y, ℓ_z)`` (Eqs. 10-11 in the path frame, see the module docstring), rad."""
    los = feature.position(tau) - uav_path.position(tau)  # ℓ = p_T - p_UAV
    tangent = uav_path.derivative(tau, 1)[..., :2]
    right = tangent @ _RIGHT.T / np.linalg.norm(tangent, axis=-1, keepdims=True)
    return np.arctan2(np.sum(los[..., :2] * right, axis=-1), los[..., 2])  # λ = atan2(ℓ_y, ℓ_z)


def pointing_residual(los_angle, bank, gimbal_angle):
    """``e = λ - (φ_G - φ_UAV)``: zero iff the feature is at the image centre (Eq. 12)."""
    return np.asarray(los_angle) - (np.asarray(gimbal_angle) - np.asarray(bank))


def centring_gimbal_angle(los_angle, bank):
    """The lateral gimbal angle that centres the feature, ``φ_G = λ + φ_UAV`` (Eq. 12 solved)."""
    return np.asarray(los_angle) + np.asarray(bank)


def in_image(residual, field_of_view: float):
    """Whether the feature stays in the image, ``|e| < θ/2`` (Eq. 13)."""
    return np.abs(residual) < 0.5 * field_of_view


# -- optimisation ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FlightPathLimits:
    """The constraints of Eqs. 15-17 and the camera. Angles in radians.

    ``max_bank`` 35° is the paper's (Eq. 6). Chosen here (spec 003 leaves them open): roll rate 20°/s, speed
    15-25 m/s (a Rascal-class aircraft), ``max_acceleration`` 6 m/s² (below ``g tan 35° ≈ 6.9``), the
    lateral gimbal ``look_range`` 10°-80° (see the module docstring), field of view 30° (the paper's mosaic
    camera) and offsets searched within ±``max_offset`` = 400 m."""

    max_bank: float = math.radians(35.0)
    max_roll_rate: float = math.radians(20.0)
    speed_range: tuple[float, float] = (15.0, 25.0)
    max_acceleration: float = 6.0
    look_range: tuple[float, float] = (math.radians(10.0), math.radians(80.0))
    field_of_view: float = math.radians(30.0)
    max_offset: float = 400.0

    def __post_init__(self):
        for name in ("max_bank", "max_roll_rate", "max_acceleration", "field_of_view", "max_offset"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        if self.max_bank >= 0.5 * math.pi or self.field_of_view >= math.pi:
            raise ValueError(f"max_bank must be below 90° and field_of_view below 180°, got {self}")
        lo, hi = self.speed_range
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
            raise ValueError(f"speed_range must be (v_min, v_max) with 0 < v_min <= v_max, got {self.speed_range}")
        lo, hi = self.look_range
        if not (math.isfinite(lo) and math.isfinite(hi) and -0.5 * math.pi < lo <= hi < 0.5 * math.pi):
            raise ValueError(f"look_range must be (min, max) within (-90°, 90°), got {self.look_range}")


@dataclass(frozen=True)
class FlightPath:
    """An optimised UAV path and its profile on the τ grid ``tau``: bank, roll rate (Eqs. 5, 7), lateral
    acceleration (Eq. 9), LOS angle λ (Eqs. 10-11), lateral gimbal angle and the residual ``e`` (Eq. 12).
    ``epsilon`` is ``max |e|`` (Eq. 14); ``altitude`` is the height above the feature (m)."""

    feature: PolynomialPath
    uav_path: PolynomialPath
    speed: float
    offset: float
    altitude: float
    epsilon: float
    tau: np.ndarray
    bank: np.ndarray
    roll_rate: np.ndarray
    lateral_acceleration: np.ndarray
    los_angle: np.ndarray
    gimbal_angle: np.ndarray
    residual: np.ndarray


def _candidates(feature, offset, altitude, tau, speeds, limits) -> list[FlightPath]:
    """The profiles of offset ``d`` at each of ``speeds`` that meet Eqs. 15-17 (none if the offset has a cusp)."""
    try:
        path = offset_path(feature, offset, feature.position(0.0)[2] - altitude)
    except ValueError:
        return []
    if np.any(np.sum(path.derivative(tau, 1)[:, :2] * feature.derivative(tau, 1)[:, :2], axis=1) <= 0.0):
        return []  # reversed between knots
    lam = lateral_los_angle(path, feature, tau)
    v = np.asarray(speeds, dtype=float)[:, None]  # every speed at once: (S, M) profiles
    bank, rate, accel = bank_angle(path, tau, v), roll_rate(path, tau, v), lateral_acceleration(path, tau, v)
    gimbal = np.clip(centring_gimbal_angle(lam, bank), *limits.look_range)
    residual = pointing_residual(lam, bank, gimbal)
    epsilon = np.max(np.abs(residual), axis=1)  # ε = max_τ |e(τ)| (Eq. 16)
    feasible = (
        np.all(np.abs(bank) <= limits.max_bank, axis=1)  # Eq. 15
        & np.all(np.abs(rate) <= limits.max_roll_rate, axis=1)  # Eq. 15
        & np.all(accel <= limits.max_acceleration, axis=1)  # Eq. 17
        & (epsilon < 0.5 * limits.field_of_view)  # Eq. 16
    )
    found = [
        FlightPath(feature, path, float(v[i, 0]), offset, altitude, float(epsilon[i]), tau, bank[i], rate[i],
                   accel[i], lam, gimbal[i], residual[i])
        for i in np.flatnonzero(feasible)
    ]
    return found


def optimise_flight_path(
    feature: PolynomialPath,
    altitude: float,
    limits: FlightPathLimits | None = None,
    *,
    spacing: float = 10.0,
    offsets: int = 41,
    speeds: int = 5,
    preferred_speed: float | None = None,
) -> FlightPath:
    """Solve Eqs. 14-17 for ``(v, d)`` on a grid (``offsets`` x ``speeds``, then ``offsets`` finer offsets around
    the best), with constraints checked every ``spacing`` metres of τ. ``altitude`` (m) is the flight height
    above the feature; ``preferred_speed`` breaks ties (default: the middle of ``speed_range``).

    Raises ``ValueError`` when no candidate meets the constraints."""
    limits = FlightPathLimits() if limits is None else limits
    if not (math.isfinite(altitude) and altitude > 0):
        raise ValueError(f"altitude must be a positive number of metres above the feature, got {altitude}")
    if offsets < 2 or speeds < 1:
        raise ValueError(f"need at least 2 offsets and 1 speed on the grid, got {offsets}, {speeds}")
    v_lo, v_hi = limits.speed_range
    v_pref = 0.5 * (v_lo + v_hi) if preferred_speed is None else float(preferred_speed)
    tau = feature.sample_tau(spacing)
    speed_grid = np.linspace(v_lo, v_hi, speeds)

    def best_of(offset_grid):
        found = [c for d in offset_grid for c in _candidates(feature, float(d), altitude, tau, speed_grid, limits)]
        if not found:
            return None
        least = min(c.epsilon for c in found)
        ties = [c for c in found if c.epsilon <= least + EPSILON_TIE]
        return min(ties, key=lambda c: (abs(c.offset), abs(c.speed - v_pref)))

    coarse = np.linspace(-limits.max_offset, limits.max_offset, offsets)
    best = best_of(coarse)
    if best is None:
        raise ValueError(
            f"no flyable path within the limits {limits} at altitude {altitude} m: every (speed, offset) on the grid "
            "breaks the bank, roll-rate, acceleration or field-of-view constraint"
        )
    step = coarse[1] - coarse[0]
    fine = best_of(np.linspace(best.offset - step, best.offset + step, offsets))
    return best if fine is None or (fine.epsilon, abs(fine.offset)) > (best.epsilon, abs(best.offset)) else fine


# -- guidance ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PathFollower:
    """Set-points that fly a :class:`FlightPath` with a constant-airspeed vehicle (vector-field guidance,
    see the module docstring). Chosen here: ``χ_∞`` 60°, ``k`` 0.02 /m, the carrot 200 m ahead (beyond the
    loiter radius of :mod:`agent.vehicles.fixed_wing`, so a position set-point never counts as reached) and a
    150 m loiter circle around the end of the path once it is flown."""

    flight: FlightPath
    approach_angle: float = math.radians(60.0)
    cross_track_gain: float = 0.02
    carrot_distance: float = 200.0
    loiter_radius: float = 150.0
    sample_spacing: float = 5.0

    def __post_init__(self):
        for name in ("approach_angle", "cross_track_gain", "carrot_distance", "loiter_radius", "sample_spacing"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        tau = self.flight.uav_path.sample_tau(self.sample_spacing)
        object.__setattr__(self, "_tau", tau)
        object.__setattr__(self, "_points", self.flight.uav_path.position(tau)[:, :2])

    def closest_tau(self, position) -> float:
        """τ of the UAV-path point horizontally closest to ``position`` (nearest sample, then Newton steps on
        ``(p(τ) - x)·p'(τ) = 0``)."""
        x = np.asarray(position, dtype=float)[:2]
        if x.shape != (2,) or not np.all(np.isfinite(x)):
            raise ValueError(f"position must be a finite NED point, got {position!r}")
        path = self.flight.uav_path
        tau = float(self._tau[np.argmin(np.sum((self._points - x) ** 2, axis=1))])
        for _ in range(3):
            diff = path.position(tau)[:2] - x
            d1, d2 = path.derivative(tau, 1)[:2], path.derivative(tau, 2)[:2]
            slope = d1 @ d1 + diff @ d2
            if slope <= 0.0:
                break
            tau = min(max(tau - (diff @ d1) / slope, 0.0), path.tau_f)
        return tau

    def abeam(self, position) -> tuple[float, np.ndarray, float]:
        """``(τ, unit tangent, signed cross-track error)`` at the closest UAV-path point."""
        tau = self.closest_tau(position)
        path = self.flight.uav_path
        tangent = path.derivative(tau, 1)[:2]
        tangent = tangent / np.linalg.norm(tangent)
        e_y = float((np.asarray(position, dtype=float)[:2] - path.position(tau)[:2]) @ (_RIGHT @ tangent))
        return tau, tangent, e_y

    def cross_track_error(self, position) -> float:
        """Signed horizontal distance from the UAV path (positive: the vehicle is right of it), m."""
        return self.abeam(position)[2]

    def feature_point(self, position) -> np.ndarray:
        """The feature point abeam ``position`` (same τ as the closest UAV-path point), NED."""
        return self.flight.feature.position(self.closest_tau(position))

    def finished(self, position) -> bool:
        """Whether the closest UAV-path point is within one sample spacing of the end."""
        return self.closest_tau(position) >= self.flight.uav_path.tau_f - self.sample_spacing

    def goal(self, position) -> Goal:
        """The set-point for a vehicle at ``position`` (NED): a carrot along the vector field's course, or the
        loiter circle around the path's end once it is flown."""
        path, speed = self.flight.uav_path, self.flight.speed
        height = -float(path.position(0.0)[2])  # above the NED origin
        tau, tangent, e_y = self.abeam(position)
        if tau >= path.tau_f - self.sample_spacing:
            return orbit_setpoint(path.position(path.tau_f)[:2], self.loiter_radius, height, 1, speed)
        course = math.atan2(tangent[1], tangent[0]) - self.approach_angle * (2 / math.pi) * math.atan(
            self.cross_track_gain * e_y
        )  # χ_d = χ_path - χ_∞ (2/π) atan(k e_y)
        heading = np.array([math.cos(course), math.sin(course)])
        carrot = np.asarray(position, dtype=float)[:2] + self.carrot_distance * heading
        return Goal(position=np.array([carrot[0], carrot[1], -height]), speed=speed)

    def setpoints(self, spacing: float) -> list[Goal]:
        """Way-points along the UAV path every ``spacing`` metres of τ (the compact uplink alternative)."""
        points = self.flight.uav_path.position(self.flight.uav_path.sample_tau(spacing))
        return [Goal(position=p, speed=self.flight.speed) for p in points]
