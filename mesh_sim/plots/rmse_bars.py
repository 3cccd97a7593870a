"""``rmse.png``: each target's position RMSE over the whole run, per agent beside the oracle's."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mesh_sim.plots.figure import figure, save
from mesh_sim.run_series import scored


def draw(metrics: dict, folder: Path) -> Path | None:
    """Grouped bars, one group per target (``None`` when no target was scored)."""
    targets = sorted({t["target"] for a in metrics["agents"] for t in a.get("targets", [])})
    if not targets:
        return None
    series = {who: {name: t["rmse"] for name, t in by_target.items()} for who, by_target in scored(metrics).items()}
    fig, axes = figure(width=7, height=4)
    ax = axes[0, 0]
    width = 0.8 / len(series)
    for k, (name, values) in enumerate(series.items()):
        ax.bar(np.arange(len(targets)) + k * width, [values.get(t) or 0.0 for t in targets], width, label=name)
    ax.set_xticks(np.arange(len(targets)) + 0.4 - width / 2, targets)
    ax.set_ylabel("position RMSE over the run [m]")
    ax.legend(fontsize="small", ncols=2)
    return save(fig, folder / "rmse.png")
