"""The fire benchmark at its smallest: well-formed rows, operating curves, goals and tables."""

from __future__ import annotations

import json

import pytest

from mesh_sim.bench import common, fire

pytestmark = pytest.mark.slow  # benchmark runs


@pytest.fixture(scope="module")
def result():
    return fire.run(quick=True, seeds=1, duration=12.0, configs=("hybrid", "hybrid-keyframes"))


def test_rows_and_curves_are_well_formed(result):
    assert result["benchmark"] == "fire"
    assert [r["config"] for r in result["rows"]] == ["hybrid", "hybrid-keyframes"]
    for row in result["rows"]:
        assert row["runs"] == 1
        assert row["grid_bytes_per_agent_per_s"] > 0
        assert row["false_alarm_rejection"] is not None
    for curve in result["roc"].values():
        thresholds = [r["threshold"] for r in curve]
        assert thresholds == sorted(thresholds) and len(thresholds) == 7
    json.dumps(common._finite(result))


def test_goals_and_the_bandwidth_ratio_are_reported(result, printed):
    goals = {g["goal"]: g for g in result["goals"]}
    assert any(key.startswith("detection rate") for key in goals)
    ratio = next(g for key, g in goals.items() if key.startswith("hybrid: delta / keyframe"))
    assert 0.0 < ratio["value"] <= 1.0 + 1e-9  # the codec never sends more than a keyframe
    text = printed(fire, result)
    assert "fire scenario" in text and "operating curve" in text and "Merino" in text


def test_an_unknown_configuration_is_an_error():
    with pytest.raises(KeyError):
        fire.run(quick=True, seeds=1, duration=2.0, configs=("bogus",))
