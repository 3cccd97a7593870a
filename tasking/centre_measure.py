"""The local "centre measure" of a bearing-only UAV on an orbit (Andreetto, Pacher, Macii, Palopoli and
Fontanelli, Electronics 2018; spec 004 §2.2, Eqs. (2)-(3)).

UAV ``i`` orbits its centre ``p̂_i`` (its estimate of the target) at distance ``r``; its camera axis points at
the centre with heading ``ψ_i``, ``c_i = [cos ψ_i, sin ψ_i]``. The camera measures the bearing ``η_i``, the
signed angle from the axis to the line of sight (LOS), so the LOS direction is ``ℓ_i = R(η_i) c_i``. Then

    ``m_i = p̂_i + l_⊥ sat_[-λ_i, λ_i](κ r sin η_i)``                        004 Eq. (2)
    ``sat_[-λ, λ](α) = min(max(α, -λ), λ)``                                   004 Eq. (3)
    ``λ_i = Λ r |sin η_i|``,  ``0 < Λ < 2``,  ``l_⊥ = R(+90°) ℓ_i``            (004 §2.2, reconstructed)

``r sin η_i · R(+90°) ℓ_i`` is exactly the vector from ``p̂_i`` to the foot of its perpendicular on the LOS
(spec 004 §2.2, geometry check), so the step is ``β r sin η_i`` along that perpendicular with the effective
gain ``β = min(κ, Λ)``: ``κ`` binds when ``κ <= Λ``, the saturation (``Λ``) when ``κ > Λ`` — with the paper's
``κ > 5`` (its whiteness condition, 004 §2.6) and ``Λ < 2`` the saturation always binds (the κ-vs-Λ
inconsistency of spec 004 §2.2; :func:`saturation_binds` says which one binds). Because the target lies on the
LOS and ``0 < β < 2``, ``m_i`` is strictly closer to the target than ``p̂_i`` unless ``η_i = 0`` — 004 Eq. (6).

Here ``r`` is the UAV's distance to its centre: the orbit radius once the UAV is on its circle (the paper);
the simulator passes the GPS distance ``‖p̂_i - ξ_i‖``, which keeps Eq. (6) exact while the UAV is still
flying to its circle (chosen here). The target is visible (a measurement exists) only if it is within
``R_max`` and ``|η_i| <= η_max`` (the triangular bird's-eye FOV, 004 §1.1); otherwise there is no measure.

Angles are measured in the horizontal plane from the first axis towards the second, the sense of
``R(θ) = [[cos θ, -sin θ], [sin θ, cos θ]]``: in NED (north, east) that is the right-hand rule about the down
axis, which is the paper's "positive counter-clockwise (right-hand rule)".

Functions work on arrays with any leading batch shape (one entry per UAV, per run, ...), so the simulator
calls the same code for a whole Monte Carlo batch; :func:`centre_measure` is the one-UAV form.
"""

from __future__ import annotations

import math

import numpy as np

from fusion.validation import as_vector

#: 004 §3: the FOV half-aperture η_max = ±30 (degrees assumed, the unit was lost in extraction).
ETA_MAX = math.radians(30.0)


def rotate(vectors, angle) -> np.ndarray:
    """``R(angle) v`` for vectors ``(..., 2)`` and angles broadcasting against ``(...)``."""
    v = np.asarray(vectors, dtype=float)
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def heading(vectors) -> np.ndarray:
    """The angle of vectors ``(..., 2)`` from the first axis towards the second, in (-π, π]."""
    v = np.asarray(vectors, dtype=float)
    return np.arctan2(v[..., 1], v[..., 0])


def wrap_angle(angle) -> np.ndarray:
    """``angle`` wrapped to [-π, π)."""
    return np.mod(np.asarray(angle, dtype=float) + np.pi, 2.0 * np.pi) - np.pi


def bearing(uav_position, axis_heading, target_position) -> np.ndarray:
    """The true bearing ``η`` of the target: the signed angle from the camera axis to the LOS, in [-π, π)."""
    los = np.asarray(target_position, dtype=float) - np.asarray(uav_position, dtype=float)
    return wrap_angle(heading(los) - axis_heading)  # η = ∠(c_i, ℓ_i)


def visible(eta, target_range, eta_max: float = ETA_MAX, range_max: float = math.inf) -> np.ndarray:
    """Whether the triangular FOV holds the target: ``|η| <= η_max`` and range ``<= R_max`` (004 §1.1)."""
    _check_fov(eta_max, range_max)
    return (np.abs(eta) <= eta_max) & (np.asarray(target_range, dtype=float) <= range_max)


def saturate(alpha, limit) -> np.ndarray:
    """004 Eq. (3): ``alpha`` clipped to ``[-limit, limit]`` (``limit >= 0``)."""
    return np.clip(alpha, -np.asarray(limit), limit)


def saturation_binds(kappa: float, Lambda: float) -> bool:
    """True when the saturation of Eq. (3) is active at every bearing (``κ > Λ``): the step is then
    ``Λ r sin η`` whatever ``κ``; otherwise ``κ`` sets it."""
    _check_gains(kappa, Lambda)
    return kappa > Lambda


def centre_measures(centre, axis_heading, eta, radius, kappa: float, Lambda: float) -> np.ndarray:
    """004 Eq. (2) for a batch: ``centre (..., 2)``, ``axis_heading``, ``eta`` and ``radius`` broadcasting
    against ``(...)``. Every entry is treated as a measurement (visibility is the caller's: :func:`visible`)."""
    _check_gains(kappa, Lambda)
    centre = np.asarray(centre, dtype=float)
    eta = np.asarray(eta, dtype=float)
    radius = np.asarray(radius, dtype=float)
    if not np.all(np.isfinite(eta)):
        raise ValueError(f"bearing eta must be finite, got {eta[~np.isfinite(eta)].ravel()[:3]}")
    bad_radius = ~(np.isfinite(radius) & (radius >= 0))
    if np.any(bad_radius):
        raise ValueError(f"radius must be a finite non-negative distance, got {radius[bad_radius].ravel()[:3]}")
    if centre.shape[-1:] != (2,) or not np.all(np.isfinite(centre)):
        raise ValueError(f"centre must be finite (..., 2) positions, got shape {centre.shape}")
    los = rotate(np.stack([np.cos(axis_heading), np.sin(axis_heading)], axis=-1), eta)  # ℓ_i = R(η_i) c_i
    l_perp = rotate(los, math.pi / 2.0)  # l_⊥ = R(+90°) ℓ_i
    limit = Lambda * radius * np.abs(np.sin(eta))  # λ_i = Λ r |sin η_i|
    step = saturate(kappa * radius * np.sin(eta), limit)  # sat_[-λ_i, λ_i](κ r sin η_i), Eq. (3)
    return centre + l_perp * step[..., None]  # m_i = p̂_i + l_⊥ sat(...), Eq. (2)


def reflected_measures(centre, measures, kappa: float, Lambda: float) -> np.ndarray:
    """The centre measures of Eq. (2) taken to the full step ``2 r sin η_i``: ``p̂_i`` reflected across the LOS,

        ``m̃_i = p̂_i + (2 / β) (m_i - p̂_i) = p̂_i + 2 r sin η_i l_⊥``,  ``β = min(κ, Λ)``.

    Unbiased measure of the target for the Kalman filter (chosen here; the paper feeds the KCF ``m_{i,ML}``,
    spec 004 §2.6). With the target on the LOS and ``e = p̂_i - p``, Eq. (2) gives
    ``m_i - p = (I - β (I - ℓℓᵀ)) e``, and for ``n >= 3`` equally spaced UAVs ``(1/n) Σ ℓ_i ℓ_iᵀ = I/2``, so the
    centroid is ``m_ML - p = (1 - β/2) e``. That bias towards the current centre is what makes the static
    algorithm a contraction (Theorem 1), but a KCF with ``H = [I 0]`` reads it as the target: its innovations are
    ``β/2`` of the true error, so its velocity converges ``β/2`` as fast as its covariance claims, and a filter
    that enters the tracking stage with a large error settles on a wrong velocity and drifts away. The
    reflection gives ``m̃_i - p = (2ℓℓᵀ - I) e``, whose centroid is 0 for equal spacing (and never larger than
    ``|e|`` otherwise). Its noise is twice that of the LOS point: see :func:`reflected_noise_std`.

    ``centre (..., 2)`` are the ``p̂_i`` the measures ``(..., 2)`` were formed about."""
    _check_gains(kappa, Lambda)
    centre = np.asarray(centre, dtype=float)
    return centre + (2.0 / min(kappa, Lambda)) * (np.asarray(measures, dtype=float) - centre)  # p̂ + (2/β)(m - p̂)


def reflected_noise_std(radius: float, sigma_angle: float) -> float:
    """Per-axis standard deviation of :func:`reflected_measures` for LOS-direction noise ``sigma_angle`` [rad]
    (bearing and axis heading combined, ``sqrt(σ_η² + σ_ψ²)``): the reflection of ``p̂_i`` across a line through
    the UAV, ``r`` away, moves ``2 r δ`` along ``l_⊥`` for a small rotation ``δ`` of that line, and a random
    ``l_⊥`` direction splits that variance evenly over the two axes: ``sqrt((2 r σ)² / 2) = sqrt(2) r σ``."""
    if not (math.isfinite(radius) and radius >= 0):
        raise ValueError(f"radius must be a finite non-negative distance, got {radius}")
    if not (math.isfinite(sigma_angle) and sigma_angle >= 0):
        raise ValueError(f"sigma_angle must be a finite non-negative angle, got {sigma_angle}")
    return math.sqrt(2.0) * radius * sigma_angle  # sqrt((2 r σ)² / 2)


def centre_measure(
    centre,
    axis_heading: float,
    eta: float | None,
    radius: float,
    kappa: float,
    Lambda: float,
    target_range: float = 0.0,
    eta_max: float = ETA_MAX,
    range_max: float = math.inf,
) -> np.ndarray | None:
    """004 Eq. (2) for one UAV; ``None`` when there is no measure: no bearing (``eta is None``) or the target
    outside the FOV (``|η| > η_max`` or ``target_range > R_max``).

    ``centre`` is ``p̂_i`` (2,), ``axis_heading`` the camera-axis heading ``ψ_i`` (e.g. magnetometer yaw plus
    the gimbal angle) [rad], ``eta`` the measured bearing [rad], ``radius`` the distance ``r`` to the centre
    [m], ``target_range`` the detector's range to the target [m] (only compared with ``range_max``)."""
    centre = as_vector(centre, "centre", 2)
    if eta is None:
        return None
    if not math.isfinite(eta):
        raise ValueError(f"bearing eta must be finite, got {eta}")
    if not (math.isfinite(radius) and radius >= 0):
        raise ValueError(f"radius must be a finite non-negative distance, got {radius}")
    if not bool(visible(eta, target_range, eta_max, range_max)):
        return None
    return centre_measures(centre, axis_heading, eta, radius, kappa, Lambda)


def _check_gains(kappa: float, Lambda: float) -> None:
    if not (math.isfinite(kappa) and kappa > 0):
        raise ValueError(f"kappa must be a positive gain, got {kappa}")
    if not (math.isfinite(Lambda) and 0 < Lambda < 2):
        raise ValueError(f"Lambda must lie in (0, 2) (004 Eq. (3)), got {Lambda}")


def _check_fov(eta_max: float, range_max: float) -> None:
    if not (math.isfinite(eta_max) and 0 < eta_max <= math.pi):
        raise ValueError(f"eta_max must be an angle in (0, pi], got {eta_max}")
    if math.isnan(range_max) or range_max <= 0:
        raise ValueError(f"range_max must be a positive distance (inf for no limit), got {range_max}")
