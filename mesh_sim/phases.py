"""A run cut into phases — partitions, merges, link changes, lost and rejoined agents — and the figures of each.

**Phases.** A phase starts at ``t = 0`` (``start``), at every phase of the compiled radio plan
(:func:`mesh_sim.radio.compile_plan`: a change of the link graph, named after the ``[[radio.events]]`` kinds
at that time), at every lost agent (``metrics["losses"]``, :func:`mesh_sim.results.losses`) and, for an agent
started again, when every survivor that heard its new incarnation had heard it (the rejoin). It ends where
the next one starts, the last one at the end of the run. A merge, a ``link_up`` and a rejoin *heal* the mesh.

**Figures.** Each phase pools the evaluators' time bins (``bins`` of :class:`agent.evaluation.TrackEvaluator`,
a bin belonging to the phase its start is in, the run's last evaluation at ``t = duration`` to the last
phase) over every agent and target: fleet RMSE ``sqrt(sum e^2 / n)``,
ANEES ``sum NEES / (6 n)``, the same for the oracle (:class:`mesh_sim.oracle.Oracle`) and the ratio of the
RMSEs. ANEES is judged against the two-sided 95 % interval of a consistent estimator: ``6 K ANEES ~ chi2(6 K)``
for ``K`` independent NEES samples of a 6-D state, so the interval is ``chi2.ppf([0.025, 0.975], 6 K) / (6 K)``
(Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001, §5.4.2).
Consecutive evaluations are not independent — one target's estimation error is correlated over the motion
model's velocity correlation time (``tau`` = 10 s), and agents' fused estimates share information — so ``K``
counts one sample per target per :data:`DECORRELATION_S` of tracked time in the phase (its longest over the
agents, at least one per tracked target; :func:`independent_samples`), as ``skymesh bench rumor`` does. The
interval over every evaluation as if independent (``samples``, about 100 times as many) was far narrower than
the evidence allows: the centralized filter itself fell outside it in every phase.

**Re-convergence.** In a phase that heals the mesh: the first time ``tau`` (a bin end) from which, in every
window ``[max(start, tau - WINDOW_S), tau)`` up to the end of the phase, every target's fleet RMSE ÷ oracle
RMSE is within :data:`RATIO_GOAL`, reported as ``tau - start`` (``None``: never). A target seen by the oracle
but by no agent in a window fails it; one that neither saw is left out. The same measured against the agents'
in-flight oracles (each agent's centralized filter holding only what could have reached it) tells fusion from
latency: on ``partition``'s line of four, with tracks leaving every 0.2 s, the in-flight oracles themselves stay at
1.2–1.4× the oracle after the merge in seeds 1 and 3 — they never re-converge to it by this rule — while the fleet is
within 1.2× of its in-flight oracles from the merge's first second on (seeds 1–3). The ratio to the oracle is the
goal a user sees; the ratio to the in-flight oracle is what fusion can be asked for.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from agent.evaluation import BIN_S

DIM = 6  # the tracked state: position and velocity in 3-D
DECORRELATION_S = 10.0  # one independent NEES sample per target per this many tracked seconds (motion tau)
CONFIDENCE = 0.95
WINDOW_S = 5.0  # s: the sliding window of the re-convergence test; chosen here
RATIO_GOAL = 1.25  # each target's fleet RMSE ÷ oracle RMSE, at most (issue 13; also the tasking benchmarks' goal)
HEALING = {"merge", "link_up"}  # radio events that give links back


def anees_interval(samples: int, dim: int = DIM, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Two-sided chi-square interval of ANEES (NEES / dim) averaged over ``samples`` independent samples:
    ``chi2.ppf([(1 - c) / 2, (1 + c) / 2], dim n) / (dim n)`` (Bar-Shalom et al. 2001, §5.4.2)."""
    from scipy.stats import chi2

    dof = max(1, samples) * dim
    tail = (1.0 - confidence) / 2
    return float(chi2.ppf(tail, dof) / dof), float(chi2.ppf(1.0 - tail, dof) / dof)


def boundaries(raw: dict, losses: list[dict], duration: float) -> list[dict]:
    """``[{"name", "start_s", "end_s", "heals"}]``: the phases of a run (see the module docstring)."""
    kinds: dict[float, list[str]] = {}
    for ev in (raw.get("radio") or {}).get("events") or []:
        kinds.setdefault(float(ev["t"]), []).append(ev["kind"])
    starts = [(0.0, "start", False)]
    for ph in (raw.get("radio_plan") or {}).get("phases", [])[1:]:
        t = float(ph["t"])
        names = kinds.get(t, ["radio"])
        starts.append((t, "+".join(dict.fromkeys(names)), bool(HEALING & set(names))))
    for loss in losses:
        starts.append((loss["t"], f"{loss['agent']} lost", False))
        heard = [s for s in (loss.get("rejoined_after") or {}).values() if s is not None]
        if heard:
            starts.append((loss["t"] + max(heard), f"{loss['agent']} rejoined", True))
    phases: list[dict] = []
    for t, name, heals in sorted(starts, key=lambda s: s[0]):
        if t >= duration:
            continue
        if phases and math.isclose(phases[-1]["start_s"], t, abs_tol=1e-9):
            phases[-1]["name"] = "start" if phases[-1]["name"] == "start" else f"{phases[-1]['name']}, {name}"
            phases[-1]["heals"] = phases[-1]["heals"] or heals
            continue
        phases.append({"name": name, "start_s": t, "end_s": duration, "heals": heals})
    for ph, nxt in zip(phases, phases[1:], strict=False):
        ph["end_s"] = nxt["start_s"]
    return phases


def _sums(target_lists: list[list[dict]], t0: float, t1: float) -> dict[str, np.ndarray]:
    """Per target, ``[squared errors, NEES, samples]`` summed over the bins starting in ``[t0, t1)`` of every
    list of per-target scores."""
    out: dict[str, np.ndarray] = {}
    for targets in target_lists:
        for t in targets:
            for start, *sums in t.get("bins", []):  # sums[3:]: the position variance, not pooled here
                if t0 - 1e-9 <= start < t1 - 1e-9:
                    out[t["target"]] = out.get(t["target"], np.zeros(3)) + sums[:3]
    return out


def independent_samples(target_lists: list[list[dict]], t0: float, t1: float) -> int:
    """``K`` of the module docstring over ``[t0, t1)``: per target, its longest tracked time over the lists (the
    :data:`BIN_S` bins with samples), one per :data:`DECORRELATION_S` of it and at least one."""
    longest: dict[str, float] = {}
    for targets in target_lists:
        for t in targets:
            seconds = BIN_S * sum(1 for start, *sums in t.get("bins", []) if t0 - 1e-9 <= start < t1 - 1e-9 and sums[2])
            longest[t["target"]] = max(longest.get(t["target"], 0.0), seconds)
    return independent_count(longest.values())


def independent_count(tracked_seconds: Iterable[float]) -> int:
    """One independent NEES sample per :data:`DECORRELATION_S` of each target's tracked seconds, at least one per
    tracked target: the rule shared by the phases and ``skymesh bench rumor`` (:mod:`mesh_sim.bench.rumor_stats`)."""
    return sum(max(1, int(s // DECORRELATION_S)) for s in tracked_seconds if s > 0)


def _rmse(sums: np.ndarray) -> float | None:
    return float(np.sqrt(sums[0] / sums[2])) if sums[2] else None


def _anees(sums: np.ndarray) -> float | None:
    return float(sums[1] / (DIM * sums[2])) if sums[2] else None


def ratio_of(a: float | None, b: float | None) -> float | None:
    """``a / b``, or ``None`` without both (or with ``b`` zero)."""
    return a / b if a is not None and b else None


def phase_figures(agents: list[list[dict]], oracle: list[dict], t0: float, t1: float,
                  in_flight: list[list[dict]] | None = None) -> dict:
    """Fleet and oracle RMSE, their ratio, the fleet's ANEES and whether it is inside its interval, over
    ``[t0, t1)``: ``agents`` holds each agent's per-target scores, ``oracle`` the oracle's. Beside them the
    oracle's own ANEES — what the shared motion model allows: a fleet at the oracle's ANEES is as consistent
    as the centralized filter with the same models — and, given each agent's in-flight oracle (``in_flight``,
    :class:`mesh_sim.oracle.InFlightOracle`), the ratio to them pooled: the fusion's own loss in the phase,
    with the network's latency and a partition's missing half taken out."""
    fleet = sum(_sums(agents, t0, t1).values(), np.zeros(3))
    central = sum(_sums([oracle], t0, t1).values(), np.zeros(3))
    reachable = sum(_sums(in_flight or [], t0, t1).values(), np.zeros(3))
    rmse, oracle_rmse, n = _rmse(fleet), _rmse(central), int(fleet[2])
    anees, k = _anees(fleet), independent_samples(agents, t0, t1)
    lo, hi = anees_interval(k)
    return {"fleet_rmse": rmse, "oracle_rmse": oracle_rmse, "rmse_ratio_to_oracle": ratio_of(rmse, oracle_rmse),
            "rmse_ratio_to_in_flight": ratio_of(rmse, _rmse(reachable)),
            "anees": anees, "oracle_anees": _anees(central), "samples": n, "independent_samples": k,
            "anees_interval": [lo, hi],
            "anees_inside": anees is not None and lo <= anees <= hi}


def worst_ratio(agents: list[list[dict]], reference: list[list[dict]], t0: float, t1: float) -> float | None:
    """The largest per-target fleet RMSE ÷ reference RMSE over ``[t0, t1)``, the reference's errors pooled over its
    lists like the fleet's (the oracle: one list; the in-flight oracles: one per agent). ``None``: a target the
    reference saw but no agent, or one it saw without error; ``0.0`` if no target was seen."""
    fleet, central = _sums(agents, t0, t1), _sums(reference, t0, t1)
    ratios = []
    for target in set(fleet) | set(central):
        rmse, oracle_rmse = _rmse(fleet.get(target, np.zeros(3))), _rmse(central.get(target, np.zeros(3)))
        if rmse is None or not oracle_rmse:
            return None
        ratios.append(rmse / oracle_rmse)
    return max(ratios, default=0.0)


def settled_after(series: list[tuple[float, float | None]], limit: float) -> float | None:
    """The first time of ``series`` (``(t, ratio)`` in time order) from which every ratio is within ``limit``
    (``None`` counts as outside); ``None`` if the last one is not."""
    first = None
    for t, ratio in series:
        if ratio is None or ratio > limit:
            first = None
        elif first is None:
            first = t
    return first


def reconvergence(agents: list[list[dict]], reference: list[list[dict]], t0: float, t1: float) -> float | None:
    """Seconds from ``t0`` until the fleet re-converged to ``reference`` for the rest of ``[t0, t1)`` (module
    docstring)."""
    ends = [t0 + k * BIN_S for k in range(1, int(math.floor((t1 - t0) / BIN_S + 1e-9)) + 1)]
    series = [(tau, worst_ratio(agents, reference, max(t0, tau - WINDOW_S), tau)) for tau in ends]
    tau = settled_after(series, RATIO_GOAL)
    return None if tau is None else round(tau - t0, 9)


def run_phases(metrics: dict, duration: float) -> list[dict]:
    """``metrics["phases"]``: each phase of the run (:func:`boundaries`) with its :func:`phase_figures` and,
    if it heals the mesh, ``reconverged_after_s`` and ``reconverged_to_in_flight_after_s`` (:func:`reconvergence`)."""
    agents = [a["targets"] for a in metrics["agents"] if "targets" in a]
    oracle = metrics["oracle"].get("targets", [])
    reachable = metrics["oracle"].get("in_flight") or {}
    in_flight = [reachable[a["id"]] for a in metrics["agents"] if "targets" in a and a.get("id") in reachable]
    out = []
    for ph in boundaries(metrics["config"], metrics.get("losses", []), duration):
        t0, t1 = ph["start_s"], ph["end_s"]
        row = {**ph, **phase_figures(agents, oracle, t0, math.inf if t1 == duration else t1, in_flight)}
        if ph["heals"]:
            row["reconverged_after_s"] = reconvergence(agents, [oracle], t0, t1)
            if in_flight:
                row["reconverged_to_in_flight_after_s"] = reconvergence(agents, in_flight, t0, t1)
        out.append(row)
    return out


def caption(phase: dict) -> str:
    """One phase under the run table."""
    anees = "-" if phase["anees"] is None else f"{phase['anees']:.2f}"
    lo, hi = phase["anees_interval"]
    verdict = "inside" if phase["anees_inside"] else "outside"
    ratio = "-" if phase["rmse_ratio_to_oracle"] is None else f"{phase['rmse_ratio_to_oracle']:.2f}"
    text = f"{phase['name']} {phase['start_s']:g}–{phase['end_s']:g} s: RMSE ÷ oracle {ratio}"
    if phase.get("rmse_ratio_to_in_flight") is not None:
        text += f" (÷ in flight {phase['rmse_ratio_to_in_flight']:.2f})"
    text += f", ANEES {anees} ({verdict} [{lo:.2f}, {hi:.2f}]"
    if phase.get("oracle_anees") is not None:
        text += f"; oracle {phase['oracle_anees']:.2f}"
    text += ")"
    if "reconverged_after_s" in phase:
        after = phase["reconverged_after_s"]
        text += (f", never re-converged (≤ {RATIO_GOAL:g} over {WINDOW_S:g} s)" if after is None
                 else f", re-converged after {after:g} s")
    if "reconverged_to_in_flight_after_s" in phase:
        after = phase["reconverged_to_in_flight_after_s"]
        text += f"; to in flight {'never' if after is None else f'after {after:g} s'}"
    return text
