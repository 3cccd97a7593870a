"""``links.png``: the communication graph over time — one row per pair of agents, a bar while the link was up as
the agents reported it (green: both ends heard each other; orange: only one did;
:func:`mesh_sim.run_series.link_intervals`), and a dashed line at each change of the scenario's radio plan
(partitions, merges, lost nodes: ``radio_plan.phases``)."""

from __future__ import annotations

from pathlib import Path

from mesh_sim.plots.figure import figure, save
from mesh_sim.run_series import link_intervals

BOTH = "tab:green"
ONE = "tab:orange"


def draw(metrics: dict, folder: Path) -> Path | None:
    """A timeline of every pair ever linked (``None`` when no agent reported a neighbour)."""
    neighbours = (metrics["oracle"].get("traces") or {}).get("neighbours") or {}
    intervals = link_intervals(neighbours, float(metrics["config"]["duration"]))
    if not intervals:
        return None
    pairs = sorted(intervals)
    fig, axes = figure(width=9, height=1.6 + 0.3 * len(pairs))
    ax = axes[0, 0]
    for row, pair in enumerate(pairs):
        for t0, t1, both in intervals[pair]:
            ax.broken_barh([(t0, t1 - t0)], (row - 0.35, 0.7), color=BOTH if both else ONE)
    for phase in (metrics["config"].get("radio_plan") or {}).get("phases", [])[1:]:
        ax.axvline(float(phase["t"]), color="0.3", ls="--", lw=0.8)
    ax.set_yticks(range(len(pairs)), [f"{a}–{b}" for a, b in pairs])
    ax.set_xlabel("time [s]")
    ax.set_xlim(0, float(metrics["config"]["duration"]))
    ax.bar(0, 0, color=BOTH, label="both ends report the link")
    ax.bar(0, 0, color=ONE, label="one end reports it")
    ax.plot([], [], color="0.3", ls="--", lw=0.8, label="radio plan change")
    fig.legend(loc="outside lower center", ncols=3, fontsize="small")
    return save(fig, folder / "links.png")
