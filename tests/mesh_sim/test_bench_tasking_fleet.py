"""The tasking-fleet benchmark at its smallest: both planners run, every target has a row, the agreement
and the goals are well formed, and the tables print."""

from __future__ import annotations

import io
import json

import pytest
from rich.console import Console

from mesh_sim.bench import common, tasking_fleet

pytestmark = pytest.mark.slow  # lockstep runs


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    return tasking_fleet.run(quick=True, repeats=1, duration=12.0, runs_dir=tmp_path_factory.mktemp("runs"))


def test_both_planners_score_every_target(result):
    planners = {(r["planner"], r["target"]) for r in result["rows"]}
    assert planners == {(p, t) for p in ("placeholder", "assignment") for t in ("car", "parked", "walker")}
    for row in result["rows"]:
        assert row["oracle_rmse"] > 0 and row["ratio"] > 0
        assert (row["coverage"] is not None) == (row["planner"] == "assignment")


def test_agreement_and_goals_are_well_formed(result):
    (lossy,) = result["agreement"]
    assert lossy["loss"] == 0.3 and lossy["changes"] > 0 and 0 <= lossy["settled_within_window"] <= 1
    assert len(result["goals"]) == 4 and all(isinstance(g["met"], bool) for g in result["goals"])
    json.dumps(common._finite(result))
    out = io.StringIO()
    tasking_fleet.report(result, Console(file=out, width=200))
    assert "assignment agreement" in out.getvalue()
