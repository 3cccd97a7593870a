"""The particles benchmark at its smallest settings: a well-formed result, the thesis's numbers beside ours,
and the tables."""

from __future__ import annotations

import json
import math

import pytest

from mesh_sim.bench import BENCHMARKS, common, particles

pytestmark = pytest.mark.slow  # benchmark runs


def _positive(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value) and value > 0


@pytest.fixture(scope="module")
def result():
    return particles.run(quick=True, repeats=1, sizes=(200,), seeds=2, fleet_seeds=0)


def test_particles_is_registered():
    assert BENCHMARKS["particles"].load() is particles


def test_smallest_run_is_well_formed(result):
    assert result["benchmark"] == "particles"
    s = result["settings"]
    assert s["sizes"] == [200] and s["seeds"] == 2 and s["repeats"] == 1 and s["dim"] == 3
    assert s["fleet_seeds"] == 0 and result["fleet"] == [] and "fleet_resolved" not in result["goals"]
    rows = result["rows"]
    assert [r["op"] for r in rows] == [key for key, _, _ in particles.OPS]
    for r in rows:
        assert r["n"] == 200 and _positive(r["ms"]) and _positive(r["best_ms"]) and _positive(r["ratio_to_baseline"]), r
        if r["baseline"] is None:
            assert r["ratio_to_baseline"] == pytest.approx(1.0)
        else:
            base = next(b for b in rows if b["op"] == r["baseline"])
            assert r["ratio_to_baseline"] == pytest.approx(r["ms"] / base["ms"])
    assert [(a["n"], a["method"]) for a in result["accuracy"]] == [(200, m) for m in particles.METHODS]
    for a in result["accuracy"]:
        assert _positive(a["mean_error_sigma_rms"]) and _positive(a["std_ratio"]) and 0 < a["distinct"] <= 1, a
        assert a["mean_error_sigma_max"] >= a["mean_error_sigma_rms"] * 0.999
    json.dumps(common._finite(result))


def test_message_sizes_reproduce_the_thesis(result):
    [m] = result["messages"]
    assert m["numbers_bytes"] == 6400
    assert 6400 <= m["payload_bytes"] <= m["envelope_bytes"] <= 6700
    assert m["compressed_bytes"] < 1000 and m["compressed_k"] == particles.COMPRESSED_K
    assert result["goals"]["message_size"]["pass"] is True


def test_goals_lop_is_conservative_and_fusion_beats_the_thesis_timing(result):
    acc = {a["method"]: a for a in result["accuracy"]}
    assert acc["lop"]["std_ratio"] > 1.5 * acc["bayes"]["std_ratio"]  # the pool's spread covers both inputs
    assert result["goals"]["lop_conservative"]["pass"] is True
    speed = result["goals"]["faster_than_thesis"]
    assert [r["n"] for r in speed["results"]] == [200] and speed["results"][0]["thesis_ms"] == 1000.0
    assert set(result["goals"]) == {"message_size", "faster_than_thesis", "tree_matches_centralized",
                                    "lop_conservative"}
    assert all(isinstance(g["pass"], bool) for g in result["goals"].values())


def test_report_prints_our_numbers_beside_the_thesis(result, printed):
    text = printed(particles, result)
    for fragment in ("Milliseconds per call", "1.86 GHz Pentium", "N=200: ≈1 s, N=500: >2 s", "very fast",
                     "Tree a - b - c", "bayes-shrunk", "Message bytes", "≈6400", "PASS"):
        assert fragment in text, fragment


@pytest.mark.parametrize(("kwargs", "match"), [({"sizes": ()}, "sizes"), ({"sizes": (10,)}, "sizes"),
                                               ({"seeds": 1}, "seeds")],
                         ids=["no-sizes", "too-few-particles", "one-seed"])
def test_rejects_bad_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        particles.run(quick=True, repeats=1, **kwargs)
