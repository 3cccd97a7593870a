"""Search, rendezvous and the static/dynamic stages of Andreetto et al. (Electronics 2018; spec 004 §2.7, §2.9).

**The three cases** (spec 004 §2.9), decided by each UAV at each step from what it sees and hears:

====================  ==========================  =========================================================
sees the target       hears an orbiting UAV       what the UAV does
====================  ==========================  =========================================================
no                    yes                         ``FLY_TO_CIRCLE`` (case 1): take the circle it is told, fly
                                                  point-to-point to it
yes                   no                          ``OWN_ORBIT`` (case 2): run the algorithm alone
yes                   yes                         ``CONSENSUS`` (case 3): consensus WLS (and KCF) with them
no                    no                          ``SEARCH``: keep patrolling (or keep orbiting, see below)
====================  ==========================  =========================================================

"Hears an orbiting UAV" means a neighbour in the disk graph that is itself on an orbit or that holds
information about the target this step (it relays a consensus estimate).

**Stages** of one UAV (spec 004 §1.3, §2.7): ``SEARCH`` (patrol) → ``APPROACH`` (static algorithm: centre from
the consensus WLS of Eq. (4)) as soon as it sees the target or is told a circle → ``TRACK`` (dynamic
algorithm: WLS → KCF → WLS) after ``approach_readings`` steps with information (the paper's "predefined number
of sensor readings"; the number is not given, 20 is chosen here). A UAV on an orbit that neither sees nor
hears keeps its circle and keeps rotating — Corollary 1's sweep brings the target back into view. A tracking
UAV without information for more than ``track_patience`` steps in a row returns to ``APPROACH`` (its filter
would otherwise extrapolate the centre away at the last velocity; chosen here: 10), and any orbiting UAV falls
back to ``SEARCH`` after more than ``lost_patience`` such steps (chosen here: 60).

Pure logic on integer arrays of any shape (one entry per UAV, per run), so the simulator updates a whole
Monte Carlo batch at once.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np


class Case(IntEnum):
    """What a UAV does this step (spec 004 §2.9)."""

    SEARCH = 0
    FLY_TO_CIRCLE = 1
    OWN_ORBIT = 2
    CONSENSUS = 3


class Stage(IntEnum):
    """Where a UAV is in the mission (spec 004 §1.3, §2.7)."""

    SEARCH = 0
    APPROACH = 1
    TRACK = 2


@dataclass(frozen=True)
class StageRules:
    """``approach_readings``: steps with information before the tracking stage (``None``: never, the static
    algorithm only); ``track_patience``: steps without information before a tracking UAV returns to the
    approaching stage; ``lost_patience``: steps without information before an orbiting UAV searches again."""

    approach_readings: int | None = 20
    track_patience: int = 10
    lost_patience: int = 60

    def __post_init__(self):
        for name in ("approach_readings", "track_patience", "lost_patience"):
            value = getattr(self, name)
            if value is None and name == "approach_readings":
                continue
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
                raise ValueError(f"{name} must be a non-negative integer, got {value!r}")


@dataclass(frozen=True)
class StageState:
    """Per-UAV ``stage``, ``readings`` (steps with information since the approach began) and ``missed``
    (steps in a row without information while orbiting); integer arrays of one shape."""

    stage: np.ndarray
    readings: np.ndarray
    missed: np.ndarray

    @classmethod
    def start(cls, shape, stage: Stage = Stage.SEARCH) -> StageState:
        return cls(np.full(shape, int(stage)), np.zeros(shape, dtype=int), np.zeros(shape, dtype=int))

    @property
    def orbiting(self) -> np.ndarray:
        return self.stage != Stage.SEARCH


def rendezvous_case(sees, hears) -> np.ndarray:
    """The case of spec 004 §2.9 for every UAV: ``sees``/``hears`` boolean arrays → :class:`Case` codes."""
    sees, hears = _booleans(sees, "sees"), _booleans(hears, "hears")
    return np.select(
        [sees & hears, sees, hears],
        [Case.CONSENSUS, Case.OWN_ORBIT, Case.FLY_TO_CIRCLE],
        default=Case.SEARCH,
    )


def next_stage(state: StageState, informed, rules: StageRules = StageRules()) -> StageState:
    """Advance every UAV's stage given whether it has target information this step (``informed``: it sees the
    target, receives a consensus estimate or is told a circle)."""
    informed = _booleans(informed, "informed")
    stage = np.asarray(state.stage)
    if informed.shape != stage.shape:
        raise ValueError(f"informed must have shape {stage.shape}, got {informed.shape}")
    orbiting = stage != Stage.SEARCH
    readings = np.where(informed, np.where(orbiting, state.readings + 1, 1), np.where(orbiting, state.readings, 0))
    missed = np.where(orbiting & ~informed, state.missed + 1, 0)
    new_stage = np.where(informed & ~orbiting, Stage.APPROACH, stage)  # SEARCH → APPROACH
    if rules.approach_readings is not None:
        ready = (new_stage == Stage.APPROACH) & (readings >= rules.approach_readings)
        new_stage = np.where(ready, Stage.TRACK, new_stage)  # APPROACH → TRACK
    fallback = (new_stage == Stage.TRACK) & (missed > rules.track_patience)
    new_stage = np.where(fallback, Stage.APPROACH, new_stage)  # TRACK → APPROACH
    lost = orbiting & (missed > rules.lost_patience)
    new_stage = np.where(lost, Stage.SEARCH, new_stage)  # orbit → SEARCH
    readings = np.where(lost | fallback, 0, readings)
    return StageState(new_stage.astype(int), readings, np.where(lost, 0, missed))


def _booleans(value, name: str) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype != bool:
        raise ValueError(f"{name} must be boolean, got dtype {arr.dtype}")
    return arr
