"""A run's plots, one module per kind, each a PNG in the run's ``plots/`` folder (matplotlib, Agg backend, written
atomically): ``rmse.png`` (final RMSE per target), ``errors.png`` (position error over time against ±2σ),
``nees.png`` (NEES over time in its χ² band), ``map.png`` (truth, tracks and UAV paths, top down), ``traffic.png``
(bytes/s and messages/s per agent), ``links.png`` (the communication graph over time) and, in a fire run,
``fire_maps.png``. The data behind them is in :mod:`mesh_sim.run_series`.
"""

from __future__ import annotations

from pathlib import Path

from mesh_sim.plots import errors, fire_maps, links, nees, rmse_bars, track_map, traffic

#: The plot kinds every run draws when it has their data, in order (a fire run: the map, traffic and links).
RUN_PLOTS = (rmse_bars, errors, nees, track_map, traffic, links)


def draw_run_plots(metrics: dict, run_dir: Path) -> list[Path]:
    """Every plot of a run into ``run_dir/plots``: RMSE, error and NEES when some target was scored, the map,
    traffic and links whenever the run recorded them, the fire maps when the run saved them. Returns the files
    written."""
    folder = run_dir / "plots"
    folder.mkdir(exist_ok=True)
    written = [m.draw(metrics, folder) for m in RUN_PLOTS]
    written.append(fire_maps.draw(run_dir / "fire_maps.npz", folder))
    return [path for path in written if path is not None]
