"""The scale and transport benchmarks at their smallest settings: result structure, and no process left behind.

Both start real processes (agents, world, an echo process) over a real Zenoh router; each test checks
that nothing it started is still alive afterwards (by PID, via psutil).
"""

from __future__ import annotations

import json
import math

import psutil
import pytest

from mesh_sim import launcher as scale_launcher
from mesh_sim.bench import common, scale, transport
from tests.processes import assert_no_children_left

pytestmark = pytest.mark.slow  # benchmark runs


def _positive(value) -> bool:
    return isinstance(value, int | float) and math.isfinite(value) and value > 0






def test_scale_smallest_run_structure_and_cleanup(private_tmp, printed):
    # Both sensors at N = 2 for 4 s; the geometric sensor with a wide view, so that tracks are confirmed and
    # shared within 4 s.
    wide = {"range": 400.0, "fov_deg": 150.0}
    result = scale.run(quick=True, sizes=(2,), duration=4.0, sensor_settings={"bearing": wide})
    assert result["benchmark"] == "scale"
    settings = result["settings"]
    assert settings["sensors"] == ["bearing", "camera"]
    assert settings["measured_sizes"] == {"bearing": [2], "camera": [2]}
    assert settings["sensor_tables"] == {"bearing": {"kind": "bearing", **wide}, "camera": {"kind": "camera"}}
    assert settings["references"] == {"imm": False, "in_flight": False}  # the world runs the oracle only
    rows = {row["sensor"]: row for row in result["rows"]}
    assert list(rows) == ["bearing", "camera"]
    for sensor, row in rows.items():
        assert row["n"] == 2 and row["completed"], (sensor, row["status"])
        assert row["agents_with_steps"] == 2 and row["min_agent_steps"] > 0
        assert row["steps_due"] >= row["steps"] > 0
        assert 0.0 <= row["missed_share"] <= 1.0
        for key in ("cpu_per_step_ms", "agent_loop_cores", "run_cpu_cores", "rss_mb", "wall_s", "startup_mean_s"):
            assert _positive(row[key]), (sensor, key, row[key])
        assert row["startup_mean_s"] <= row["startup_max_s"] < scale_launcher.READY_TIMEOUT_S
        assert row["memory_probed_agents"] == 2 and _positive(row["pss_mb"]) and _positive(row["uss_mb"])
        assert row["baseline_n"] == 2 and row["cpu_per_step_ms_ratio"] == pytest.approx(1.0)
        assert "latency_mean_ms_ratio" in row
    bearing = rows["bearing"]  # a camera may confirm no track within 4 s: its latency may be undefined
    assert bearing["beliefs_fused"] > 0
    assert math.isfinite(bearing["latency_mean_ms"]) and bearing["latency_mean_ms"] >= 0.0
    assert math.isfinite(bearing["latency_p95_ms"]) and bearing["latency_p95_ms"] >= 0.0
    goals = result["goals"]
    assert set(goals["per_sensor"]) == {"bearing", "camera"}
    for sensor, goal in goals["per_sensor"].items():
        row = rows[sensor]
        passing = 2 if row["meets_goal"] else None
        assert goal["largest_N_under_1pct"] == goals["largest_N_under_1pct"][sensor] == passing
        assert goal["target_N"] == scale.TARGET_N[sensor]
        # only N = 2 was measured: the target N is missed if N = 2 failed, otherwise not reached (None)
        assert goal["meets_target_N"] is (None if row["meets_goal"] else False)
        assert goal["pss_mb_at_N16"] is None and goal["pss_meets_goal"] is None  # N = 16 not measured
    json.dumps(common._finite(result))  # JSON-serialisable once non-finite floats become null
    text = printed(scale, result)
    assert "largest N" in text and "Live scale, bearing sensor" in text and "Live scale, camera sensor" in text
    assert "PSS at N = 16: not measured" in text
    assert not [p for p in private_tmp.iterdir() if p.name.startswith("skymesh-bench-scale-")], "run folders left"
    assert_no_children_left()


def test_scale_goals_per_sensor():
    """The largest N passing with every smaller size, the target N and the PSS goal at N = 16, per sensor."""
    def row(sensor, n, missed, pss=50.0):
        return {"sensor": sensor, "n": n, "completed": True, "missed_share": missed, "pss_mb": pss}

    rows = [row("bearing", 8, 0.0), row("bearing", 16, 0.001, pss=61.0), row("bearing", 32, 0.0),
            row("bearing", 40, 0.02), row("bearing", 48, 0.0),
            row("camera", 4, 0.0), row("camera", 8, 0.0, pss=math.nan)]
    goals = scale._goals(rows, ("bearing", "camera"))
    bearing, camera = goals["per_sensor"]["bearing"], goals["per_sensor"]["camera"]
    assert goals["largest_N_under_1pct"] == {"bearing": 32, "camera": 8}
    assert bearing["meets_target_N"] is False  # N = 40 missed 2 % (48 passing does not count)
    assert bearing["pss_mb_at_N16"] == 61.0 and bearing["pss_meets_goal"] is False
    assert camera["meets_target_N"] is None and camera["pss_meets_goal"] is None  # N = 16 not measured
    assert [r["meets_goal"] for r in rows] == [True, True, True, False, True, True, True]


def test_scale_rejects_bad_settings():
    with pytest.raises(ValueError):
        scale.run(quick=True, sizes=(0,))
    with pytest.raises(ValueError):
        scale.run(quick=True, sizes=(2,), duration=-1.0)
    with pytest.raises(ValueError, match="sensor must be one of"):
        scale.run(quick=True, sizes=(2,), sensor="lidar")
    with pytest.raises(ValueError, match="sensor_settings"):
        scale.run(quick=True, sizes=(2,), overrides={"sensor": {"kind": "bearing"}})
    with pytest.raises(ValueError, match="sensor kinds"):
        scale.run(quick=True, sizes=(2,), sensor_settings={"lidar": {}})
    assert_no_children_left()


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
