"""Entropy-greedy exploration of a certainty grid, Merino (4.21)-(4.24) (spec 001a §3.14).

Each decision the UAV either stays or moves one ``step`` to one of its 8 neighbours (Merino §4.3.1)
and picks (4.24)

    ``k* = argmax_k [ α G(k) - β costMove(k) ]``

where ``G(k)`` is the expected entropy reduction of the grid cells its sensor sees from position k
(the cells whose centre lies within ``footprint`` of k, horizontally; chosen here):

* cell entropy (4.21): ``h(p) = -p ln p - (1 - p) ln(1 - p)`` (nats; ``0 ln 0 = 0``);
* expected posterior entropy (4.22)-(4.23): ``E[h'] = P(d) h(p_d) + P(¬d) h(p_¬d)`` with
  ``P(d) = P_D p + P_F (1 - p)``, ``P(¬d) = (1 - P_D) p + (1 - P_F)(1 - p)`` and the Bayes posteriors
  ``p_d = P_D p / P(d)``, ``p_¬d = (1 - P_D) p / P(¬d)``;
* gain ``h(p) - E[h']``: the mutual information between the cell and one detection, so it is
  ``>= 0``, zero at ``p ∈ {0, 1}`` and zero for an uninformative sensor ``P_D = P_F``.

Beta-grid variant (Merino §4.7: "the entropy of the Beta distribution is used instead"; the formula is
not given): with per-cell counts ``(a, b)`` the differential entropy is

    ``H(a, b) = ln B(a, b) - (a - 1) ψ(a) - (b - 1) ψ(b) + (a + b - 2) ψ(a + b)``

and one look adds a detection (``B(a + 1, b)``) with predictive probability ``a / (a + b)`` or a
non-detection (``B(a, b + 1)``), so ``G = H(a, b) - [a H(a + 1, b) + b H(a, b + 1)] / (a + b)``; it
falls as the evidence ``a + b`` grows, so cells with little evidence are preferred.

``costMove`` (form chosen here; the thesis only says it "penalizes changes in velocity and larger
paths"): ``|m| / step + turn_cost (1 - cos θ)`` with θ the angle between the move m and the previous
one (no turn term when either is "stay"). With ``horizon = H > 1`` the planner scores every sequence
of H moves: a cell seen n times gets the information of n independent looks (below), the costs add
up, and the first move of the best sequence is taken. ``horizon = 1`` is the thesis's greedy rule.

n looks (for ``horizon > 1``): with c detections out of n, ``P(c | x) = Bin(c; n, P_D)``,
``P(c | ¬x) = Bin(c; n, P_F)`` (Bernoulli) or ``c ~ BetaBinomial(n, a, b)`` with posterior
``B(a + c, b + n - c)`` (Beta), and the gain is the prior entropy minus the expected posterior one.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from numbers import Integral, Real

import numpy as np
from scipy.special import digamma, entr, gammaln

from fusion.grid import beta_entropy as grid_beta_entropy
from tasking.alarm_watch import watched_alarm
from tasking.base import VehicleStateLike
from tasking.orbit import Goal, goto_goal
from tasking.search import check_area

__all__ = [
    "EntropyPlannerConfig",
    "EntropyPlanner",
    "MOVES",
    "bernoulli_entropy",
    "beta_entropy",
    "expected_entropy_reduction",
    "beta_expected_entropy_reduction",
    "move_cost",
]

MAX_HORIZON = 3  # chosen here: 9^3 = 729 move sequences per decision at most
#: Stay first, then the 8 neighbours (unit steps in (north, east)); ties go to the earlier entry.
MOVES: tuple[tuple[int, int], ...] = ((0, 0),) + tuple(
    (dn, de) for dn in (-1, 0, 1) for de in (-1, 0, 1) if dn or de
)
_AREA_TOL = 1e-9  # relative slack on the area bounds (chosen here)


# ------------------------------------------------------------------------------------ information


def _probabilities(p, name: str = "p") -> np.ndarray:
    arr = np.asarray(p, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains non-finite values (NaN or inf)")
    if arr.size and (arr.min() < 0.0 or arr.max() > 1.0):
        raise ValueError(f"{name} must lie in [0, 1], got values in [{arr.min()}, {arr.max()}]")
    return arr


def _unit(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not (0.0 <= float(value) <= 1.0):
        raise ValueError(f"{name} must be a probability in [0, 1], got {value!r}")
    return float(value)


def _looks(looks) -> int:
    if isinstance(looks, bool) or not isinstance(looks, Integral) or looks < 0:
        raise ValueError(f"looks must be a non-negative integer, got {looks!r}")
    return int(looks)


def bernoulli_entropy(p) -> np.ndarray:
    """Merino (4.21): ``-p ln p - (1 - p) ln(1 - p)`` in nats (0 at p = 0 and p = 1)."""
    p = _probabilities(p)
    return entr(p) + entr(1.0 - p)


def beta_entropy(alpha, beta) -> np.ndarray:
    """Differential entropy of ``Beta(alpha, beta)`` in nats (see the module docstring)."""
    return grid_beta_entropy(*_counts(alpha, beta))


def _counts(alpha, beta) -> tuple[np.ndarray, np.ndarray]:
    a, b = np.asarray(alpha, dtype=float), np.asarray(beta, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"alpha and beta must have the same shape, got {a.shape} and {b.shape}")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ValueError("alpha and beta contain non-finite values (NaN or inf)")
    if a.size and (a.min() <= 0.0 or b.min() <= 0.0):
        raise ValueError("alpha and beta must be > 0 (Beta counts)")
    return a, b


def expected_entropy_reduction(p, pd: float, pf: float, looks: int = 1) -> np.ndarray:
    """Per cell, Merino (4.21)-(4.23): ``h(p) - [P(d) h(p_d) + P(¬d) h(p_¬d)]`` for one look (the
    default), or the same with ``looks`` independent looks (``Bin(c; n, P_D)`` vs ``Bin(c; n, P_F)``
    detections). ``p`` in [0, 1]; ``pd``, ``pf`` in [0, 1] (any order: equal means no information).
    Mutual information, so the result is clipped at 0 against round-off."""
    p = _probabilities(p)
    pd, pf, n = _unit(pd, "pd"), _unit(pf, "pf"), _looks(looks)
    expected = np.zeros(p.shape)
    for c in range(n + 1):
        log_comb = gammaln(n + 1.0) - gammaln(c + 1.0) - gammaln(n - c + 1.0)
        like_x = math.exp(log_comb) * pd**c * (1.0 - pd) ** (n - c)
        like_not = math.exp(log_comb) * pf**c * (1.0 - pf) ** (n - c)
        joint_x = like_x * p
        total = joint_x + like_not * (1.0 - p)
        post = np.divide(joint_x, total, out=p.copy(), where=total > 0.0)
        expected += total * (entr(post) + entr(1.0 - post))
    return np.maximum(entr(p) + entr(1.0 - p) - expected, 0.0)


def beta_expected_entropy_reduction(alpha, beta, looks: int = 1) -> np.ndarray:
    """Per cell, the information ``n`` looks (``looks``) give about a ``Beta(a, b)`` cell:
    ``H(a, b) - Σ_c BetaBin(c; n, a, b) H(a + c, b + n - c)``, clipped at 0 against round-off.

    Computed on the discrete side of the same mutual information, ``I = H(C) - E_X[H(Bin(n, X))]`` with
    ``w_c = BetaBin(c; n, a, b)``::

        I = -Σ_c w_c ln w_c + Σ_c w_c [ln C(n, c) + c (ψ(a + c) - ψ(a + b + n)) + (n - c) (ψ(b + n - c) - ψ(a + b + n))]

    (``E[X^c (1-X)^(n-c) ln X] = B(a + c, b + n - c) / B(a, b) (ψ(a + c) - ψ(a + b + n))``), and
    ``ln w_c = ln C(n, c) + Σ_{i<c} ln(a + i) + Σ_{j<n-c} ln(b + j) - Σ_{k<n} ln(a + b + k)``: sums of logarithms,
    with no difference of large numbers. The differential entropies' route cancels terms of size ``a + b``: at
    ``a = b = 1e15`` it gave 32 nats for one look instead of 1e-16 (a naive-fusion rumour grows counts that
    large), and it could overflow."""
    a, b = _counts(alpha, beta)
    n = _looks(looks)
    log_a = np.zeros((n + 1, *a.shape))  # log_a[c] = Σ_{i<c} ln(a + i)
    log_b = np.zeros((n + 1, *b.shape))
    for i in range(n):
        log_a[i + 1] = log_a[i] + np.log(a + i)
        log_b[i + 1] = log_b[i] + np.log(b + i)
    log_total = sum((np.log(a + b + k) for k in range(n)), np.zeros(a.shape))
    psi_total = digamma(a + b + n)
    information = np.zeros(a.shape)
    for c in range(n + 1):
        log_comb = gammaln(n + 1.0) - gammaln(c + 1.0) - gammaln(n - c + 1.0)
        log_w = log_comb + log_a[c] + log_b[n - c] - log_total
        expected_log_likelihood = log_comb  # the c = 0 and c = n terms skip ψ(a) and ψ(b): -1/a at a tiny count
        if c:
            expected_log_likelihood = expected_log_likelihood + c * (digamma(a + c) - psi_total)
        if n - c:
            expected_log_likelihood = expected_log_likelihood + (n - c) * (digamma(b + n - c) - psi_total)
        information += np.exp(log_w) * (expected_log_likelihood - log_w)
    return np.maximum(information, 0.0)


def explored_share(probability) -> float:
    """The share of cells whose entropy (4.21) is below half of a cell's most, ``ln 2 / 2`` (p outside about
    [0.11, 0.89]): how much of the area the map has settled."""
    return float(np.mean(bernoulli_entropy(probability) < 0.5 * math.log(2.0)))


def move_cost(move, previous, step: float, turn_cost: float) -> float:
    """costMove of (4.24), form chosen here: ``|move| / step + turn_cost (1 - cos θ)``, θ the angle
    between ``move`` and ``previous`` ((north, east) metres); no turn term when either is zero."""
    m, q = np.asarray(move, dtype=float), np.asarray(previous, dtype=float)
    length, before = float(np.hypot(*m)), float(np.hypot(*q))
    cost = length / step
    if length > 0.0 and before > 0.0:
        cost += turn_cost * (1.0 - float(m @ q) / (length * before))
    return cost


# ----------------------------------------------------------------------------------------- planner


@dataclass(frozen=True)
class EntropyPlannerConfig:
    """Parameters of (4.24); every default is chosen here except the form of the gain."""

    step: float = 20.0  # m: one move (the thesis moves one grid cell)
    footprint: float = 40.0  # m: radius of the ground disc seen from a candidate position
    pd: float = 0.9  # P_D of (4.23)
    pf: float = 0.05  # P_F of (4.23)
    gain_weight: float = 1.0  # α of (4.24)
    cost_weight: float = 0.1  # β of (4.24)
    turn_cost: float = 1.0  # weight of the direction change in costMove
    horizon: int = 1  # look-ahead moves (1: the thesis's greedy rule)
    watch: bool = False  # hover over an alarm this agent won (tasking.alarm_watch); the others explore
    explorers: int = 1  # with watch: agents that never watch, so the area keeps being explored
    watch_from: float = 0.0  # with watch: the explored share of the area (cells of entropy < ln 2 / 2) to start at

    def __post_init__(self):
        for name in ("step", "footprint", "pd", "pf", "gain_weight", "cost_weight", "turn_cost", "watch_from"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
                raise ValueError(f"entropy planner {name} must be a finite number, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.step <= 0 or self.footprint <= 0:
            raise ValueError(f"step and footprint must be > 0 m, got {self.step} and {self.footprint}")
        if not (0.0 <= self.pf < self.pd <= 1.0):
            raise ValueError(f"need 0 <= pf < pd <= 1 (a sensor better than chance), got pd={self.pd}, pf={self.pf}")
        for name in ("gain_weight", "cost_weight", "turn_cost"):
            if getattr(self, name) < 0:
                raise ValueError(f"entropy planner {name} must be >= 0, got {getattr(self, name)}")
        h = self.horizon
        if isinstance(h, bool) or not isinstance(h, Integral) or not 1 <= h <= MAX_HORIZON:
            raise ValueError(f"horizon must be an integer in [1, {MAX_HORIZON}], got {h!r}")
        object.__setattr__(self, "horizon", int(h))
        if not isinstance(self.watch, bool):
            raise ValueError(f"entropy planner watch must be true or false, got {self.watch!r}")
        e = self.explorers
        if isinstance(e, bool) or not isinstance(e, Integral) or e < 0:
            raise ValueError(f"entropy planner explorers must be an integer >= 0, got {e!r}")
        if not 0.0 <= self.watch_from <= 1.0:
            raise ValueError(f"entropy planner watch_from must be a share in [0, 1], got {self.watch_from!r}")


class EntropyPlanner:
    """Greedy information-gain exploration (module docstring). After each :meth:`plan`,
    ``last_move`` is the chosen (north, east) move [m] (the reference of the next turn cost) and
    ``last_gain`` the expected entropy reduction [nats] of the chosen move (sequence)."""

    def __init__(self, config: EntropyPlannerConfig, area: tuple[float, float, float, float], altitude: float):
        if not isinstance(config, EntropyPlannerConfig):
            raise ValueError(f"config must be an EntropyPlannerConfig, got {type(config).__name__}")
        if isinstance(altitude, bool) or not isinstance(altitude, Real) or not math.isfinite(altitude):
            raise ValueError(f"altitude must be a finite number of metres, got {altitude!r}")
        self.config = config
        self.area = check_area(area)
        self.altitude = float(altitude)
        self.last_move = np.zeros(2)
        self.last_gain = 0.0
        self.watching = False  # the watch has begun (config.watch, once the area was explored enough)
        self._sequences = np.array(list(itertools.product(range(len(MOVES)), repeat=config.horizon)), int)
        moves = np.array(MOVES, float) * config.step
        self._offsets = np.cumsum(moves[self._sequences], axis=1)  # (S, H, 2) positions relative to the start
        self._moves = moves

    def _inside(self, ne: np.ndarray) -> np.ndarray:
        n0, n1, e0, e1 = self.area
        tol = _AREA_TOL * max(1.0, *(abs(v) for v in self.area))
        return (ne[..., 0] >= n0 - tol) & (ne[..., 0] <= n1 + tol) & (ne[..., 1] >= e0 - tol) & (ne[..., 1] <= e1 + tol)

    def _gain_tables(self, probability, beta, near) -> np.ndarray:
        """(H + 1, m) expected entropy reduction of n = 0..H looks at the m nearby cells."""
        c = self.config
        if beta is None:
            p = probability[near]
            return np.stack([expected_entropy_reduction(p, c.pd, c.pf, n) for n in range(c.horizon + 1)])
        a, b = beta[0][near], beta[1][near]
        return np.stack([beta_expected_entropy_reduction(a, b, n) for n in range(c.horizon + 1)])

    def plan(self, state: VehicleStateLike, views: Mapping[str, object]) -> Goal:
        """The planner seam (:class:`tasking.base.Planner`): explore the ``"grid"`` view; with ``watch``, first
        hover over the alarm this agent won (:func:`tasking.alarm_watch.watched_alarm`), if any."""
        grid = views["grid"]
        if self.config.watch and not self.watching:
            self.watching = explored_share(grid.probability) >= self.config.watch_from
        if self.watching:
            k = watched_alarm(state.position, grid.peers, grid.alarms, self.config.explorers)
            if k is not None:
                self.last_move, self.last_gain = np.zeros(2), 0.0
                return goto_goal(grid.alarms[k], self.altitude)
        return self.goal_for(state.position, grid.probability, grid.centres, grid.beta)

    def goal_for(self, position, probability, centres, beta: tuple[np.ndarray, np.ndarray] | None = None) -> Goal:
        """The next goal from the vehicle's NED ``position`` (north, east[, down]), the grid's per-cell
        fire ``probability`` (rows, cols), the cells' (north, east) ``centres`` (rows, cols, 2) and,
        for the Beta variant, ``beta = (alpha, beta)`` counts (rows, cols). Candidates leaving the area
        are excluded; from outside the area the goal is the nearest point of the area."""
        pos = np.asarray(position, dtype=float)
        if pos.shape not in ((2,), (3,)) or not np.all(np.isfinite(pos)):
            raise ValueError(f"position must be 2 or 3 finite numbers (NED), got {position!r}")
        probability = _probabilities(probability, "probability")
        if probability.ndim != 2 or probability.size == 0:
            raise ValueError(f"probability must be a non-empty (rows, cols) array, got shape {probability.shape}")
        centres = np.asarray(centres, dtype=float)
        if centres.shape != (*probability.shape, 2):
            raise ValueError(f"centres must have shape {(*probability.shape, 2)}, got {centres.shape}")
        if not np.all(np.isfinite(centres)):
            raise ValueError("centres contain non-finite values (NaN or inf)")
        if beta is not None:
            if not isinstance(beta, tuple | list) or len(beta) != 2:
                raise ValueError("beta must be a pair (alpha, beta) of (rows, cols) arrays")
            counts = _counts(*beta)
            if counts[0].shape != probability.shape:
                raise ValueError(f"alpha and beta must have shape {probability.shape}, got {counts[0].shape}")
            beta = counts
        here = pos[:2]
        c = self.config
        positions = here + self._offsets  # (S, H, 2)
        valid = np.all(self._inside(positions), axis=1)
        if not valid.any():  # outside the area: back to its nearest point
            n0, n1, e0, e1 = self.area
            target = np.array([min(max(here[0], n0), n1), min(max(here[1], e0), e1)])
            self.last_move, self.last_gain = target - here, 0.0
            return goto_goal(target, self.altitude)

        reach = c.horizon * c.step * math.sqrt(2.0) + c.footprint
        near = np.sum((centres - here) ** 2, axis=-1) <= reach * reach
        gains = self._gain_tables(probability, beta, near)  # (H + 1, m)
        cells = centres[near]  # (m, 2)
        # Unique positions reachable in H moves: a (2H + 1)^2 lattice of offsets; disc masks per lattice point.
        lattice = np.rint(self._offsets / c.step).astype(int) + c.horizon  # (S, H, 2) indices
        side = 2 * c.horizon + 1
        points = here + (np.indices((side, side)).reshape(2, -1).T - c.horizon) * c.step  # (side², 2)
        seen = (np.sum((cells[None, :, :] - points[:, None, :]) ** 2, axis=-1) <= c.footprint**2).astype(np.int64)
        flat = lattice[..., 0] * side + lattice[..., 1]  # (S, H)

        index = np.flatnonzero(valid)
        looks = seen[flat[index]].sum(axis=1)  # (S', m) looks per nearby cell
        gain = np.take_along_axis(gains, looks, axis=0).sum(axis=1) if looks.size else np.zeros(len(index))
        cost = np.array([self._sequence_cost(self._sequences[s]) for s in index])
        score = c.gain_weight * gain - c.cost_weight * cost
        best = int(np.argmax(score))  # first maximum: sequences are ordered with "stay" first
        first = self._moves[self._sequences[index[best], 0]]
        self.last_move, self.last_gain = first.copy(), float(gain[best])
        return goto_goal(here + first, self.altitude)

    def _sequence_cost(self, sequence) -> float:
        previous, total = self.last_move, 0.0
        for k in sequence:
            move = self._moves[k]
            total += move_cost(move, previous, self.config.step, self.config.turn_cost)
            if np.any(move):
                previous = move
        return total
