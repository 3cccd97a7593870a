"""The scale and transport benchmarks at their smallest settings: result structure, and no process left behind.

Both start real processes (agents, world, an echo process) over a real Zenoh router; each test checks
that nothing it started is still alive afterwards (by PID, via psutil).
"""

from __future__ import annotations

import json
import math

import psutil
import pytest

from mesh_sim.bench import common, scale, transport
from tests.processes import assert_no_children_left

pytestmark = pytest.mark.slow  # benchmark runs


def _positive(value) -> bool:
    return isinstance(value, int | float) and math.isfinite(value) and value > 0






def test_scale_smallest_run_structure_and_cleanup(private_tmp, printed):
    # The geometric sensor with a wide view, so that tracks are confirmed and shared within 4 s.
    wide = {"sensor": {"kind": "bearing", "range": 400.0, "fov_deg": 150.0}}
    result = scale.run(quick=True, sizes=(2,), duration=4.0, overrides=wide)
    assert result["benchmark"] == "scale"
    assert result["settings"]["measured_sizes"] == [2]
    [row] = result["rows"]
    assert row["n"] == 2 and row["completed"], row["status"]
    assert row["agents_with_steps"] == 2 and row["min_agent_steps"] > 0
    assert row["steps_due"] >= row["steps"] > 0
    assert 0.0 <= row["missed_share"] <= 1.0
    for key in ("cpu_per_step_ms", "agent_loop_cores", "run_cpu_cores", "rss_mb", "wall_s"):
        assert _positive(row[key]), (key, row[key])
    assert row["beliefs_fused"] > 0
    assert row["memory_probed_agents"] == 2 and _positive(row["pss_mb"]) and _positive(row["uss_mb"])
    assert math.isfinite(row["latency_mean_ms"]) and row["latency_mean_ms"] >= 0.0
    assert math.isfinite(row["latency_p95_ms"]) and row["latency_p95_ms"] >= 0.0
    assert row["baseline_n"] == 2 and row["cpu_per_step_ms_ratio"] == pytest.approx(1.0)
    assert "latency_mean_ms_ratio" in row
    goals = result["goals"]
    assert goals["largest_N_under_1pct"] in (None, 2)
    assert goals["largest_N_under_1pct"] == (2 if row["meets_goal"] else None)
    json.dumps(common._finite(result))  # JSON-serialisable once non-finite floats become null
    text = printed(scale, result)
    assert "largest N" in text and "Live scale" in text
    assert not [p for p in private_tmp.iterdir() if p.name.startswith("skymesh-bench-scale-")], "run folders left"
    assert_no_children_left()


def test_scale_rejects_bad_settings():
    with pytest.raises(ValueError):
        scale.run(quick=True, sizes=(0,))
    with pytest.raises(ValueError):
        scale.run(quick=True, sizes=(2,), duration=-1.0)


def test_transport_smallest_run_structure_and_cleanup(printed):
    result = transport.run(quick=True, repeats=2, round_trips=200, burst=300)
    assert result["benchmark"] == "transport"
    rows = {r["path"]: r for r in result["rows"]}
    assert set(rows) == {"bare", "queue", "agent"}
    for path, row in rows.items():
        assert row["round_trips"] + row["lost"] == 200, path
        assert row["round_trips"] >= 190, (path, row["lost"])
        assert row["message_bytes"] > 4000  # one encoded trajectory track (~4.9 kB)
        for key in ("rtt_median_us", "rtt_p90_us", "rtt_p99_us", "rtt_mean_us", "one_way_median_us",
                    "throughput_msgs_s", "throughput_mb_s", "send_rate_msgs_s"):
            assert _positive(row[key]), (path, key, row[key])
        assert row["rtt_median_us"] <= row["rtt_p99_us"]
        assert row["burst_sent"] == 600 and row["burst_delivered"] > 0
        assert row["echo_rejected"] == 0
    assert rows["bare"]["message_bytes"] == rows["queue"]["message_bytes"] == rows["agent"]["message_bytes"]
    for ratios in ("ratios", "ratios_queue_over_bare", "ratios_agent_over_queue"):
        for key in ("rtt_median", "rtt_p90", "rtt_p99", "rtt_mean", "throughput"):
            assert _positive(result[ratios][key]), (ratios, key)
    assert result["goals"]["agent_over_bare"] == result["ratios"]
    assert _positive(result["codec"]["encode"]) and _positive(result["codec"]["decode"])
    json.dumps(common._finite(result))
    assert "agent ÷ bare" in printed(transport, result)
    echo = result["settings"]["echo_pid"]
    assert not psutil.pid_exists(echo) or psutil.Process(echo).status() == psutil.STATUS_ZOMBIE
    assert_no_children_left()


def test_transport_rejects_bad_settings():
    for bad in ({"round_trips": 0}, {"burst": -1}, {"repeats": 0}, {"poll_sleep": -1.0}):
        with pytest.raises(ValueError):
            transport.run(quick=True, **bad)
    assert_no_children_left()
