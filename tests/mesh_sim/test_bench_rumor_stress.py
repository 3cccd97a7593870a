"""The rumor and stress benchmarks at their smallest settings: result structure, the effects they measure, and
no process left behind.

``rumor`` runs lockstep runs in worker processes; ``stress`` starts real agent and world processes over a real
Zenoh router. Each test checks that nothing it started is still alive afterwards (psutil, by PID).
"""

from __future__ import annotations

import math

import pytest

from mesh_sim.bench import rumor, stress
from mesh_sim.radio import compile_plan
from tests.processes import assert_no_children_left

pytestmark = pytest.mark.slow  # benchmark runs


def test_anees_interval_and_independent_samples():
    lo, hi = rumor.anees_interval(36)
    assert 0.8 < lo < 1.0 < hi < 1.25
    lo1, hi1 = rumor.anees_interval(1)
    assert lo1 < lo and hi1 > hi  # fewer samples, wider interval
    # 40 s tracked at 0.2 s steps = 200 samples -> 4 blocks of 10 s; a target seen once still counts once
    assert rumor.independent_samples({"a": 200, "b": 1, "c": 0}, 0.2) == 5


def test_a_run_whose_tracks_explode_is_stopped_and_scored_until_then(monkeypatch):
    from mesh_sim import lockstep

    agent_cls, world_cls = lockstep.Agent, lockstep.World
    monkeypatch.setattr(rumor, "DIVERGED_TRACKS", 1)  # any second track counts as an explosion
    job = {"cell": ("ring", 0.0, "naive"),
           "scenario": {"topology": "ring", "loss": 0.0, "policy": "naive", "seed": 1, "agents": 3, "duration": 6.0}}
    out = rumor._one(job)
    assert (lockstep.Agent, lockstep.World) == (agent_cls, world_cls)  # restored
    assert out["diverged_at"] is not None and out["t_end"] == out["diverged_at"] < 6.0
    assert out["crashed_at"] is None and out["error"] is None and out["max_tracks"] >= 2
    assert out["oracle_targets"] and max(out["per_target_samples"].values()) <= out["t_end"] / out["step"] + 1


def test_churn_events_are_deterministic_and_valid():
    agents = [f"uav{i}" for i in range(6)]
    events = stress.churn_events(agents, 60.0, seed=3, mean_degree=3.0)
    assert events == stress.churn_events(agents, 60.0, seed=3, mean_degree=3.0)
    gaps = [b["t"] - a["t"] for a, b in zip(events, events[1:], strict=False)]
    assert len(events) >= 10 and all(2.9 <= g <= 5.1 for g in gaps)
    kinds = {e["kind"] for e in events}
    assert {"link_down", "partition", "merge"} <= kinds
    radio = {"topology": "random", "mean_degree": 3.0, "events": events}
    plan = compile_plan(radio, agents, 3)  # raises on an event the topology cannot take
    assert len(plan["phases"]) > 1


def test_rumor_smallest_run(tmp_path, printed):
    result = rumor.run(quick=True, topologies=("ring",), losses=(0.0,), policies=("naive", "hybrid"), seeds=1,
                       duration=8.0, agents=4, workers=2, plot_dir=tmp_path / "plot")
    assert_no_children_left()
    assert result["benchmark"] == "rumor"
    assert {"settings", "environment", "rows", "goals", "plot", "diagnostics"} <= set(result)
    rows = {r["policy"]: r for r in result["rows"]}
    assert set(rows) == {"naive", "hybrid"}
    for r in rows.values():
        assert r["topology"] == "ring" and r["loss"] == 0.0 and r["seeds"] == [1]
        assert r["rmse"] > 0 and r["oracle_rmse"] > 0 and math.isfinite(r["rmse_ratio"])
        assert r["anees_lo"] < 1.0 < r["anees_hi"] and r["independent_samples"] >= 1
        assert r["radio_bytes_per_agent_s"] > 0 and r["drops_per_agent_s"].get("down", 0) > 0  # ring of 4: 2 non-edges
    # the rumor effect: naive fusion double-counts around the loop, hybrid (CI on a ring) does not
    assert rows["naive"]["anees"] > rows["hybrid"]["anees"]
    assert rows["naive"]["fusions"].get("naive", 0) > 0 and rows["hybrid"]["ci_share"] == 1.0
    goals = result["goals"]
    assert [c["topology"] for c in goals["cells"]] == ["ring"] and goals["hybrid_rmse_lossless_tree"] is None
    assert goals["pass"] == (goals["cells"][0]["rmse_pass"] and goals["cells"][0]["consistent"])
    assert (tmp_path / "plot" / "rumor.png").stat().st_size > 0
    text = printed(rumor, result)
    assert "naive" in text and "hybrid" in text and "rumor.png" in text


def test_stress_smallest_run(private_tmp, printed):
    result = stress.run(quick=True, caps=(2000,), agents=3, duration=8.0)
    assert_no_children_left()
    assert list(private_tmp.iterdir()) == []  # the run folders were removed
    assert result["benchmark"] == "stress"
    rows = result["rows"]
    assert [r["cap"] for r in rows] == [0.0, 2000.0]  # the unlimited baseline is added and comes first
    for r in rows:
        assert r["completed"], r["status"]
        assert set(r["drops"]) == {"down", "range", "loss", "rate"}
        assert r["sent_bytes_per_agent_s"] > 0 and r["delivered_bytes_per_agent_s"] > 0
        assert r["rmse"] is not None and r["rmse"] > 0 and r["anees_lo"] < r["anees_hi"]
        assert 0.0 <= r["coverage_min"] <= r["coverage_mean"] <= 1.0
    assert rows[0]["delivered_ratio"] == 1.0 and rows[0]["rmse_ratio_to_baseline"] == 1.0
    # a falling cap: the receivers' token buckets drop more
    assert rows[0]["drops"]["rate"] == 0 < rows[1]["drops"]["rate"]
    assert rows[1]["delivered_bytes_per_agent_s"] < rows[0]["delivered_bytes_per_agent_s"]
    assert {"breaks_at_cap", "holds_down_to_cap", "results"} <= set(result["goals"])
    assert result["settings"]["churn_events"]
    text = printed(stress, result)
    assert "unlimited" in text and "2 kB/s" in text
