"""Merge a run's per-process metrics into ``metrics.json``, print the summary table, draw the plots
(:mod:`mesh_sim.plots`) and finish the Rerun recording (:mod:`mesh_sim.observer_series`).

Fleet figures pool every (agent, target) pair by samples: ``rmse = sqrt(sum n_i rmse_i^2 / sum n_i)``
and ``anees = sum n_i anees_i / sum n_i``, likewise for the oracle, so ``rmse_ratio_to_oracle`` compares
like with like; ``rmse_ratio_to_in_flight`` pools each agent's in-flight oracle (:mod:`mesh_sim.oracle`:
the centralized filter holding what could have reached that agent) the same way. ``tail_rmse`` and
``tail_anees`` pool the targets' ``tail`` figures (the final
``agent.evaluation.TAIL_S`` seconds of the run) the same way. ``phases`` holds the same figures per phase of
the run (partition, merge, a lost agent...: :mod:`mesh_sim.phases`).
"""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path

import numpy as np
from rich.console import Console, Group
from rich.markup import escape
from rich.table import Table

from agent.runtime import write_json
from mesh_sim.phases import anees_interval, caption, independent_samples, ratio_of, run_phases


def pooled(targets: list[dict]) -> tuple[float | None, float | None]:
    """Sample-weighted RMSE and ANEES over a list of per-target scores."""
    n = np.array([t.get("samples", 0) for t in targets if t.get("rmse") is not None], float)
    if n.sum() == 0:
        return None, None
    rmse = np.array([t["rmse"] for t in targets if t.get("rmse") is not None])
    anees = np.array([t["anees"] for t in targets if t.get("rmse") is not None])
    return float(np.sqrt(np.sum(n * rmse**2) / n.sum())), float(np.sum(n * anees) / n.sum())


DEATHS_FILE = "deaths.json"  # the launcher's record of the children that died while the run went on


def losses(run_dir: Path, scenario, agents: list[dict]) -> list[dict]:
    """The agents lost during the run, emulated or real, in one shape: the radio's ``node_loss`` events
    (:mod:`mesh_sim.radio`) and the agent processes that died (the launcher's :data:`DEATHS_FILE`). Each
    loss says when (simulation seconds) and why, and how long each survivor took to notice it:
    ``last heard + neighbour timeout - t`` (:meth:`agent.net.topology.Topology.metrics`; ``None`` for a
    survivor that never heard the lost agent). An agent started again (``skymesh run --restart``) says instead
    how long after its death each survivor first heard its new incarnation (``rejoined_after``,
    :class:`agent.net.incarnation.ReceiveWindow`)."""
    plan = scenario.raw.get("radio_plan") or {}
    lost = [{"agent": d["node"], "t": float(d["t"]), "cause": "node_loss"} for d in plan.get("down_nodes", [])]
    lost += [{"agent": d["agent"], "t": float(d["t"]), "cause": d["cause"], "pid": d["pid"],
              "exit_code": d["exit_code"], "restarted_as": d.get("restarted_as")}
             for d in (_read(run_dir / DEATHS_FILE) or []) if d.get("role") == "agent"]
    gone = {loss["agent"] for loss in lost if loss.get("restarted_as") is None}
    for loss in lost:
        survivors = [a for a in agents if a["id"] not in gone | {loss["agent"]} and "peers_last_heard" in a]
        if loss.get("restarted_as") is None:
            loss["detected_after"] = {a["id"]: _noticed(a, loss) for a in survivors}
        else:
            loss["rejoined_after"] = {a["id"]: next((t - loss["t"] for peer, n, t in a.get("peer_restarts", [])
                                                     if peer == loss["agent"] and n == loss["restarted_as"]), None)
                                      for a in survivors}
    return lost


def _noticed(survivor: dict, loss: dict) -> float | None:
    """Seconds from a loss until ``survivor`` dropped the lost agent from its neighbours."""
    heard = survivor["peers_last_heard"].get(loss["agent"])
    return None if heard is None else max(0.0, heard + survivor["neighbour_timeout"] - loss["t"])


def _read(path: Path) -> dict | list | None:
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None


def collect(run_dir: Path, scenario, status: str, speed: float) -> dict:
    sc = scenario.agent
    agents = []
    for i in range(sc.agents):
        data = _read(run_dir / f"agent-uav{i}.json")
        agents.append(data if data is not None else {"id": f"uav{i}", "status": "died: no metrics written"})
    oracle = _read(run_dir / "oracle.json") or {"targets": [], "status": "missing"}
    all_targets = [t for a in agents for t in a.get("targets", [])]
    rmse, anees = pooled(all_targets)
    oracle_rmse, oracle_anees = pooled(oracle.get("targets", []))
    in_flight_rmse, _ = pooled([t for a in agents if "targets" in a
                                for t in oracle.get("in_flight", {}).get(a["id"], [])])
    tail_rmse, tail_anees = pooled(_tails(all_targets))
    oracle_tail_rmse, oracle_tail_anees = pooled(_tails(oracle.get("targets", [])))
    imm_rmse, imm_anees = pooled(oracle.get("imm_targets", []))
    tx = [a["bytes_tx"] for a in agents if "bytes_tx" in a]
    metrics = {
        "status": status,
        "agents": agents,
        "oracle": {**oracle, "rmse": oracle_rmse, "anees": oracle_anees, "tail_rmse": oracle_tail_rmse,
                   "tail_anees": oracle_tail_anees, "imm_rmse": imm_rmse, "imm_anees": imm_anees},
        "fleet": {
            "rmse": rmse,
            "anees": anees,
            "tail_rmse": tail_rmse,
            "tail_anees": tail_anees,
            "rmse_ratio_to_oracle": ratio_of(rmse, oracle_rmse),
            "rmse_ratio_to_in_flight": ratio_of(rmse, in_flight_rmse),
            "bytes_per_agent_per_s": float(np.mean(tx)) / sc.duration if tx else None,
            "targets_tracked_by_every_agent": _tracked_by_all(agents, scenario),
            "exact_share": _exact_share(agents),
        },
        "config": {**scenario.raw, "speed": speed},
        "losses": losses(run_dir, scenario, agents),
    }
    metrics["phases"] = run_phases(metrics, sc.duration)
    if "grid" in oracle:
        metrics["fleet"]["grid"] = grid_fleet(agents, oracle["grid"], sc)
    write_json(run_dir / "metrics.json", metrics)
    try:
        from mesh_sim.plots import draw_run_plots  # matplotlib only when a run is collected, not on import

        draw_run_plots(metrics, run_dir)
    except (OSError, ValueError) as err:  # a plot is a convenience; the metrics are already written
        Console(stderr=True).print(f"[yellow]plots skipped: {err}")
    if (run_dir / "recording.rrd").is_file():
        finish(run_dir / "recording.rrd", metrics)
    return metrics


def finish(recording: Path, metrics: dict) -> None:
    """The run's series, compaction and final layout in its Rerun recording (:mod:`mesh_sim.observer_series`);
    a recording that cannot be finished (e.g. cut short, without its footer) is left as it is, with a warning."""
    from mesh_sim.observer_series import finish_recording  # Rerun only for a run that recorded

    try:
        finish_recording(recording, metrics)
    except (OSError, ValueError, RuntimeError) as err:
        Console(stderr=True).print(f"[yellow]recording left unfinished: {err}")


def grid_fleet(agents: list[dict], grid: dict, sc) -> dict:
    """Fleet fire-map figures at the alarm threshold: detection, decoy rejection, localisation, KL to the
    centralized map, grid bytes per agent per second (Merino's field figures: > 95 %, > 80 %, < 1 m)."""
    threshold = sc.grid.alarm_threshold
    rows = [a_roc for a in grid["agents"].values() for a_roc in a["roc"] if a_roc["threshold"] == threshold]

    def mean(key):
        values = [r[key] for r in rows if r[key] is not None]
        return float(np.mean(values)) if values else None

    kl = [a["kl_final"] for a in grid["agents"].values() if a["kl_final"] is not None]
    located = [r["localisation_error_m"] for r in grid.get("located", {}).values()
               if r["localisation_error_m"] is not None]
    grid_bytes = [a["grid"]["grid_bytes"] for a in agents if "grid" in a]
    return {
        "threshold": threshold,
        "detection_rate": mean("detection_rate"),
        "false_alarm_rejection": mean("false_alarm_rejection"),
        "localisation_error_m": mean("localisation_error_m"),
        "reported_localisation_error_m": float(np.mean(located)) if located else None,
        "other_false_alarms": mean("other_false_alarms"),
        "kl_to_central": float(np.mean(kl)) if kl else None,
        "grid_bytes_per_agent_per_s": float(np.mean(grid_bytes)) / sc.duration if grid_bytes else None,
    }


def grid_table(metrics: dict) -> Table | None:
    """Per agent: its fire map against the truth and the centralized map, and its alarms where it reports them
    (the hand-off of ``[grid] handoff``: at their tracks) (``None`` without a grid)."""
    grid = metrics["oracle"].get("grid")
    if not grid:
        return None
    threshold = metrics["fleet"]["grid"]["threshold"]
    table = Table(title=f"fire map — alarms at p > {threshold:g}")
    for col in ("agent", "fires found", "decoys ignored", "other alarms", "loc. error [m]", "reported loc. [m]",
                "KL to central", "grid [B/s]", "grid msgs (key)"):
        table.add_column(escape(col), justify="right", overflow="fold")
    duration = metrics["config"]["duration"]
    by_id = {a["id"]: a for a in metrics["agents"]}
    for agent, g in grid["agents"].items():
        r = next(x for x in g["roc"] if x["threshold"] == threshold)
        m = by_id.get(agent, {}).get("grid", {})
        reported = grid.get("located", {}).get(agent, {}).get("localisation_error_m")
        table.add_row(agent, f"{r['detected']}/{r['fires']}", f"{r['decoys_rejected']}/{r['decoys']}",
                      str(r["other_false_alarms"]), _fmt(r["localisation_error_m"], ".2f"), _fmt(reported, ".2f"),
                      _fmt(g["kl_final"], ".1f"),
                      _fmt(m.get("grid_bytes", 0) / duration, ",.0f"),
                      f"{m.get('grid_messages', 0)} ({m.get('grid_keyframes', 0)})")
    r = next(x for x in grid["central"]["roc"] if x["threshold"] == threshold)
    table.add_row("central", f"{r['detected']}/{r['fires']}", f"{r['decoys_rejected']}/{r['decoys']}",
                  str(r["other_false_alarms"]), _fmt(r["localisation_error_m"], ".2f"), "", "0", "", "", style="dim")
    return table


def _exact_share(agents: list[dict]) -> float | None:
    """The share of received track beliefs fused exactly (the rest by intersection), over the fleet."""
    exact = sum(a.get("fusions", {}).get("exact", 0) for a in agents)
    ci = sum(a.get("fusions", {}).get("ci", 0) for a in agents)
    return exact / (exact + ci) if exact + ci else None


def _tails(targets: list[dict]) -> list[dict]:
    return [t["tail"] for t in targets if isinstance(t.get("tail"), dict)]


def _tracked_by_all(agents: list[dict], scenario) -> bool:
    ids = {t.id for t in scenario.targets}
    return all(ids <= {t["target"] for t in a.get("targets", []) if t.get("rmse") is not None} for a in agents)


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


#: Under the tracking table: what a value outside its interval means.
ANEES_LEGEND = "ANEES ↓ below its 95 % χ² interval: covariances too large; ↑ above: too small"


def anees_cell(anees: float | None, samples: int) -> str:
    """``0.31 ↓ [0.62, 1.45]``: an ANEES, its two-sided 95 % χ² interval for ``samples`` independent samples
    (:func:`mesh_sim.phases.anees_interval`) and an arrow when it lies below (↓) or above (↑) it."""
    if anees is None:
        return "-"
    lo, hi = anees_interval(samples)
    mark = " ↓" if anees < lo else " ↑" if anees > hi else ""
    return escape(f"{anees:.2f}{mark} [{lo:.2f}, {hi:.2f}]")


def summary_table(metrics: dict) -> Group:
    """The run's terminal summary, at most 80 columns wide: a tracking table (omitted when no agent tracks
    targets, e.g. the fire scenario) and a network table, each with a labelled fleet row."""
    tracking = tracking_table(metrics)
    network = network_table(metrics)
    if tracking is None:
        network.title = f"skymesh run — {metrics['status']} — network"
        return Group(network)
    return Group(tracking, network)


def tracking_table(metrics: dict) -> Table | None:
    """Per agent, the oracles and the fleet: RMSE, RMSE ÷ the oracle's, ANEES with its interval, targets
    tracked and the last first track (``None`` when no agent scored a target)."""
    agents = [a for a in metrics["agents"] if a.get("targets")]
    if not agents:
        return None
    o, f = metrics["oracle"], metrics["fleet"]
    table = Table(title=f"skymesh run — {metrics['status']} — tracking", caption_justify="left")
    for col in ("agent", "RMSE [m]", "÷ oracle", "ANEES [95 % χ²]", "targets", "first track [s]"):
        table.add_column(escape(col), justify="right", no_wrap=col.startswith("ANEES"), overflow="fold")
    for a in metrics["agents"]:
        if "targets" not in a:
            table.add_row(a["id"], a.get("status", "?"), *["-"] * 4)
            continue
        rmse, anees = pooled(a["targets"])
        firsts = [t["time_to_first_track"] for t in a["targets"] if t["time_to_first_track"] is not None]
        tracked = sum(t["rmse"] is not None for t in a["targets"])
        table.add_row(a["id"], _fmt(rmse, ".2f"), _fmt(ratio_of(rmse, o["rmse"]), ".2f"),
                      anees_cell(anees, independent_samples([a["targets"]], 0.0, math.inf)),
                      f"{tracked}/{len(a['targets'])}", _fmt(max(firsts) if firsts else None, ".1f"))
    for name, rmse_key, anees_key, targets_key in (("oracle", "rmse", "anees", "targets"),
                                                    ("oracle IMM", "imm_rmse", "imm_anees", "imm_targets")):
        if o.get(rmse_key) is not None:
            k = independent_samples([o.get(targets_key, [])], 0.0, math.inf)
            table.add_row(name, _fmt(o[rmse_key], ".2f"), _fmt(ratio_of(o[rmse_key], o["rmse"]), ".2f"),
                          anees_cell(o[anees_key], k), "", "", style="dim")
    k = independent_samples([a["targets"] for a in agents], 0.0, math.inf)
    table.add_row("fleet", _fmt(f["rmse"], ".2f"), _fmt(f["rmse_ratio_to_oracle"], ".2f"), anees_cell(f["anees"], k),
                  "all" if f["targets_tracked_by_every_agent"] else "not all", "", style="bold")
    phases = metrics.get("phases", [])
    captions = [c for c in (_in_flight(f), _orbit_caption(o.get("orbits")),
                            *map(_loss_caption, metrics.get("losses", [])),
                            *(map(caption, phases) if len(phases) > 1 else ())) if c]
    table.caption = "\n".join([ANEES_LEGEND, *captions])
    return table


def network_table(metrics: dict) -> Table:
    """Per agent and for the fleet: bytes sent per second, the share of beliefs fused exactly, radio drops,
    rejected messages and deadline misses (the fleet row: the mean rate per agent, the other counts summed)."""
    table = Table(title="network", caption_justify="left")
    for col in ("agent", "sent [B/s]", "exact", "radio drops", "rejected", "deadline misses"):
        table.add_column(escape(col), justify="right", no_wrap=col == "radio drops", overflow="fold")
    duration = metrics["config"]["duration"]
    drops: Counter = Counter()
    for a in metrics["agents"]:
        if "bytes_tx" not in a:
            table.add_row(a["id"], a.get("status", "?"), *["-"] * 4)
            continue
        drops.update(a.get("radio_drops_by_cause", {}))
        table.add_row(a["id"], f"{a['bytes_tx'] / duration:,.0f}", _fmt(a.get("exact_share"), ".0%"),
                      _drops(a.get("radio_drops_by_cause", {})), str(a["msgs_rejected"]),
                      str(a.get("deadline_misses", "-")))
    f, alive = metrics["fleet"], [a for a in metrics["agents"] if "bytes_tx" in a]
    table.add_row("fleet", _fmt(f["bytes_per_agent_per_s"], ",.0f"), _fmt(f.get("exact_share"), ".0%"), _drops(drops),
                  str(sum(a["msgs_rejected"] for a in alive)),
                  str(sum(a.get("deadline_misses", 0) for a in alive)), style="bold")
    table.caption = "fleet row: sent is the mean per agent; drops, rejections and misses are summed"
    return table


def _loss_caption(loss: dict) -> str:
    """One lost agent under the table: when, why, and how long the survivors took to notice (or to hear its
    next incarnation)."""
    if loss.get("restarted_as") is not None:
        heard = [s for s in loss["rejoined_after"].values() if s is not None]
        after = f", heard by every survivor within {max(heard):.1f} s" if len(heard) == len(loss["rejoined_after"]) \
            and heard else ""
        return f"{loss['agent']} died at t = {loss['t']:.1f} s ({loss['cause']}), restarted{after}"
    noticed = [s for s in loss["detected_after"].values() if s is not None]
    after = f"; the survivors noticed within {max(noticed):.1f} s" if noticed else ""
    return f"{loss['agent']} lost at t = {loss['t']:.1f} s ({loss['cause']}){after}"


def _orbit_caption(orbits: dict | None) -> str | None:
    """A shared orbit's outcome (``mesh_sim.orbit_watch``) under the table, when the scenario has one."""
    if orbits is None:
        return None
    radius = f"{orbits['radius_m']:g} m"
    if orbits["rendezvous_s"] is None:
        return f"shared orbit: the UAVs never were all on one target's {radius} circle"
    steady = orbits["steady_spacing_error_deg"]
    spacing = "" if steady is None else f"; spacing error {steady['median']:.0f}° (median, steady)"
    return (f"shared orbit: all on the {radius} circle at {orbits['rendezvous_s']:.1f} s, "
            f"{orbits['on_circle_share']:.0%} of the time after{spacing}")


def _in_flight(fleet: dict) -> str | None:
    """The fleet's RMSE over its in-flight oracles', under the tracking table."""
    ratio = fleet.get("rmse_ratio_to_in_flight")
    return None if ratio is None else f"fleet RMSE ÷ in-flight oracles' (what could reach each agent): {ratio:.2f}"


def _drops(by_cause: dict) -> str:
    """``12 (loss 9, rate 3)``: radio drops and their causes."""
    total = sum(by_cause.values())
    return f"{total} ({', '.join(f'{k} {v}' for k, v in sorted(by_cause.items()))})" if total else "0"
