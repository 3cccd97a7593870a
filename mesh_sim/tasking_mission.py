"""The thesis' RHTA mission simulation: nominal vs health-extended task assignment (thesis 000 §4.4).

Spec 000 §4.3 (MIT thesis supervised by J. P. How): a base, 20 vehicles all starting there, tasks
generated at random, vehicle failures at random (a failure raises the fuel burn); metrics: the task
service time (arrival -> a vehicle reaches the task) and the vehicles lost (fuel exhausted in the air).
Published: nominal RHTA median 18.8 s, mean 21.3 s, 5 of 20 vehicles lost; the extended RHTA about 18 %
faster (median 14.0 s) with far fewer losses.

The world (all of it chosen here; the thesis gives none of these numbers, spec 000 §4.3 and §3). The
values put the nominal case near the thesis' nominal figures (:mod:`mesh_sim.bench.tasking_health`
measures it):

* the base at the origin; tasks in the square ``[0, area] × [-area/2, area/2]`` north of it
  (north, east) [m]; ``area`` = 420 m;
* ``vehicles`` = 20 at base, first-order flight at ``speed`` = v_max = 5 m/s straight to their goal
  (spec 000 §2.7.2), hovering when idle; time step ``dt`` = 0.2 s;
* tasks arrive as a Poisson process of ``arrival_rate`` = 0.2 per second at uniform positions, with a value
  ``s ~ U(value_range)`` = U(1, 2) and no dwell; a task is served when a vehicle reaches it;
* fuel and failures (:class:`tasking.health.HealthModel` defaults): full tank 1, ``k_fuel`` = 1/600 per
  second (10 min, 3 km on a full tank), ``k_fuel,failure`` = 2 ``k_fuel``, ``p_f`` = 1/500 per second of
  flight, 20 s on the ground to refuel and repair; a vehicle that runs dry in the air is lost and its
  task goes back into the pool;
* RHTA (:func:`tasking.rhta.rhta`, greedy selection, ``first_only``) with ``n_c`` = 2 and ``λ`` = 0.98 per
  second (trips last 10-100 s: a steeper discount would leave far tasks waiting), re-run every
  ``replan_period`` = 1 s on the current state (receding horizon: each vehicle flies to the first task of
  its plan; arrivals, services, failures, losses and refuels are taken into account at the next period);
  the range given to RHTA is ``r`` less ``v_max (replan_period + 2 dt)``, what a vehicle can burn hovering
  until the next plan, plus the rounding of the step;
* ``duration`` = 600 s per run.

Measured with these values (``skymesh bench tasking``, 20 runs per mode, seed 2024): nominal median
17.2 s, mean 22.9 s, 4.25 of 20 vehicles lost per run (thesis: 18.8 s, 21.3 s, 5); extended median 11.9 s,
mean 18.2 s (0.80 × nominal; thesis ≈ 0.82), 1.45 lost per run (0.34 × nominal). The extended fleet flies
about twice as long (it loiters instead of waiting at base) and so fails more than twice as often, yet
loses a third as many vehicles.

The two modes, with the same tasks and the same failure clocks (per-vehicle generators, common random
numbers):

* ``nominal`` (thesis Fig. 4-3): the range ``r = v_max f / k_fuel`` uses the *nominal* burn rate whatever
  the failures (the fuel ``f`` itself is measured), so a failed vehicle keeps flying to tasks it can no
  longer reach and back, and turns home too late; petals beyond that range are pruned and a vehicle with
  nothing in range flies home (that is how a healthy vehicle goes refuelling); no loiter tasks, so with
  no active task every airborne vehicle is called home (the "needless recall" of §2.7.4);
* ``extended`` (thesis Fig. 4-4): the range uses the *current* burn rate (a failure is seen at once), a
  vehicle for which the §2.7.5 return rule (:meth:`tasking.health.VehicleHealth.must_return`) holds is
  sent home, and loiter tasks (:func:`loiter_tasks`: the centres of a ``loiter_grid`` × ``loiter_grid``
  = 4 × 4 grid over the area, value ``loiter_value`` = 0.05, below any real task) are added whenever
  fewer real tasks are active than vehicles can take them, so idle vehicles wait spread over the area
  instead of being recalled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from tasking.health import HealthModel, VehicleHealth
from tasking.rhta import DEFAULT_HORIZON, check_parameters, rhta
from tasking.tasks import Capability, Task

__all__ = ["MODES", "MissionConfig", "MissionResult", "loiter_tasks", "monte_carlo", "random_arrivals",
           "run_mission"]

MODES = ("nominal", "extended")
BASE = np.zeros(2)
HOME = object()  # a vehicle's goal when it flies home (a sentinel no task key can equal)

# vehicle states
PARKED, REFUELLING, FLYING, LOST = "parked", "refuelling", "flying", "lost"


@dataclass(frozen=True)
class MissionConfig:
    """The mission's parameters (module docstring; all chosen here)."""

    vehicles: int = 20
    area: float = 420.0
    speed: float = 5.0
    duration: float = 600.0
    dt: float = 0.2
    arrival_rate: float = 0.2
    value_range: tuple[float, float] = (1.0, 2.0)
    horizon: int = DEFAULT_HORIZON
    discount: float = 0.98
    replan_period: float = 1.0
    loiter_grid: int = 4
    loiter_value: float = 0.05
    health: HealthModel = field(default_factory=HealthModel)

    def __post_init__(self):
        for name in ("area", "speed", "duration", "dt", "replan_period", "loiter_value"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        if self.vehicles < 1:
            raise ValueError(f"vehicles must be ≥ 1, got {self.vehicles}")
        if not (math.isfinite(self.arrival_rate) and self.arrival_rate >= 0):
            raise ValueError(f"arrival_rate must be ≥ 0 tasks per second, got {self.arrival_rate}")
        low, high = self.value_range
        if not 0 < low <= high:
            raise ValueError(f"value_range must be 0 < low ≤ high, got {self.value_range}")
        if self.loiter_grid < 1:
            raise ValueError(f"loiter_grid must be ≥ 1, got {self.loiter_grid}")
        check_parameters(self.horizon, self.discount)


@dataclass
class MissionResult:
    """One run: ``service_times`` [s] of the served tasks, vehicles ``lost``, ``failures``, tasks
    ``arrived`` and left ``unserved``, ``airborne`` vehicle-seconds of flight; ``losses`` and
    ``failure_log`` hold ``(time, vehicle, distance from base)`` of each event."""

    mode: str
    service_times: np.ndarray
    lost: int
    failures: int
    arrived: int
    unserved: int
    airborne: float
    losses: list[tuple[float, int, float]]
    failure_log: list[tuple[float, int, float]]

    @property
    def mean_service(self) -> float:
        return float(np.mean(self.service_times)) if self.service_times.size else math.nan

    @property
    def median_service(self) -> float:
        return float(np.median(self.service_times)) if self.service_times.size else math.nan


def random_arrivals(config: MissionConfig, rng: np.random.Generator) -> list[tuple[float, Task]]:
    """Poisson arrivals of rate ``arrival_rate`` over the mission, uniform over the area, ``s ~ U(value_range)``."""
    arrivals, t = [], 0.0
    while config.arrival_rate > 0:
        t += rng.exponential(1.0 / config.arrival_rate)  # exponential gaps: a Poisson process
        if t >= config.duration:
            break
        where = (rng.uniform(0.0, config.area), rng.uniform(-config.area / 2, config.area / 2))
        arrivals.append((t, Task(len(arrivals), where, float(rng.uniform(*config.value_range)))))
    return arrivals


def loiter_tasks(config: MissionConfig) -> list[Task]:
    """The loiter tasks (§2.7.4): the centres of a ``loiter_grid`` × ``loiter_grid`` grid over the area."""
    cells = (np.arange(config.loiter_grid) + 0.5) / config.loiter_grid * config.area
    return [
        Task(("loiter", i, j), (north, east - config.area / 2), config.loiter_value, kind="loiter")
        for i, north in enumerate(cells)
        for j, east in enumerate(cells)
    ]


class _Mission:
    """The state of one run; :meth:`run` steps it to the end."""

    def __init__(self, config: MissionConfig, mode: str, arrivals, rngs):
        self.config, self.extended = config, mode == "extended"
        self.mode = mode
        self.arrivals = sorted(arrivals, key=lambda item: item[0])
        self.health = [VehicleHealth(config.health, rng) for rng in rngs]
        n = config.vehicles
        self.position = np.zeros((n, 2))
        self.status = [PARKED] * n
        self.goal: list[object] = [None] * n  # a task key, HOME, or None (hover / stay parked)
        self.active: dict[object, tuple[Task, float]] = {}  # key -> (task, arrival time)
        self.loiter = {task.key: task for task in loiter_tasks(config)}
        self.service_times: list[float] = []
        self.losses: list[tuple[float, int, float]] = []
        self.failure_log: list[tuple[float, int, float]] = []
        self.airborne = 0.0

    # -- planning ------------------------------------------------------------------------------------------
    def _plan(self) -> None:
        config = self.config
        ready = [v for v, status in enumerate(self.status) if status in (PARKED, FLYING)]
        planned = []
        for v in ready:
            home = float(np.hypot(*self.position[v]))
            if self.extended and self.health[v].must_return(home, config.speed):  # §2.7.5
                self.goal[v] = HOME
            else:
                planned.append(v)
        margin = config.speed * (config.replan_period + 2 * config.dt)  # hovering until the next plan + rounding
        vehicles = {
            v: Capability(self.position[v], config.speed, BASE,
                          reach=max(self.health[v].reach(config.speed, health_aware=self.extended) - margin, 0.0),
                          quality=self.health[v].quality)
            for v in planned
        }
        tasks = [task for task, _ in self.active.values()]
        if self.extended and len(tasks) < len(planned):
            tasks += self.loiter.values()
        plans = rhta(vehicles, tasks, config.horizon, config.discount, first_only=True)
        for v, plan in plans.items():
            self.goal[v] = plan.tasks[0] if plan.tasks else HOME if plan.home else None

    # -- motion and events ---------------------------------------------------------------------------------
    def _goal_position(self, v: int) -> np.ndarray | None:
        goal = self.goal[v]
        if goal is None:
            return None
        if goal is HOME:
            return BASE
        if goal in self.active:
            return self.active[goal][0].position
        return self.loiter[goal].position if goal in self.loiter else None  # served meanwhile: hover

    def _step_vehicle(self, v: int, t: float) -> None:
        """Advance vehicle ``v`` by one step ending at ``t``."""
        health, dt, speed = self.health[v], self.config.dt, self.config.speed
        if self.status[v] == REFUELLING:
            health.step(dt, flying=False)
            if not health.refuelling:
                self.status[v] = PARKED
            return
        target = self._goal_position(v)
        if self.status[v] == PARKED and (target is None or target is BASE):
            health.step(dt, flying=False)
            return
        self.status[v] = FLYING
        self.airborne += dt
        was_failed = health.failed
        arrived = False
        if target is not None:
            offset = target - self.position[v]
            distance = float(np.hypot(*offset))
            arrived = distance <= speed * dt
            self.position[v] = target.copy() if arrived else self.position[v] + offset * (speed * dt / distance)
        health.step(dt, flying=True)
        home = float(np.hypot(*self.position[v]))
        if health.failed and not was_failed:
            self.failure_log.append((t, v, home))
        if health.lost:
            self.status[v], self.goal[v] = LOST, None
            self.losses.append((t, v, home))
        elif arrived:
            self._arrive(v, t)

    def _arrive(self, v: int, t: float) -> None:
        goal = self.goal[v]
        if goal is HOME:
            self.status[v], self.goal[v] = REFUELLING, None
            self.health[v].start_refuel()
            if not self.health[v].refuelling:
                self.status[v] = PARKED
        elif goal in self.active:
            _, arrival = self.active.pop(goal)
            self.service_times.append(t - arrival)  # service time: arrival -> reached
            self.goal[v] = None
        # else at a loiter point: stay

    def run(self) -> MissionResult:
        config = self.config
        steps = int(round(config.duration / config.dt))
        pending = list(self.arrivals)
        next_plan = 0.0
        for k in range(steps):
            t = k * config.dt
            while pending and pending[0][0] <= t:
                arrival, task = pending.pop(0)
                self.active[task.key] = (task, arrival)
            if t >= next_plan - 1e-9:  # receding horizon: re-plan every period
                self._plan()
                next_plan += config.replan_period
            for v in range(config.vehicles):
                if self.status[v] != LOST:
                    self._step_vehicle(v, t + config.dt)
        return MissionResult(
            mode=self.mode,
            service_times=np.array(self.service_times),
            lost=len(self.losses),
            failures=sum(health.failures for health in self.health),
            arrived=len(self.arrivals) - len(pending),
            unserved=len(self.active),
            airborne=self.airborne,
            losses=self.losses,
            failure_log=self.failure_log,
        )


def _streams(seed: int, vehicles: int) -> tuple[np.random.Generator, list[np.random.Generator]]:
    """The task generator and one failure generator per vehicle, from ``seed`` (the same in both modes)."""
    tasks, *fleet = np.random.SeedSequence(seed).spawn(vehicles + 1)
    return np.random.default_rng(tasks), [np.random.default_rng(s) for s in fleet]


def run_mission(
    config: MissionConfig, mode: str, seed: int, arrivals: list[tuple[float, Task]] | None = None
) -> MissionResult:
    """One run in ``mode`` (``"nominal"`` or ``"extended"``); ``arrivals`` ``[(time, task), ...]`` replace
    the random tasks (a hand-built scenario)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    task_rng, fleet = _streams(seed, config.vehicles)
    if arrivals is None:
        arrivals = random_arrivals(config, task_rng)
    return _Mission(config, mode, arrivals, fleet).run()


def monte_carlo(config: MissionConfig, runs: int, seed: int = 0) -> dict[str, list[MissionResult]]:
    """``runs`` runs of each mode with seeds ``seed, seed + 1, ...`` (the same seeds for both modes)."""
    if runs < 1:
        raise ValueError(f"runs must be ≥ 1, got {runs}")
    return {mode: [run_mission(config, mode, seed + r) for r in range(runs)] for mode in MODES}
