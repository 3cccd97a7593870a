"""The stress benchmark at its smallest settings: result structure, the effects it measures, and no process left
behind (``stress`` starts real agent and world processes over a real Zenoh router; the test checks that nothing
it started is still alive afterwards, psutil, by PID). The rumor benchmark: ``test_bench_rumor.py``.
"""

from __future__ import annotations

import pytest

from mesh_sim.bench import stress
from mesh_sim.radio import compile_plan
from tests.processes import assert_no_children_left

pytestmark = pytest.mark.slow  # benchmark runs


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


def test_stress_smallest_run(private_tmp, printed):
    """100 B/s per link: low enough to bind within the 16 KiB bucket in 10 s (an agent now receives ~1.4 kB/s
    per link: peers' tracks and topology beacons, no telemetry)."""
    result = stress.run(quick=True, caps=(100,), agents=3, duration=10.0)
    assert_no_children_left()
    assert list(private_tmp.iterdir()) == []  # the run folders were removed
    assert result["benchmark"] == "stress"
    rows = result["rows"]
    assert [r["cap"] for r in rows] == [0.0, 100.0]  # the unlimited baseline is added and comes first
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
    assert "unlimited" in text and "0.1 kB/s" in text
