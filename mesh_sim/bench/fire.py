"""``skymesh bench fire``: the fire scenario, lockstep Monte Carlo, beside Merino's field figures.

Each run is the shipped ``fire`` scenario (:mod:`mesh_sim.scenarios`, 4 UAVs, 3 spreading fires, 3
flickering decoys) in the lockstep harness — the real agents over the in-memory bus with the radio
model — with a different seed, under five configurations:

* ``hybrid``: the default (channel filters on tree edges, the Chernoff rule on loops) with delta-encoded
  grid messages;
* ``hybrid-keyframes``: the same fusion with every grid message a full keyframe (``delta = false``) —
  the bandwidth baseline measured in the same run;
* ``naive``: every received grid added as independent evidence (double counting, Merino §4.1.3) — the
  rumour baseline;
* ``tree`` and ``tree-keyframes``: the agents on a line (a tree), where channel filters are exact and a
  delta carries only what changed locally — with and without delta encoding.

Per configuration, pooled over agents and seeds, at the scenario's alarm threshold: the detection rate
of the true fires, the decoy (false-alarm) rejection, the alarm localisation error, other false alarms,
the KL divergence of each agent's map to the centralized map (Merino (4.25)), and grid bytes per agent
per second. The operating curve (detection vs false alarms per agent over thresholds; Merino Fig.
4.10/4.21) is printed and plotted. Goals are Merino's field figures (001b §4.4: > 95 % detection,
> 80 % false-alarm rejection, < 1 m localisation error) and, chosen here, delta encoding at most half the
bytes of keyframes.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from mesh_sim.bench import common
from mesh_sim.bench.common import fmt

NAME = "fire"
CONFIGS = {
    "hybrid": {"grid": {"policy": "hybrid", "delta": True}},
    "hybrid-keyframes": {"grid": {"policy": "hybrid", "delta": False}},
    "naive": {"grid": {"policy": "naive", "delta": True}},
    "tree": {"grid": {"policy": "hybrid", "delta": True}, "radio": {"topology": "line"}},
    "tree-keyframes": {"grid": {"policy": "hybrid", "delta": False}, "radio": {"topology": "line"}},
}
FULL = {"seeds": 5, "duration": 120.0}
QUICK = {"seeds": 1, "duration": 45.0}
GOALS = {"detection_rate": 0.95, "false_alarm_rejection": 0.80, "localisation_error_m": 1.0, "delta_bytes_ratio": 0.5}
MERINO = "Merino 001b §4.4 (COMETS field demo): detection > 95 %, false-alarm rejection > 80 %, error < 1 m"


def run_one(config: str, seed: int, duration: float, runs_dir: Path) -> dict:
    """One lockstep run of the fire scenario; returns its fleet grid figures and per-agent ROC rows."""
    from mesh_sim.lockstep import run_lockstep
    from mesh_sim.scenario import load

    scenario = load("fire", seed=seed, duration=duration, **CONFIGS[config])
    run_dir = Path(tempfile.mkdtemp(prefix=f"{config}-{seed}-", dir=runs_dir))
    metrics = run_lockstep(scenario, run_dir)
    grid = metrics["oracle"]["grid"]
    return {"config": config, "seed": seed, **metrics["fleet"]["grid"],
            "roc": [row for a in grid["agents"].values() for row in a["roc"]]}


def run(quick: bool = False, repeats: int | None = None, runs_dir=None, seeds: int | None = None,
        duration: float | None = None, configs=tuple(CONFIGS)) -> dict:
    settings = dict(QUICK if quick else FULL)
    if seeds is not None:
        settings["seeds"] = seeds
    if repeats is not None:
        settings["seeds"] = max(1, min(settings["seeds"], repeats))
    if duration is not None:
        settings["duration"] = duration
    outcomes = []
    with common.runs_folder(runs_dir, "skymesh-bench-fire-") as folder, \
            common.run_progress(NAME, len(configs) * settings["seeds"]) as (_, advance):
        for seed in range(1, settings["seeds"] + 1):
            for config in configs:
                outcomes.append(run_one(config, seed, settings["duration"], folder))
                advance(f"{config} seed {seed}", 1)
    rows = [_summarise(config, [o for o in outcomes if o["config"] == config]) for config in configs]
    return {"benchmark": NAME, "settings": {**settings, "configs": list(configs)}, "rows": rows,
            "roc": {config: _roc([o for o in outcomes if o["config"] == config]) for config in configs},
            "goals": _goals(rows), "environment": common.environment()}


def _mean(values) -> float | None:
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else None


def _summarise(config: str, outcomes: list[dict]) -> dict:
    keys = ("detection_rate", "false_alarm_rejection", "localisation_error_m", "other_false_alarms", "kl_to_central",
            "grid_bytes_per_agent_per_s")
    return {"config": config, "runs": len(outcomes), **{k: _mean(o[k] for o in outcomes) for k in keys}}


def _roc(outcomes: list[dict]) -> list[dict]:
    """Per threshold, pooled over agents and runs: detection rate and false alarms per agent."""
    rows = [r for o in outcomes for r in o["roc"]]
    out = []
    for threshold in sorted({r["threshold"] for r in rows}):
        at = [r for r in rows if r["threshold"] == threshold]
        out.append({
            "threshold": threshold,
            "detection_rate": _mean(r["detection_rate"] for r in at),
            "false_alarms_per_agent": _mean(r["decoys"] - r["decoys_rejected"] + r["other_false_alarms"] for r in at),
        })
    return out


def _goals(rows: list[dict]) -> list[dict]:
    by = {r["config"]: r for r in rows}
    main = by.get("hybrid")
    goals = []
    if main is not None:
        for key, label, better in (("detection_rate", "detection rate", "higher"),
                                   ("false_alarm_rejection", "false-alarm rejection", "higher"),
                                   ("localisation_error_m", "localisation error [m]", "lower")):
            value = main[key]
            ok = None if value is None else (value >= GOALS[key] if better == "higher" else value < GOALS[key])
            goals.append({"goal": f"{label} ({'>=' if better == 'higher' else '<'} {GOALS[key]:g}, Merino)",
                          "value": value, "ok": ok})
    for delta, keyframes in (("hybrid", "hybrid-keyframes"), ("tree", "tree-keyframes")):
        if delta in by and keyframes in by:
            a, b = by[delta]["grid_bytes_per_agent_per_s"], by[keyframes]["grid_bytes_per_agent_per_s"]
            ratio = a / b if a and b else None
            goals.append({"goal": f"{delta}: delta / keyframe bytes (<= {GOALS['delta_bytes_ratio']:g}, chosen here)",
                          "value": ratio, "ok": None if ratio is None else ratio <= GOALS["delta_bytes_ratio"]})
    return goals


def report(result: dict, console=None) -> None:
    console = console or common.make_console()
    s = result["settings"]
    common.print_table(
        console, f"fire scenario — {s['seeds']} seed(s) x {s['duration']:g} s, lockstep",
        ["config", "runs", "detection", "decoys rejected", "other false/agent", "loc. error [m]", "KL to central",
         "grid bytes/agent/s"],
        [(r["config"], r["runs"], fmt(r["detection_rate"], ".0%"), fmt(r["false_alarm_rejection"], ".0%"),
          fmt(r["other_false_alarms"], ".2f"), fmt(r["localisation_error_m"], ".2f"), fmt(r["kl_to_central"], ".1f"),
          fmt(r["grid_bytes_per_agent_per_s"], ",.0f")) for r in result["rows"]],
        caption=MERINO,
    )
    for config, curve in result["roc"].items():
        common.print_table(console, f"operating curve — {config}", ["threshold", "detection", "false alarms/agent"],
                           [(f"{r['threshold']:g}", fmt(r["detection_rate"], ".0%"),
                             fmt(r["false_alarms_per_agent"], ".2f")) for r in curve])
    common.print_table(console, "goals", ["goal", "value", "verdict"],
                       [(g["goal"], fmt(g["value"], ".3g"), common.verdict(g["ok"])) for g in result["goals"]])
