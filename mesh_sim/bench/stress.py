"""``skymesh bench stress`` (alias ``skymesh stress``): a live team under topology churn and a falling bandwidth cap.

Live runs (:class:`mesh_sim.launcher.Launcher`: one OS process per agent over the launcher's Zenoh router,
the world process with the centralized oracle, Rerun off, ``speed`` 1.0 so simulation seconds are wall
seconds), one per per-link bandwidth cap, swept downward: unlimited, 50, 20, 10, 5 and 2 kB/s with 6
agents for 30 s (``--quick``: unlimited, 10 and 2 kB/s, 4 agents, 12 s). Every run of one invocation has the
same team, seed and churn schedule, so the caps are compared like with like; the unlimited run is the
baseline of the ratios.

**Scenario** (the default scenario with overrides): radio ``random`` topology with mean degree 3
(clamped to n - 1), the ``wifi`` preset (2 ms, 0.14 % loss) with ``rate`` = the cap, a radio range of
``RANGE_M``, and **topology churn**: every 3-5 s (drawn from the seed) one ``[[radio.events]]`` entry —
a random edge goes down, a downed edge comes back, the team splits into two random groups, or (after a
split) merges again (:func:`churn_events`). Sensor range 300 m and a 120 deg cone so the targets are
found within the first seconds; each agent orbits one target and knows the others mostly through its
peers, which is what the cap starves. Sending and tracking keep their defaults (information-triggered
every 1 s, ``hybrid`` fusion, bearing measurements).

**Token-bucket depth.** The radio's default bucket depth is ``max(64 KiB, 0.1 s x rate)``: at 2 kB/s
that is 32 s of traffic, so a cap would not bind within a run of this length. Here the depth is
``max(BURST_MIN_BYTES, BURST_S x rate)`` (2 s of traffic, at least 16 KiB so that a message carrying
three tracks of ~4.8 kB still fits). The agents' sender budget knows only the rate (``plan.sender_budget``)
and keeps its own 64 KiB bucket, so what it sends in bursts beyond the link's depth is policed at the
receivers: those are the ``rate`` drops.

**Per cap**: bytes received per agent per second (what passed the agent's radio, from all its neighbours)
and its ratio to the unlimited run's; radio bytes sent per agent per second (track + telemetry); radio
drops per agent per second by cause (``down``: no edge at the message's stamp — non-neighbours, churn and
partitions; ``range``; ``loss``; ``rate``: the receive-side token bucket); tracks and telemetry messages
thinned by the senders' budgets; fleet RMSE, its ratio to the oracle's and to the baseline's; fleet ANEES
against the upper end of its 95 % chi-square interval (independent samples as in :mod:`mesh_sim.bench.rumor_stats`);
**coverage** — per agent and target, the time the agent held a matched track over the time from
``ACQUIRE_S`` after the oracle first tracked the target to the end of the run (``samples x step /
(duration - oracle's first track - ACQUIRE_S)``, at most 1) — and whether every agent still tracks every
target (every coverage at least ``COVERAGE_GOAL``); steps the agents missed (late or skipped: machine load).

**Where it breaks**: the largest cap at which tracking (every agent, every target) or consistency (ANEES
above the upper bound) fails, or the run did not complete.
"""

from __future__ import annotations

import math
import os
import random
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

from rich.console import Console

from mesh_sim.bench import common
from mesh_sim.bench.common import fmt
from mesh_sim.bench.rumor_stats import anees_interval, independent_samples

NAME = "stress"
SCENARIO = "default"
SPEED = 1.0  # simulation seconds per wall second: live, real time
FULL_CAPS = (0, 50_000, 20_000, 10_000, 5_000, 2_000)  # bytes/s per directed link; 0 = unlimited
QUICK_CAPS = (0, 10_000, 2_000)
FULL_AGENTS, QUICK_AGENTS = 6, 4
FULL_DURATION_S, QUICK_DURATION_S = 30.0, 12.0  # chosen here; quick: three runs stay under a minute
SEED = 7  # chosen here: draws the random topology, the churn and the noise
MEAN_DEGREE = 3.0
CHURN_EVERY_S = (3.0, 5.0)  # a topology event every 3-5 s (from the issue)
RANGE_M = 200.0  # radio range [m]; chosen here: the ends of the starting line are ~200 m apart
BURST_S, BURST_MIN_BYTES = 2.0, 16 * 1024  # token-bucket depth (see the module docstring); chosen here
# The geometric bearing sensor (the network is under test, not perception); targets found within seconds.
SENSOR = {"kind": "bearing", "range": 300.0, "fov_deg": 120.0}
COVERAGE_GOAL = 0.8  # an agent "tracks" a target holding it at least this share of the time; chosen here
ACQUIRE_S = 2.0  # s allowed to take up a target the oracle tracks (1 s send period + 3 confirming hits); chosen here


def churn_events(agents: Sequence[str], duration: float, seed: int, mean_degree: float) -> list[dict]:
    """``[[radio.events]]`` every ``CHURN_EVERY_S`` seconds, drawn from ``seed``: after a partition a merge;
    otherwise a split into two random groups (p = 0.25), a downed edge back up (p = 0.3, if any is down) or
    a random edge of the base topology down. ``merge`` restores the base topology (:mod:`mesh_sim.radio`)."""
    from mesh_sim.radio import topology_edges

    agents = list(agents)
    base = sorted(sorted(e) for e in topology_edges("random", agents, seed, mean_degree))
    rng = random.Random(f"skymesh.bench.stress:{seed}")
    events, down, split = [], [], False
    t = rng.uniform(*CHURN_EVERY_S)
    while t < duration:
        if split:
            events.append({"t": round(t, 2), "kind": "merge"})
            split, down = False, []
        else:
            u = rng.random()
            if u < 0.25 and len(agents) >= 2:
                order = rng.sample(agents, len(agents))
                k = rng.randint(1, len(agents) - 1)
                events.append({"t": round(t, 2), "kind": "partition", "groups": [order[:k], order[k:]]})
                split = True
            elif u < 0.55 and down:
                edge = down.pop(rng.randrange(len(down)))
                events.append({"t": round(t, 2), "kind": "link_up", "link": edge})
            else:
                up = [e for e in base if e not in down]
                if up:
                    edge = rng.choice(up)
                    down.append(edge)
                    events.append({"t": round(t, 2), "kind": "link_down", "link": edge})
        t += rng.uniform(*CHURN_EVERY_S)
    return events


def scenario_overrides(cap: float, agents: int, duration: float, seed: int = SEED) -> dict:
    names = [f"uav{i}" for i in range(agents)]
    degree = min(MEAN_DEGREE, agents - 1.0)
    radio = {"topology": "random", "mean_degree": degree, "preset": "wifi", "range": RANGE_M,
             "rate": float(cap), "events": churn_events(names, duration, seed, degree)}
    if cap > 0:
        radio["burst"] = max(float(BURST_MIN_BYTES), BURST_S * cap)
    return {"agents": agents, "duration": duration, "seed": seed, "radio": radio, "sensor": dict(SENSOR)}


def run(
    quick: bool = False,
    repeats: int | None = None,
    *,
    caps: Sequence[float] | None = None,
    agents: int | None = None,
    duration: float | None = None,
    seed: int = SEED,
    runs_dir: str | os.PathLike | None = None,
) -> dict:
    """Run the benchmark. ``caps`` (bytes/s per link, 0 = unlimited; sorted downward, unlimited first, and
    an unlimited baseline is added if missing), ``agents``, ``duration`` override the mode's defaults;
    ``repeats`` runs per cap (seeds ``seed``, ``seed + 1``, ...; pooled). Run folders go to a temporary
    folder removed afterwards, or under ``runs_dir`` (kept)."""
    from mesh_sim.scenario import load

    caps = sorted({float(c) for c in (caps if caps is not None else QUICK_CAPS if quick else FULL_CAPS)} | {0.0},
                  key=lambda c: -math.inf if c == 0 else -c)
    agents = int(agents or (QUICK_AGENTS if quick else FULL_AGENTS))
    duration = float(duration or (QUICK_DURATION_S if quick else FULL_DURATION_S))
    runs = int(repeats or 1)
    if any(c < 0 for c in caps) or agents < 2 or not duration > 0 or runs < 1:
        raise ValueError(f"bad settings: caps {caps}, agents {agents}, duration {duration}, repeats {runs}")
    seeds = [seed + r for r in range(runs)]
    load_before = os.getloadavg()
    rows = []
    folder = common.runs_folder(runs_dir, "skymesh-bench-stress-")
    with folder as base, common.run_progress(NAME, len(caps) * runs) as (console, advance):
        launcher_console = console if console.is_terminal else Console(stderr=True, quiet=True)
        for cap in caps:
            outcomes = []
            for s in seeds:
                advance(f"cap {_cap(cap)}, seed {s} ({duration:g} s)", 0)
                scenario = load(SCENARIO, **scenario_overrides(cap, agents, duration, s))
                outcomes.append(_one_run(scenario, base, launcher_console, cap))
                if outcomes[-1]["status"] == "interrupted":
                    raise KeyboardInterrupt
                advance(f"cap {_cap(cap)} done", 1)
            rows.append(_summarise(cap, outcomes, agents, duration))
    _add_ratios(rows)
    events = scenario_overrides(0.0, agents, duration, seeds[0])["radio"]["events"]
    return {
        "benchmark": NAME,
        "settings": {
            "quick": quick, "caps": caps, "agents": agents, "duration_s": duration, "speed": SPEED,
            "seeds": seeds, "topology": "random", "mean_degree": min(MEAN_DEGREE, agents - 1.0), "preset": "wifi",
            "range_m": RANGE_M, "burst": {"seconds": BURST_S, "min_bytes": BURST_MIN_BYTES}, "sensor": SENSOR,
            "churn_every_s": list(CHURN_EVERY_S), "churn_events": events,
            "churn_kinds": dict(Counter(e["kind"] for e in events)), "coverage_goal": COVERAGE_GOAL,
            "load_average_before": list(load_before), "load_average_after": list(os.getloadavg()),
        },
        "environment": common.environment(("numpy", "scipy", "eclipse-zenoh", "msgpack")),
        "rows": rows,
        "goals": _goals(rows),
    }


def _cap(cap: float) -> str:
    return "unlimited" if cap == 0 else f"{cap / 1000:g} kB/s"


def _one_run(scenario, base: Path, console: Console, cap: float) -> dict:
    from mesh_sim.launcher import Launcher, new_run_dir

    run_dir = new_run_dir(base, f"{NAME}-{int(cap)}")
    outcome = Launcher(scenario, run_dir, speed=SPEED, rerun="off", console=console).run()
    return {"status": outcome.status, "metrics": outcome.metrics, "step": scenario.agent.step}


def _coverage(agents: list[dict], oracle_targets: list[dict], duration: float, step: float) -> list[float]:
    """Per (agent, target): share of the time from ``ACQUIRE_S`` after the oracle's first track of it to the end
    that the agent held it (at most 1)."""
    out = []
    for o in oracle_targets:
        if o.get("time_to_first_track") is None:
            continue
        window = max(step, duration - o["time_to_first_track"] - ACQUIRE_S)
        for a in agents:
            mine = next((t for t in a.get("targets", []) if t["target"] == o["target"]), None)
            held = 0.0 if mine is None else mine.get("samples", 0) * step
            out.append(min(1.0, held / window))
    return out


def _summarise(cap: float, outcomes: list[dict], agents: int, duration: float) -> dict:
    from mesh_sim.results import pooled

    ran = [a for o in outcomes for a in o["metrics"].get("agents", []) if isinstance(a.get("steps"), int)]
    step = outcomes[0]["step"]
    rmse, anees = pooled([t for a in ran for t in a.get("targets", [])])
    o_rmse, o_anees = pooled([t for o in outcomes for t in o["metrics"].get("oracle", {}).get("targets", [])])
    k = 0
    coverage: list[float] = []
    for o in outcomes:
        mine = [a for a in o["metrics"].get("agents", []) if isinstance(a.get("steps"), int)]
        per_target: dict[str, int] = {}
        for a in mine:
            for t in a.get("targets", []):
                per_target[t["target"]] = max(per_target.get(t["target"], 0), int(t.get("samples", 0)))
        k += independent_samples(per_target, step)
        coverage += _coverage(o["metrics"].get("agents", []), o["metrics"].get("oracle", {}).get("targets", []),
                              duration, step)
    lo, hi = anees_interval(k)
    drops, tx = Counter(), Counter()
    for a in ran:
        drops.update(a.get("radio_drops_by_cause", {}))
        tx.update(a.get("bytes_tx_by_kind", {}))
    agent_s = agents * duration * len(outcomes)
    completed = all(o["status"] == "completed" for o in outcomes) and len(ran) == agents * len(outcomes)
    tracking = completed and bool(coverage) and min(coverage) >= COVERAGE_GOAL
    consistent = anees is not None and anees <= hi
    missed, due = common.missed_steps(ran)
    return {
        "cap": cap, "status": "; ".join(sorted({o["status"] for o in outcomes})), "completed": completed,
        "delivered_bytes_per_agent_s": sum(a.get("bytes_rx", 0) for a in ran) / agent_s,  # received per agent
        "sent_bytes_per_agent_s": (tx["track"] + tx["telemetry"]) / agent_s,
        "drops": {c: int(drops.get(c, 0)) for c in ("down", "range", "loss", "rate")},
        "drops_per_agent_s": {c: drops.get(c, 0) / agent_s for c in ("down", "range", "loss", "rate")},
        "tracks_thinned": sum(a.get("tracks_thinned", 0) for a in ran),
        "telemetry_thinned": sum(a.get("telemetry_thinned", 0) for a in ran),
        "fusions": dict(sum((Counter(a.get("fusions", {})) for a in ran), Counter())),
        "rmse": rmse, "oracle_rmse": o_rmse, "rmse_ratio_to_oracle": rmse / o_rmse if rmse and o_rmse else math.nan,
        "anees": anees, "oracle_anees": o_anees, "independent_samples": k, "anees_lo": lo, "anees_hi": hi,
        "consistent": consistent,
        "coverage_min": min(coverage, default=math.nan), "coverage_mean": _mean(coverage),
        "every_agent_tracks_every_target": tracking,
        "missed_steps_share": missed / due if due else math.nan,
        "ok": completed and tracking and consistent,
    }


def _mean(values) -> float:
    values = [v for v in values if v is not None and math.isfinite(v)]
    return sum(values) / len(values) if values else math.nan


def _add_ratios(rows: list[dict]) -> None:
    """Delivered bytes and RMSE as ratios to the unlimited run of the same invocation (the first row)."""
    base = rows[0]
    for r in rows:
        r["delivered_ratio"] = (r["delivered_bytes_per_agent_s"] / base["delivered_bytes_per_agent_s"]
                                if base["delivered_bytes_per_agent_s"] else math.nan)
        r["rmse_ratio_to_baseline"] = r["rmse"] / base["rmse"] if r["rmse"] and base["rmse"] else math.nan


def _goals(rows: list[dict]) -> dict:
    failing = [r for r in rows if not r["ok"]]
    breaks = failing[0] if failing else None
    why = None
    if breaks is not None:
        why = [w for w, bad in (("did not complete", not breaks["completed"]),
                                ("an agent lost a target", not breaks["every_agent_tracks_every_target"]),
                                ("overconfident", not breaks["consistent"])) if bad]
    return {
        "description": f"the largest cap at which tracking (every agent holds every target >= {COVERAGE_GOAL:.0%} of "
        "the time) or consistency (ANEES <= upper 95 % bound) fails, or the run does not complete",
        "breaks_at_cap": None if breaks is None else breaks["cap"],
        "breaks_because": why,
        "holds_down_to_cap": min((r["cap"] for r in rows if r["cap"] > 0 and all(
            x["ok"] for x in rows if x["cap"] == 0 or x["cap"] >= r["cap"])), default=None),
        "baseline_ok": rows[0]["ok"] if rows else None,
        "results": [{"cap": r["cap"], "ok": r["ok"], "tracking": r["every_agent_tracks_every_target"],
                     "consistent": r["consistent"], "completed": r["completed"]} for r in rows],
    }


# ==================================================================================================
# report
# ==================================================================================================
def report(result: dict, console=None) -> None:
    """Print the per-cap table and where it breaks."""
    console = console or common.make_console()
    s, env = result["settings"], result["environment"]
    console.print(
        f"[bold]{NAME}[/bold]  {'quick' if s['quick'] else 'full'} run: live, {s['agents']} agents, "
        f"{s['duration_s']:g} s at speed {s['speed']:g}, seeds {s['seeds']}, random topology (mean degree "
        f"{s['mean_degree']:g}), wifi preset, range {s['range_m']:g} m, churn every {s['churn_every_s'][0]:g}-"
        f"{s['churn_every_s'][1]:g} s ({', '.join(f'{n} {k}' for k, n in s['churn_kinds'].items())}), bucket "
        f"depth max({s['burst']['min_bytes'] // 1024} KiB, {s['burst']['seconds']:g} s x cap).  "
        f"{env['processor']} ({env['cpu_count']} CPUs), zenoh {env['packages'].get('eclipse-zenoh')}; load "
        f"average before/after {s['load_average_before'][0]:.2f} / {s['load_average_after'][0]:.2f}",
        highlight=False,
    )
    rows = []
    for r in result["rows"]:
        d = r["drops_per_agent_s"]
        rows.append([
            _cap(r["cap"]) if r["completed"] else f"[red]{_cap(r['cap'])}: {r['status']}[/red]",
            f"{r['sent_bytes_per_agent_s']:,.0f}/{r['delivered_bytes_per_agent_s']:,.0f} "
            f"({common.fmt_ratio(r['delivered_ratio'])})",
            "/".join(f"{d[c]:.2g}" for c in ("down", "range", "loss", "rate")),
            f"{r['tracks_thinned']}/{r['telemetry_thinned']}",
            f"{fmt(r['rmse'], '.2f')} ({common.fmt_ratio(r['rmse_ratio_to_baseline'])})",
            fmt(r["rmse_ratio_to_oracle"], ".2f", "x"),
            f"{fmt(r['anees'], '.2f')} {'≤' if r['consistent'] else '[red]>[/red]'} {r['anees_hi']:.2f}",
            fmt(r["oracle_anees"], ".2f"),
            f"{fmt(100 * r['coverage_min'], '.0f')}/{fmt(100 * r['coverage_mean'], '.0f')} % "
            + ("yes" if r["every_agent_tracks_every_target"] else "[red]no[/red]"),
            fmt(100 * r["missed_steps_share"], ".1f", " %"),
            common.verdict(r["ok"]),
        ])
    common.print_table(
        console, "stress: live team under topology churn and a per-link bandwidth cap",
        ["cap", "sent/recv B/ag/s (÷unl)", "drops/ag/s dn/rng/loss/rate", "thinned trk/tel", "RMSE m (÷unl)",
         "÷ oracle", "ANEES ≤ bound", "oracle ANEES", "coverage min/mean, all?", "missed", "ok"],
        rows,
        caption="sent: track + telemetry bytes per agent per second; recv: bytes per agent per second that passed its "
        "radio (from all its neighbours), ÷unl: ratio to the unlimited run of this invocation. Drops at the receivers: "
        "dn = no edge at the stamp (non-neighbours, churn, partitions), rng = out of range, rate = the receive-side "
        "token bucket. Thinned: tracks / telemetry messages the senders' budgets held back. bound: upper end of the "
        f"95 % chi-square interval. Coverage: time an agent held a target / time from {ACQUIRE_S:g} s after the "
        "oracle first tracked it to the end (min/mean over agents x targets; all? = min >= "
        f"{s['coverage_goal']:.0%}: every agent still tracks every target). Missed: late or skipped agent steps.",
    )
    g = result["goals"]
    if g["breaks_at_cap"] is None:
        console.print(f"Breaks: nowhere down to {_cap(min(c for c in s['caps'] if c > 0) if any(s['caps']) else 0)} "
                      "— every cap kept tracking and consistency.", highlight=False)
    else:
        console.print(f"Breaks at: [red]{_cap(g['breaks_at_cap'])}[/red] ({', '.join(g['breaks_because'])}); holds "
                      f"down to {_cap(g['holds_down_to_cap']) if g['holds_down_to_cap'] else '—'}.", highlight=False)
