"""``skymesh bench tasking`` (part ``health``): nominal vs health-extended RHTA, the thesis' §4.4 simulation.

Thesis 000 §4.4 (spec 000 §4.3; MIT thesis supervised by J. P. How): 20 vehicles from one base serve
randomly arriving tasks while failures raise their fuel burn. Published: nominal RHTA median service
time 18.8 s, mean 21.3 s, 5 of 20 vehicles lost; the health-extended RHTA (range from the current burn
rate, recall of failed vehicles, loiter tasks) about 18 % faster (median 14.0 s) and "significantly"
fewer losses. The world and its parameters are those of :mod:`mesh_sim.tasking_mission` (all chosen
there, to put the nominal case near the published figures); both modes run with the same seeds (same
tasks, same failure clocks), so their ratio is measured within one run of this benchmark.

Per mode: the median and mean service time over every task served in every run (the thesis' histograms
pool one mission's tasks), the spread of the per-run means, and the vehicles lost (mean per run, total).

Goals (from the task): over at least 20 Monte-Carlo runs, the extended mean service time at least 15 %
below the nominal one, and the extended losses at most half the nominal ones. Quick mode: fewer and
shorter runs (the goals are still evaluated, on less data).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, replace

import numpy as np

from mesh_sim.bench import common
from mesh_sim.tasking_mission import MODES, MissionConfig, MissionResult, monte_carlo

NAME = "tasking-health"
PART = "health"
FULL_RUNS, QUICK_RUNS = 20, 2
QUICK_DURATION_S = 240.0
SEED = 2024
THESIS = {  # [THESIS] §4.4, Figs. 4-3 / 4-4 (spec 000 §4.3)
    "nominal": {"median_service_s": 18.8, "mean_service_s": 21.3, "lost_per_run": 5.0},
    "extended": {"median_service_s": 14.0, "mean_service_s": 21.3 * (1 - 0.18), "lost_per_run": None},
}
GOAL_SPEEDUP = 0.15  # extended mean service time at least 15 % below nominal (from the task)
GOAL_LOSS_RATIO = 0.5  # extended losses at most half the nominal ones (from the task)


def _summary(results: list[MissionResult]) -> dict:
    times = np.concatenate([r.service_times for r in results])
    per_run = np.array([r.mean_service for r in results])
    lost = np.array([r.lost for r in results])
    return {
        "median_service_s": float(np.median(times)),
        "mean_service_s": float(np.mean(times)),
        "per_run_mean_sd_s": float(np.std(per_run, ddof=1)) if len(per_run) > 1 else math.nan,
        "lost_per_run": float(lost.mean()),
        "lost_total": int(lost.sum()),
        "failures_per_run": float(np.mean([r.failures for r in results])),
        "served": int(times.size),
        "unserved_per_run": float(np.mean([r.unserved for r in results])),
        "runs": len(results),
    }


def _ratio(a: float, b: float) -> float:
    return a / b if b else math.nan


def run(quick: bool = False, repeats: int | None = None) -> dict:
    """Run both modes over the Monte-Carlo seeds; ``repeats`` overrides the number of runs."""
    runs = repeats if repeats is not None else QUICK_RUNS if quick else FULL_RUNS
    if runs < 1:
        raise ValueError(f"repeats (Monte-Carlo runs) must be ≥ 1, got {runs}")
    config = MissionConfig()
    if quick:
        config = replace(config, duration=min(config.duration, QUICK_DURATION_S))
    start = time.perf_counter()
    results = monte_carlo(config, runs, seed=SEED)
    elapsed = time.perf_counter() - start
    summary = {mode: _summary(results[mode]) for mode in MODES}
    nominal, extended = summary["nominal"], summary["extended"]
    rows = [{"mode": mode, **summary[mode]} for mode in MODES]
    rows += [{"mode": f"thesis {mode}", **THESIS[mode]} for mode in MODES]
    ratios = {
        "median_service": _ratio(extended["median_service_s"], nominal["median_service_s"]),
        "mean_service": _ratio(extended["mean_service_s"], nominal["mean_service_s"]),
        "lost": _ratio(extended["lost_total"], nominal["lost_total"]),
        "thesis_median_service": THESIS["extended"]["median_service_s"] / THESIS["nominal"]["median_service_s"],
        "thesis_mean_service": 1 - 0.18,
    }
    goals = [
        {"name": "mean service time", "target": f"extended ≤ {1 - GOAL_SPEEDUP:.2f} × nominal",
         "measured": ratios["mean_service"], "met": bool(ratios["mean_service"] <= 1 - GOAL_SPEEDUP)},
        {"name": "vehicles lost", "target": f"extended ≤ {GOAL_LOSS_RATIO:.2f} × nominal",
         "measured": ratios["lost"], "met": bool(extended["lost_total"] <= GOAL_LOSS_RATIO * nominal["lost_total"])},
        {"name": "Monte-Carlo runs", "target": f"≥ {FULL_RUNS}", "measured": runs, "met": runs >= FULL_RUNS},
    ]
    return {
        "benchmark": NAME,
        "part": PART,
        "settings": {"quick": quick, "runs": runs, "seed": SEED, "wall_s": elapsed,
                     "config": {k: v for k, v in asdict(config).items() if k != "health"},
                     "health": asdict(config.health)},
        "environment": common.environment(),
        "rows": rows,
        "ratios": ratios,
        "goals": goals,
    }


def report(result: dict, console=None) -> None:
    """Print the comparison table, the ratios beside the thesis', and the goal verdicts."""
    console = console or common.make_console()
    settings = result["settings"]
    config, health = settings["config"], settings["health"]
    console.print(
        f"[bold]{NAME}[/bold]  {'quick' if settings['quick'] else 'full'} run: {settings['runs']} Monte-Carlo runs "
        f"per mode ({config['duration']:.0f} s missions, {config['vehicles']} vehicles, seed {settings['seed']}), "
        f"{settings['wall_s']:.1f} s wall",
        highlight=False,
    )
    rows = []
    for row in result["rows"]:
        rows.append([
            row["mode"], common.fmt(row.get("median_service_s"), ".1f"), common.fmt(row.get("mean_service_s"), ".1f"),
            common.fmt(row.get("per_run_mean_sd_s"), ".1f"), common.fmt(row.get("lost_per_run"), ".2f"),
            common.fmt(row.get("lost_total"), "d"), common.fmt(row.get("failures_per_run"), ".2f"),
            common.fmt(row.get("served"), "d"), common.fmt(row.get("runs"), "d"),
        ])
    common.print_table(
        console, "Nominal vs health-extended RHTA (thesis 000 §4.4)",
        [("mode", "left"), "median service [s]", "mean service [s]", "sd of run means [s]", "lost / run",
         "lost total", "failures / run", "tasks served", "runs"],
        rows,
        caption=(f"v_max {config['speed']} m/s, area {config['area']:.0f} m, {config['arrival_rate']} tasks/s, "
                 f"n_c {config['horizon']}, λ {config['discount']}; fuel 1 at k {health['burn']:.4g}/s, "
                 f"failure ×{health['burn_failed'] / health['burn']:.1f}, p_f {health['failure_rate']:.3g}/s, "
                 f"refuel {health['refuel_time']:.0f} s. Thesis: losses of the extended RHTA not given."),
    )
    ratios = result["ratios"]
    common.print_table(
        console, "extended / nominal",
        [("figure", "left"), "measured", "thesis"],
        [["median service time", common.fmt(ratios["median_service"], ".2f"),
          common.fmt(ratios["thesis_median_service"], ".2f")],
         ["mean service time", common.fmt(ratios["mean_service"], ".2f"),
          common.fmt(ratios["thesis_mean_service"], ".2f")],
         ["vehicles lost", common.fmt(ratios["lost"], ".2f"), "“significantly reduced”"]],
    )
    common.print_table(
        console, "Goals",
        [("goal", "left"), ("target", "left"), "measured", "verdict"],
        [[g["name"], g["target"], common.fmt(float(g["measured"]), ".3g"), common.verdict(g["met"])]
         for g in result["goals"]],
    )
