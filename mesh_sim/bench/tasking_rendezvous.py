"""``skymesh bench tasking-rendezvous``: spec 004's shared orbit and rendezvous in the running fleet (lockstep).

The shipped ``orbit`` scenario (five UAVs, the figure-8 target of 004 §6.1) and ``rendezvous`` scenario (four
UAVs search a 200 m square for 004 §4.4's man-like target) fly the assignment planner with ``orbit_slots`` =
every UAV: each track is that many CBBA tasks, and the winners share the target's circle, equally spaced by
004's rotation law about the fused estimate (:mod:`tasking.assignment`). The baseline, run on the same seeds
in the same run, is the same scenario with ``orbit_slots = 1``: one UAV orbits the target, the others search.

Per run, from the world's truth (:mod:`mesh_sim.orbit_watch`): the time at which every UAV is first on the
circle (004's rendezvous; ``None`` if never), the share of the time after it with all on the circle, the
spacing error (largest deviation of a gap from ``2π / n``) from 10 s after meeting; and the estimation: the
oracle's RMSE (what the UAVs' geometry lets the bearings give) and the fleet's ÷ the oracle's.

Goals (004 §5.3-5.4: "all UAVs eventually converge to the same location", "all distances converge to zero";
the paper gives no times; the thresholds are chosen here): every run meets; all on the circle ≥ 90 % of the time
after meeting; steady spacing error median ≤ 15°; no two UAVs closer than the scenario's ``min_separation``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mesh_sim.bench import common

NAME = "tasking-rendezvous"
SCENARIOS = {"orbit": 60.0, "rendezvous": 90.0}  # scenario -> full-run duration [s]
QUICK = {"orbit": 30.0, "rendezvous": 60.0}


def _lockstep(runs: Path, name: str, seed: int, duration: float, slots: int | None) -> dict:
    from mesh_sim.launcher import new_run_dir
    from mesh_sim.lockstep import run_lockstep
    from mesh_sim.scenario import load

    scenario = load(name, seed=seed, duration=duration, tasking=None if slots is None else {"orbit_slots": slots})
    return run_lockstep(scenario, new_run_dir(runs, f"{NAME}-{name}-{seed}"))


def _row(name: str, seed: int, variant: str, metrics: dict) -> dict:
    oracle = metrics["oracle"]
    orbits = oracle.get("orbits") or {}
    steady = orbits.get("steady_spacing_error_deg") or {}
    target = oracle["targets"][0] if oracle["targets"] else {}
    return {"scenario": name, "seed": seed, "variant": variant,
            "rendezvous_s": orbits.get("rendezvous_s"), "on_circle_share": orbits.get("on_circle_share"),
            "spacing_median_deg": steady.get("median"), "spacing_p95_deg": steady.get("p95"),
            "oracle_rmse": target.get("rmse"), "fleet_ratio": metrics["fleet"]["rmse_ratio_to_oracle"],
            "first_track_s": target.get("time_to_first_track"),
            "violations": oracle.get("separation", {}).get("violations")}


def run(quick: bool = False, repeats: int | None = None, runs_dir=None, durations: dict | None = None) -> dict:
    """``repeats`` seeds (1 quick, 3 full) of each scenario for ``durations`` (scenario -> seconds; by default
    :data:`QUICK` or :data:`SCENARIOS`); quick runs skip the rendezvous baseline."""
    seeds = list(range(1, 1 + (repeats or (1 if quick else 3))))
    durations = durations or (QUICK if quick else SCENARIOS)
    rows = []
    with common.runs_folder(runs_dir, "skymesh-tasking-rendezvous-") as runs:
        for name, duration in durations.items():
            for seed in seeds:
                rows.append(_row(name, seed, "shared", _lockstep(runs, name, seed, duration, None)))
                if not (quick and name == "rendezvous"):
                    rows.append(_row(name, seed, "one orbiter", _lockstep(runs, name, seed, duration, 1)))
    return {"benchmark": NAME, "quick": quick, "seeds": seeds, "durations_s": durations, "rows": rows,
            "goals": _goals(rows)}


def _mean(rows, scenario, variant, key):
    values = [r[key] for r in rows if r["scenario"] == scenario and r["variant"] == variant and r[key] is not None]
    return float(np.mean(values)) if values else None


def _goals(rows: list[dict]) -> list[dict]:
    shared = [r for r in rows if r["variant"] == "shared"]
    met = [r["rendezvous_s"] is not None for r in shared]
    share = min((r["on_circle_share"] or 0.0 for r in shared), default=0.0)
    spacing = max((r["spacing_median_deg"] if r["spacing_median_deg"] is not None else np.inf for r in shared),
                  default=np.inf)
    violations = sum(r["violations"] or 0 for r in shared)
    return [
        {"name": "runs in which every UAV reaches the circle", "target": "all", "measured": f"{sum(met)}/{len(met)}",
         "met": all(met)},
        {"name": "worst run: share of the time all are on the circle after meeting", "target": "≥ 0.9",
         "measured": share, "met": share >= 0.9},
        {"name": "worst run: steady spacing error, median", "target": "≤ 15°", "measured": spacing,
         "met": bool(spacing <= 15.0)},
        {"name": "separation violations", "target": "0", "measured": violations, "met": violations == 0},
    ]


def report(result: dict, console=None) -> None:
    console = console or common.make_console()
    rows = result["rows"]
    table = []
    for name in result["durations_s"]:
        for variant in ("shared", "one orbiter"):
            if not any(r["scenario"] == name and r["variant"] == variant for r in rows):
                continue
            oracle = _mean(rows, name, variant, "oracle_rmse")
            baseline = _mean(rows, name, "one orbiter", "oracle_rmse")
            table.append((name, variant, common.fmt(_mean(rows, name, variant, "first_track_s"), ".1f", " s"),
                          common.fmt(_mean(rows, name, variant, "rendezvous_s"), ".1f", " s"),
                          common.fmt(_mean(rows, name, variant, "on_circle_share"), ".0%"),
                          common.fmt(_mean(rows, name, variant, "spacing_median_deg"), ".1f", "°"),
                          common.fmt(_mean(rows, name, variant, "spacing_p95_deg"), ".1f", "°"),
                          common.fmt(oracle, ".2f", " m"),
                          common.fmt_ratio(None if oracle is None or not baseline else oracle / baseline),
                          common.fmt_ratio(_mean(rows, name, variant, "fleet_ratio"))))
    common.print_table(
        console, f"{NAME}: shared orbits (004 §2.8-2.9) vs one orbiter, seeds {result['seeds']} (lockstep)",
        ["scenario", "variant", "first track", "all on circle at", "on circle after", "spacing median",
         "spacing p95", "oracle RMSE", "÷ one orbiter", "fleet ÷ oracle"], table)
    common.print_table(console, "goals", ["goal", "target", "measured", "met"],
                       [(g["name"], g["target"], g["measured"] if isinstance(g["measured"], str)
                         else common.fmt(g["measured"], ".3g"), common.verdict(g["met"])) for g in result["goals"]])
