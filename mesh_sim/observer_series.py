"""After a run: the recording gets the run's series, is compacted and carries its final layout.

The series are those of the run's plots (:mod:`mesh_sim.run_series`), logged as Rerun scalars on the ``sim_time``
timeline at each 1 s bin's middle, one line per agent named after it and coloured by its place in the fleet (its
live metrics take their colours in the order the agents were first heard: the same unless one started late)::

    series/error/<target>/<who>             Scalars  position RMSE of the bin (who: an agent or "oracle")
    series/error/<target>/<who>/two_sigma   Scalars  2 sqrt(mean trace(P_pos)): the estimator's own 2-sigma
    series/anees/<who>                      Scalars  ANEES of the bin (who: an agent, "fleet" or "oracle")
    series/anees/band/{low,high}            Scalars  the fleet's 95 % chi-square interval for the bin
    series/sent_bytes/<agent>               Scalars  bytes/s the agent sent
    series/sent_messages/<agent>            Scalars  messages/s the agent sent

Compaction: the observer's chunks (small, one batcher tick each: ``rerun rrd stats`` called the file ~23x larger
in chunks than needed) are merged by Rerun's optimizer (``collect(optimize=OptimizationProfile.LIVE)``, what
``rerun rrd optimize --profile live`` does), written with the series and the final blueprint
(:func:`mesh_sim.observer_blueprint.fleet_blueprint`) into a new file that then replaces the recording; the live
layouts the observer sent on the way are left out, so the file holds one.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import rerun as rr
from rerun.chunk import OptimizationProfile, RrdReader

from mesh_sim.observer_blueprint import LIVE_METRICS, ORACLE_COLOUR, PALETTE, fleet_blueprint
from mesh_sim.run_series import error_series, nees_series, scored, traffic_series

FLEET_COLOUR = (214, 39, 40)
BAND_COLOUR = (160, 160, 160)


def finish_recording(path: Path, metrics: dict) -> None:
    """Add the series of ``metrics`` to the recording at ``path``, compact it and give it its final layout."""
    reader = RrdReader(path)
    entries = reader.recordings()
    if not entries:
        raise ValueError(f"{path} holds no recording")
    store = reader.stream(store=entries[0]).collect(optimize=OptimizationProfile.LIVE)
    paths = {chunk.entity_path for chunk in store.stream()}
    agents = [a["id"] for a in metrics["agents"]]
    live = [m for m in LIVE_METRICS if any(p.startswith(f"/metrics/{m}/") for p in paths)]
    maps = any(p.startswith("/maps/") for p in paths)
    tmp = path.with_name(path.name + ".tmp")
    rec = rr.RecordingStream(entries[0].application_id, recording_id=entries[0].recording_id)
    try:
        rec.save(str(tmp))
        rr.send_chunks(store, recording=rec)
        series = log_series(rec, metrics)
        rec.send_blueprint(fleet_blueprint(agents, live, maps, series))
        rec.flush(timeout_sec=30.0)
    finally:
        rec.disconnect()
    os.replace(tmp, path)


def log_series(rec: rr.RecordingStream, metrics: dict) -> dict[str, list[str]]:
    """Log the run's series (module docstring); returns the panels they make, ``{kind: [sub-path, ...]}``."""
    colours = {a["id"]: PALETTE[k % len(PALETTE)] for k, a in enumerate(metrics["agents"])}
    colours["oracle"] = ORACLE_COLOUR
    panels: dict[str, list[str]] = {}
    by_who = scored(metrics)
    for who, by_target in by_who.items():
        for target in by_target.values():
            series = error_series(target)
            if len(series):
                base = f"series/error/{target['target']}/{who}"
                _line(rec, base, who, colours[who], series[:, 0], series[:, 1])
                _line(rec, f"{base}/two_sigma", f"{who} 2σ", colours[who], series[:, 0], 2 * series[:, 2])
                panels.setdefault("error", []).append(target["target"])
    fleet = nees_series([a.get("targets", []) for a in metrics["agents"]])
    if len(fleet):
        for who, by_target in by_who.items():
            series = nees_series([list(by_target.values())])
            if len(series):
                _line(rec, f"series/anees/{who}", who, colours[who], series[:, 0], series[:, 1])
        _line(rec, "series/anees/fleet", "fleet", FLEET_COLOUR, fleet[:, 0], fleet[:, 1])
        _line(rec, "series/anees/band/low", "95 % low", BAND_COLOUR, fleet[:, 0], fleet[:, 2])
        _line(rec, "series/anees/band/high", "95 % high", BAND_COLOUR, fleet[:, 0], fleet[:, 3])
        panels["anees"] = [""]
    for a in metrics["agents"]:
        series = traffic_series(a)
        if len(series):
            _line(rec, f"series/sent_bytes/{a['id']}", a["id"], colours[a["id"]], series[:, 0], series[:, 1])
            _line(rec, f"series/sent_messages/{a['id']}", a["id"], colours[a["id"]], series[:, 0], series[:, 2])
            panels["sent_bytes"] = panels["sent_messages"] = [""]
    return {kind: list(dict.fromkeys(subs)) for kind, subs in panels.items()}


def _line(rec: rr.RecordingStream, path: str, name: str, colour, t: np.ndarray, values: np.ndarray) -> None:
    """One named, coloured line of scalars at simulation times ``t`` (s)."""
    rec.log(path, rr.SeriesLines(colors=[colour], names=[name]), static=True)
    rec.send_columns(path, indexes=[rr.TimeColumn("sim_time", duration=t)],
                     columns=rr.Scalars.columns(scalars=np.asarray(values, float)))
