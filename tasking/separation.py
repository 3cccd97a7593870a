"""Separation between vehicles: a repulsive potential plus a hard projection (thesis 000 §2.9, §5.2.4).

The thesis (spec 000 §2.9) adds a potential-function safety layer: "if a UAV comes too close to another
UAV ... it is repelled away by seeking to move to an area of lower potential"; the form, gains and radii
are not specified. The choices made here:

Potential (Khatib's FIRAS barrier, shifted to the minimum distance ``d_min``), per neighbour at distance
``d = |p - p_j|`` with influence radius ``R > d_min``::

    U(d) = (k / 2) (1 / (d - d_min) - 1 / (R - d_min))^2     for d_min < d < R,   0 for d >= R

It grows without bound as ``d -> d_min`` and is C1 at ``R`` (``U`` and ``U'`` vanish there). Its gradient
with respect to the own position is ``∇U = U'(d) (p - p_j) / d`` with
``U'(d) = -k (1 / (d - d_min) - 1 / (R - d_min)) / (d - d_min)^2``. The gain ``k`` [m^4/s] is set from the
dimensionless ``gain`` so that the repulsion ``|∇U|`` equals ``gain * max_speed`` halfway through the
band (``d - d_min = δ = (R - d_min) / 2``, where ``|U'| = k / (2 δ^3)``): ``k = 2 gain max_speed δ^3``.

Desired velocity: the command, plus the repulsion ``-∇U`` of every neighbour inside ``R``, plus a
*swirl* ``c_s`` times the repulsion turned 90° to the right in the horizontal plane
(``(n, e) -> (e, -n)``), clipped to ``max_speed``. Two agents meeting head on both veer right and pass,
so the pure repulsion's symmetric deadlock does not happen.

Hard guarantee (discrete time, reciprocal): each agent holds its velocity ``v`` for the step ``dt`` and
has ``|v| <= v_max``. For every neighbour with ``d < d_min + 2 v_max dt`` (closer ones could touch within
one step), with ``n = (p - p_j) / d``, the velocity is projected onto the half-spaces

    n · v >= -s,    s = (d - d_min) / (2 dt)                                         (closing speed share)

i.e. each agent takes at most half of the slack ``d - d_min`` per step. If both agents of a pair do so,
for ``0 <= t <= dt``: ``|p_i - p_j + t (v_i - v_j)| >= n · (p_i - p_j) + t n · (v_i - v_j) >= d - 2 s t
>= d_min`` (Cauchy–Schwarz), so a pair that starts at least ``d_min`` apart never comes closer, at the
samples or in between. The projection (Euclidean, onto the intersection of the half-spaces, by
Dykstra's algorithm) contains ``v = 0``, so it is never empty; the last iterate is scaled towards 0 by
the largest factor in [0, 1] that satisfies every half-space exactly, which keeps the guarantee whatever
Dykstra's residual. Neighbour velocities are not needed: the guarantee rests only on both agents
applying the same rule to the same positions with the same ``v_max`` and ``dt``.

Defaults chosen here: ``R = 2 d_min``, ``gain = 1``, ``swirl = 0.5``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Real

import numpy as np

from fusion.validation import as_vector, positive

#: Dykstra iterations at most, and the change below which they stop (m/s); chosen here.
DYKSTRA_ITERATIONS = 100
DYKSTRA_TOL = 1e-12



@dataclass(frozen=True)
class SeparationLayer:
    """The separation layer of the module docstring; :meth:`adjust` is the call a planner makes."""

    d_min: float
    max_speed: float
    influence_radius: float | None = None  # R; None: 2 d_min (chosen here)
    gain: float = 1.0  # repulsion / max_speed halfway through the band (chosen here)
    swirl: float = 0.5  # right-turn share of the repulsion (chosen here)

    def __post_init__(self):
        positive("d_min", self.d_min)
        positive("max_speed", self.max_speed)
        positive("gain", self.gain)
        if isinstance(self.swirl, bool) or not isinstance(self.swirl, Real) or not (
            math.isfinite(self.swirl) and self.swirl >= 0
        ):
            raise ValueError(f"swirl must be a non-negative finite number, got {self.swirl!r}")
        radius = 2.0 * self.d_min if self.influence_radius is None else self.influence_radius
        if positive("influence_radius", radius) <= self.d_min:
            raise ValueError(f"influence_radius ({radius}) must exceed d_min ({self.d_min})")
        object.__setattr__(self, "influence_radius", float(radius))

    @property
    def potential_gain(self) -> float:
        """``k = 2 gain max_speed δ^3`` with ``δ = (R - d_min) / 2`` [m^4/s]."""
        half_band = 0.5 * (self.influence_radius - self.d_min)
        return 2.0 * self.gain * self.max_speed * half_band**3

    def potential(self, distance) -> np.ndarray:
        """``U(d)`` per distance (inf at or below ``d_min``, 0 from ``R`` on)."""
        d = np.asarray(distance, dtype=float)
        inside = (d > self.d_min) & (d < self.influence_radius)
        gap = np.where(inside, d - self.d_min, 1.0)
        term = 1.0 / gap - 1.0 / (self.influence_radius - self.d_min)
        u = np.where(inside, 0.5 * self.potential_gain * term**2, 0.0)  # U = k/2 (1/(d - d_min) - 1/(R - d_min))^2
        return np.where(d <= self.d_min, np.inf, u)

    def potential_derivative(self, distance) -> np.ndarray:
        """``U'(d)`` per distance (-inf at or below ``d_min``, 0 from ``R`` on)."""
        d = np.asarray(distance, dtype=float)
        inside = (d > self.d_min) & (d < self.influence_radius)
        gap = np.where(inside, d - self.d_min, 1.0)
        term = 1.0 / gap - 1.0 / (self.influence_radius - self.d_min)
        du = np.where(inside, -self.potential_gain * term / gap**2, 0.0)  # U' = -k term / (d - d_min)^2
        return np.where(d <= self.d_min, -np.inf, du)

    def gradient(self, own_position, neighbours) -> np.ndarray:
        """``Σ_j ∇_p U(|p - p_j|)`` over the neighbours (K, D); infinite when one is within ``d_min``."""
        own, others = _check_positions(own_position, neighbours)
        rel = own - others
        d = np.linalg.norm(rel, axis=1)
        _check_distinct(d)
        return np.sum(self.potential_derivative(d)[:, None] * rel / d[:, None], axis=0)  # ∇U = U'(d) (p - p_j) / d

    def reach(self, dt: float) -> float:
        """How far the layer acts for a command held ``dt`` s: ``max(R, d_min + 2 max_speed dt)``; beyond it
        :meth:`adjust` only clips the command to ``max_speed``."""
        return max(self.influence_radius, self.d_min + 2.0 * self.max_speed * dt)

    def adjust(self, own_position, own_velocity_cmd, neighbours, dt: float) -> np.ndarray:
        """The separated velocity command for this step.

        ``own_position`` (D,), ``own_velocity_cmd`` (D,) and ``neighbours`` (K, D) positions, D = 2 or 3
        (north, east[, down]), metres and m/s; ``dt`` the step [s] the command is held for. The command is
        first clipped to ``max_speed``; it is returned unchanged when no neighbour is within :meth:`reach`.
        """
        own, others = _check_positions(own_position, neighbours)
        command = as_vector(own_velocity_cmd, "own_velocity_cmd", own.shape[0])
        dt = positive("dt", dt)
        speed = float(np.linalg.norm(command))
        velocity = command * (self.max_speed / speed) if speed > self.max_speed else command.copy()
        rel = own - others
        d = np.linalg.norm(rel, axis=1)
        _check_distinct(d)
        normals = rel / d[:, None]
        near = d < self.influence_radius
        if np.any(near):
            velocity = _clip_speed(velocity + self._repulsion(d[near], normals[near]), self.max_speed)
        guarded = d < self.d_min + 2.0 * self.max_speed * dt
        if np.any(guarded):
            slack = np.maximum(d[guarded] - self.d_min, 0.0) / (2.0 * dt)  # s = (d - d_min) / (2 dt)
            velocity = _project_halfspaces(velocity, normals[guarded], slack)
        return velocity

    def _repulsion(self, d: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """``Σ_j -∇U_j + swirl (-∇U_j turned right)``; each ``|∇U_j|`` is capped at ``max_speed`` (the sum is
        clipped to it anyway), which also makes it finite for a neighbour already within ``d_min``."""
        magnitude = np.minimum(-self.potential_derivative(d), self.max_speed)  # |-∇U| = -U'(d), capped
        push = magnitude[:, None] * normals
        right = np.zeros_like(push)
        right[:, 0], right[:, 1] = push[:, 1], -push[:, 0]  # (n, e) -> (e, -n): 90° to the right seen from above
        return np.sum(push + self.swirl * right, axis=0)


def _clip_speed(velocity: np.ndarray, max_speed: float) -> np.ndarray:
    speed = float(np.linalg.norm(velocity))
    return velocity * (max_speed / speed) if speed > max_speed else velocity


def _project_halfspaces(v: np.ndarray, normals: np.ndarray, slack: np.ndarray) -> np.ndarray:
    """The point nearest ``v`` with ``normals[k] · x >= -slack[k]`` for all k (``slack >= 0``).

    Dykstra's alternating projections, then the exact feasibility scaling ``x <- α x`` with
    ``α = min(1, min_k slack_k / (-n_k · x))`` over the violated half-spaces (``0`` is feasible, so
    ``α x`` is feasible for that α)."""
    x = v.copy()
    increments = np.zeros_like(normals)
    for _ in range(DYKSTRA_ITERATIONS):
        start = x
        for k, n in enumerate(normals):
            y = x + increments[k]
            shortfall = -slack[k] - float(n @ y)  # > 0: y violates n · y >= -s
            x = y + shortfall * n if shortfall > 0 else y
            increments[k] = y - x
        if float(np.max(np.abs(x - start))) < DYKSTRA_TOL:
            break
    closing = normals @ x
    violated = closing < -slack
    if np.any(violated):
        x = x * float(np.min(slack[violated] / -closing[violated]))  # α = min_k s_k / (-n_k · x)
    return x


def _check_positions(own_position, neighbours) -> tuple[np.ndarray, np.ndarray]:
    own = as_vector(own_position, "own_position")
    dim = own.shape[0]
    if dim not in (2, 3):
        raise ValueError(f"own_position must have 2 or 3 components (north, east[, down]), got {dim}")
    others = np.asarray(neighbours, dtype=float)
    if others.size == 0:
        others = others.reshape(0, dim)
    if others.ndim != 2 or others.shape[1] != dim:
        raise ValueError(f"neighbours must be a (K, {dim}) array, got shape {others.shape}")
    if not np.all(np.isfinite(others)):
        raise ValueError("neighbours contains non-finite values (NaN or inf)")
    return own, others


def _check_distinct(d: np.ndarray) -> None:
    if np.any(d == 0.0):
        raise ValueError(f"own position coincides with neighbour {int(np.argmin(d))}: no direction to separate")


@dataclass(frozen=True)
class SeparationStats:
    """Over a run: the smallest pairwise distance [m] and the number of (sample, pair) below ``d_min``."""

    min_separation: float
    violations: int


def separation_stats(trajectory, d_min: float) -> SeparationStats:
    """:class:`SeparationStats` of a ``(T, N, D)`` array of positions (T samples of N agents)."""
    d_min = positive("d_min", d_min)
    positions = np.asarray(trajectory, dtype=float)
    if positions.ndim != 3 or positions.shape[1] < 2:
        raise ValueError(f"trajectory must be (T, N >= 2, D), got shape {positions.shape}")
    if not np.all(np.isfinite(positions)):
        raise ValueError("trajectory contains non-finite values (NaN or inf)")
    i, j = np.triu_indices(positions.shape[1], k=1)
    distances = np.linalg.norm(positions[:, i] - positions[:, j], axis=2)  # (T, pairs)
    return SeparationStats(float(distances.min()), int(np.count_nonzero(distances < d_min)))


def goal_velocity(position: np.ndarray, goal: np.ndarray, max_speed: float, arrival_gain: float = 1.0) -> np.ndarray:
    """Fly to ``goal``: ``(g - p) min(max_speed / |g - p|, arrival_gain)`` (full speed, then a linear
    approach over the last ``max_speed / arrival_gain`` metres; ``arrival_gain`` [1/s] chosen here)."""
    error = goal - position
    distance = float(np.linalg.norm(error))
    if distance == 0.0:
        return np.zeros_like(error)
    return error * min(max_speed / distance, arrival_gain)


def fly_swarm(starts, goals, max_speed: float, dt: float, steps: int, layer: SeparationLayer | None = None):
    """Point masses flying to their goals, ``p <- p + v dt``, every agent choosing its velocity from the same
    positions (synchronous, as the reciprocal guarantee assumes): :func:`goal_velocity`, then
    ``layer.adjust`` if a layer is given. Returns the positions, ``(steps + 1, N, D)``."""
    positions = np.array(starts, dtype=float)
    targets = np.asarray(goals, dtype=float)
    if positions.ndim != 2 or targets.shape != positions.shape:
        raise ValueError(f"starts and goals must both be (N, D), got {positions.shape} and {targets.shape}")
    max_speed, dt = positive("max_speed", max_speed), positive("dt", dt)
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    out = np.empty((steps + 1, *positions.shape))
    out[0] = positions
    everyone = np.arange(len(positions))
    for step in range(1, steps + 1):
        velocities = np.array([goal_velocity(p, g, max_speed) for p, g in zip(positions, targets, strict=True)])
        if layer is not None:
            velocities = np.array([
                layer.adjust(positions[i], velocities[i], positions[everyone != i], dt) for i in everyone
            ])
        positions = positions + velocities * dt
        out[step] = positions
    return out
