"""Feature paths as polynomials in a virtual arc length, and the flight quantities along them.

Lee, Kaminer, Dobrokhodov and Jones, "Autonomous Feature Following for Visual Surveillance Using a Small
Unmanned Aerial Vehicle with Gimbaled Camera System" (NPS, 2010), spec 003 §2.1-§2.2.

Polynomial path (spec 003 §2.1). Each coordinate of ``p(τ) = [x(τ), y(τ), z(τ)]`` (local NED: north,
east, down) is a polynomial in the virtual arc length ``τ ∈ [0, τ_f]``:

    x_i(τ) = Σ_{d=0..N} a_{i,d} τ^d                                                      (Eq. 1)

whose coefficients follow from the boundary conditions ``x_i^{(r)}(0)``, ``r <= N0``, and
``x_i^{(r)}(τ_f)``, ``r <= Nf``, of minimum degree ``N* = N0 + Nf + 1``; for ``N0 = Nf = 2`` this is the
quintic of the corrected Eq. 2 (:func:`boundary_polynomial`, any ``N0``, ``Nf``).

The paper leaves open how a polynomial follows an arbitrary scribbled road (spec 003 §2.1 ⚠). Chosen here:
a *piecewise* quintic (:class:`PolynomialPath`), one Eq.-2 segment between consecutive polyline points,
with ``τ`` the chord length along the polyline (so ``τ_f`` is the polyline length) and the knot
conditions ``p, p', p''`` taken from the natural cubic spline through the points (:func:`fit_feature`).
The path is then C² and passes through every operator point; because a cubic satisfies the six conditions
of Eq. 2, each quintic segment *is* that spline's cubic (the tests use scipy's spline as the oracle). The
same segment solver builds the UAV flight path (:mod:`tasking.feature_following`), whose knot conditions
are not those of a cubic. No smoothing of the scribble is applied (spec 003 leaves it unspecified): the
caller passes the points it wants interpolated.

Flight quantities along a path flown at constant speed ``v`` (spec 003 §2.2):

    T = p'/‖p'‖,   κ = ‖dT/dτ‖ / ‖p'‖ = ‖(I - T Tᵀ) p''‖ / ‖p'‖²                          (Eqs. 3-4)
    φ = atan(v² κ / g)                  (bank; the paper's "v κ / g" is a typo)            (Eq. 5)
    φ̇ = dφ/dτ · v / ‖p'‖                                                                   (Eq. 7)
    a_p = v² / ‖p'‖² · ‖(I - p'p'ᵀ/‖p'‖²) p''‖                                             (Eq. 9)

``speed`` may be an array broadcasting against ``τ`` (e.g. (S, 1) speeds by (M,) τ values). Bank and roll rate
are signed (:func:`signed_curvature`): a right turn (clockwise seen from above,
north -> east) has positive curvature and positive bank (right wing down, FRD roll), as in
:mod:`agent.vehicles.fixed_wing`.
"""

from __future__ import annotations

import bisect
import math

import numpy as np
from scipy.interpolate import CubicSpline

from fusion.validation import as_vector

#: Standard gravity (m/s²), the value :mod:`agent.vehicles.base` uses (tasking may not import agent).
GRAVITY = 9.80665

#: Relative tolerance on τ outside ``[0, τ_f]`` (rounding of a caller's arithmetic), chosen here.
TAU_RTOL = 1e-9

#: Degree of every segment of a :class:`PolynomialPath`: the quintic of Eq. 2 (``N0 = Nf = 2``).
SEGMENT_DEGREE = 5

#: Highest derivative order :meth:`PolynomialPath.derivative` serves (Eq. 7 needs p''').
MAX_ORDER = 3


def _falling_factorial(k: np.ndarray, r: int) -> np.ndarray:
    """``k! / (k - r)!`` (zero where ``k < r``): the factor of ``a_k τ^(k-r)`` in the r-th derivative."""
    out = np.ones(k.shape)
    for j in range(r):
        out = out * (k - j)
    return np.where(k >= r, out, 0.0)


def boundary_matrix(tau_f, n0: int, nf: int) -> np.ndarray:
    """The matrix of Eq. 2 generalised to ``N0``, ``Nf``: rows ``x^{(r)}(0)``, r = 0..N0, then
    ``x^{(r)}(τ_f)``, r = 0..Nf, columns ``a_0 .. a_N*`` (``N* = N0 + Nf + 1``). Broadcasts over ``tau_f``."""
    tau_f = np.asarray(tau_f, dtype=float)
    k = np.arange(n0 + nf + 2)
    rows = []
    for r in range(n0 + 1):  # x^{(r)}(0) = r! a_r
        rows.append(np.broadcast_to(np.where(k == r, _falling_factorial(k, r), 0.0), tau_f.shape + k.shape))
    for r in range(nf + 1):  # x^{(r)}(τ_f) = Σ_k k!/(k-r)! a_k τ_f^(k-r)
        power = np.maximum(k - r, 0)
        rows.append(_falling_factorial(k, r) * tau_f[..., None] ** power)
    return np.stack(rows, axis=-2)


def boundary_polynomial(tau_f, start, end) -> np.ndarray:
    """Coefficients ``a_{i,d}`` of Eq. 1 from the boundary conditions (Eq. 2, solved exactly).

    ``start`` (..., N0+1, D) holds ``p(0), p'(0), ..., p^{(N0)}(0)`` and ``end`` (..., Nf+1, D) the same at
    ``τ_f`` (..., ); returns (..., D, N*+1), lowest power first. ``τ_f`` must be positive."""
    tau_f = np.asarray(tau_f, dtype=float)
    start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    if not np.all(np.isfinite(tau_f)) or np.any(tau_f <= 0.0):
        raise ValueError(f"tau_f must be positive and finite, got {tau_f}")
    if not (np.all(np.isfinite(start)) and np.all(np.isfinite(end))):
        raise ValueError("boundary conditions contain non-finite values (NaN or inf)")
    A = boundary_matrix(tau_f, start.shape[-2] - 1, end.shape[-2] - 1)
    rhs = np.concatenate([start, end], axis=-2)  # [x(0), x'(0), ..., x(τ_f), x'(τ_f), ...]
    return np.swapaxes(np.linalg.solve(A, rhs), -1, -2)  # A a = rhs (Eq. 2)


class PolynomialPath:
    """A C² piecewise polynomial path ``p(τ)`` in NED, ``τ ∈ [0, τ_f]`` (Eq. 1 per segment).

    ``knots`` (K+1,) increasing from 0; ``coefficients`` (K, 3, N+1): segment ``k`` is
    ``Σ_d a_{k,i,d} (τ - knots[k])^d``. Build it with :meth:`from_knot_conditions` or :func:`fit_feature`."""

    def __init__(self, knots, coefficients):
        knots = as_vector(knots, "knots")
        coefficients = np.asarray(coefficients, dtype=float)
        if knots.size < 2 or knots[0] != 0.0 or np.any(np.diff(knots) <= 0.0):
            raise ValueError(f"knots must start at 0 and increase strictly, got {knots}")
        if coefficients.ndim != 3 or coefficients.shape[:2] != (knots.size - 1, 3):
            raise ValueError(f"coefficients must be ({knots.size - 1}, 3, N+1), got shape {coefficients.shape}")
        if not np.all(np.isfinite(coefficients)):
            raise ValueError("path coefficients contain non-finite values (NaN or inf)")
        self.knots = knots
        self.coefficients = coefficients
        powers = np.arange(coefficients.shape[2])
        # Derivative coefficients (order r: a_k k!/(k-r)! multiplies s^(k-r)), computed once.
        self._derivatives = [coefficients * _falling_factorial(powers, r) for r in range(MAX_ORDER + 1)]
        self._exponents = [np.maximum(powers - r, 0).astype(float) for r in range(MAX_ORDER + 1)]
        self._knot_list = knots.tolist()

    @classmethod
    def from_knot_conditions(cls, knots, conditions) -> PolynomialPath:
        """Quintic segments through ``conditions`` (K+1, 3, 3) = ``[p, p', p'']`` at each knot (Eq. 2)."""
        knots = as_vector(knots, "knots")
        conditions = np.asarray(conditions, dtype=float)
        if conditions.shape != (knots.size, 3, 3):
            raise ValueError(f"conditions must be ({knots.size}, 3, 3) = [p, p', p''] per knot, got {conditions.shape}")
        return cls(knots, boundary_polynomial(np.diff(knots), conditions[:-1], conditions[1:]))

    @property
    def tau_f(self) -> float:
        """Total virtual arc length ``τ_f``."""
        return float(self.knots[-1])

    def derivative(self, tau, order: int = 0) -> np.ndarray:
        """``d^order p / dτ^order`` at ``tau`` (scalar or (M,)) -> (3,) or (M, 3)."""
        if order not in range(MAX_ORDER + 1):
            raise ValueError(f"derivative order must be 0..{MAX_ORDER}, got {order}")
        tau_f = self._knot_list[-1]
        exponents = self._exponents[order]  # s^(k - r); the factor in the coefficients zeroes k < r
        if isinstance(tau, float | int | np.floating) and not isinstance(tau, bool):  # one point: plain Python
            value = float(tau)
            if not math.isfinite(value) or not -TAU_RTOL * tau_f <= value <= tau_f * (1.0 + TAU_RTOL):
                raise ValueError(f"tau must be a finite value in [0, tau_f = {tau_f:.6g}], got {tau}")
            value = min(max(value, 0.0), tau_f)
            segment = min(bisect.bisect_right(self._knot_list, value) - 1, len(self._knot_list) - 2)
            return self._derivatives[order][segment] @ (value - self._knot_list[segment]) ** exponents
        t = np.asarray(tau, dtype=float)
        if not np.all(np.isfinite(t)):
            raise ValueError("tau contains non-finite values (NaN or inf)")
        if np.any(t < -TAU_RTOL * tau_f) or np.any(t > tau_f * (1.0 + TAU_RTOL)):
            raise ValueError(f"tau must lie in [0, tau_f = {tau_f:.6g}], got values in [{t.min()}, {t.max()}]")
        flat = np.minimum(np.maximum(t.ravel(), 0.0), self.tau_f)
        segment = np.minimum(np.searchsorted(self.knots, flat, side="right") - 1, self.knots.size - 2)
        powers = (flat - self.knots[segment])[:, None] ** exponents
        value = np.sum(self._derivatives[order][segment] * powers[:, None, :], axis=-1)
        return value.reshape(t.shape + (3,))

    def position(self, tau) -> np.ndarray:
        return self.derivative(tau, 0)

    def sample_tau(self, spacing: float) -> np.ndarray:
        """τ values at most ``spacing`` apart from 0 to ``τ_f`` (both included)."""
        if not (math.isfinite(spacing) and spacing > 0):
            raise ValueError(f"spacing must be a positive number, got {spacing}")
        return np.linspace(0.0, self.tau_f, max(2, math.ceil(self.tau_f / spacing) + 1))


def _as_polyline(points) -> np.ndarray:
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"the feature polyline must be (N, 2) (north, east) points, got shape {pts.shape}")
    if pts.shape[0] < 2:
        raise ValueError(f"the feature polyline needs at least 2 points, got {pts.shape[0]}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("the feature polyline contains non-finite values (NaN or inf)")
    chords = np.hypot(*np.diff(pts, axis=0).T)
    if np.any(chords <= 0.0):
        first = int(np.flatnonzero(chords <= 0.0)[0])
        raise ValueError(f"the feature polyline repeats point {first} at index {first + 1}: {pts[first].tolist()}")
    return pts


def fit_feature(points_ne, down: float = 0.0) -> PolynomialPath:
    """The feature path through an operator's polyline of (north, east) points at depth ``down`` (m, NED).

    ``τ`` is the chord length; the knot conditions ``p, p', p''`` are those of the natural cubic spline through
    the points (zero second derivative at the two ends), and each segment is the Eq.-2 quintic through them.
    Raises ``ValueError`` for fewer than 2 points, a repeated consecutive point, or a non-finite value."""
    pts = _as_polyline(points_ne)
    if not math.isfinite(down):
        raise ValueError(f"down must be finite, got {down}")
    knots = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])  # chord length
    spline = CubicSpline(knots, pts, bc_type="natural")
    conditions = np.zeros((knots.size, 3, 3))
    for r in range(3):
        conditions[:, r, :2] = spline(knots, r)
    conditions[:, 0, 2] = down
    return PolynomialPath.from_knot_conditions(knots, conditions)


# -- flight quantities (Eqs. 3-9) ------------------------------------------------------------------
def _check_speed(speed) -> np.ndarray | float:
    """A positive finite speed (m/s), or an array of them broadcasting against τ (e.g. (S, 1) for S speeds)."""
    if isinstance(speed, bool):
        raise ValueError(f"speed must be a finite number of m/s, got {speed!r}")
    v = np.asarray(speed, dtype=float)
    if not np.all(np.isfinite(v)):
        raise ValueError(f"speed must be a finite number of m/s, got {speed!r}")
    if np.any(v <= 0):
        raise ValueError(f"speed must be positive, got {speed}")
    return float(v) if v.ndim == 0 else v


def _speed_along(path: PolynomialPath, tau) -> np.ndarray:
    """``‖p'(τ)‖``; a stationary point (``p' = 0``) has no tangent and raises ``ValueError``."""
    norm = np.linalg.norm(path.derivative(tau, 1), axis=-1)
    if np.any(norm <= 0.0):
        raise ValueError("the path is stationary (p'(tau) = 0) at some tau: its tangent is undefined")
    return norm


def unit_tangent(path: PolynomialPath, tau) -> np.ndarray:
    """``T = p'/‖p'‖`` (Eq. 4)."""
    return path.derivative(tau, 1) / _speed_along(path, tau)[..., None]


def curvature(path: PolynomialPath, tau) -> np.ndarray:
    """``κ = ‖(I - T Tᵀ) p''‖ / ‖p'‖²`` (Eqs. 3-4; ``dT/dτ = (I - T Tᵀ) p'' / ‖p'‖``), 1/m."""
    d1, d2 = path.derivative(tau, 1), path.derivative(tau, 2)
    norm = _speed_along(path, tau)
    T = d1 / norm[..., None]
    normal_part = d2 - np.sum(d2 * T, axis=-1, keepdims=True) * T  # (I - T Tᵀ) p''
    return np.linalg.norm(normal_part, axis=-1) / norm**2


def _horizontal_terms(path: PolynomialPath, tau):
    d1, d2, d3 = (path.derivative(tau, r) for r in (1, 2, 3))
    s2 = d1[..., 0] ** 2 + d1[..., 1] ** 2
    if np.any(s2 <= 0.0):
        raise ValueError("the path is vertical (no horizontal tangent) at some tau: no signed curvature")
    cross = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]  # x'y'' - y'x''
    return d1, d2, d3, s2, cross


def signed_curvature(path: PolynomialPath, tau) -> np.ndarray:
    """Curvature of the horizontal projection, positive for a right turn (clockwise from above):
    ``κ_s = (x'y'' - y'x'') / (x'² + y'²)^{3/2}`` (equal to Eq. 3's κ for a level path), 1/m."""
    _, _, _, s2, cross = _horizontal_terms(path, tau)
    return cross / s2**1.5


def signed_curvature_rate(path: PolynomialPath, tau) -> np.ndarray:
    """``dκ_s/dτ = (x'y''' - y'x''') / s³ - 3 (x'y'' - y'x'')(x'x'' + y'y'') / s⁵``, ``s = ‖(x', y')‖``."""
    d1, d2, d3, s2, cross = _horizontal_terms(path, tau)
    cross3 = d1[..., 0] * d3[..., 1] - d1[..., 1] * d3[..., 0]
    dot = d1[..., 0] * d2[..., 0] + d1[..., 1] * d2[..., 1]
    return cross3 / s2**1.5 - 3.0 * cross * dot / s2**2.5


def bank_angle(path: PolynomialPath, tau, speed: float) -> np.ndarray:
    """Coordinated-turn bank ``φ = atan(v² κ_s / g)`` (Eq. 5, signed), rad."""
    v = _check_speed(speed)
    return np.arctan(v * v * signed_curvature(path, tau) / GRAVITY)  # φ = atan(v² κ / g)


def roll_rate(path: PolynomialPath, tau, speed: float) -> np.ndarray:
    """``φ̇ = dφ/dτ · v / ‖p'‖`` (Eq. 7) with ``dφ/dτ = (v²/g) κ_s' / (1 + (v² κ_s / g)²)``, rad/s."""
    v = _check_speed(speed)
    c = v * v / GRAVITY
    dphi_dtau = c * signed_curvature_rate(path, tau) / (1.0 + (c * signed_curvature(path, tau)) ** 2)
    return dphi_dtau * v / _speed_along(path, tau)  # φ̇ = dφ/dτ · v/‖p'‖


def lateral_acceleration(path: PolynomialPath, tau, speed: float) -> np.ndarray:
    """``a_p = v²/‖p'‖² ‖(I - p'p'ᵀ/‖p'‖²) p''‖`` (Eq. 9), m/s² (``= v² κ``)."""
    v = _check_speed(speed)
    d1, d2 = path.derivative(tau, 1), path.derivative(tau, 2)
    n2 = _speed_along(path, tau) ** 2
    normal_part = d2 - (np.sum(d1 * d2, axis=-1) / n2)[..., None] * d1  # (I - p'p'ᵀ/‖p'‖²) p''
    return v * v / n2 * np.linalg.norm(normal_part, axis=-1)
