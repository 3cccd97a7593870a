"""Tasks, and what a sequence of them is worth to one vehicle: the shared vocabulary of task assignment.

Thesis 000 Ch. 4 (spec 000 §2.7). A task is a location ``w`` with a value (priority) ``s_w``; a vehicle
serves a *petal*, an ordered sequence of up to ``n_c`` tasks, flying straight between them at ``v_max``
(first-order translational dynamics, §2.7.2). The petal's worth is the time-discounted sum (4.1)::

    S_vp = Σ_{i ∈ P_vp} λ^{T_i} s_{w_i},      0 < λ ≤ 1,

with ``T_i`` the time (from now) at which task ``i`` of the petal is completed. Here it is multiplied by
the vehicle's *sensor state* ``q ∈ [0, 1]`` for tasks that need the camera (the video-quality measure
D(t) of §2.4, mapped to a quality by the caller): a vehicle whose camera fails bids less for tracking and
searching, not for loitering (§2.7.2, "sensor state").

Health extension (§2.7.4): a vehicle with fuel ``f`` burning at ``k`` per second (the *current*,
post-failure rate) can still fly ``r = v_max · f / k`` metres; a petal is pruned when it cannot reach its
last task and then the base on that fuel, ``L + d(w_last, x_base) > r`` with
``L = d(v, w_1) + Σ_j d(w_{j-1}, w_j)``. Service times (dwelling at a task) burn fuel too: the range test
charges them as ``v_max · duration`` metres.

:mod:`tasking.rhta` selects petals centrally (the thesis' receding-horizon assignment);
:mod:`tasking.cbba` reaches the same kind of assignment by consensus between vehicles.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import numpy as np

from fusion.validation import as_vector

TASK_KINDS = ("track", "search", "loiter")
CAMERA_TASKS = frozenset({"track", "search"})  # tasks whose value the camera's quality scales


@dataclass(frozen=True)
class Task:
    """A task ``(w, s_w)`` (§2.7.1): ``position`` (north, east) [m], ``value`` > 0, its ``kind`` (keep a
    target in view, search an area, loiter), and ``duration`` [s] the vehicle stays there to perform it."""

    key: Hashable
    position: np.ndarray
    value: float
    kind: str = "track"
    duration: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "position", as_vector(self.position, f"task {self.key!r} position", 2))
        if not (math.isfinite(self.value) and self.value > 0):
            raise ValueError(f"task {self.key!r} value must be a positive number, got {self.value}")
        if self.kind not in TASK_KINDS:
            raise ValueError(f"task {self.key!r} kind must be one of {TASK_KINDS}, got {self.kind!r}")
        if not (math.isfinite(self.duration) and self.duration >= 0):
            raise ValueError(f"task {self.key!r} duration must be ≥ 0 s, got {self.duration}")


@dataclass(frozen=True)
class Capability:
    """One vehicle as the assignment sees it (§2.7.2): where it is, how fast it flies, how far it can still
    fly (``reach``, metres; ``None``: no health model, unlimited), where its base is, and its camera quality
    ``q`` in [0, 1]."""

    position: np.ndarray
    speed: float
    base: np.ndarray
    reach: float | None = None
    quality: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "position", as_vector(self.position, "vehicle position", 2))
        object.__setattr__(self, "base", as_vector(self.base, "base position", 2))
        if not (math.isfinite(self.speed) and self.speed > 0):
            raise ValueError(f"vehicle speed must be a positive number of m/s, got {self.speed}")
        if self.reach is not None and not (self.reach >= 0 and math.isfinite(self.reach)):
            raise ValueError(f"vehicle reach must be ≥ 0 m or None, got {self.reach}")
        if not 0.0 <= self.quality <= 1.0:
            raise ValueError(f"vehicle camera quality must be in [0, 1], got {self.quality}")


def operational_range(fuel: float, speed: float, burn_rate: float) -> float:
    """``r = v_max · f / k`` (§2.7.4): metres left on ``fuel`` at ``burn_rate`` per second."""
    if not (math.isfinite(fuel) and fuel >= 0):
        raise ValueError(f"fuel must be ≥ 0, got {fuel}")
    if not (math.isfinite(burn_rate) and burn_rate > 0):
        raise ValueError(f"burn rate must be > 0 per second, got {burn_rate}")
    return speed * fuel / burn_rate  # r_i = v_max · f_i / k


def _legs(start: np.ndarray, tasks: Sequence[Task]) -> np.ndarray:
    """Straight-line leg lengths ``d(v, w_1), d(w_1, w_2), ...``."""
    points = np.vstack([start, *(task.position for task in tasks)])
    return np.hypot(*np.diff(points, axis=0).T)


def completion_times(vehicle: Capability, tasks: Sequence[Task]) -> np.ndarray:
    """``T_i``: when each task of the petal is done, flying at ``v_max`` and dwelling ``duration`` at each."""
    dwell = np.array([task.duration for task in tasks])
    return np.cumsum(_legs(vehicle.position, tasks) / vehicle.speed + dwell)


def petal_value(vehicle: Capability, tasks: Sequence[Task], discount: float) -> float:
    """``S_vp = Σ λ^{T_i} s_{w_i}`` (4.1), camera tasks scaled by the vehicle's quality ``q``."""
    if not 0.0 < discount <= 1.0:
        raise ValueError(f"time discount λ must be in (0, 1], got {discount}")
    if not tasks:
        return 0.0
    values = np.array([task.value * (vehicle.quality if task.kind in CAMERA_TASKS else 1.0) for task in tasks])
    return float(np.sum(discount ** completion_times(vehicle, tasks) * values))  # Σ λ^{T_i} s_{w_i}


def within_reach(vehicle: Capability, tasks: Sequence[Task]) -> bool:
    """The pruning test of §2.7.4: ``L + d(w_last, x_base) ≤ r`` (dwell charged at ``v_max``)."""
    if vehicle.reach is None:
        return True
    last = tasks[-1].position if tasks else vehicle.position
    length = float(np.sum(_legs(vehicle.position, tasks)))  # L_i = d(v, w_1) + Σ d(w_{j-1}, w_j)
    dwell = vehicle.speed * sum(task.duration for task in tasks)
    home = float(np.hypot(*(last - vehicle.base)))  # d(w_{n_c}, x_base)
    return length + dwell + home <= vehicle.reach
