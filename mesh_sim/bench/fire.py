"""``skymesh bench fire``: whole fire missions, scored every 30 s window, beside Merino's field figures.

Each run is the shipped ``fire`` scenario (:mod:`mesh_sim.scenarios`, 4 UAVs, 3 spreading fires, 3
flickering decoys) in the lockstep harness — the real agents over the in-memory bus with the radio
model — for the scenario's whole duration, with a different seed per repeat. The world's grid oracle
scores the centralized map and every agent's map at the scenario's alarm threshold against the truth at
the end of every window (:mod:`mesh_sim.fire_windows`); the bench pools those scores over agents and
seeds, per configuration and window. Configurations, for log-odds and Beta grids (``-beta``):

* ``hybrid``: full mesh, channel filters on tree edges and the Chernoff rule on loops, delta-encoded grids;
* ``naive``: full mesh, every received grid added as independent evidence (double counting, Merino
  §4.1.3) — the rumour baseline: the decoys are there to become false alarms;
* ``tree``: the agents on a line (``radio.topology = "line"``), where channel filters are exact;
* ``ring``: the agents on a ring (``radio.topology = "ring"``), hybrid;
* ``hybrid-keyframes``, ``ring-keyframes``, ``tree-keyframes`` (log-odds): every grid message a full
  keyframe (``delta = false``), the bandwidth baselines of the delta encoding.

Goals (issue 15): in every window after the first detection (after the first window at whose end an
agent's map, in any seed, has detected a fire — that window holds time before it; every window if none ever
did), pooled over agents and seeds, for hybrid log-odds and hybrid Beta:
detection ≥ 95 %, false-alarm (decoy) rejection ≥ 80 % and localisation error < 1 m (Merino 001b §4.4,
the COMETS field figures) — judged both for the grid's own alarms (4.20) and for the alarms where the agents
report them (the hand-off of Merino Ch. 8, ``[grid] handoff``: at the tracks of their hot spots,
:mod:`agent.beliefs.alarm_handoff`); naive fusion shows at least one decoy-made false alarm across the seeds; grid
bytes delta ÷ keyframe ≤ 0.2 on the full mesh and on the ring (the tree's ratio is reported).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from mesh_sim.bench import common
from mesh_sim.bench.common import fmt

NAME = "fire"
_TOPOLOGIES = {"hybrid": ("hybrid", "full"), "naive": ("naive", "full"), "tree": ("hybrid", "line"),
               "ring": ("hybrid", "ring")}


def _config(policy: str, topology: str, belief: str = "logodds", delta: bool = True) -> dict:
    """Scenario overrides of one configuration. Beta grids send exact deltas (``delta_tolerance = 0``: a
    deadband on counts would make the channel filters' subtraction negative, :class:`agent.beliefs.grid_config.
    GridConfig`); log-odds grids keep the scenario's deadband."""
    grid = {"policy": policy, "belief": belief, "delta": delta}
    if belief == "beta":
        grid["delta_tolerance"] = 0.0
    return {"grid": grid, "radio": {"topology": topology}}


CONFIGS = {
    **{name: _config(*setting) for name, setting in _TOPOLOGIES.items()},
    **{f"{name}-beta": _config(*setting, belief="beta") for name, setting in _TOPOLOGIES.items()},
    **{f"{name}-keyframes": _config(*_TOPOLOGIES[name], delta=False) for name in ("hybrid", "ring", "tree")},
}
FULL = {"seeds": 5, "duration": None, "configs": tuple(CONFIGS)}  # duration None: the scenario's (120 s)
#: quick (under a minute on one core): the two configurations of the windowed goals, one seed, one window
QUICK = {"seeds": 1, "duration": 30.0, "configs": ("hybrid", "hybrid-beta")}
GOALS = {"detection_rate": 0.95, "false_alarm_rejection": 0.80, "localisation_error_m": 1.0, "located_error_m": 1.0,
         "delta_bytes_ratio": 0.2, "naive_decoy_alarms": 1}
WINDOWED_GOAL_CONFIGS = ("hybrid", "hybrid-beta")
BYTES_GOALS = {"hybrid": True, "ring": True, "tree": False}  # delta config -> judged (else reported)
MERINO = ("Merino 001b §4.4 (COMETS field demo): detection > 95 %, false-alarm rejection > 80 %, error < 1 m; "
          "windows ending before the first detection are marked '(before)', the one that saw it '(first)'; the goals "
          "judge the windows after it")


def scenario_duration() -> float:
    """The shipped fire scenario's duration, s."""
    from mesh_sim.scenario import load

    return load("fire").agent.duration


def run_one(config: str, seed: int, duration: float, runs_dir: Path) -> dict:
    """One lockstep run of the fire scenario: its grid bytes per agent per second and its window series."""
    from mesh_sim.lockstep import run_lockstep
    from mesh_sim.scenario import load

    scenario = load("fire", seed=seed, duration=duration, **CONFIGS[config])
    run_dir = Path(tempfile.mkdtemp(prefix=f"{config}-{seed}-", dir=runs_dir))
    metrics = run_lockstep(scenario, run_dir)
    return {"config": config, "seed": seed,
            "grid_bytes_per_agent_per_s": metrics["fleet"]["grid"]["grid_bytes_per_agent_per_s"],
            "windows": metrics["oracle"]["grid"]["windows"]}


def run(quick: bool = False, repeats: int | None = None, runs_dir=None, seeds: int | None = None,
        duration: float | None = None, configs=None) -> dict:
    """Run every configuration on every seed; ``repeats`` (tests) caps the seeds like ``seeds`` sets them."""
    settings = dict(QUICK if quick else FULL)
    for key, value in (("seeds", seeds), ("duration", duration), ("configs", configs)):
        if value is not None:
            settings[key] = value
    if repeats is not None:
        settings["seeds"] = max(1, min(settings["seeds"], repeats))
    unknown = [c for c in settings["configs"] if c not in CONFIGS]
    if unknown:
        raise ValueError(f"unknown fire bench configuration(s) {unknown}; known: {', '.join(CONFIGS)}")
    if settings["duration"] is None:
        settings["duration"] = scenario_duration()
    outcomes = []
    with common.runs_folder(runs_dir, "skymesh-bench-fire-") as folder, \
            common.run_progress(NAME, len(settings["configs"]) * settings["seeds"]) as (_, advance):
        for seed in range(1, settings["seeds"] + 1):
            for config in settings["configs"]:
                outcomes.append(run_one(config, seed, settings["duration"], folder))
                advance(f"{config} seed {seed}", 1)
    rows = [row for config in settings["configs"]
            for row in window_rows(config, [o for o in outcomes if o["config"] == config])]
    bytes_per_s = {config: _mean(o["grid_bytes_per_agent_per_s"] for o in outcomes if o["config"] == config)
                   for config in settings["configs"]}
    return {"benchmark": NAME, "settings": {**settings, "configs": list(settings["configs"])}, "rows": rows,
            "grid_bytes_per_agent_per_s": bytes_per_s, "goals": goals(rows, bytes_per_s),
            "environment": common.environment()}


def _mean(values) -> float | None:
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else None


def window_rows(config: str, outcomes: list[dict]) -> list[dict]:
    """Per window, the agents' scores pooled over agents and seeds (the runs' windows align: same length)."""
    rows = []
    for index in range(max((len(o["windows"]) for o in outcomes), default=0)):
        windows = [o["windows"][index] for o in outcomes if index < len(o["windows"])]
        scores = [s for w in windows for s in w["agents"].values()]
        errors = [s["localisation_error_m"] for s in scores if s["localisation_error_m"] is not None]
        located = [s["localisation_error_m"] for w in windows for s in w.get("located", {}).values()
                   if s["localisation_error_m"] is not None]
        rows.append({
            "config": config, "window": index, "start": windows[0]["start"], "end": windows[0]["end"],
            "runs": len(windows), "maps": len(scores),
            "before_first_detection": all(w["before_first_detection"] for w in windows),
            "detection_rate": _mean(s["detection_rate"] for s in scores),
            "false_alarm_rejection": _mean(s["false_alarm_rejection"] for s in scores),
            "decoy_alarms": sum(s["decoys"] - s["decoys_rejected"] for s in scores),
            "other_false_alarms": _mean(s["other_false_alarms"] for s in scores),
            "localisation_error_m": _mean(errors),
            "localisation_worst_m": max(errors, default=None),
            "located_error_m": _mean(located),
            "located_worst_m": max(located, default=None),
        })
    return rows


def windows_after_first_detection(windows: list[dict]) -> list[dict]:
    """The windows after the one in which the first detection was made (that one holds time before it); every
    window when no map ever detected a fire (the detection goal then misses)."""
    first = next((i for i, w in enumerate(windows) if not w["before_first_detection"]), None)
    return windows if first is None else windows[first + 1:]


def goals(rows: list[dict], bytes_per_s: dict[str, float | None]) -> list[dict]:
    """The issue's goals, PASS/MISS (``ok`` None when the run holds no figure for one)."""
    out = []
    for config in WINDOWED_GOAL_CONFIGS:
        windows = [r for r in rows if r["config"] == config]
        if not windows:
            continue
        after = windows_after_first_detection(windows)
        for key, label, higher in (("detection_rate", "detection", True),
                                   ("false_alarm_rejection", "false-alarm rejection", True),
                                   ("localisation_error_m", "grid alarm localisation (m)", False),
                                   ("located_error_m", "reported alarm localisation (m)", False)):
            values = [r[key] for r in after if r[key] is not None]
            worst = (min if higher else max)(values, default=None)
            ok = None if worst is None else (worst >= GOALS[key] if higher else worst < GOALS[key])
            out.append({"goal": f"{config}: {label} {'>=' if higher else '<'} {GOALS[key]:g} in every window "
                                f"after the first detection (worst window)", "value": worst, "ok": ok})
    for config in ("naive", "naive-beta"):
        naive = [r for r in rows if r["config"] == config]
        if naive:
            count = sum(r["decoy_alarms"] for r in naive)
            out.append({"goal": f"{config}: decoy-made false alarms across seeds and windows "
                                f">= {GOALS['naive_decoy_alarms']}", "value": count,
                        "ok": count >= GOALS["naive_decoy_alarms"]})
    for config, judged in BYTES_GOALS.items():
        keyframes = f"{config}-keyframes"
        if config in bytes_per_s and keyframes in bytes_per_s:
            value = common.ratio(bytes_per_s[config], bytes_per_s[keyframes])
            ok = None if value is None or not judged else value <= GOALS["delta_bytes_ratio"]
            goal = f"<= {GOALS['delta_bytes_ratio']:g}" if judged else "reported"
            out.append({"goal": f"{config}: grid bytes delta / keyframe ({goal})", "value": value, "ok": ok})
    return out


def _mark(row: dict, rows: list[dict]) -> str:
    """' (before)' for a window ending before its configuration's first detection, ' (first)' for the one
    that saw it."""
    if row["before_first_detection"]:
        return " (before)"
    earlier = [r for r in rows if r["config"] == row["config"] and r["window"] < row["window"]]
    return " (first)" if all(r["before_first_detection"] for r in earlier) else ""


def report(result: dict, console=None) -> None:
    console = console or common.make_console()
    s = result["settings"]
    common.print_table(
        console, f"fire missions — {s['seeds']} seed(s) x {s['duration']:g} s, lockstep, agents' maps per window",
        ["config", "window (s)", "maps", "detection", "decoys rejected", "decoy alarms", "other false/map",
         "grid loc. mean (m)", "grid loc. worst (m)", "reported loc. mean (m)", "reported loc. worst (m)",
         "grid bytes/agent/s"],
        [(r["config"], f"{r['start']:g}-{r['end']:g}" + _mark(r, result["rows"]),
          r["maps"], fmt(r["detection_rate"], ".0%"), fmt(r["false_alarm_rejection"], ".0%"), r["decoy_alarms"],
          fmt(r["other_false_alarms"], ".2f"), fmt(r["localisation_error_m"], ".2f"),
          fmt(r["localisation_worst_m"], ".2f"), fmt(r["located_error_m"], ".2f"), fmt(r["located_worst_m"], ".2f"),
          fmt(result["grid_bytes_per_agent_per_s"][r["config"]], ",.0f") if r["window"] == 0 else "")
         for r in result["rows"]],
        caption=MERINO,
    )
    common.print_table(console, "goals (issue 15)", ["goal", "value", "verdict"],
                       [(g["goal"], fmt(g["value"], ".3g"), common.verdict(g["ok"])) for g in result["goals"]])
