"""``skymesh bench tasking``: every tasking benchmark of issue 13 in one run, side by side with the papers.

Runs, in turn, the parts listed in :data:`PARTS` — each also a benchmark of its own (``skymesh bench
tasking-fleet``, ...) — and prints their tables; the result holds each part's result under its name and
every goal, prefixed with the part. ``--quick`` passes on to every part (each well under a minute; the whole
quick run takes a few minutes).
"""

from __future__ import annotations

import importlib

from mesh_sim.bench import common

PARTS = ("tasking_fleet", "tasking_health", "tasking_orbit", "tasking_rendezvous", "tasking_paths", "tasking_feature",
         "tasking_standoff")


def _part(module: str):
    return importlib.import_module(f"mesh_sim.bench.{module}")


def run(quick: bool = False, repeats: int | None = None) -> dict:
    parts = {module: _part(module).run(quick=quick, repeats=repeats) for module in PARTS}
    goals = [{**goal, "name": f"{result['benchmark']}: {goal['name']}"}
             for result in parts.values() for goal in result["goals"]]
    rows = [{"part": result["benchmark"], **row} for result in parts.values() for row in result["rows"]]
    return {"benchmark": "tasking", "quick": quick, "parts": parts, "rows": rows, "goals": goals}


def report(result: dict, console=None) -> None:
    console = console or common.make_console()
    for module, part in result["parts"].items():
        _part(module).report(part, console)
    common.print_table(console, "tasking: every goal", ["goal", "target", "measured", "met"],
                       [(g["name"], g["target"], _measured(g["measured"]), common.verdict(g["met"]))
                        for g in result["goals"]])


def _measured(value) -> str:
    """A goal's measured value: numbers to 3 significant digits, a list of them joined."""
    if isinstance(value, list | tuple):
        return ", ".join(_measured(v) for v in value)
    return common.fmt(value, ".3g") if isinstance(value, float) else str(value)
