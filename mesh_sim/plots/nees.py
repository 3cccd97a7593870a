"""``nees.png``: ANEES over time against the 95 % χ² band of a consistent estimator.

Per 1 s bin: each agent's ANEES over its targets (thin), the fleet's pooled over every agent (bold), the oracle's
(black, dashed) and the band for the fleet's independent samples in the bin (:func:`mesh_sim.run_series.nees_series`).
Below the band: covariances too large (under-confident); above: too small (over-confident).
"""

from __future__ import annotations

from pathlib import Path

from mesh_sim.plots.figure import ORACLE_COLOUR, agent_colour, figure, plain_log_scale, save
from mesh_sim.run_series import nees_series


def draw(metrics: dict, folder: Path) -> Path | None:
    """One panel, log scale (``None`` when no target was scored)."""
    agents = [a for a in metrics["agents"] if a.get("targets")]
    fleet = nees_series([a["targets"] for a in agents])
    if not len(fleet):
        return None
    fig, axes = figure(width=9, height=4)
    ax = axes[0, 0]
    ax.fill_between(fleet[:, 0], fleet[:, 2], fleet[:, 3], color="0.85", step="mid", label="95 % χ² band (fleet)")
    for k, a in enumerate(metrics["agents"]):
        series = nees_series([a.get("targets", [])])
        if len(series):
            ax.plot(series[:, 0], series[:, 1], color=agent_colour(k), lw=0.8, label=a["id"])
    ax.plot(fleet[:, 0], fleet[:, 1], color="C3", lw=2.0, label="fleet")
    oracle = nees_series([metrics["oracle"].get("targets", [])])
    if len(oracle):
        ax.plot(oracle[:, 0], oracle[:, 1], color=ORACLE_COLOUR, lw=1.2, ls="--", label="oracle")
    ax.axhline(1.0, color="0.4", lw=0.6)
    plain_log_scale(ax)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("ANEES per 1 s bin")
    ax.set_title("below the band: covariances too large; above: too small")
    fig.legend(loc="outside right upper", fontsize="small")
    return save(fig, folder / "nees.png")
