"""The planner seam (DESIGN.md §4, "plan"): what every planner takes and returns, in the style of Stone
Soup's tiny ``base.py`` per component family.

A planner is called once per agent cycle with the vehicle's state and the read-only *views* of the
agent's beliefs, keyed by belief kind (``"track"``: :class:`TrackView`, ``"grid"``: :class:`MapView`, ``"tasks"``:
:class:`AssignmentView`),
and returns a :class:`tasking.orbit.Goal` (plain data; the vehicle turns it into a setpoint). A planner
reads only the views it needs; a view it needs but the agent does not hold is a configuration error,
caught when the planner is built (:mod:`tasking.registry`).
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from tasking.orbit import Goal
from tasking.tasks import Task


class VehicleStateLike(Protocol):
    """What a planner reads of the vehicle: its NED position [m] and velocity [m/s]."""

    position: np.ndarray
    velocity: np.ndarray


@dataclass(frozen=True)
class TrackView:
    """The agent's confirmed, fused tracks: ``(track id, NED mean position)`` pairs, and the tracks' horizontal
    mean velocities (north, east) by id (absent for a model without velocity)."""

    positions: Sequence[tuple[Hashable, np.ndarray]]
    velocities: Mapping[Hashable, np.ndarray] = field(default_factory=dict)


@dataclass(frozen=True)
class MapView:
    """The agent's certainty grid as a planner sees it: the per-cell probability to plan on (rows, cols),
    the cells' (north, east) centres (rows, cols, 2) and, for a Beta grid, its ``(alpha, beta)`` counts; the
    alarms' (north, east) positions as the agent reports them, and its peers' last heard (north, east) positions."""

    probability: np.ndarray
    centres: np.ndarray
    beta: tuple[np.ndarray, np.ndarray] | None = None
    alarms: Sequence[np.ndarray] = ()
    peers: Mapping[str, np.ndarray] = field(default_factory=dict)


@dataclass(frozen=True)
class AssignmentView:
    """This vehicle's share of the fleet's agreed assignment (:mod:`agent.beliefs.assignment`): the task it
    serves now (``None``: nothing won), whether it must go home (every task is out of its reach), where its
    base is, its peers' last reported (north, east) positions, and among them the ``partners`` that won
    another slot of the same target (a shared orbit, :mod:`tasking.assignment`)."""

    task: Task | None
    home: bool
    base: np.ndarray
    peers: Mapping[str, np.ndarray]
    partners: Mapping[str, np.ndarray] = field(default_factory=dict)


class Planner(Protocol):
    """One signature for all planners."""

    def plan(self, state: VehicleStateLike, views: Mapping[str, object]) -> Goal:
        """The goal for this cycle."""
        ...
