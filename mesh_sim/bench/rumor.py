"""``skymesh bench rumor``: decentralized fusion in the running fleet against the centralized oracle of the same
runs, by topology, loss and fusion method — the goals of issue 11.

Lockstep Monte Carlo (:func:`mesh_sim.lockstep.run_lockstep`: the real agents over the in-memory bus, the
same radio model, deterministic) of the **default scenario as shipped** (camera sensor, its sending and radio
preset), with only the team size, the duration, the seed, the topology, the loss and the method's settings
overridden. Rows:

* **cells**: topology (tree, full, ring) x Bernoulli loss (0, 30 %) x method, seeds 1..S each (the seed draws
  the tree, the sensor noise and the loss); full run 7 agents, 120 s, 5 seeds;
* **demo**: the `make demo` configuration (the default scenario as shipped: 4 agents, full mesh, its own
  duration), same seeds;
* **partition**: the idea of ``scenarios/partition.toml`` on the default scenario — a tree, ``hybrid``, the
  team split into two halves at 1/3 of the run and merged at 2/3 — scored like a cell, plus, for every
  directed channel on a tree edge after the merge, the time until it fuses exactly again (the agents'
  channel timelines, :class:`agent.fusion_log.FusionLog`).

``--quick``: 4 agents, 20 s, one seed, tree and full at 0 % loss, methods exact / hybrid / naive / flood, plus the demo
and partition rows (about a minute on 2 cores).

**Methods** are named sets of scenario overrides (:data:`METHODS`): adding one is one line. A method whose
settings the scenario loader rejects (an unknown setting or policy: the code that implements it is not in
this tree) is reported as unavailable with the loader's error, and its rows are not run.

Per row, pooled over seeds (:mod:`mesh_sim.bench.rumor_stats`): fleet RMSE / oracle RMSE, fleet ANEES with its
95 % chi-square interval, the oracle's ANEES with its own, every agent's ANEES (min and max), the share of
exact fusions, radio bytes per agent per second, and the goals marked PASS / FAIL. Runs go to ``workers``
worker processes (:mod:`mesh_sim.bench.rumor_jobs`, default 2); runs whose tracks explode are stopped and
scored up to then.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from mesh_sim import phases
from mesh_sim.bench import common, rumor_jobs, rumor_stats
from mesh_sim.bench.common import fmt

NAME = "rumor"
SCENARIO = "default"
#: Fusion methods: name -> overrides of the scenario ([tracking] policy names and settings of issue 11).
METHODS: dict[str, dict] = {
    "naive": {"tracking": {"policy": "naive"}},
    "exact": {"tracking": {"policy": "exact"}},
    "ci": {"tracking": {"policy": "ci"}},
    "fast_ci": {"tracking": {"policy": "ci", "intersection": "fast_ci"}},
    "ici": {"tracking": {"policy": "ci", "intersection": "ici"}},
    "flood": {"tracking": {"policy": "flood"}},
    "flood_imm": {"tracking": {"policy": "flood", "motion": "imm"}},
    "hybrid": {"tracking": {"policy": "hybrid"}},
}
TOPOLOGIES = ("tree", "full", "ring")
LOSSES = (0.0, 0.3)
#: The two modes; ``demo_duration`` None: the shipped scenario's own duration.
FULL = {"topologies": TOPOLOGIES, "losses": LOSSES, "methods": tuple(METHODS), "seeds": 5, "duration": 120.0,
        "agents": 7, "demo_duration": None}
QUICK = {"topologies": ("tree", "full"), "losses": (0.0,), "methods": ("exact", "hybrid", "naive", "flood"), "seeds": 1,
         "duration": 20.0, "agents": 4, "demo_duration": 20.0}
PARTITION_METHOD = "hybrid"
WORKERS = 2


def _merged(*parts: dict) -> dict:
    """Scenario overrides merged section by section (a later part wins per key)."""
    out: dict = {}
    for part in parts:
        for key, value in part.items():
            out[key] = {**out[key], **value} if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def unavailable(methods: Sequence[str]) -> dict[str, str]:
    """Method -> the scenario loader's error, for each method this tree's code rejects."""
    from mesh_sim.scenario import load

    out = {}
    for m in methods:
        try:
            load(SCENARIO, **METHODS[m])
        except ValueError as err:
            out[m] = str(err)
    return out


def partition_events(agents: int, duration: float) -> list[dict]:
    """Split the team into two halves (uav0.. | ..uavN-1) at 1/3 of the run, merge at 2/3."""
    names = [f"uav{i}" for i in range(agents)]
    half = agents // 2
    return [{"t": duration / 3, "kind": "partition", "groups": [names[:half], names[half:]]},
            {"t": 2 * duration / 3, "kind": "merge"}]


def _jobs(topologies, losses, methods, seeds, duration, agents, demo_duration, demo, partition) -> list[dict]:
    """The runs: one job per row and seed; ``row`` names the row a run belongs to."""
    team = {"agents": agents, "duration": duration}
    jobs = []
    for s in seeds:
        for t in topologies:
            for x in losses:
                for m in methods:
                    jobs.append({"row": {"kind": "cell", "topology": t, "loss": x, "method": m},
                                 "overrides": _merged(team, {"seed": s, "radio": {"topology": t, "loss": x}},
                                                      METHODS[m])})
        if demo:
            jobs.append({"row": {"kind": "demo", "topology": "full", "loss": None, "method": "hybrid"},
                         "overrides": _merged({"seed": s}, {"duration": demo_duration} if demo_duration else {})})
        if partition:
            radio = {"topology": "tree", "loss": 0.0, "events": partition_events(agents, duration)}
            jobs.append({"row": {"kind": "partition", "topology": "tree", "loss": 0.0, "method": PARTITION_METHOD},
                         "overrides": _merged(team, {"seed": s, "radio": radio}, METHODS[PARTITION_METHOD]),
                         "edges_at": 2 * duration / 3})
    for job in jobs:
        job["scenario"] = SCENARIO
        job["label"] = f"{row_name(job['row'])} seed {job['overrides']['seed']}"
    return jobs


def row_name(row: dict) -> str:
    if row["kind"] == "demo":
        return "demo (make demo)"
    name = f"{row['topology']} {100 * row['loss']:.0f} % {row['method']}"
    return f"partition {name}" if row["kind"] == "partition" else name


def run(
    quick: bool = False,
    repeats: int | None = None,
    *,
    topologies: Sequence[str] | None = None,
    losses: Sequence[float] | None = None,
    methods: Sequence[str] | None = None,
    seeds: int | None = None,
    duration: float | None = None,
    agents: int | None = None,
    workers: int | None = None,
    demo: bool = True,
    partition: bool = True,
) -> dict:
    """Run the benchmark. ``repeats`` and ``seeds`` both set the seeds per row (``seeds`` wins); the other
    keywords override the mode's grid (``duration`` and ``agents`` apply to cells and the partition row; the
    demo row keeps the shipped scenario's)."""
    mode = QUICK if quick else FULL
    topologies = tuple(topologies or mode["topologies"])
    losses = tuple(float(x) for x in (losses if losses is not None else mode["losses"]))
    methods = tuple(methods or mode["methods"])
    n_seeds = int(seeds or repeats or mode["seeds"])
    duration = float(duration or mode["duration"])
    agents = int(agents or mode["agents"])
    workers = int(workers or WORKERS)
    bad = [t for t in topologies if t not in TOPOLOGIES] + [m for m in methods if m not in METHODS]
    if bad or n_seeds < 1 or agents < 2 or not duration > 0 or any(not 0 <= x < 1 for x in losses):
        raise ValueError(f"bad settings: unknown {bad} (topologies {TOPOLOGIES}, methods {tuple(METHODS)}), seeds "
                         f"{n_seeds}, agents {agents}, duration {duration}, losses {losses}")
    missing = unavailable(dict.fromkeys(methods + (PARTITION_METHOD,)))
    seed_list = list(range(1, n_seeds + 1))
    jobs = _jobs(topologies, losses, [m for m in methods if m not in missing], seed_list, duration, agents,
                 mode["demo_duration"], demo, partition and PARTITION_METHOD not in missing)
    outcomes = rumor_jobs.run_jobs(jobs, workers, NAME)
    rows = _rows(outcomes, topologies, losses, methods, missing, 2 * duration / 3)
    return {
        "benchmark": NAME,
        "settings": {
            "quick": quick, "scenario": SCENARIO, "topologies": list(topologies), "losses": list(losses),
            "methods": {m: METHODS[m] for m in methods}, "unavailable": missing, "seeds": seed_list,
            "duration_s": duration, "agents": agents, "demo_duration_s": mode["demo_duration"], "workers": workers,
            "demo": demo, "partition": partition,
            "partition_events": partition_events(agents, duration) if partition else None,
            "decorrelation_s": phases.DECORRELATION_S, "confidence": rumor_stats.CONFIDENCE,
            "diverged_tracks": rumor_jobs.DIVERGED_TRACKS,
        },
        "environment": common.environment(("numpy", "scipy")),
        "rows": rows,
        "goals": rumor_stats.goals(rows),
    }


def _rows(outcomes, topologies, losses, methods, missing, t_merge) -> list[dict]:
    """One row per cell (in grid order; unavailable methods as rows without figures), then demo, partition."""
    by_row: dict[str, list[dict]] = {}
    for o in outcomes:
        by_row.setdefault(row_name(o["job"]["row"]), []).append(o)
    wanted = [{"kind": "cell", "topology": t, "loss": x, "method": m}
              for t in topologies for x in losses for m in methods]
    wanted += sorted((o[0]["job"]["row"] for o in by_row.values() if o[0]["job"]["row"]["kind"] != "cell"),
                     key=lambda row: row["kind"])  # demo, then partition
    rows = []
    for row in wanted:
        name = row_name(row)
        if row["method"] in missing:
            rows.append({**row, "name": name, "unavailable": missing[row["method"]]})
            continue
        runs = by_row[name]
        rows.append({**row, "name": name, **rumor_stats.summarise(runs)})
        if row["kind"] == "partition":
            rows[-1]["t_merge"] = t_merge
            rows[-1]["channels"] = [c for o in runs for c in rumor_stats.recovery(o, t_merge)]
    return rows


# ==================================================================================================
# report
# ==================================================================================================
def _mark(ok: bool | None) -> str:
    return "" if ok is None else "[green]PASS[/green]" if ok else "[red]FAIL[/red]"


def _note(r: dict, seeds: int) -> str:
    out = []
    if r["diverged_runs"]:
        out.append(f"diverged {r['diverged_runs']}/{seeds} @{r['diverged_first_at']:.0f} s "
                   f"({r['max_tracks_per_agent']} tracks)")
    if r["crashed_runs"]:
        out.append(f"raised {r['crashed_runs']}/{seeds} @{r['crashed_first_at']:.0f} s")
    return f"[red]{', '.join(out)}[/red]" if out else ""


def _anees(value, lo, hi, k) -> str:
    flag = "" if value is None or value <= hi else " [red]>[/red]"
    return f"{fmt(value, '.2f')}{flag} [{lo:.2f}-{hi:.2f}, K {k}]"


def report(result: dict, console=None) -> None:
    """Print the row table, the goals, the partition channels and any unavailable method of a :func:`run`."""
    console = console or common.make_console()
    s = result["settings"]
    seeds = len(s["seeds"])
    console.print(
        f"[bold]{NAME}[/bold]  {'quick' if s['quick'] else 'full'} run: lockstep, scenario '{s['scenario']}' as "
        f"shipped, {s['agents']} agents, {s['duration_s']:g} s (demo row: the scenario's own team, "
        f"{'its own duration' if s['demo_duration_s'] is None else format(s['demo_duration_s'], 'g') + ' s'}), "
        f"seeds {s['seeds']}.",
        highlight=False,
    )
    table = []
    for r in result["rows"]:
        if r.get("unavailable"):
            table.append([r["name"], "[yellow]unavailable[/yellow]"] + [""] * 8 + [r["unavailable"]])
            continue
        goal = {ratio: f" (<= {r['ratio_limit']:g}) {_mark(r.get('ratio_pass'))}"
                for ratio in ("rmse_ratio", "in_flight_ratio") if r.get("ratio_goal_on") == ratio}
        table.append([
            r["name"], f"{fmt(r['rmse_ratio'], '.2f')}{goal.get('rmse_ratio', '')}",
            f"{fmt(r['in_flight_ratio'], '.2f')}{goal.get('in_flight_ratio', '')}",
            _anees(r["anees"], r["anees_lo"], r["anees_hi"], r["independent_samples"]),
            _anees(r["oracle_anees"], r["oracle_anees_lo"], r["oracle_anees_hi"], r["oracle_independent_samples"]),
            f"{fmt(r['agents_anees_min'], '.2f')}-{fmt(r['agents_anees_max'], '.2f')} "
            f"({r['agents_consistent']}/{r['agents']}) {_mark(r.get('agents_pass'))}",
            _mark(r.get("naive_pass")), fmt(100 * r["exact_share"], ".0f"), f"{r['bytes_per_agent_s']:,.0f}",
            fmt(r.get("recovery_s"), ".1f", " s") if r["kind"] == "partition" else "", _note(r, seeds),
        ])
    common.print_table(
        console, "rumor: decentralized fusion vs the centralized oracle of the same runs (pooled over seeds)",
        [("row", "left"), "÷ oracle", "÷ in flight", "fleet ANEES [95 %, K]", "IMM oracle ANEES [95 %, K]",
         "agents' ANEES",
         "naive > hi", "exact %", "B/agent/s", "re-exact", ("note", "left")],
        table,
        caption="÷ oracle: fleet RMSE / oracle RMSE, each pooled by samples over agents, targets and seeds; ÷ in "
        "flight: the same over each agent's in-flight oracle (what could have reached it, one step per hop); each "
        "with its goal where the issue sets one. IMM oracle: the consistent reference (matched to the targets). "
        "ANEES: mean NEES / 6 (1 = consistent), '>' above the upper bound; K independent samples = one per "
        f"(seed, target, {s['decorrelation_s']:g} s tracked). agents' ANEES: min-max over agents (agents inside "
        f"[{rumor_stats.ANEES_FLOOR:g}, own upper bound]). exact %: share of received beliefs fused exactly. "
        "B/agent/s: radio bytes sent. re-exact: partition row, worst time after the merge until a tree-edge "
        f"channel fuses exactly again. note: runs stopped when an agent held > {s['diverged_tracks']} tracks "
        "(double counting) or raised; scored up to then.",
    )
    _report_errors(result["rows"], console)
    goals = result["goals"]
    common.print_table(
        console, "rumor: goals of issue 11" + (" (quick run: indicative only)" if s["quick"] else ""),
        [("goal", "left"), ("row", "left"), ("measured", "left"), "verdict"],
        [[g["goal"], g["row"], g["figure"], _mark(g["pass"])] for g in goals],
    )
    passed = sum(bool(g["pass"]) for g in goals)
    console.print(f"Goals: {passed}/{len(goals)} pass.", highlight=False)
    for r in result["rows"]:
        if r["kind"] == "partition" and not r.get("unavailable"):
            _report_partition(r, console)


def _report_errors(rows: list[dict], console) -> None:
    errors: dict[str, list[str]] = {}  # message -> rows
    for r in rows:
        for message in dict.fromkeys(e.partition(": ")[2] for e in r.get("errors", [])):
            errors.setdefault(message, []).append(r["name"])
    for message, where in errors.items():
        console.print(f"[red]an agent raised[/red] in {'; '.join(where)}: {message}", highlight=False)


def _report_partition(r: dict, console) -> None:
    slow = sorted(r["channels"], key=lambda c: -math.inf if c["exact_after_s"] is None else -c["exact_after_s"])
    shown = ", ".join(f"{c['agent']}<-{c['peer']} (seed {c['seed']}) {fmt(c['exact_after_s'], '.1f', ' s')}"
                      for c in slow[:6])
    never = sum(c["exact_after_s"] is None for c in r["channels"])
    console.print(
        f"Partition/merge (merge at {r['t_merge']:.1f} s): {len(r['channels'])} directed tree-edge channels; slowest "
        f"to fuse exactly again: {shown or 'none'}" + (f"; [red]{never} never did[/red]" if never else "") + ".",
        highlight=False,
    )

