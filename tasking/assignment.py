"""``[tasking] planner = "assignment"``: the fleet's tasks, and the planner that serves what CBBA gave it.

**Tasks** (thesis 000 §2.7.1, spec 000 §2.7): every confirmed track is a task to *keep in view* (value
``track_value``), every cell of a ``search_cell`` grid over the area is a task to *search* (value
``search_value``, less than a track's, so that no target is left unwatched while a cell is searched).
Tasks are persistent: a vehicle serves one until the assignment changes. The assignment itself is reached
by consensus (:mod:`tasking.cbba`, carried over the mesh by ``agent.beliefs.assignment``).

**Serving** (:class:`AssignmentPlanner`): a track task is orbited at ``orbit_radius`` around its fused
estimate (Andreetto et al.'s circle, spec 004 §2.8; the centre follows the estimate every cycle); a search
cell is swept by a boustrophedon of ``spacing`` (:func:`tasking.search.lawnmower_waypoints`), resumed where
it was left; ``home`` flies to the base; with no task the vehicle holds an orbit where it is. Whatever the
task, a peer closer than the separation layer's reach turns the goal into a point along the separated
velocity (:class:`tasking.separation.SeparationLayer`, thesis 000 §2.9), so that no two vehicles come
closer than ``min_separation``. With ``standoff = "collocation"`` a track task served alone is flown instead on
Ross et al.'s receding-horizon collocation plan about the target (spec 002 §2.7, :mod:`tasking.standoff`; the
plans are adopted ``adopt_after`` seconds after their request, every 2 s).

**Shared orbits** (``orbit_slots`` = k > 1; spec 004 §2.8-2.9): every track is k tasks, its *slots*
``track:<id>`` and ``track:<id>#1`` ... ``#k-1``, of values ``track_value / (s + 1)`` for slot s (each further
vehicle on a target adds less: CBBA fills every target's first slot before any second one, while every slot
still outbids a search cell when ``track_value / k > search_value``). The vehicles that won slots of one target
share its circle and space themselves equally on it with 004's rotation law (:mod:`tasking.circle_spacing`:
``θ̇_i = ω_0 + k_θ (g⁺ - g⁻)/2`` about the fused estimate, the peers' phases from their reported positions);
this is 004's rendezvous in the fleet: a vehicle that sees the target starts its own orbit, one told of it
by a peer's track flies to the circle (case 1), and the fused track is the consensus on the centre.

**Health** (``flight_time`` > 0; thesis 000 §2.7.4-2.7.5, :mod:`tasking.sortie`): fuel burns while flying,
failures arrive as a Poisson process (``failure_rate``) and multiply the burn (``failure_burn``); a
vehicle bids only for petals it can fly and still come home from, goes home when its fuel (at the current
burn) or its camera say so, refuels there and comes back; its camera quality scales its bids.

Parameters chosen here (the thesis gives none for the fleet): values 10 (track) and 1 (search), time
discount λ = 0.95 per second (a target 100 m away at 10 m/s is worth 0.6 of one at hand), one task per
vehicle (``capacity`` = L_t = 1: tasks are served continuously, not visited), ``stickiness`` 1.2.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, fields

import numpy as np

from tasking.base import AssignmentView, TrackView, VehicleStateLike
from tasking.circle_spacing import circle_gaps, spacing_rate, spacing_setpoint
from tasking.health import HealthModel
from tasking.orbit import Goal, goto_goal, orbit_setpoint
from tasking.search import Area, WaypointFollower, check_area, lawnmower_waypoints
from tasking.separation import SeparationLayer
from tasking.standoff import REPLAN_PERIOD, STANDOFFS, StandoffPilot
from tasking.tasks import Task

SEPARATION_LOOKAHEAD = 1.0  # s: a separated velocity becomes a goal this far ahead
SLOT = "#"  # separates a track task's key from its slot number (slot 0 has none)
OPTIONAL = frozenset({"min_separation", "flight_time", "failure_rate", "refuel_time", "reserve",
                      "adopt_after"})  # 0: off / none
WORDS = {"standoff": STANDOFFS}  # the keys whose values are words, and the words they take

@dataclass(frozen=True)
class AssignmentConfig:
    """The ``[tasking]`` keys of ``planner = "assignment"`` (see the module docstring for the defaults)."""

    track_value: float = 10.0
    search_value: float = 1.0
    search_cell: float = 80.0  # m, side of a search cell
    spacing: float = 40.0  # m, lawnmower leg spacing inside a cell
    orbit_radius: float = 40.0  # m
    discount: float = 0.95  # λ per second, (4.1)
    capacity: int = 1  # L_t
    stickiness: float = 1.2
    cruise_speed: float = 10.0  # m/s, the travel-time estimate of the scores
    match_radius: float = 25.0  # m: a peer's track task within this of ours is the same task
    min_separation: float = 10.0  # m: no two vehicles closer (tasking.separation), 0 switches the layer off
    flight_time: float = 0.0  # s on a full tank (tasking.sortie; 0: no health model)
    failure_rate: float = 0.0  # p_f, failures per second of flight (Poisson)
    failure_burn: float = 2.0  # k_fuel,failure / k_fuel: a failure multiplies the burn rate
    refuel_time: float = 20.0  # s on the ground at the base to refuel and repair
    reserve: float = 10.0  # s of flight kept in hand on the way home
    landing_radius: float = 5.0  # m from the base at which a returning vehicle lands
    period: float = 1.0  # s between bid broadcasts when nothing changed
    peer_timeout: float = 5.0  # s without news of a vehicle before its claims are released (tasking.cbba.CBBA.expire)
    orbit_slots: int = 1  # vehicles that share one target's circle, equally spaced (spec 004 §2.8)
    standoff: str = "circle"  # how a lone vehicle serves a track: the circle, or "collocation" (tasking.standoff)
    adopt_after: float = 0.6  # s after its request at which a collocation replanning is adopted (tasking.standoff)

    def __post_init__(self):
        for name, words in WORDS.items():
            if getattr(self, name) not in words:
                raise ValueError(f"tasking.{name} must be one of {list(words)}, got {getattr(self, name)!r}")
        for f in fields(self):
            if f.name in WORDS:
                continue
            value = getattr(self, f.name)
            bad = isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value)
            if bad or value < 0 or (value == 0 and f.name not in OPTIONAL):
                raise ValueError(f"tasking.{f.name} must be a positive number, got {value!r}")
        if not 0 < self.discount <= 1:
            raise ValueError(f"tasking.discount (λ) must be in (0, 1], got {self.discount}")
        for name in ("capacity", "orbit_slots"):
            if int(getattr(self, name)) != getattr(self, name):
                raise ValueError(f"tasking.{name} must be an integer, got {getattr(self, name)}")
        if self.stickiness < 1:
            raise ValueError(f"tasking.stickiness must be ≥ 1, got {self.stickiness}")
        if self.failure_burn <= 1:
            raise ValueError(f"tasking.failure_burn must be > 1 (a failure burns faster), got {self.failure_burn}")
        if self.adopt_after >= REPLAN_PERIOD:
            raise ValueError(f"tasking.adopt_after must be below the {REPLAN_PERIOD:g} s replanning period, "
                             f"got {self.adopt_after}")
        if self.search_value >= self.track_value:
            raise ValueError(f"tasking.search_value ({self.search_value}) must be below track_value "
                             f"({self.track_value}): a target in view comes before an area to search")

    @classmethod
    def from_options(cls, options: Mapping[str, object]) -> AssignmentConfig:
        return cls(**{k: v for k, v in options.items() if k in {f.name for f in fields(cls)}})

    def health_model(self) -> HealthModel | None:
        """The fleet's :class:`tasking.health.HealthModel` (``None`` without ``flight_time``)."""
        if self.flight_time <= 0:
            return None
        burn = 1.0 / self.flight_time  # k_fuel on a tank of capacity 1
        return HealthModel(capacity=1.0, burn=burn, burn_failed=burn * self.failure_burn,
                           failure_rate=self.failure_rate, refuel_time=self.refuel_time)


def _cell_grid(area: Area, cell: float) -> tuple[float, float, float, float, int, int]:
    """``area`` and the rows and columns of cells of about ``cell`` metres that tile it."""
    n0, n1, e0, e1 = check_area(area)
    return n0, n1, e0, e1, max(1, round((n1 - n0) / cell)), max(1, round((e1 - e0) / cell))


def search_cells(area: Area, cell: float) -> dict[str, np.ndarray]:
    """The search cells' centres, keyed ``"search:<row>:<col>"``, tiling ``area`` with cells of about ``cell``."""
    n0, n1, e0, e1, rows, cols = _cell_grid(area, cell)
    return {f"search:{r}:{c}": np.array([n0 + (r + 0.5) * (n1 - n0) / rows, e0 + (c + 0.5) * (e1 - e0) / cols])
            for r in range(rows) for c in range(cols)}


def cell_area(area: Area, key: str, cell: float) -> tuple[float, float, float, float]:
    """The (north min, max, east min, max) of search cell ``key``."""
    n0, n1, e0, e1, rows, cols = _cell_grid(area, cell)
    r, c = (int(x) for x in key.split(":")[1:])
    dn, de = (n1 - n0) / rows, (e1 - e0) / cols
    return (n0 + r * dn, n0 + (r + 1) * dn, e0 + c * de, e0 + (c + 1) * de)


def search_tasks(cells: Mapping[str, np.ndarray], config: AssignmentConfig) -> dict[Hashable, Task]:
    """One ``search:r:c`` task per cell (they never change: built once per agent)."""
    return {key: Task(key, centre, config.search_value, "search") for key, centre in cells.items()}


def fleet_tasks(tracks: Sequence[tuple[Hashable, np.ndarray]], searches: Mapping[Hashable, Task],
                config: AssignmentConfig) -> dict[Hashable, Task]:
    """The task set: the ``searches`` (:func:`search_tasks`) and ``orbit_slots`` tasks per confirmed track,
    ``track:<id>`` and ``track:<id>#s`` of value ``track_value / (s + 1)`` (module docstring)."""
    tasks = dict(searches)
    for track_id, position in tracks:
        for slot in range(config.orbit_slots):
            key = slot_key(f"track:{track_id}", slot)
            tasks[key] = Task(key, np.asarray(position, float)[:2], config.track_value / (slot + 1), "track")
    return tasks


def slot_key(target: str, slot: int) -> str:
    """The key of ``target``'s slot ``slot`` (slot 0: ``target`` itself); :func:`slot_of` reads it back."""
    return target + (f"{SLOT}{slot}" if slot else "")


def slot_of(key: str) -> tuple[str, int]:
    """``("track:<id>", s)`` of a track task's key ``track:<id>#s`` (slot 0: the key itself)."""
    target, _, slot = key.partition(SLOT)
    return target, int(slot) if slot else 0


class AssignmentPlanner:
    """Serve the task the fleet's consensus gave this vehicle (:class:`tasking.base.AssignmentView`), kept
    ``min_separation`` from its peers by :class:`tasking.separation.SeparationLayer` (acting on the vehicle's
    velocity, every ``step`` seconds, bounded by the fleet's top speed ``max_speed``). With a ``standoff`` pilot
    (``standoff = "collocation"``) a track served alone is flown on the pilot's collocation plan, the circle
    until its first plan; the planner's clock counts its calls, ``step`` seconds each."""

    def __init__(self, config: AssignmentConfig, area: Area, altitude: float, step: float = 0.2,
                 max_speed: float | None = None, standoff: StandoffPilot | None = None):
        self.config, self.area, self.altitude, self.step = config, check_area(area), float(altitude), float(step)
        self.standoff, self._calls = standoff, 0
        self.layer_speed = max_speed if max_speed is not None else config.cruise_speed
        self.layer = SeparationLayer(config.min_separation, self.layer_speed) if config.min_separation > 0 else None
        self._sweeps: dict[str, WaypointFollower] = {}
        self._hold: np.ndarray | None = None
        self.mode = "idle"

    def plan(self, state: VehicleStateLike, views: Mapping[str, object]) -> Goal:
        view: AssignmentView = views["tasks"]
        self._calls += 1
        goal = self._serve(state, view, views.get("track"))
        return goal if self.layer is None else self._separated(state, view, goal)

    def _separated(self, state: VehicleStateLike, view: AssignmentView, goal: Goal) -> Goal:
        """The goal, or — with a peer within the layer's reach — a point one second along the separated
        velocity (the layer's guarantee holds for velocities held over ``step``; the vehicle tracks them)."""
        if not view.peers:
            return goal
        own = np.asarray(state.position, float)[:2]
        peers = np.array(list(view.peers.values()))
        if np.min(np.hypot(*(peers - own).T)) >= self.layer.reach(self.step):
            return goal
        velocity = self.layer.adjust(own, np.asarray(state.velocity, float)[:2], peers, self.step)
        speed = float(np.hypot(*velocity))
        return goto_goal(own + velocity * SEPARATION_LOOKAHEAD, self.altitude, speed if speed > 0.1 else None)

    def _serve(self, state: VehicleStateLike, view: AssignmentView, tracks: TrackView | None) -> Goal:
        position = np.asarray(state.position, float)
        task = view.task
        if self.standoff is not None and (task is None or task.kind != "track" or view.home or view.partners):
            self.standoff.release()
        if view.home:
            self.mode = "home"
            return goto_goal(view.base, self.altitude)
        if task is None:
            self.mode = "idle"
            if self._hold is None:
                self._hold = position[:2].copy()
            return orbit_setpoint(self._hold, self.config.orbit_radius, self.altitude)
        self._hold = None
        self.mode = task.kind
        if task.kind == "search":
            return goto_goal(self._sweep(task.key).current(position)[:2], self.altitude)
        if view.partners:
            return self._spaced(position[:2], task, view.partners, tracks)
        circle = orbit_setpoint(task.position, self.config.orbit_radius, self.altitude)
        if self.standoff is None:
            return circle
        target = slot_of(task.key)[0]
        velocity = _velocity(tracks, target)
        planned = self.standoff.goal((self._calls - 1) * self.step, state, target, task.position, velocity)
        return circle if planned is None else planned

    def close(self) -> None:
        """Stop the standoff pilot's worker thread (the agent's ``close``)."""
        if self.standoff is not None:
            self.standoff.close()

    def metrics(self) -> dict:
        """The standoff pilot's figures under ``"standoff"`` (nothing without one)."""
        return {} if self.standoff is None else {"standoff": self.standoff.metrics()}

    def _spaced(self, own: np.ndarray, task: Task, partners: Mapping[str, np.ndarray],
                tracks: TrackView | None) -> Goal:
        """004's set-point on the shared circle about the task's target (``circle_spacing.spacing_setpoint``):
        the point of the circle at this vehicle's phase ``θ_i`` with the feed-forward velocity ``ṗ̂ + r θ̇_i t̂`` —
        the target's fused velocity (004 §2.8's translation) plus the rotation at the rate of the spacing law
        between this vehicle's circle-neighbours among ``partners``. Flown clockwise, the sense in which the
        phase grows; the vehicle's position loop pulls it onto the circle, the feed-forward carries it along."""
        centre_velocity = _velocity(tracks, slot_of(task.key)[0])
        positions = np.vstack([own, *partners.values()])
        theta, ahead, behind = circle_gaps(np.broadcast_to(task.position, positions.shape), positions,
                                           np.ones((len(positions),) * 2, bool))
        radius = self.config.orbit_radius
        rate = spacing_rate(ahead[:1], behind[:1], radius, self.step, float(np.hypot(*centre_velocity)),
                            max_speed=self.layer_speed)
        point = spacing_setpoint(task.position, centre_velocity, theta[:1], rate, radius, self.layer_speed)
        return Goal(position=np.array([*point.position[0], -self.altitude]), velocity=point.velocity[0])

    def _sweep(self, key: str) -> WaypointFollower:
        """The boustrophedon of one cell, kept so that a vehicle sent back to a cell resumes its sweep."""
        if key not in self._sweeps:
            cell = cell_area(self.area, key, self.config.search_cell)
            path = lawnmower_waypoints(cell, self.config.spacing, self.altitude)
            self._sweeps[key] = WaypointFollower(path, self.config.spacing / 2)
        return self._sweeps[key]


def _velocity(tracks: TrackView | None, target: str) -> np.ndarray:
    """The fused velocity (north, east) of ``target`` (``track:<id>``), zero if the view has none."""
    velocities = {} if tracks is None else {str(tid): v for tid, v in tracks.velocities.items()}
    return np.asarray(velocities.get(target.removeprefix("track:"), np.zeros(2)), float)[:2]
