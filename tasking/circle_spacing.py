"""Equal angular spacing on the orbit and the resulting set-point (Andreetto et al., Electronics 2018; spec 004
§2.8).

The paper says only that UAV ``i`` "computes its position set-point by using the position and velocity of
pairs of neighbour UAVs to compute the correct rotation on the circle, and then by superimposing this circular
motion to a translation towards the estimated centre"; optimal bearing-only sensing wants the UAVs equally
spaced (Zhao et al.). The law below is the minimal implementation of spec 004 §2.8 [NOT IN PAPER]:

* UAV ``i`` takes its phase ``θ_i`` and its neighbours' phases ``θ_j`` about its own centre ``p̂_i``; its two
  circle-neighbours are the nearest heard UAV ahead (``i⁺``) and behind (``i⁻``), with the gaps
  ``g⁺ = (θ_{i⁺} - θ_i) mod 2π`` and ``g⁻ = (θ_i - θ_{i⁻}) mod 2π`` in (0, 2π] (both 2π when it hears nobody);
* ``θ̇_i = ω_0 + k_θ (g⁺ - g⁻) / 2`` (spec 004 §2.8), clipped to ``[0, θ̇_max]`` with
  ``θ̇_max = min(2π / (3 Δt), (v_max - |ṗ̂_i|) / r)``: at least 3 measurements per revolution (Corollary 1)
  and the tangential speed within what the 13 m/s cap leaves after the centre's own motion. When
  ``ω_0 > θ̇_max / 2`` the nominal rate is lowered to ``θ̇_max / 2``: otherwise every UAV sits at the cap, the
  spacing term has no effect, and the UAVs stay bunched (at 11 m/s on a 30 m circle, ``θ̇_max`` = 0.06 rad/s);
  bunched UAVs see the target along nearly parallel lines of sight, which leaves the estimate unobservable
  along them;
* set-point ``ξ_i^d = p̂_i + r [cos θ_i, sin θ_i]`` (the radial projection of the UAV on its circle: a UAV far
  from it flies point-to-point to it) with the feed-forward velocity ``ξ̇_i^d = ṗ̂_i + r θ̇_i [-sin θ_i, cos θ_i]``
  (translation with the centre plus rotation), scaled to at most ``v_max``.

On a common fixed circle the gap vector ``g`` (every UAV hearing its two circle-neighbours) follows
``g ← g - (k_θ Δt / 2) L g`` with ``L`` the ring Laplacian, which converges to equal gaps ``2π/n`` for
``0 < k_θ Δt < 1``. Defaults chosen here: ``ω_0 = 0.2 rad/s`` (3 m/s on a 15 m circle), ``k_θ = 0.5 1/s``.

Arrays: positions ``(..., n, 2)``, one row per UAV; ``heard (..., n, n)`` says who hears whom.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tasking.centre_measure import heading

#: 004 §3: the UAVs' maximum speed (a Parrot Bebop) [m/s].
MAX_SPEED = 13.0
#: Chosen here: the nominal orbit rate [rad/s] and the spacing gain [1/s].
OMEGA_0 = 0.2
K_THETA = 0.5


@dataclass(frozen=True)
class SetPoint:
    """Where a UAV should be now (``position (..., 2)``) and its feed-forward ``velocity (..., 2)``."""

    position: np.ndarray
    velocity: np.ndarray


def circle_gaps(centres, positions, heard) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(θ_i, g⁺_i, g⁻_i)``: each UAV's phase about its own centre and its gaps to the nearest heard UAV
    ahead and behind, in (0, 2π] (2π when it hears nobody). ``centres``/``positions (..., n, 2)``."""
    centres, positions = np.asarray(centres, dtype=float), np.asarray(positions, dtype=float)
    heard = np.asarray(heard, dtype=bool)
    n = positions.shape[-2]
    if heard.shape[-2:] != (n, n):
        raise ValueError(f"heard must be (..., {n}, {n}), got shape {heard.shape}")
    relative = positions[..., None, :, :] - centres[..., :, None, :]  # ξ_j - p̂_i
    phases = heading(relative)  # θ_ij: UAV j's phase about centre i
    theta = np.diagonal(phases, axis1=-2, axis2=-1)  # θ_i = θ_ii
    others = heard & ~np.eye(n, dtype=bool)
    two_pi = 2.0 * np.pi
    ahead = two_pi - np.mod(theta[..., :, None] - phases, two_pi)  # (θ_j - θ_i) mod 2π, in (0, 2π]
    behind = two_pi - np.mod(phases - theta[..., :, None], two_pi)  # (θ_i - θ_j) mod 2π, in (0, 2π]
    gap_ahead = np.where(others, ahead, two_pi).min(axis=-1)
    gap_behind = np.where(others, behind, two_pi).min(axis=-1)
    return theta, gap_ahead, gap_behind


def spacing_rate(
    gap_ahead,
    gap_behind,
    radius: float,
    dt: float,
    centre_speed=0.0,
    omega_0: float = OMEGA_0,
    k_theta: float = K_THETA,
    max_speed: float = MAX_SPEED,
) -> np.ndarray:
    """``θ̇_i = ω_0 + k_θ (g⁺ - g⁻) / 2`` clipped to ``[0, θ̇_max]`` (module docstring)."""
    _check_radius(radius)
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive time step, got {dt}")
    if not (math.isfinite(omega_0) and omega_0 > 0):
        raise ValueError(f"omega_0 must be a positive orbit rate, got {omega_0}")
    if not (math.isfinite(k_theta) and k_theta >= 0):
        raise ValueError(f"k_theta must be a non-negative gain, got {k_theta}")
    if not (math.isfinite(max_speed) and max_speed > 0):
        raise ValueError(f"max_speed must be a positive speed, got {max_speed}")
    tangential_room = np.maximum(max_speed - np.asarray(centre_speed, dtype=float), 0.0) / radius
    rate_max = np.minimum(2.0 * np.pi / (3.0 * dt), tangential_room)  # ≥ 3 measures per turn; speed cap
    nominal = np.minimum(omega_0, rate_max / 2.0)  # ω_0, leaving the spacing term room both ways
    rate = nominal + k_theta * (np.asarray(gap_ahead) - np.asarray(gap_behind)) / 2.0  # θ̇ = ω_0 + k_θ (g⁺ - g⁻)/2
    return np.clip(rate, 0.0, rate_max)


def spacing_setpoint(
    centre, centre_velocity, theta, rate, radius: float, max_speed: float = MAX_SPEED, lead: float = 0.0
) -> SetPoint:
    """The set-point on the circle of ``radius`` about ``centre`` at the phase ``θ_i + θ̇_i lead``, with the
    feed-forward velocity ``ṗ̂_i + r θ̇_i t̂`` (capped at ``max_speed``).

    ``centre`` is the centre at the set-point's time: the translation is already in it (``p̂_i(t+1)`` of
    Eq. (4) or of the tracking stage), so a point-mass follower stepping by ``lead`` towards the set-point stays
    on the circle instead of on its tangent. ``θ_i`` is the UAV's phase on the circle it was orbiting (about
    ``p̂_i(t)``): the circle translates and the UAV keeps its place on it (the "translation towards the estimated
    centre" superimposed on the rotation, 004 §2.8). Taking the phase about the new centre instead projects the
    UAV radially onto the translated circle, and a moving centre then slips every UAV towards the trailing side
    of its circle by ``|ṗ̂| / r`` rad/s, which bunches them up (at 11 m/s on a 30 m circle, faster than ``ω_0``)."""
    _check_radius(radius)
    if not (math.isfinite(lead) and lead >= 0):
        raise ValueError(f"lead must be a non-negative time, got {lead}")
    rate = np.asarray(rate, dtype=float)
    centre = np.asarray(centre, dtype=float)
    phase = np.asarray(theta, dtype=float) + rate * lead
    radial = np.stack([np.cos(phase), np.sin(phase)], axis=-1)
    tangent = np.stack([-np.sin(phase), np.cos(phase)], axis=-1)
    position = centre + radius * radial  # ξ^d = p̂_i + r [cos θ_i, sin θ_i]
    velocity = np.asarray(centre_velocity, dtype=float) + radius * rate[..., None] * tangent  # ṗ̂_i + r θ̇_i t̂
    return SetPoint(position, cap_speed(velocity, max_speed))


def cap_speed(velocity, max_speed: float = MAX_SPEED) -> np.ndarray:
    """``velocity (..., 2)`` scaled down to a norm of at most ``max_speed``."""
    velocity = np.asarray(velocity, dtype=float)
    speed = np.linalg.norm(velocity, axis=-1, keepdims=True)
    return velocity * np.minimum(1.0, max_speed / np.maximum(speed, 1e-300))


def _check_radius(radius: float) -> None:
    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive orbit radius, got {radius}")
