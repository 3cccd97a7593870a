"""``errors.png``: per target, each agent's and the oracle's position error over time against their own ±2σ.

Solid: the RMSE of each 1 s bin; dashed, same colour: ``2 sigma = 2 sqrt(mean trace(P_pos))``
(:func:`mesh_sim.run_series.error_series`). A consistent estimator's error stays mostly under its dashed line; an
error far under it means covariances too large, one above it too small.
"""

from __future__ import annotations

import math
from pathlib import Path

from mesh_sim.plots.figure import ORACLE_COLOUR, agent_colour, figure, plain_log_scale, save
from mesh_sim.run_series import error_series, scored


def draw(metrics: dict, folder: Path) -> Path | None:
    """One panel per target (``None`` when no target was scored)."""
    by_who = scored(metrics)
    targets = sorted({name for by_target in by_who.values() for name in by_target})
    if not targets:
        return None
    cols = min(2, len(targets))
    rows = math.ceil(len(targets) / cols)
    fig, axes = figure(rows, cols, width=6 * cols, height=3.2 * rows, sharex=True)
    for ax, name in zip(axes.flat, targets, strict=False):
        for k, (who, by_target) in enumerate(by_who.items()):
            series = error_series(by_target.get(name, {}))
            if not len(series):
                continue
            colour = ORACLE_COLOUR if who == "oracle" else agent_colour(k)
            ax.plot(series[:, 0], series[:, 1], color=colour, lw=1.2, label=f"{who} error")
            ax.plot(series[:, 0], 2 * series[:, 2], color=colour, lw=0.8, ls="--", label=f"{who} 2σ")
        ax.set_title(f"target {name}")
        ax.set_ylabel("position error [m]")
        plain_log_scale(ax)
    for ax in axes.flat[len(targets):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside right upper", fontsize="small")
    fig.suptitle("position error (solid) against the estimator's own 2σ = 2√tr(P_pos) (dashed)")
    return save(fig, folder / "errors.png")
