"""``skymesh bench tasking`` part ``paths``: the collocation planner's solve time and information gain, and the
separation layer over crossing swarms.

Collocation (:mod:`tasking.collocation`, spec 002 §2.7; Ross, Geiger, Sinsley, Horn, Long & Niessner):

* **solve time** — from ``states`` initial states drawn around a stationary target (range 50-250 m, any
  heading), per vehicle (fixed wing, multirotor): a cold solve at ``t = 0``, then at ``t = 2`` s (the
  next replanning) the same problem solved cold and warm-started from the first plan (the receding-horizon
  case). Median and 95th percentile wall time, SLSQP iterations, and the ratios to the 0.5 s budget and to
  Ross's 2 s replanning period (Ross: the planner overran 2 s in 3 of 251 cycles). SLSQP's own BLAS runs
  on one thread (:func:`scipy_blas_threads`), the setting for an agent process: on a shared machine
  OpenBLAS's worker threads cost ~5-10x per solve; the full run also times cold solves with the default;
* **stand-off information** — a fixed wing flies ``duration`` s about a stationary target: the receding
  horizon planner (replanning every 2 s, the vehicle integrating the plan's controls with RK4) against a
  fixed circle orbit at the fixed wing's loiter radius (``1.2 v^2 / (g tan φ_max)``, what
  ``agent.vehicles.fixed_wing`` flies for an orbit goal) and a straight pass over the target, all at
  ``λ = 4`` Hz bearings. Figure: ``sqrt(det I_plan / det I_baseline)`` (the ratio of the geometric means of
  the information's eigenvalues) and the share of samples with the target in the footprint.

Separation (:mod:`tasking.separation`, spec 000 §2.9): ``N`` = 8 and 16 point-mass agents start on a
circle of radius 60 m (at least ``d_min`` apart) and fly at 10 m/s to the antipodal point, all through the
centre at once; with and without the layer: minimum pairwise separation, violations
(sample, pair) below ``d_min`` = 5 m, and the time until all have arrived (within 1 m).
"""

from __future__ import annotations

import ctypes
import glob
import math
import os
import time
from contextlib import contextmanager

import numpy as np

from mesh_sim.bench import common
from mesh_sim.bench.common import fmt, fmt_ms, fmt_ratio
from tasking.collocation import (
    PlannerConfig,
    RecedingHorizonPlanner,
    VehicleLimits,
    accumulated_information,
    dynamics,
    orbit_guess,
    plan,
    shifted_guess,
)
from tasking.separation import SeparationLayer, fly_swarm, separation_stats

NAME = "tasking-paths"
PART = "paths"
BUDGET_S = 0.5  # the brief's goal: a collocation solve within 0.5 s
REPLAN_S = 2.0  # Ross's horizon update (spec 002 §2.7)
QUICK = {"states": 6, "duration": 30.0, "swarm_seeds": 1, "default_blas_states": 0}
FULL = {"states": 30, "duration": 120.0, "swarm_seeds": 5, "default_blas_states": 5}
SAMPLE_DT = 0.25  # s: the 4 Hz localizer of Ross
D_MIN, SWARM_SPEED, SWARM_DT, SWARM_RADIUS = 5.0, 10.0, 0.1, 60.0
VEHICLES = {"fixed wing": VehicleLimits.fixed_wing(), "multirotor": VehicleLimits.multirotor()}
CRUISE = 18.0  # m/s, the fixed wing's cruise airspeed (agent.vehicles.fixed_wing default)
LOITER_MARGIN = 1.2  # agent.vehicles.fixed_wing's loiter margin


# -- BLAS threads ----------------------------------------------------------------------------------------------
@contextmanager
def scipy_blas_threads(n: int):
    """Run with scipy's bundled OpenBLAS on ``n`` threads (restored afterwards); yields ``n``, or ``None`` when
    that library cannot be found (then nothing changes)."""
    library = _scipy_openblas()
    if library is None:
        yield None
        return
    before = library.scipy_openblas_get_num_threads()
    library.scipy_openblas_set_num_threads(n)
    try:
        yield n
    finally:
        library.scipy_openblas_set_num_threads(before)


def _scipy_openblas():
    import scipy

    for path in glob.glob(os.path.join(os.path.dirname(scipy.__file__), os.pardir, "scipy.libs", "*openblas*.so")):
        try:
            library = ctypes.CDLL(path)
            library.scipy_openblas_get_num_threads  # noqa: B018 - the symbol must exist
            return library
        except (OSError, AttributeError):
            continue
    return None


# -- collocation: solve time -----------------------------------------------------------------------------------
def initial_states(count: int, limits: VehicleLimits, seed: int = 0) -> np.ndarray:
    """``(north, east, heading, speed)`` 50-250 m from the origin, any heading, mid-band speed."""
    rng = np.random.default_rng(seed)
    bearing, distance = rng.uniform(0, 2 * math.pi, count), rng.uniform(50.0, 250.0, count)
    speed = 0.5 * (limits.min_speed + limits.max_speed)
    return np.column_stack([distance * np.cos(bearing), distance * np.sin(bearing),
                            rng.uniform(-math.pi, math.pi, count), np.full(count, speed)])


def time_solves(limits: VehicleLimits, states: np.ndarray) -> dict[str, list]:
    """Per initial state: a cold solve at t = 0; then at t = 2 s, from the first plan's state there, a cold
    solve, a warm one (the first plan shifted) and, for a vehicle that cannot hover, one from the orbit guess.
    A receding-horizon replanning is the warm solve plus that orbit solve (as :class:`RecedingHorizonPlanner`)."""
    config, target, still = PlannerConfig(), np.zeros(2), np.zeros(2)
    out: dict[str, list] = {f"{kind}_{figure}": [] for kind in ("cold", "warm", "replan")
                            for figure in ("s", "iterations")}
    out["ok"] = []
    for state in states:
        first = plan(state, target, still, limits)
        later = first.sample(REPLAN_S)
        cold = plan(later, target, still, limits, t0=REPLAN_S)
        warm = plan(later, target, still, limits, t0=REPLAN_S,
                    initial_guess=shifted_guess(first, REPLAN_S, later, config))
        replan = [warm]
        if RecedingHorizonPlanner(limits).orbit_start:
            replan.append(plan(later, target, still, limits, t0=REPLAN_S,
                               initial_guess=orbit_guess(later, target, still, limits, config)))
        for solve, kind in ((first, "cold"), (cold, "cold"), (warm, "warm")):
            out[f"{kind}_s"].append(solve.solve_time)
            out[f"{kind}_iterations"].append(solve.iterations)
        out["replan_s"].append(sum(s.solve_time for s in replan))
        out["replan_iterations"].append(sum(s.iterations for s in replan))
        out["ok"].extend(s.success for s in (first, cold, *replan))
    return out


def _timing_row(vehicle: str, kind: str, seconds: list[float], iterations: list[int], blas: str) -> dict:
    median, p95 = float(np.median(seconds)), float(np.percentile(seconds, 95))
    return {"section": "solve time", "vehicle": vehicle, "start": kind, "blas": blas, "solves": len(seconds),
            "median_s": median, "p95_s": p95, "iterations_median": float(np.median(iterations)),
            "median_over_budget": median / BUDGET_S, "p95_over_budget": p95 / BUDGET_S,
            "p95_over_replan": p95 / REPLAN_S}


# -- collocation: information over a run --------------------------------------------------------------------------
def _rk4(state: np.ndarray, t: float, dt: float, control) -> np.ndarray:
    """One RK4 step of Ross (8) with the control ``control(t)`` (linear between the plan's nodes)."""
    def f(x, s):
        return dynamics(x, control(s))

    k1 = f(state, t)
    k2 = f(state + 0.5 * dt * k1, t + 0.5 * dt)
    k3 = f(state + 0.5 * dt * k2, t + 0.5 * dt)
    k4 = f(state + dt * k3, t + dt)
    return state + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def fly_receding_horizon(limits: VehicleLimits, start: np.ndarray, duration: float) -> tuple[np.ndarray, list]:
    """The vehicle flying the receding-horizon plans about a target at the origin; positions every
    ``SAMPLE_DT`` (T, 2) and the solves."""
    planner = RecedingHorizonPlanner(limits)
    state, path = start.copy(), []
    for t in np.arange(0.0, duration, SAMPLE_DT):
        planner.setpoint(float(t), state, np.zeros(2), np.zeros(2))
        path.append(state[:2].copy())
        state = _rk4(state, float(t), SAMPLE_DT, planner.plan.control)
    return np.array(path), planner.solves


def circle_path(radius: float, speed: float, duration: float) -> np.ndarray:
    angle = speed / radius * np.arange(0.0, duration, SAMPLE_DT)
    return radius * np.column_stack([np.cos(angle), np.sin(angle)])


def straight_path(speed: float, duration: float) -> np.ndarray:
    north = speed * (np.arange(0.0, duration, SAMPLE_DT) - 0.5 * duration)
    return np.column_stack([north, np.zeros_like(north)])


def information_rows(duration: float) -> list[dict]:
    limits, config = VEHICLES["fixed wing"], PlannerConfig()
    loiter = LOITER_MARGIN * CRUISE**2 / limits.max_lateral_accel  # margin x v^2 / (g tan φ_max)
    start = np.array([loiter, 0.0, math.pi / 2, CRUISE])  # on the circle, flying along it (clockwise)
    planned, solves = fly_receding_horizon(limits, start, duration)
    paths = {"collocation": planned, f"circle r = {loiter:.0f} m": circle_path(loiter, CRUISE, duration),
             "straight pass": straight_path(CRUISE, duration)}
    logdet = {name: float(np.linalg.slogdet(accumulated_information(p, np.zeros(2), SAMPLE_DT, config))[1])
              for name, p in paths.items()}
    rows = []
    for name, path in paths.items():
        in_view = float(np.mean(np.linalg.norm(path, axis=1) <= config.footprint_radius))
        rows.append({"section": "information", "path": name, "duration_s": duration, "logdet": logdet[name],
                     "gain_vs_path": math.exp(0.5 * (logdet["collocation"] - logdet[name])),
                     "in_footprint": in_view,
                     "solves": len(solves) if name == "collocation" else None,
                     "solves_ok": sum(s.success for s in solves) if name == "collocation" else None})
    return rows


# -- separation ---------------------------------------------------------------------------------------------------
def crossing_swarm(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` starts on a circle of radius 60 m (angles jittered, at least ``D_MIN`` apart) and the antipodal goals:
    everyone reaches the centre at the same time."""
    rng = np.random.default_rng(seed)
    angles = (np.arange(n) + rng.uniform(-0.3, 0.3, n)) * 2 * math.pi / n  # >= 0.4 (2π/n) 60 m apart: 9.4 m for n = 16
    starts = SWARM_RADIUS * np.column_stack([np.cos(angles), np.sin(angles)])
    return starts, -starts


def _arrival_time(trajectory: np.ndarray, goals: np.ndarray) -> float | None:
    arrived = np.all(np.linalg.norm(trajectory - goals[None], axis=2) < 1.0, axis=1)
    return float(np.argmax(arrived) * SWARM_DT) if arrived.any() else None


def separation_rows(seeds: int) -> list[dict]:
    steps = int(4 * SWARM_RADIUS / SWARM_SPEED / SWARM_DT)  # twice the straight crossing time
    rows = []
    for n in (8, 16):
        for layer_on in (False, True):
            layer = SeparationLayer(d_min=D_MIN, max_speed=SWARM_SPEED) if layer_on else None
            minima, violations, arrivals = [], 0, []
            for seed in range(seeds):
                starts, goals = crossing_swarm(n, seed)
                trajectory = fly_swarm(starts, goals, SWARM_SPEED, SWARM_DT, steps, layer)
                stats = separation_stats(trajectory, D_MIN)
                minima.append(stats.min_separation)
                violations += stats.violations
                arrivals.append(_arrival_time(trajectory, goals))
            done = [a for a in arrivals if a is not None]
            rows.append({"section": "separation", "agents": n, "layer": layer_on, "seeds": seeds,
                         "min_separation_m": float(min(minima)), "violations": violations,
                         "arrived": len(done), "arrival_s": float(np.mean(done)) if done else None})
    return rows


# -- run and report --------------------------------------------------------------------------------------------------
def run(quick: bool = False, repeats: int | None = None) -> dict:
    """Run the benchmark; ``repeats`` caps the number of initial states of the timing section."""
    settings = dict(QUICK if quick else FULL)
    if repeats is not None:
        if repeats < 1:
            raise ValueError(f"repeats must be at least 1, got {repeats}")
        settings["states"] = min(settings["states"], repeats)
    rows: list[dict] = []
    started = time.perf_counter()
    with scipy_blas_threads(1) as threads:
        blas = "1 thread" if threads else "default"
        for vehicle, limits in VEHICLES.items():
            solves = time_solves(limits, initial_states(settings["states"], limits))
            for kind in ("cold", "warm", "replan"):
                rows.append(_timing_row(vehicle, kind, solves[f"{kind}_s"], solves[f"{kind}_iterations"], blas))
                rows[-1]["success_share"] = float(np.mean(solves["ok"]))
        rows.extend(information_rows(settings["duration"]))
    if settings["default_blas_states"]:
        limits = VEHICLES["fixed wing"]
        solves = time_solves(limits, initial_states(settings["default_blas_states"], limits))
        rows.append(_timing_row("fixed wing", "cold", solves["cold_s"], solves["cold_iterations"], "default"))
    rows.extend(separation_rows(settings["swarm_seeds"]))
    return {"benchmark": NAME, "part": PART, "settings": settings, "rows": rows, "goals": _goals(rows),
            "elapsed_s": time.perf_counter() - started, "environment": common.environment()}


def _goals(rows: list[dict]) -> list[dict]:
    timing = [r for r in rows if r["section"] == "solve time" and r["blas"] != "default"]
    info = {r["path"]: r for r in rows if r["section"] == "information"}
    separated = [r for r in rows if r["section"] == "separation" and r["layer"]]
    goals = []
    for r in timing:
        goals.append({"name": f"{r['vehicle']}, {r['start']}: median <= {BUDGET_S:g} s",
                      "target": BUDGET_S, "measured": r["median_s"], "met": r["median_s"] <= BUDGET_S})
    worst = max(r["p95_s"] for r in timing)
    goals.append({"name": f"p95 solve within the {REPLAN_S:g} s replanning period (Ross)", "target": REPLAN_S,
                  "measured": worst, "met": worst <= REPLAN_S})
    for name, r in info.items():
        if name != "collocation":
            goals.append({"name": f"information gain of collocation vs {name} > 1", "target": 1.0,
                          "measured": r["gain_vs_path"], "met": r["gain_vs_path"] > 1.0})
    for r in separated:
        goals.append({"name": f"{r['agents']} agents with the layer: no violation of d_min = {D_MIN:g} m",
                      "target": 0, "measured": r["violations"], "met": r["violations"] == 0})
    return goals


def report(result: dict, console=None) -> None:
    console = console or common.make_console()
    rows = result["rows"]
    common.print_table(
        console, "collocation solve time (7 nodes, 20 s horizon, SLSQP)",
        [("vehicle", "left"), ("start", "left"), ("BLAS", "left"), "solves", "median ms", "p95 ms",
         "iterations", "median / 0.5 s", "p95 / 0.5 s", "p95 / 2 s"],
        [(r["vehicle"], r["start"], r["blas"], r["solves"], fmt_ms(1e3 * r["median_s"]), fmt_ms(1e3 * r["p95_s"]),
          fmt(r["iterations_median"], ".0f"), fmt_ratio(r["median_over_budget"]), fmt_ratio(r["p95_over_budget"]),
          fmt_ratio(r["p95_over_replan"])) for r in rows if r["section"] == "solve time"],
        caption="cold: from a gentle turn at the current speed; warm: the previous plan shifted by 2 s; replan: "
                "warm + orbit-guess solves (fixed wing only), as RecedingHorizonPlanner does (Ross et al.: 7 nodes, "
                "20 s horizon, replanned every 2 s)",
    )
    common.print_table(
        console, "stand-off information, fixed wing about a stationary target",
        [("path", "left"), "duration s", "log det I", "collocation gain", "target in footprint"],
        [(r["path"], fmt(r["duration_s"], ".0f"), fmt(r["logdet"], ".2f"), fmt_ratio(r["gain_vs_path"]),
          fmt(r["in_footprint"], ".0%")) for r in rows if r["section"] == "information"],
        caption="gain = sqrt(det I_collocation / det I_path), bearings at 4 Hz, σ = 0.01 rad, 60 m above the target",
    )
    common.print_table(
        console, f"separation over a crossing swarm (d_min = {D_MIN:g} m, {SWARM_SPEED:g} m/s, dt = {SWARM_DT:g} s)",
        [("agents", "left"), ("layer", "left"), "seeds", "min separation m", "violations", "arrived",
         "mean arrival s"],
        [(r["agents"], "on" if r["layer"] else "off", r["seeds"], fmt(r["min_separation_m"], ".2f"), r["violations"],
          f"{r['arrived']}/{r['seeds']}", fmt(r["arrival_s"], ".1f")) for r in rows if r["section"] == "separation"],
    )
    common.print_table(console, "goals", [("goal", "left"), "target", "measured", "verdict"],
                       [(g["name"], fmt(g["target"], ".3g"), fmt(g["measured"], ".3g"), common.verdict(g["met"]))
                        for g in result["goals"]])
