"""The statistics of ``skymesh bench rumor``: a row's pooled figures, the chi-square interval of ANEES, the
channels' return to exact fusion after a merge, and the goals of issue 11.

**Pooling.** A row pools its runs (seeds): fleet RMSE and ANEES by samples over every agent, target and seed
(:func:`mesh_sim.results.pooled`), the oracle's likewise over its targets and seeds; the ratio fleet RMSE /
oracle RMSE compares with the oracle of the same runs (same models, every bearing at once), the in-flight
ratio with each agent's in-flight oracle (the same filter holding only what could have reached that agent,
one step per hop: :mod:`mesh_sim.oracle`). Consistency is judged against the IMM oracle (matched to the
targets, consistent per target). Each agent's ANEES is pooled over its targets and the seeds on its own.

**Which ratio a goal uses.** Issue 11 asks that on a lossless tree every agent equal the centralized filter
"up to the information still in flight": that goal is on the in-flight ratio (the other ratio, which adds the
mesh's latency of one step per hop, is shown beside it). The full-mesh, ring and demo goals are on the plain
ratio.

**Independent samples for the ANEES interval.** ANEES = mean NEES / ``DIM``. An independent sample is one
(seed, target, ``DECORRELATION_S`` block of tracked time): runs with different seeds are independent and
targets move and are measured independently, but within a run one target's estimation error is correlated
over the motion model's velocity correlation time (``tau`` = 10 s), so consecutive 0.2 s evaluations are not
independent; agents do not count separately (fused estimates share information). With K such samples
``DIM K ANEES ~ chi2(DIM K)`` for a consistent estimator (Bar-Shalom, Li & Kirubarajan 2001, §5.4.2), giving
the interval ``chi2.ppf([0.025, 0.975], DIM K) / (DIM K)``. The fleet's K counts each target's longest
tracked time over the agents, the oracle's and each agent's their own.
"""

from __future__ import annotations

import math
from collections import Counter

from mesh_sim.phases import CONFIDENCE, anees_interval, independent_count
from mesh_sim.results import pooled

ANEES_FLOOR = 0.5  # issue 11: an agent's ANEES below this is wastefully conservative
#: Fleet RMSE / oracle RMSE limits (issue 11): (topologies, losses, methods, limit, ratio the goal is on).
RATIO_GOALS = (
    (("tree",), (0.0,), ("hybrid", "exact", "flood"), 1.05, "in_flight_ratio"),
    (("full", "ring"), (0.0, 0.3), ("hybrid", "flood"), 1.25, "rmse_ratio"),
)
DEMO_LIMIT = 1.25  # the 4-agent `make demo` configuration (issue 11)
RECOVERY_LIMIT_S = 10.0  # after a merge, every tree-edge channel fuses exactly again within this (issue 11)
NAIVE = "naive"  # the method that must show the rumour problem (ANEES above the interval)
GOAL_METHODS = ("hybrid", "flood")  # the methods whose every agent must be consistent


def independent_samples(per_target_samples: dict, step: float) -> int:
    """One per target per ``DECORRELATION_S`` of tracked time (at least one per tracked target)."""
    return independent_count(n * step for n in per_target_samples.values())


def _longest(target_lists: list[list[dict]]) -> dict[str, int]:
    """Per target, the most samples any of the lists scored it with."""
    out: dict[str, int] = {}
    for targets in target_lists:
        for t in targets:
            out[t["target"]] = max(out.get(t["target"], 0), int(t.get("samples", 0)))
    return out


def _interval(runs: list[tuple[float, list[list[dict]]]]) -> tuple[int, float, float]:
    """K independent samples over ``runs`` — each (agent step, lists of per-target scores) — and the ANEES
    interval."""
    k = sum(independent_samples(_longest(lists), step) for step, lists in runs)
    return (k, *anees_interval(k))


def summarise(outcomes: list[dict]) -> dict:
    """The pooled figures of one row from its runs (:func:`mesh_sim.bench.rumor_jobs.run_job` outcomes)."""
    rmse, anees = pooled([t for o in outcomes for a in o["agents"] for t in a["targets"]])
    o_rmse, same_model_anees = pooled([t for o in outcomes for t in o["oracle_targets"]])
    f_rmse, _ = pooled([t for o in outcomes for t in o.get("in_flight_targets", [])])
    imm = [t for o in outcomes for t in o.get("imm_targets", [])]
    _, o_anees = pooled(imm)
    k, lo, hi = _interval([(o["step"], [a["targets"] for a in o["agents"]]) for o in outcomes])
    ko, o_lo, o_hi = _interval([(o["step"], [o.get("imm_targets", [])]) for o in outcomes])
    per_agent = {}
    for name in dict.fromkeys(a["id"] for o in outcomes for a in o["agents"]):
        runs = [(o["step"], [a["targets"] for a in o["agents"] if a["id"] == name]) for o in outcomes]
        _, a_anees = pooled([t for _, lists in runs for targets in lists for t in targets])
        _, _, a_hi = _interval(runs)
        per_agent[name] = {"anees": a_anees, "anees_hi": a_hi,
                           "ok": a_anees is not None and ANEES_FLOOR <= a_anees <= a_hi}
    fusions = Counter()
    for o in outcomes:
        fusions.update(o["fusions"])
    fused = sum(n for method, n in fusions.items() if method != "stale")
    agent_s = sum(o["agents_n"] * o["t_end"] for o in outcomes)  # a diverged run counts until it was stopped
    diverged = [o["diverged_at"] for o in outcomes if o["diverged_at"] is not None]
    crashed = [o["crashed_at"] for o in outcomes if o["crashed_at"] is not None]
    agent_anees = [a["anees"] for a in per_agent.values() if a["anees"] is not None]
    return {
        "seeds": sorted(o["job"]["overrides"]["seed"] for o in outcomes),
        "rmse": rmse, "oracle_rmse": o_rmse,
        "rmse_ratio": rmse / o_rmse if rmse is not None and o_rmse else math.nan,
        "in_flight_ratio": rmse / f_rmse if rmse is not None and f_rmse else math.nan,
        "same_model_oracle_anees": same_model_anees,
        "anees": anees, "independent_samples": k, "anees_lo": lo, "anees_hi": hi,
        "oracle_anees": o_anees, "oracle_independent_samples": ko, "oracle_anees_lo": o_lo, "oracle_anees_hi": o_hi,
        "agents_anees": per_agent,
        "agents_anees_min": min(agent_anees, default=None), "agents_anees_max": max(agent_anees, default=None),
        "agents_consistent": sum(a["ok"] for a in per_agent.values()), "agents": len(per_agent),
        "fusions": dict(fusions), "exact_share": fusions["exact"] / fused if fused else math.nan,
        "bytes_per_agent_s": sum(o["radio_bytes"] for o in outcomes) / agent_s,
        "diverged_runs": len(diverged), "diverged_first_at": min(diverged, default=None),
        "max_tracks_per_agent": max(o["max_tracks"] for o in outcomes),
        "crashed_runs": len(crashed), "crashed_first_at": min(crashed, default=None),
        "errors": [o["error"] for o in outcomes if o["error"]],
    }


def recovery(outcome: dict, t_merge: float) -> list[dict]:
    """Per directed channel (agent, peer) on an edge of the radio plan after the merge (``outcome["edges"]``):
    seconds from ``t_merge`` to the channel's first exact fusion at or after it, from the agent's exact spans
    (:class:`agent.fusion_log.FusionLog`). A span that runs across the merge (exact messages no further apart
    than the log's silence limit) counts 0 s; a channel that never fuses exactly again counts ``None``."""
    channels = {a["id"]: a["channels"] for a in outcome["agents"]}
    out = []
    for a, b in outcome["edges"]:
        for me, peer in ((a, b), (b, a)):
            spans = channels.get(me, {}).get(peer, {}).get("exact_spans_s", [])
            after = [max(0.0, start - t_merge) for start, end in spans if end >= t_merge]
            out.append({"agent": me, "peer": peer, "seed": outcome["job"]["overrides"]["seed"],
                        "exact_after_s": min(after, default=None)})
    return out


# ==================================================================================================
# goals
# ==================================================================================================
def _ratio_limit(row: dict) -> tuple[float, str] | None:
    """The row's ratio goal: (limit, the ratio it is on)."""
    if row["kind"] == "demo":
        return DEMO_LIMIT, "rmse_ratio"
    if row["kind"] != "cell":
        return None
    return next(((limit, ratio) for topologies, losses, methods, limit, ratio in RATIO_GOALS
                 if row["topology"] in topologies and row["loss"] in losses and row["method"] in methods), None)


def _ok_run(row: dict) -> bool:
    return not row["diverged_runs"] and not row["crashed_runs"]


def goals(rows: list[dict]) -> list[dict]:
    """The issue's goals over the measured rows (unavailable rows are skipped); marks each row's own goals in
    place (``ratio_limit``/``ratio_pass``, ``agents_pass``, ``oracle_pass``, ``naive_pass``) and returns one
    entry per goal and row: ``{"goal", "row", "figure", "pass"}``."""
    out = []
    for r in rows:
        if r.get("unavailable"):
            continue
        name = r["name"]
        goal = _ratio_limit(r)
        if goal is not None:
            limit, ratio = goal
            r["ratio_limit"], r["ratio_goal_on"] = limit, ratio
            r["ratio_pass"] = bool(math.isfinite(r[ratio]) and r[ratio] <= limit and _ok_run(r))
            what = "in-flight oracle" if ratio == "in_flight_ratio" else "oracle"
            out.append({"goal": f"fleet RMSE / {what} <= {limit:g}", "row": name,
                        "figure": f"{r[ratio]:.2f}", "pass": r["ratio_pass"]})
        if r["method"] in GOAL_METHODS:
            r["agents_pass"] = r["agents_consistent"] == r["agents"] and _ok_run(r)
            out.append({"goal": f"every agent's ANEES in [{ANEES_FLOOR:g}, upper bound]", "row": name,
                        "figure": f"{r['agents_consistent']}/{r['agents']} agents "
                                  f"({_fmt(r['agents_anees_min'])}-{_fmt(r['agents_anees_max'])})",
                        "pass": r["agents_pass"]})
        if r["method"] == NAIVE:
            r["naive_pass"] = r["anees"] is not None and r["anees"] > r["anees_hi"]
            out.append({"goal": "naive overconfident (ANEES above the upper bound)", "row": name,
                        "figure": f"{_fmt(r['anees'])} vs {r['anees_hi']:.2f}", "pass": r["naive_pass"]})
        r["oracle_pass"] = r["oracle_anees"] is not None and r["oracle_anees_lo"] <= r["oracle_anees"] <= \
            r["oracle_anees_hi"]
        out.append({"goal": f"oracle ANEES inside its {CONFIDENCE:.0%} interval", "row": name,
                    "figure": f"{_fmt(r['oracle_anees'])} in {r['oracle_anees_lo']:.2f}-{r['oracle_anees_hi']:.2f}",
                    "pass": r["oracle_pass"]})
        if r["kind"] == "partition":
            times = [c["exact_after_s"] for c in r["channels"]]
            worst = math.inf if None in times else max(times, default=math.nan)
            r["recovery_s"] = worst
            r["recovery_pass"] = bool(times) and worst <= RECOVERY_LIMIT_S
            out.append({"goal": f"every tree-edge channel exact again <= {RECOVERY_LIMIT_S:g} s after the merge",
                        "row": name, "figure": f"worst {_fmt(worst, '.1f')} s over {len(times)} channels",
                        "pass": r["recovery_pass"]})
    return out


def _fmt(value, spec: str = ".2f") -> str:
    return "—" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, spec)
