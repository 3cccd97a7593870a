"""``map.png``: the run from above — the targets' true paths, each agent's track estimates and each UAV's path.

East to the right, north up (NED ``n, e``), one row a second (:mod:`mesh_sim.run_traces`). Estimates that follow
a true path are tracks of that target; a cloud off every path is a false or lost track.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mesh_sim.plots.figure import agent_colour, figure, save


def draw(metrics: dict, folder: Path) -> Path | None:
    """One square panel (``None`` when the run recorded no UAV path; a run without targets, e.g. fire, draws the
    UAV paths alone)."""
    traces = metrics["oracle"].get("traces") or {}
    if not traces.get("uavs"):
        return None
    fig, axes = figure(width=8, height=7)
    ax = axes[0, 0]
    for name, rows in sorted(traces.get("truth", {}).items()):
        path = np.array(rows, float)
        ax.plot(path[:, 2], path[:, 1], color="black", lw=2.0)
        ax.annotate(name, (path[-1, 2], path[-1, 1]), fontsize="small", weight="bold",
                    xytext=(4, 4), textcoords="offset points")
    if traces.get("truth"):
        ax.plot([], [], color="black", lw=2.0, label="true target paths")
    for k, a in enumerate(metrics["agents"]):
        colour = agent_colour(k)
        uav = np.array(traces.get("uavs", {}).get(a["id"], []), float).reshape(-1, 4)
        ax.plot(uav[:, 2], uav[:, 1], color=colour, lw=0.8, ls=":", label=f"{a['id']} path")
        tracks = traces.get("tracks", {}).get(a["id"], [])
        if tracks:
            ax.scatter([r[3] for r in tracks], [r[2] for r in tracks], s=4, color=colour, alpha=0.5,
                       label=f"{a['id']} tracks")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    fig.legend(loc="outside right upper", fontsize="small")
    return save(fig, folder / "map.png")
