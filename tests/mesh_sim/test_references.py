"""``[references]``: which centralized filters the world runs beside the fleet (``mesh_sim.scenario.References``).

The oracle always runs; the IMM reference and the in-flight oracle (one tracker per agent) can be turned off,
as ``skymesh bench scale`` does, without changing the oracle the run's ratio is measured against."""

from __future__ import annotations

import pytest

from mesh_sim.lockstep import run_lockstep
from mesh_sim.scenario import References, load

WIDE = {"kind": "bearing", "range": 400.0, "fov_deg": 150.0}  # tracks confirmed within the short run


def _oracle(tmp_path, name, **references):
    scenario = load("default", agents=2, duration=4.0, sensor=WIDE, references=references)
    folder = tmp_path / name
    folder.mkdir()
    return run_lockstep(scenario, folder)["oracle"]


def test_references_off_leave_the_oracle_unchanged(tmp_path):
    both = _oracle(tmp_path, "both")
    neither = _oracle(tmp_path, "neither", imm=False, in_flight=False)
    assert both["targets"] and neither["targets"] == both["targets"]
    assert both["imm_targets"] and set(both["in_flight"]) == {"uav0", "uav1"}
    assert "imm_targets" not in neither and "in_flight" not in neither


def test_references_default_to_every_reference():
    assert load("default").references == References(imm=True, in_flight=True)
    assert load("default", references={"in_flight": False}).references == References(imm=True, in_flight=False)


@pytest.mark.parametrize(
    "references, match",
    [
        ({"in_flight": "no"}, "references.in_flight must be true or false"),  # a string, not a boolean
        ({"imm": 0}, "references.imm must be true or false"),  # an integer, not a boolean
        ({"inflight": False}, "unknown references settings: \\['inflight'\\]"),  # a misspelt key
        ([False], "\\[references\\] must be a table"),  # a list, not a table
    ],
)
def test_bad_references_are_refused_with_the_setting_named(references, match):
    with pytest.raises(ValueError, match=match):
        load("default", references=references)
