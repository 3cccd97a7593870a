"""``[tasking] standoff = "collocation"``: a vehicle serving a track task flies Ross et al.'s receding-horizon
collocation plan about its target instead of the loiter circle (spec 002 §2.7; :mod:`tasking.collocation`).

**What is flown.** Every ``replan_period`` (Ross: 2 s) of simulation time the planner solves the collocation
problem from the vehicle's state (:func:`tasking.collocation.unicycle_state`) for the target's fused mean and
velocity (the agent's :class:`tasking.base.TrackView`), warm-started from the plan in use
(:meth:`RecedingHorizonPlanner.solve`). Each cycle the goal is the adopted plan's set-point at the current time:
its position at the flight altitude and its ground velocity as feed-forward (``Goal(position, velocity)``). Before
the first plan is adopted the vehicle flies the circle it would otherwise fly.

**Non-blocking and deterministic.** A solve takes up to ~0.5 s; the agent steps at 5 Hz. The solve of the
replanning requested at ``t_r`` therefore runs on the agent's one worker thread, and its result is adopted at
the simulation time ``t_r + adopt_after`` (the first call at or after it), never earlier and never later:
meanwhile the vehicle flies the previous plan. At the adoption instant the planner joins the solve. In lockstep
(``wait = None``) it waits for it however long it takes, so the flown path depends on simulation time only and
two runs are identical whatever the thread timing. Live, the solve normally finished long before (``adopt_after``
exceeds the 0.5 s budget); one that has not is waited for at most ``wait`` wall seconds, then counted ``late``
and dropped, the old plan kept — the agent's 5 Hz deadline outranks a late plan; while that solve still runs
no new one is requested (``skipped``: queued behind it, every later plan would be late too). Lockstep and live
thus fly the same rule; only the clock differs (DESIGN §4). One worker per agent (the solves of one agent never
overlap); :meth:`StandoffPilot.close` stops it (the agent's ``close``), so no thread outlives its agent.

The GIL: SLSQP's objective and constraints are numpy in Python, so the worker holds the GIL for much of a solve;
the interpreter hands it back to the agent's loop every ``sys.getswitchinterval()`` (5 ms), so a step overlapping
a solve is slowed but not blocked (measured in the README). SLSQP's BLAS should run on one thread (see
:mod:`tasking.collocation`; the launcher starts its agents with ``OPENBLAS_NUM_THREADS=1``).

Chosen here: ``adopt_after`` 0.6 s (the 0.5 s budget plus a step), ``wait`` 0.05 s live (a quarter of a 5 Hz
step), the fixed wing's speed band ±5 % (the kinematic fixed wing holds its airspeed), the footprint radius
equal to the altitude (a 90° nadir field of view).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from concurrent.futures import wait as wait_for

import numpy as np

from tasking.collocation import PlannerConfig, RecedingHorizonPlanner, Replanning, VehicleLimits, unicycle_state
from tasking.orbit import Goal

STANDOFFS = ("circle", "collocation")
FIXED_WING_SPEED_BAND = 0.05  # the kinematic fixed wing flies at constant airspeed (chosen here)
REPLAN_PERIOD = 2.0  # s, Ross's horizon update (spec 002 §2.7)
LIVE_WAIT = 0.05  # s of wall time a live agent waits, at the adoption instant, for an unfinished solve


def vehicle_limits(vehicle: Mapping[str, object], max_speed: float | None) -> VehicleLimits:
    """The collocation limits of the agent's ``[vehicle]`` section: a fixed wing's ``airspeed`` and ``max_bank_deg``
    (the model's defaults 18 m/s, 35°), a multirotor's top speed (``max_speed``) and ``max_accel``."""
    if vehicle.get("kind") == "fixed_wing":
        airspeed = float(vehicle.get("airspeed", max_speed or 18.0))
        bank = math.radians(float(vehicle.get("max_bank_deg", 35.0)))
        return VehicleLimits.fixed_wing(airspeed, bank, speed_band=FIXED_WING_SPEED_BAND)
    return VehicleLimits.multirotor(float(max_speed or vehicle.get("max_speed", 10.0)),
                                    float(vehicle.get("max_accel", 3.0)))


class StandoffPilot:
    """The collocation set-point about one target at a time, replanned on a worker thread (module docstring).

    ``wait``: wall seconds to wait for an unfinished solve at its adoption instant (``None``: wait until done)."""

    def __init__(self, limits: VehicleLimits, altitude: float, adopt_after: float = 0.6,
                 replan_period: float = REPLAN_PERIOD, wait: float | None = LIVE_WAIT):
        config = PlannerConfig(altitude=float(altitude), footprint_radius=float(altitude))
        self.planner = RecedingHorizonPlanner(limits, config, replan_period)
        if not 0 <= adopt_after < replan_period:
            raise ValueError(f"tasking.adopt_after must be in [0, {replan_period}) s, got {adopt_after}")
        self.adopt_after, self.wait = adopt_after, wait
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="standoff")
        self._pending: tuple[float, Future] | None = None  # (adoption time, solve)
        self._last: Future | None = None  # the latest solve submitted
        self._target: str | None = None
        self._next_request = 0.0
        self.requested = self.adopted = self.late = self.failed = self.skipped = 0
        self.replannings: list[Replanning] = []  # adopted or failed, in order
        self.late_replannings: list[Replanning] = []  # finished after their adoption instant (live)

    def goal(self, t: float, state, target: str, mean, velocity) -> Goal | None:
        """The goal at simulation time ``t`` for ``target`` (mean (north, east), velocity (north, east)) from the
        vehicle ``state`` (NED ``position``, ``velocity``, ``yaw``); ``None`` before the first plan about this target
        is adopted."""
        if target != self._target:
            self._restart(target, t)
        if self._pending is not None and t >= self._pending[0] - 1e-9:
            self._adopt()
        if t >= self._next_request - 1e-9:
            self._request(t, state, mean, velocity)
        if self.planner.plan is None:
            return None
        point = self.planner.sample(t)
        return Goal(position=point.position, velocity=point.velocity[:2])

    def release(self) -> None:
        """Not serving a target any more: forget it (the next :meth:`goal` starts afresh)."""
        self._target = None
        self._drop()

    def _restart(self, target: str, t: float) -> None:
        """A new target: forget the plan (and drop a solve for the old target); replan now."""
        self._target, self._next_request, self.planner.plan = target, t, None
        self._drop()

    def _request(self, t: float, state, mean, velocity) -> None:
        self._next_request = t + self.planner.replan_period
        if self._last is not None and not self._last.done():
            self.skipped += 1  # live: a late solve still holds the worker; queueing behind it would cascade
            return
        x = unicycle_state(state.position, state.velocity, float(getattr(state, "yaw", 0.0)))
        mean, velocity = np.array(mean, float)[:2], np.array(velocity, float)[:2]
        future = self._worker.submit(self.planner.solve, t, x, mean, velocity, self.planner.plan)
        self._pending, self._last = (t + self.adopt_after, future), future
        self.requested += 1

    def _adopt(self) -> None:
        future = self._pending[1]
        self._pending = None
        try:
            replanning = future.result(timeout=self.wait)
        except FutureTimeout:
            self.late += 1  # keep the old plan; the solve finishes in the background, timed but not flown
            future.add_done_callback(self._timed)
            return
        self.replannings.append(replanning)
        if self.planner.adopt(replanning):
            self.adopted += 1
        else:
            self.failed += 1

    def _timed(self, future: Future) -> None:
        """A late solve's times, from the worker when it ends (a list append is atomic under the GIL)."""
        if not future.cancelled() and future.exception() is None:
            self.late_replannings.append(future.result())

    def _drop(self) -> None:
        """Forget the pending solve; in lockstep (``wait = None``) wait for it to end if it cannot be cancelled, so
        that the worker is free at the next request whatever the thread timing."""
        if self._pending is not None:
            future = self._pending[1]
            self._pending = None
            if not future.cancel() and self.wait is None:
                wait_for([future])

    def close(self) -> None:
        """Stop the worker (a solve under way is finished first: SLSQP cannot be interrupted)."""
        self._drop()
        self._worker.shutdown(wait=True, cancel_futures=True)

    def metrics(self) -> dict:
        """Replannings requested, adopted (a successful plan taken), failed (no solve succeeded), late (not done at
        the adoption instant, live), skipped (not requested: a late solve still running, live), and the wall and
        thread-CPU times (median, p95) [ms] of every finished one."""
        timed = self.replannings + self.late_replannings
        walls, cpus = [1e3 * r.wall for r in timed], [1e3 * r.cpu for r in timed]
        return {"requested": self.requested, "adopted": self.adopted, "failed": self.failed, "late": self.late,
                "skipped": self.skipped,
                "solve_ms_median": _percentile(walls, 50), "solve_ms_p95": _percentile(walls, 95),
                "solve_cpu_ms_median": _percentile(cpus, 50), "solve_cpu_ms_p95": _percentile(cpus, 95),
                "solve_ms": walls, "solve_cpu_ms": cpus}


def _percentile(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None
