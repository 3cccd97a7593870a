"""The perception and coop-vs-single benchmarks and the detection-rate tables at their smallest settings:
well-formed results and tables."""

from __future__ import annotations

import io
import json
import math

import pytest
from rich.console import Console

from mesh_sim.bench import common, coop_vs_single, detection_rates, perception

pytestmark = pytest.mark.slow  # benchmark runs


def _positive(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value) and value > 0


def _printed(module, result) -> str:
    out = io.StringIO()
    module.report(result, Console(file=out, width=220))
    return out.getvalue()


def test_perception_smallest_run():
    result = perception.run(quick=True, repeats=1, sizes=((160, 120),), default_threads=False)
    assert result["benchmark"] == "perception"
    assert result["settings"]["sizes"] == ["160x120"] and result["settings"]["threads"] == [1]
    rows = result["rows"]
    assert [r["op"] for r in rows] == [op.key for op in perception.OPS]
    for r in rows:
        assert r["size"] == "160x120" and r["threads"] == 1
        assert _positive(r["ms"]) and _positive(r["best_ms"]) and _positive(r["ratio_to_baseline"]), r
    assert next(r for r in rows if r["op"] == "baseline")["ratio_to_baseline"] == pytest.approx(1.0)
    [step] = result["steps"]
    in_step = [r["ms"] for r in rows if r["in_step"]]
    assert step["step_ms"] == pytest.approx(sum(in_step))
    assert _positive(step["render_ms"]) and _positive(step["perception_ms"])
    assert step["agents_per_core"] == int(step["budget_ms"] // step["step_ms"]) > 0
    assert step["perception_agents_per_core"] >= step["agents_per_core"]
    assert result["goals"]["one_agent_per_core"]["pass"] is True
    ms = {r["op"]: r["ms"] for r in rows}
    assert [(r["size"], r["stage"]) for r in result["roi"]] == [("160x120", s) for s in perception.CAMERA_STAGES]
    for r in result["roi"]:  # each ROI stage against its whole-frame stage, timed in the same run
        assert r["full_ms"] == ms[f"camera_{r['stage']}_full"] and r["roi_ms"] == ms[f"camera_{r['stage']}_roi"]
        assert r["ratio"] == pytest.approx(r["roi_ms"] / r["full_ms"])
    json.dumps(common._finite(result))
    text = _printed(perception, result)
    assert "Agent step budget" in text and "agents / core" in text and "160x120" in text
    assert "whole frame vs ROI" in text and "ROI ÷ whole" in text and "camera sensor step" in text


def test_perception_rejects_bad_sizes():
    with pytest.raises(ValueError):
        perception.run(quick=True, repeats=1, sizes=())
    with pytest.raises(ValueError):
        perception.run(quick=True, repeats=1, sizes=((8, 8),))


def test_coop_vs_single_smallest_run():
    result = coop_vs_single.run(quick=True, runs=2, filter_runs=1, duration=13.0, windows=(5, 10))
    assert result["benchmark"] == "coop-vs-single"
    s = result["settings"]
    assert s["runs"] == 2 and s["filter_runs"] == 1 and s["steps"] == 130 and s["warmup_steps"] == 100
    rows = {(r["estimator"], r["scenario"]): r for r in result["rows"]}
    assert set(rows) == {(e, sc) for e in coop_vs_single.ESTIMATORS for sc in coop_vs_single.SCENARIOS}
    for r in rows.values():
        assert all(_positive(v) for v in r["std"]) and _positive(r["std_3d"]), r
        assert all(math.isfinite(v) for v in r["mean"]), r
        assert r["samples"] == r["runs"] * 30
    # the thesis's method, on the thesis's geometry: two observers beat one by about an order of magnitude
    pi = result["ratios"]["pi"]["vs_moving"]
    assert pi["std_3d"] < 0.5
    for estimator in coop_vs_single.ESTIMATORS:
        assert result["ratios"][estimator]["vs_moving"]["std_3d"] < 1.0, estimator
        assert result["ratios"][estimator]["vs_hover_3d"] < 1.0, estimator
    assert result["goals"]["two_beat_one"]["pass"] is True
    # first-order covariance (3.26) agrees with the Monte Carlo spread of the cooperative estimate
    coop = rows[("pi", "coop")]
    assert coop["predicted_std_3d"] == pytest.approx(coop["std_3d"], rel=0.25)
    assert [w["n"] for w in result["window_sweep"]] == [5, 10]
    assert result["window_sweep"][0]["std_3d"] > result["window_sweep"][1]["std_3d"]  # a longer window helps
    assert result["thesis"]["coop"]["std"] == [0.0082, 0.0083, 0.0074]
    json.dumps(common._finite(result))
    text = _printed(coop_vs_single, result)
    assert "Table 3.1" in text and "two cooperating observers" in text


def test_coop_vs_single_rejects_bad_settings():
    with pytest.raises(ValueError):
        coop_vs_single.run(quick=True, runs=2, filter_runs=3)
    with pytest.raises(ValueError):
        coop_vs_single.run(quick=True, runs=2, filter_runs=1, duration=10.0)  # nothing after the warm-up


def test_detection_rates_prints_both_tables(capsys):
    detection_rates.main(["--frames", "3", "--width", "160", "--height", "120"])
    text = capsys.readouterr().out
    assert "Target detection, 3 frames per row, 160x120" in text and "Fire segmentation (per pixel)" in text
    for condition in detection_rates.CONDITIONS:
        assert condition in text
