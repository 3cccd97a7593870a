"""``fire_maps.png``: the true fire beside the centralized map and every agent's, in a grid of square panels.

The truth panel is categorical (unburnt / burning / burnt, in its legend); the maps share one colour bar of the
cell probability ``p(fire)``. North up, east to the right, metres.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch

from mesh_sim.plots.figure import figure, save

COLS = 4  # panels per row
TRUTH_STATES = ("unburnt", "burning", "burnt")
TRUTH_COLOURS = ListedColormap(["#f2f2f2", "#e8491d", "#3b3b3b"])


def draw(maps_file: Path, folder: Path) -> Path | None:
    """The panels of ``maps_file`` (``fire_maps.npz`` of the world; ``None`` when there is none)."""
    if not maps_file.is_file():
        return None
    maps = np.load(maps_file)
    panels = [(k, maps[k]) for k in ("central", *sorted(k for k in maps.files if k.startswith("agent_")))]
    has_truth = "truth" in maps.files
    count = len(panels) + has_truth
    cols = min(COLS, count)
    rows = math.ceil(count / cols)
    fig, axes = figure(rows, cols, width=3.3 * cols + 1.2, height=3.2 * rows, sharex=True, sharey=True)
    cells = list(axes.flat)
    n0, n1, e0, e1 = maps["extent"]
    if has_truth:
        ax = cells.pop(0)
        tn0, tn1, te0, te1 = maps["truth_extent"]
        ax.imshow(maps["truth"], origin="lower", extent=(te0, te1, tn0, tn1), cmap=TRUTH_COLOURS, vmin=-0.5, vmax=2.5)
        ax.set_title("truth")
        ax.legend(handles=[Patch(facecolor=TRUTH_COLOURS(k), edgecolor="0.5", label=state)
                           for k, state in enumerate(TRUTH_STATES)], loc="lower left", fontsize="x-small")
    for ax, (name, p) in zip(cells, panels, strict=False):
        image = ax.imshow(p, origin="lower", extent=(e0, e1, n0, n1), cmap="inferno", vmin=0.0, vmax=1.0)
        ax.set_title(name.removeprefix("agent_"))
    for ax in cells[len(panels):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("east [m]")
    for ax in axes[:, 0]:
        ax.set_ylabel("north [m]")
    fig.colorbar(image, ax=axes.ravel().tolist(), shrink=0.8, label="p(fire) of the maps")
    return save(fig, folder / "fire_maps.png")
