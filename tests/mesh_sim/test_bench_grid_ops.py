"""``skymesh bench grid-ops`` at its smallest settings: a well-formed result, agreeing operations, message
sizes that follow the codec's documented behaviour, goal verdicts that follow the rows, and the tables."""

from __future__ import annotations

import json
import math

import pytest

from mesh_sim.bench import BENCHMARKS, common
from mesh_sim.bench import grid_ops as bench

pytestmark = pytest.mark.slow  # benchmark runs

KINDS = {"keyframe", "keyframe, all prior", "delta 1 %", "delta 10 %", "delta, no change"}


def _positive(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value) and value > 0


@pytest.fixture(scope="module")
def result():
    return bench.run(quick=True, repeats=1)


def test_registered_under_its_name():
    assert BENCHMARKS["grid-ops"].load() is bench and bench.NAME == "grid-ops"


def test_rows_cover_every_operation_and_size_and_agree_with_their_bounds(result):
    assert result["benchmark"] == "grid-ops"
    s = result["settings"]
    assert s["quick"] is True and s["repeats"] == 1 and s["sizes"] == [f"{n}x{n}" for n in bench.QUICK_SIZES]
    rows = result["rows"]
    assert [(r["op"], r["n"]) for r in rows] == [(op.key, n) for n in bench.QUICK_SIZES for op in bench.OPS]
    for r in rows:
        assert r["agrees"] is True, r  # each operation computed what its numpy bound computed
        assert r["cells"] == r["n"] ** 2
        for key in ("us", "best_us", "bound_us", "bound_best_us", "cells_per_s", "bound_cells_per_s", "ratio"):
            assert _positive(r[key]), (key, r)
        assert r["best_us"] <= r["us"] and r["bound_best_us"] <= r["bound_us"]
        assert r["cells_per_s"] == pytest.approx(r["cells"] / (r["us"] * 1e-6))
        assert r["bound_cells_per_s"] == pytest.approx(r["cells"] / (r["bound_us"] * 1e-6))
        assert r["ratio"] == pytest.approx(r["us"] / r["bound_us"])
        assert r["repeats"] == 1 and r["number"] >= 1
        assert r["goal"] is (r["op"] != "encode_delta_10")


def test_message_sizes_follow_the_codec(result):
    by = {(m["n"], m["layers"], m["kind"]): m for m in result["messages"]}
    assert set(by) == {(n, L, k) for n in bench.QUICK_SIZES for L in (1, 2) for k in KINDS} | {
        (n, 1, bench.STEP_KIND) for n in bench.QUICK_SIZES}
    for (n, L, kind), m in by.items():
        assert m["raw_bytes"] == 4 * L * n * n and _positive(m["bytes"])
        assert m["fits_wire"] is (m["bytes"] <= 1 << 20)
        if kind == "keyframe":
            assert m["mode"] == "key" and m["ratio_to_keyframe"] == 1.0
            assert 0.3 < m["bytes"] / m["raw_bytes"] < 1.0  # half the cells are random: compresses ~2:1
        elif kind == "keyframe, all prior":
            assert m["bytes"] < 0.01 * m["raw_bytes"]
        elif kind == "delta, no change":
            assert m["mode"] == "delta" and m["bytes"] < 100
        elif kind == bench.STEP_KIND:  # whole quanta of q max(1, |b|) in 1-2 bytes, zlib'd, vs float32 values
            assert m["mode"] == "step" and m["bytes"] < 0.75 * by[(n, L, "delta 10 %")]["bytes"]
        else:
            assert m["mode"] == "delta"
    for n in bench.QUICK_SIZES:
        for L in (1, 2):
            one, ten = by[(n, L, "delta 1 %")]["ratio_to_keyframe"], by[(n, L, "delta 10 %")]["ratio_to_keyframe"]
            assert one < bench.BYTES_GOAL and 5 * one < ten < 0.5


def test_goals_follow_the_rows(result):
    speed, delta = result["goals"]
    assert speed["name"] == "speed" and delta["name"] == "delta_bytes"
    goal_rows = [r for r in result["rows"] if r["goal"]]
    assert [(g["op"], g["size"]) for g in speed["results"]] == [(r["op"], r["size"]) for r in goal_rows]
    assert all(g["pass"] is (g["ratio"] <= bench.SPEED_GOAL) for g in speed["results"])
    assert speed["pass"] is all(g["pass"] for g in speed["results"])
    assert len(delta["results"]) == 2 * len(bench.QUICK_SIZES)
    assert delta["pass"] is True


def test_goal_verdicts_on_made_up_rows():
    rows = [{"op": "a", "size": "8x8", "ratio": 2.9, "goal": True}, {"op": "b", "size": "8x8", "ratio": 50.0,
                                                                      "goal": False}]
    messages = [{"size": "8x8", "layers": 1, "kind": "delta 1 %", "mode": "delta", "ratio_to_keyframe": 0.05}]
    speed, delta = bench._goals(rows, messages)
    assert speed["pass"] and delta["pass"] and [r["op"] for r in speed["results"]] == ["a"]
    rows[0]["ratio"] = 3.1
    messages[0]["ratio_to_keyframe"] = 0.11
    speed, delta = bench._goals(rows, messages)
    assert not speed["pass"] and not delta["pass"]
    messages[0].update(ratio_to_keyframe=0.05, mode="key")  # a keyframe is not a delta
    assert not bench._goals(rows, messages)[1]["pass"]


def test_report_prints_the_tables_and_json_round_trips(result, printed, tmp_path):
    text = printed(bench, result)
    assert "million cells per second" in text and "Bytes per grid message" in text
    for op in bench.OPS:
        assert op.label in text
    assert "512x512" in text and ("PASS" in text or "MISS" in text)
    path = common.write_json(tmp_path / "grid.json", result)
    assert json.loads(path.read_text())["benchmark"] == "grid-ops"
