"""``traffic.png``: what each agent sent over the radio, bytes/s and messages/s per 1 s bin
(:func:`mesh_sim.run_series.traffic_series`; the bytes sum to the agent's ``bytes_tx``)."""

from __future__ import annotations

from pathlib import Path

from mesh_sim.plots.figure import agent_colour, figure, save
from mesh_sim.run_series import traffic_series


def draw(metrics: dict, folder: Path) -> Path | None:
    """Two panels sharing the time axis (``None`` when no agent recorded its traffic)."""
    series = {a["id"]: (k, traffic_series(a)) for k, a in enumerate(metrics["agents"])}
    if not any(len(s) for _, s in series.values()):
        return None
    fig, axes = figure(2, 1, width=9, height=5.5, sharex=True)
    for name, (k, s) in series.items():
        if len(s):
            axes[0, 0].plot(s[:, 0], s[:, 1], color=agent_colour(k), lw=1.0, label=name)
            axes[1, 0].plot(s[:, 0], s[:, 2], color=agent_colour(k), lw=1.0)
    axes[0, 0].set_ylabel("sent [B/s]")
    axes[1, 0].set_ylabel("sent [messages/s]")
    axes[1, 0].set_xlabel("time [s]")
    fig.legend(loc="outside right upper", fontsize="small")
    return save(fig, folder / "traffic.png")
