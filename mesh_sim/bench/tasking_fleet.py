"""``skymesh bench tasking-fleet``: the running fleet with the consensus assignment against the placeholder planner.

Lockstep runs of the default scenario (4 camera agents, a parked car, a walker, a figure-8 car), the same
seeds for both planners, measured in the same run:

* **placeholder** (the baseline): lawnmower lanes, then every agent orbits the track ``index mod M`` at 40 m
  (``tasking/planner.py``) — nobody is assigned to a target, several agents may share one;
* **assignment** (the default scenario's planner, :mod:`tasking.assignment`): CBBA over the mesh gives each
  target one agent, which orbits it at 15 m; the others sweep search cells.

The cost of planning shows as the lockstep wall time per agent step of both runs (the whole agent: sensing,
tracking, messages, planning), and safety as the closest two UAVs came. Per target: the oracle's RMSE (the
centralized filter over every bearing, so it measures what the paths let the cameras see) and the fleet's
(the RMS over agents of each agent's RMSE) ÷ the oracle's; **coverage**, the share of the time after the
target's first track during which some agent believes *itself* assigned to it.
Then the assignment under **30 % message loss**: the share of time all agents hold the same map of who
serves which target, and for every change of any agent's map whether all agreed again within 3 s
(:func:`agent.beliefs.assignment.agreement`); conflicts resolved by the consensus (Table 1 releases).

Goals (issue 13): every target covered; each target's fleet RMSE ≤ 1.25× the oracle's; the oracle's RMSE on
the figure-8 car at least halved from the baseline's; agreement within 3 s in ≥ 95 % of changes under 30 % loss.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from agent.beliefs.assignment import agreement
from mesh_sim.bench import common
from mesh_sim.phases import RATIO_GOAL

NAME = "tasking-fleet"
BASELINE = {"planner": "placeholder", "search": "lawnmower", "spacing": 80.0, "orbit_radius": 40.0}
WINDOW = 3.0  # s: the agreement goal's window
LOSS = 0.3


def _lockstep(runs: Path, seed: int, duration: float, scenario: str = "default", **overrides) -> dict:
    """A lockstep run of ``scenario`` (with the loader's ``overrides``) in a new folder under ``runs``."""
    from mesh_sim.launcher import new_run_dir
    from mesh_sim.lockstep import run_lockstep
    from mesh_sim.scenario import load

    loaded = load(scenario, seed=seed, duration=duration, **overrides)
    return run_lockstep(loaded, new_run_dir(runs, f"{scenario}-{seed}"))


def _per_target(metrics: dict) -> dict[str, dict]:
    oracle = {t["target"]: t["rmse"] for t in metrics["oracle"]["targets"]}
    out = {}
    for target, rmse in oracle.items():
        agents = [t["rmse"] for a in metrics["agents"] for t in a.get("targets", []) if t["target"] == target]
        fleet = float(np.sqrt(np.mean(np.square(agents)))) if agents else None
        out[target] = {"oracle_rmse": rmse, "fleet_rmse": fleet,
                       "ratio": None if fleet is None or not rmse else fleet / rmse}
    return out


def _coverage(metrics: dict) -> dict[str, float]:
    """Per target label: the share of the time from its first appearance in any map to the end during which
    some agent believes itself assigned to it."""
    lines = {a["id"]: a["assignment"]["timeline"] for a in metrics["agents"]}
    end = max(a["assignment"]["evaluated_until"] for a in metrics["agents"])
    times = sorted({t for line in lines.values() for t, _ in line})
    spans = np.diff([*times, end])

    def held(line, t):
        past = [served for when, served in line if when <= t]
        return past[-1] if past else {}

    labels = {label for line in lines.values() for _, served in line for label in served if ":" not in label}
    out = {}
    for label in sorted(labels):
        served = np.array([any(held(line, t).get(label) == agent for agent, line in lines.items()) for t in times])
        seen = np.array([any(label in held(line, t) for line in lines.values()) for t in times])
        first = int(np.argmax(seen))
        out[label] = float(np.dot(spans[first:], served[first:]) / spans[first:].sum()) if spans[first:].sum() else 0.0
    return out


def run(quick: bool = False, repeats: int | None = None, runs_dir=None, duration: float | None = None) -> dict:
    """``repeats`` seeds (1 quick, 3 full) of ``duration`` simulated seconds (20 quick, 60 full) per planner."""
    seeds = list(range(1, 1 + (repeats or (1 if quick else 3))))
    duration = duration or (20.0 if quick else 60.0)
    rows, agreement_rows = [], []
    with common.runs_folder(runs_dir, "skymesh-tasking-fleet-") as runs:
        for seed in seeds:
            for planner, overrides in (("placeholder", {"tasking": BASELINE}), ("assignment", {})):
                metrics = _lockstep(runs, seed, duration, **overrides)
                coverage = _coverage(metrics) if planner == "assignment" else {}
                cpu = float(np.mean([a["cpu_per_step_ms"] for a in metrics["agents"]]))
                closest = metrics["oracle"].get("separation", {}).get("closest_m")
                for target, numbers in _per_target(metrics).items():
                    rows.append({"seed": seed, "planner": planner, "target": target, **numbers,
                                 "coverage": coverage.get(target), "cpu_per_step_ms": cpu, "closest_m": closest})
            lossy = _lockstep(runs, seed, duration, radio={"loss": LOSS})
            lines = {a["id"]: a["assignment"]["timeline"] for a in lossy["agents"]}
            end = max(a["assignment"]["evaluated_until"] for a in lossy["agents"])
            agreement_rows.append({"seed": seed, "loss": LOSS, **agreement(lines, end, WINDOW),
                                   "conflicts_resolved": sum(a["assignment"]["conflicts_resolved"]
                                                             for a in lossy["agents"])})
    return {"benchmark": NAME, "quick": quick, "seeds": seeds, "duration_s": duration, "rows": rows,
            "agreement": agreement_rows, "goals": _goals(rows, agreement_rows)}


def _mean(rows, planner, target, key):
    values = [r[key] for r in rows if r["planner"] == planner and r["target"] == target and r[key] is not None]
    return float(np.mean(values)) if values else None


def _goals(rows: list[dict], agreement_rows: list[dict]) -> list[dict]:
    targets = sorted({r["target"] for r in rows})
    coverage = min((_mean(rows, "assignment", t, "coverage") or 0.0) for t in targets) if targets else 0.0
    worst = max((_mean(rows, "assignment", t, "ratio") or np.inf) for t in targets) if targets else np.inf
    car = [_mean(rows, p, "car", "oracle_rmse") for p in ("assignment", "placeholder")]
    car_ratio = car[0] / car[1] if None not in car and car[1] else None
    settled = [a["settled_within_window"] for a in agreement_rows if a["settled_within_window"] is not None]
    settled_share = float(np.mean(settled)) if settled else None
    return [
        {"name": "least covered target: share of time an agent serves it", "target": "≥ 0.9",
         "measured": coverage, "met": coverage >= 0.9},
        {"name": "worst target: fleet RMSE ÷ oracle RMSE", "target": f"≤ {RATIO_GOAL:g}", "measured": worst,
         "met": bool(worst <= RATIO_GOAL)},
        {"name": "figure-8 car: oracle RMSE assignment ÷ placeholder", "target": "≤ 0.5", "measured": car_ratio,
         "met": car_ratio is not None and car_ratio <= 0.5},
        {"name": f"changes agreed within {WINDOW:g} s at {LOSS:.0%} loss", "target": "≥ 0.95",
         "measured": settled_share, "met": settled_share is not None and settled_share >= 0.95},
    ]


def report(result: dict, console=None) -> None:
    console = console or common.make_console()
    rows = result["rows"]
    targets = sorted({r["target"] for r in rows})
    common.print_table(
        console, f"{NAME}: default scenario, {result['duration_s']:g} s, seeds {result['seeds']} (lockstep)",
        ["target", "oracle RMSE placeholder", "oracle RMSE assignment", "÷ placeholder",
         "fleet ÷ oracle placeholder", "fleet ÷ oracle assignment", "coverage"],
        [(t, common.fmt(_mean(rows, "placeholder", t, "oracle_rmse"), ".2f", " m"),
          common.fmt(_mean(rows, "assignment", t, "oracle_rmse"), ".2f", " m"),
          common.fmt_ratio(common.ratio(_mean(rows, "assignment", t, "oracle_rmse"),
                                  _mean(rows, "placeholder", t, "oracle_rmse"))),
          common.fmt_ratio(_mean(rows, "placeholder", t, "ratio")),
          common.fmt_ratio(_mean(rows, "assignment", t, "ratio")),
          common.fmt(_mean(rows, "assignment", t, "coverage"), ".0%")) for t in targets])
    common.print_table(
        console, "cost and safety (lockstep wall time per agent step; closest approach of two UAVs)",
        ["planner", "ms per agent step", "÷ placeholder", "closest approach"],
        [(p, common.fmt_ms(_mean(rows, p, targets[0], "cpu_per_step_ms")),
          common.fmt_ratio(common.ratio(_mean(rows, p, targets[0], "cpu_per_step_ms"),
                                  _mean(rows, "placeholder", targets[0], "cpu_per_step_ms"))),
          common.fmt(min((r["closest_m"] for r in rows if r["planner"] == p and r["closest_m"] is not None),
                         default=None), ".1f", " m"))
         for p in ("placeholder", "assignment")] if targets else [])
    common.print_table(
        console, f"assignment agreement at {LOSS:.0%} message loss",
        ["seed", "time all agree", "changes", f"settled within {WINDOW:g} s", "conflicts resolved"],
        [(a["seed"], common.fmt(a["agreed_time_share"], ".1%"), a["changes"],
          common.fmt(a["settled_within_window"], ".1%"), a["conflicts_resolved"]) for a in result["agreement"]])
    common.print_table(console, "goals", ["goal", "target", "measured", "met"],
                       [(g["name"], g["target"], common.fmt(g["measured"], ".3f"), common.verdict(g["met"]))
                        for g in result["goals"]])
