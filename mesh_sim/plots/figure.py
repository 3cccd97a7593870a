"""What every plot module shares: matplotlib on the Agg backend (no display), one colour per agent, and an
atomic save (:func:`agent.runtime.atomic_file`: a reader never sees half a PNG)."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

from agent.runtime import atomic_file  # noqa: E402

DPI = 100
ORACLE_COLOUR = "black"


def agent_colour(index: int) -> str:
    """The ``index``-th agent's colour (matplotlib's ``tab10`` cycle)."""
    return f"C{index % 10}"


def figure(rows: int = 1, cols: int = 1, width: float = 8.0, height: float = 4.0, **kwargs):
    """A new figure and its axes array (always 2-D), ``width`` x ``height`` inches for the whole figure, laid out
    by matplotlib's constrained layout (titles, tick labels and colour bars do not overlap)."""
    return plt.subplots(rows, cols, figsize=(width, height), squeeze=False, layout="constrained", **kwargs)


def plain_log_scale(ax) -> None:
    """A logarithmic y axis labelled ``0.5, 1, 2`` rather than ``5 x 10^-1``."""
    ax.set_yscale("log")
    ax.yaxis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
    ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())


def save(fig, path: Path) -> Path:
    """Write ``fig`` to ``path`` as a PNG atomically, close it, return ``path``."""
    with atomic_file(path, "wb") as f:
        fig.savefig(f, format="png", dpi=DPI)
    plt.close(fig)
    return path
