"""Receding-horizon task assignment (RHTA) with the health extension.

Thesis 000 §4.3 (spec 000 §2.7.3-§2.7.4; MIT thesis supervised by J. P. How, RHTA from its reference
[27], Alighanbari et al.'s receding-horizon task assignment). One iteration:

1. **Petals.** For every vehicle ``v`` enumerate the petals ``P_vp``: ordered sequences of 1 to ``n_c``
   distinct active tasks (loiter tasks included, like real ones).
2. **Values** (4.1), from the vehicle's *virtual* state (position, elapsed plan time ``t_v``)::

       S_vp = λ^{t_v} Σ_{i ∈ P_vp} λ^{T_i} s_{w_i}

   ``T_i`` the completion time of task ``i`` from the virtual position
   (:func:`tasking.tasks.petal_value`; camera tasks scaled by the vehicle's quality ``q``). The factor
   ``λ^{t_v}`` keeps the discount of (4.1) on the time from *now* once earlier tasks are committed.
3. **Pruning** (§2.7.4): a petal fails the range test :func:`tasking.tasks.within_reach`
   ``L + d(w_last, x_base) > r`` and is removed (a vehicle without a range model, ``reach=None``, keeps
   every petal). The range ``r`` shrinks along the plan by the distance flown.
4. **Selection** (4.2)-(4.4)::

       max J = Σ_v Σ_p S_vp x_vp
       s.t.  Σ_v Σ_p A_vpi x_vp ≤ 1   ∀ i   (each task at most once)      (4.3)
             Σ_p x_vp = 1             ∀ v   (one petal per vehicle)        (4.4)

   where every vehicle also has the *empty* petal (``S = 0``), so that (4.4) can always be met. Solvers:
   ``"exact"``: depth-first enumeration with a bound (the sum of each remaining vehicle's best petal),
   for small instances; ``"greedy"`` (default): best petal first — take the most valuable petal over all
   vehicles, drop that vehicle and the petal's tasks, repeat. A petal touches one vehicle and at most
   ``n_c`` tasks, so the optimal petals it excludes are at most ``n_c + 1``, each worth no more than it:
   ``J_greedy ≥ J_opt / (n_c + 1)`` (the greedy bound of weighted ``k``-set packing, ``k = n_c + 1``).
5. **Commit** only the first task of each chosen petal: move that vehicle's virtual position to the task,
   advance its time ``t_v`` by the flight (and dwell), take the distance from its range, remove the
   committed tasks, and repeat from 1 until every task is assigned or no vehicle takes one.

The classic RHTA of [27] commits one task per iteration (the first task of the single best petal); here
every vehicle commits the first task of its selected petal in the same iteration (spec 000 §2.7.3 reads
it so), which needs ``≈ #tasks / #vehicles`` iterations instead of ``#tasks``.

**Loiter tasks** (§2.7.4) are valued and pruned like real tasks, with one rule added here: a loiter task
may only end a petal. Loitering before a real task gains nothing, yet the sum (4.1) would still reward
it — a vehicle already at a loiter point would collect its value at ``T = 0`` ahead of every real task
and never leave.

**Return to base** (§2.7.4): a vehicle with a range whose petals at the first iteration are *all* pruned
(including the case of no active task at all) is sent home; the thesis' loiter tasks exist to keep healthy
vehicles from this when few tasks are active.

Ties (equal values) are broken by key: vehicles and tasks are ordered by their keys, a lower vehicle
wins, then the shorter petal, then the lexicographically smaller sequence of task keys.

Defaults (chosen here; the thesis gives neither, spec 000 §3): ``n_c = 2``, ``λ = 0.95`` per second.

The petal values and range tests of one iteration are computed for all vehicles and petals at once
(:func:`petal_table`); they are the same numbers as :func:`tasking.tasks.petal_value` and
:func:`tasking.tasks.within_reach` (the tests check it petal by petal), which cost tens of microseconds
per petal — too slow for thousands of petals per replanning of a 20-vehicle fleet.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from tasking.tasks import CAMERA_TASKS, Capability, Task

__all__ = [
    "DEFAULT_DISCOUNT", "DEFAULT_HORIZON", "SOLVERS", "PetalTable", "Plan", "check_parameters", "enumerate_petals",
    "petal_table", "rhta", "select_exact", "select_greedy", "selection_value",
]

DEFAULT_HORIZON = 2  # n_c, chosen here
DEFAULT_DISCOUNT = 0.95  # λ per second, chosen here
SOLVERS = ("greedy", "exact")
EMPTY = -1  # the empty petal (S = 0) in a selection; also the padding of a petal's task indices


def check_parameters(horizon: int, discount: float) -> None:
    """Raise ``ValueError`` unless ``n_c`` is an integer ≥ 1 and ``0 < λ ≤ 1``."""
    if isinstance(horizon, bool) or not isinstance(horizon, int | np.integer) or horizon < 1:
        raise ValueError(f"petal length n_c must be an integer ≥ 1, got {horizon!r}")
    if not 0.0 < discount <= 1.0:
        raise ValueError(f"time discount λ must be in (0, 1], got {discount}")


@functools.lru_cache(maxsize=64)
def enumerate_petals(n_tasks: int, horizon: int) -> np.ndarray:
    """All ordered sequences of 1..``horizon`` distinct task indices out of ``n_tasks``: shape
    ``(P, horizon)``, padded with ``-1``; shorter petals first, each length in lexicographic order.
    (Cached: the array is read-only.)"""
    check_parameters(horizon, 1.0)
    rows = [
        petal + (EMPTY,) * (horizon - length)
        for length in range(1, min(horizon, n_tasks) + 1)
        for petal in itertools.permutations(range(n_tasks), length)
    ]
    petals = np.array(rows, dtype=int).reshape(-1, horizon)
    petals.flags.writeable = False
    return petals


@dataclass(frozen=True)
class PetalTable:
    """The petals of one iteration: ``petals`` ``(P, n_c)`` task indices (``-1`` padded), ``visits``
    ``(P, N_w)`` the incidence ``A_pi`` of (4.3) (petal ``p`` visits task ``i``), ``values`` ``(N_v, P)``
    the ``S_vp`` (4.1), ``feasible`` ``(N_v, P)`` the petals that pass the range test."""

    petals: np.ndarray
    visits: np.ndarray
    values: np.ndarray
    feasible: np.ndarray


def petal_table(
    vehicles: Sequence[Capability],
    tasks: Sequence[Task],
    horizon: int = DEFAULT_HORIZON,
    discount: float = DEFAULT_DISCOUNT,
    elapsed: Sequence[float] | None = None,
) -> PetalTable:
    """Values ``S_vp = λ^{t_v} Σ λ^{T_i} s_{w_i}`` (4.1) and range tests (§2.7.4) of every petal of every
    vehicle; ``elapsed`` holds each vehicle's virtual time ``t_v`` (default 0)."""
    check_parameters(horizon, discount)
    petals = enumerate_petals(len(tasks), horizon)
    visits = np.any(petals[:, :, None] == np.arange(len(tasks)), axis=1)  # A_pi
    n_vehicles = len(vehicles)
    if len(petals) == 0 or n_vehicles == 0:
        empty = np.zeros((n_vehicles, len(petals)))
        return PetalTable(petals, visits, empty, empty.astype(bool))
    elapsed = np.zeros(n_vehicles) if elapsed is None else np.asarray(elapsed, dtype=float)
    where = np.array([task.position for task in tasks])
    dwell = np.array([task.duration for task in tasks])
    camera = np.array([task.kind in CAMERA_TASKS for task in tasks])
    value = np.array([task.value for task in tasks])
    position = np.array([vehicle.position for vehicle in vehicles])
    base = np.array([vehicle.base for vehicle in vehicles])
    speed = np.array([vehicle.speed for vehicle in vehicles])
    quality = np.array([vehicle.quality for vehicle in vehicles])
    reach = np.array([math.inf if vehicle.reach is None else vehicle.reach for vehicle in vehicles])

    # A padding task (index m) with no value, no dwell and legs of length 0 stands for the empty slots.
    padded = np.where(petals == EMPTY, len(tasks), petals)  # (P, n_c)
    between = np.zeros((len(tasks) + 1, len(tasks) + 1))
    between[:-1, :-1] = _distances(where, where)  # d(w_i, w_j)
    path = np.zeros(petals.shape)
    np.cumsum(between[padded[:, :-1], padded[:, 1:]], axis=1, out=path[:, 1:])  # w_1 -> w_j along the petal
    stay = np.cumsum(np.append(dwell, 0.0)[padded], axis=1)  # dwell up to and including w_j
    first = _distances(position, where)[:, petals[:, 0]]  # d(v, w_1), (N_v, P)
    times = (first[:, :, None] + path) * (1.0 / speed)[:, None, None] + stay  # T_i
    scaled = value * np.where(camera, quality[:, None], 1.0)  # s_w, times q for camera tasks, (N_v, m)
    worth = np.pad(scaled, ((0, 0), (0, 1)))[:, padded]
    discounted = np.einsum("vpi,vpi->vp", discount**times, worth)  # Σ λ^{T_i} s_{w_i}
    values = discount ** elapsed[:, None] * discounted  # λ^{t_v} Σ λ^{T_i} s_{w_i}

    rows = np.arange(len(petals))
    last = (petals != EMPTY).sum(axis=1) - 1
    home = _distances(base, where)[:, petals[rows, last]]  # d(w_last, x_base), (N_v, P)
    flown = first + path[rows, last] + speed[:, None] * stay[:, -1]  # L, plus the dwell flown at v_max
    feasible = flown + home <= reach[:, None]  # L + d(w_last, x_base) ≤ r
    return PetalTable(petals, visits, values, feasible)


def _distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distances between the rows of ``a`` and of ``b``, shape ``(len(a), len(b))``."""
    return np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])


def selection_value(table: PetalTable, choice: Sequence[int]) -> float:
    """``J = Σ_v S_{v, choice_v}`` (4.2); ``choice_v = -1`` is the empty petal."""
    return float(sum(table.values[v, p] for v, p in enumerate(choice) if p != EMPTY))


def select_greedy(table: PetalTable) -> np.ndarray:
    """Best petal first: the most valuable feasible petal over all vehicles, then the best of those left
    that share neither vehicle nor task with it, ... (ties: lower vehicle, then earlier petal). Returns
    the chosen petal index per vehicle (``-1``: empty). ``J ≥ J_opt / (n_c + 1)``."""
    choice = np.full(table.values.shape[0], EMPTY)
    visits = table.visits
    open_values = np.where(table.feasible & (table.values > 0), table.values, -np.inf)
    while open_values.size:
        v, p = np.unravel_index(np.argmax(open_values), open_values.shape)  # first maximum in (v, p) order
        if open_values[v, p] == -np.inf:
            break
        choice[v] = p
        open_values[v] = -np.inf  # (4.4): one petal for this vehicle
        open_values[:, np.any(visits[:, visits[p]], axis=1)] = -np.inf  # (4.3): its tasks are taken
    return choice
def select_exact(table: PetalTable) -> np.ndarray:
    """The optimum of (4.2)-(4.4) by depth-first enumeration over the vehicles, cut when the current value
    plus every remaining vehicle's best petal cannot beat the best found; the first optimum in the
    tie-breaking order is kept. Exponential: for small instances."""
    n_vehicles = table.values.shape[0]
    masks = [sum(1 << int(i) for i in np.flatnonzero(row)) for row in table.visits]  # task sets as bit masks
    options = []  # per vehicle: feasible petals, best first (ties: earlier petal)
    for v in range(n_vehicles):
        (petals,) = np.nonzero(table.feasible[v] & (table.values[v] > 0))
        options.append(petals[np.lexsort((petals, -table.values[v, petals]))].tolist())
    best_of = [table.values[v, petals[0]] if petals else 0.0 for v, petals in enumerate(options)]
    still = np.concatenate([np.cumsum(best_of[::-1])[::-1], [0.0]])  # bound on what vehicles v.. can add
    best = {"value": -math.inf, "choice": None}
    choice = [EMPTY] * n_vehicles

    def search(v: int, taken: int, value: float) -> None:
        if value + still[v] <= best["value"]:
            return
        if v == n_vehicles:
            best["value"], best["choice"] = value, list(choice)
            return
        for p in options[v]:
            if not masks[p] & taken:
                choice[v] = p
                search(v + 1, taken | masks[p], value + table.values[v, p])
        choice[v] = EMPTY
        search(v + 1, taken, value)

    search(0, 0, 0.0)
    return np.array(best["choice"], dtype=int)


@dataclass(frozen=True)
class Plan:
    """One vehicle's assignment: its ``tasks`` (keys, in order) or ``home`` (return to base)."""

    tasks: tuple[Hashable, ...] = ()
    home: bool = False


def _loiter_last(petals: np.ndarray, tasks: Sequence[Task]) -> np.ndarray:
    """Petals in which a loiter task, if any, comes last (module docstring): ``(P,)`` bool."""
    loiter = np.array([task.kind == "loiter" for task in tasks] + [False])  # + the padding slot
    slots = loiter[np.where(petals == EMPTY, len(tasks), petals)]
    return ~np.any(slots[:, :-1] & (petals[:, 1:] != EMPTY), axis=1)


def _by_key(keys) -> list:
    """Keys in sorted order (by ``repr`` when the keys do not compare)."""
    try:
        return sorted(keys)
    except TypeError:
        return sorted(keys, key=repr)


def rhta(
    vehicles: Mapping[Hashable, Capability],
    tasks: Sequence[Task],
    horizon: int = DEFAULT_HORIZON,
    discount: float = DEFAULT_DISCOUNT,
    solver: str = "greedy",
    first_only: bool = False,
) -> dict[Hashable, Plan]:
    """Assign the active ``tasks`` to ``vehicles`` by RHTA (module docstring, steps 1-5); a vehicle with
    a range (``reach``) whose petals are all pruned at the first iteration is sent home.

    ``first_only``: stop iterating once every vehicle has its first task (or can take none), which is all
    a receding-horizon executor flies before re-planning; those first tasks are the full plan's."""
    check_parameters(horizon, discount)
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    keys = [task.key for task in tasks]
    if len(set(keys)) != len(keys):
        raise ValueError(f"task keys must be unique, got {keys}")
    select = select_exact if solver == "exact" else select_greedy
    names = _by_key(vehicles)
    by_key = {task.key: task for task in tasks}
    tasks = [by_key[key] for key in _by_key(by_key)]
    state = [vehicles[name] for name in names]  # virtual states
    elapsed = np.zeros(len(names))
    plans: list[list[Hashable]] = [[] for _ in names]
    # One table over all tasks; a committed task closes its petals, a moved vehicle gets its row again.
    table = petal_table(state, tasks, horizon, discount)
    home = [vehicle.reach is not None and not table.feasible[v].any() for v, vehicle in enumerate(state)]
    allowed = _loiter_last(table.petals, tasks)  # petals still open: loiter only at the end, no task assigned
    assigned = np.zeros(len(tasks), dtype=bool)
    while not assigned.all():
        allowed &= ~table.visits[:, assigned].any(axis=1)
        current = replace(table, feasible=table.feasible & allowed)
        choice = select(current)
        moved = np.flatnonzero(choice != EMPTY)
        if moved.size == 0:
            break
        for v in moved:
            first = table.petals[choice[v], 0]
            task, vehicle = tasks[first], state[v]
            leg = float(np.hypot(*(task.position - vehicle.position)))
            elapsed[v] += leg / vehicle.speed + task.duration  # t_v <- t_v + d(v, w_1)/v_max + dwell
            reach = None if vehicle.reach is None else max(vehicle.reach - leg - vehicle.speed * task.duration, 0.0)
            state[v] = replace(vehicle, position=task.position, reach=reach)
            plans[v].append(task.key)
            assigned[first] = True
        if first_only and all(plans[v] or not current.feasible[v].any() for v in range(len(names))):
            break
        rows = petal_table([state[v] for v in moved], tasks, horizon, discount, elapsed[moved])
        values, feasible = table.values.copy(), table.feasible.copy()
        values[moved], feasible[moved] = rows.values, rows.feasible
        table = replace(table, values=values, feasible=feasible)
    return {name: Plan(tuple(plans[v]), home[v]) for v, name in enumerate(names)}
