"""``skymesh bench mavlink`` at its smallest settings (one simulator, a few steps and echoes): a well-formed
result whose goal verdicts follow its rows, simulators that were stopped, and the tables."""

from __future__ import annotations

import math

import pytest

from mesh_sim.autopilot.streams import ONBOARD_RATES
from mesh_sim.bench import BENCHMARKS
from mesh_sim.bench import mavlink as bench
from tests.processes import assert_no_children_left

pytestmark = pytest.mark.slow  # a benchmark run with processes


@pytest.fixture(scope="module")
def result():
    return bench.run(quick=True, repeats=1)


def test_registered_under_its_name():
    assert BENCHMARKS["mavlink"].load() is bench and bench.NAME == "mavlink"


def test_response_and_bare_round_trips_were_measured(result):
    assert result["benchmark"] == "mavlink"
    s = result["settings"]
    assert s["quick"] is True and s["simulators"] == 1 and s["trials"] == 4 and s["echoes"] == 50
    response, bare = result["rows"]
    assert response["count"] == 4 and bare["count"] == 50
    assert response["lost"] == 0 and bare["lost"] == 0
    assert 0 < bare["median_ms"] < response["median_ms"] < 1000
    assert result["response_over_bare"] == pytest.approx(response["median_ms"] / bare["median_ms"])
    assert result["goals"]["response_pass"] == (response["median_ms"] <= result["response_floor_ms"] + 5.0)


def test_rates_cover_the_streams_and_the_goal_follows_them(result):
    rates = result["rates"]
    assert [r["message"] for r in rates[:-1]] == [bench.mavlink.mavlink_map[m].msgname for m in ONBOARD_RATES]
    assert rates[-1]["requested_hz"] == bench.TRIAL_LPN_RATE
    judged = [r for r in rates if r["requested_hz"] >= 1.0]
    assert result["goals"]["rates_pass"] == all(abs(r["ratio"] - 1) <= bench.RATE_TOLERANCE for r in judged)
    attitude = next(r for r in rates if r["message"] == "ATTITUDE")
    assert attitude["achieved_hz"] > 50  # requested 100 Hz: a stream that is not running would show 0


def test_cpu_was_read_from_proc_and_the_simulators_were_stopped(result):
    (cpu,) = result["cpu_per_simulator"]
    assert 0 < cpu < 1.5 and math.isfinite(cpu)
    assert result["goals"]["cpu_pass"] == (cpu < bench.CPU_GOAL)
    (counters,) = result["simulator_counters"]
    assert counters["received"]["SET_POSITION_TARGET_LOCAL_NED"] > 20  # the 20 Hz stream
    assert counters["rejected"] == {}
    assert_no_children_left()


def test_report_prints_the_tables(result, printed):
    out = printed(bench, result)
    for text in ("Setpoint response", "bare pymavlink UDP echo", "Telemetry rates", "CPU per simulator"):
        assert text in out
