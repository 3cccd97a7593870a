"""``skymesh bench geolocation-latency``: Ross et al.'s 0.43 s GPS latency and its compensation."""

from __future__ import annotations

import json

import pytest
from rich.console import Console

from mesh_sim.bench import common
from mesh_sim.bench import geolocation_latency as bench

pytestmark = pytest.mark.slow  # benchmark runs


@pytest.fixture(scope="module")
def result():
    return bench.run(quick=True, repeats=1)


def test_latency_puts_observations_behind_and_compensation_recovers_the_baseline(result):
    rows = {r["condition"]: r for r in result["rows"]}
    assert set(rows) == {"baseline", "late", "compensated"}
    assert rows["late"]["observations"] == rows["baseline"]["observations"] > 50  # same frames, same detections
    speed = result["settings"]["airspeeds_ms"][0]
    # Ross: "the target will always appear to be behind" — by latency x ground speed (5.6 m at 13 m/s)
    assert rows["late"]["along_track_mean_m"] == pytest.approx(-bench.LATENCY_S * speed, abs=1.0)
    assert abs(rows["baseline"]["along_track_mean_m"]) < 1.0
    assert rows["compensated"]["frame_error_mean_m"] == pytest.approx(rows["baseline"]["frame_error_mean_m"], rel=0.15)
    (ratio,) = result["ratios"]
    assert ratio["frame_late_over_compensated"] >= bench.GOAL_MIN_RATIO
    assert ratio["kf_late_over_compensated"] > 1.5
    assert result["goals"]["compensation_halves_error"]["pass"]


def test_report_and_json(result, tmp_path):
    console = Console(record=True, width=200)
    bench.report(result, console)
    text = console.export_text()
    assert "Late ÷ compensated" in text and "compensated" in text and "PASS" in text
    path = common.write_json(tmp_path / "geo.json", result)
    assert json.loads(path.read_text())["benchmark"] == "geolocation-latency"
