"""The tasking-rendezvous benchmark at its smallest: both variants run on the orbit scenario, the rendezvous
run is too short to meet and its goal says so, and the tables print."""

from __future__ import annotations

import io
import json

import pytest
from rich.console import Console

from mesh_sim.bench import common, tasking_rendezvous

pytestmark = pytest.mark.slow  # lockstep runs


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    return tasking_rendezvous.run(quick=True, repeats=1, durations={"orbit": 15.0, "rendezvous": 10.0},
                                  runs_dir=tmp_path_factory.mktemp("runs"))


def test_the_orbit_meets_and_the_short_rendezvous_does_not(result):
    rows = {(r["scenario"], r["variant"]): r for r in result["rows"]}
    assert set(rows) == {("orbit", "shared"), ("orbit", "one orbiter"), ("rendezvous", "shared")}
    assert rows["orbit", "shared"]["rendezvous_s"] is not None
    assert rows["orbit", "one orbiter"]["rendezvous_s"] is None  # no watch: one orbiter is no shared circle
    assert rows["rendezvous", "shared"]["rendezvous_s"] is None  # 10 s: nobody has found the walker yet
    meets = result["goals"][0]
    assert meets["measured"] == "1/2" and meets["met"] is False


def test_the_result_is_json_and_the_tables_print(result):
    json.dumps(common._finite(result))
    out = io.StringIO()
    tasking_rendezvous.report(result, Console(file=out, width=220))
    assert "shared orbits" in out.getvalue() and "goals" in out.getvalue()
