"""The feature-following benchmark in quick mode: a well-formed, JSON-serialisable result with finite numbers,
the isolation ratio computed against the not-isolated baseline, and the tables."""

from __future__ import annotations

import json
import math

import pytest

from mesh_sim.bench import common, tasking_feature

pytestmark = pytest.mark.slow  # a benchmark run


@pytest.fixture(scope="module")
def result():
    return tasking_feature.run(quick=True)


def test_quick_run_is_well_formed(result):
    assert result["benchmark"] == "tasking-feature" and result["part"] == "feature"
    assert [r["scenario"] for r in result["rows"]] == ["clean", "step, isolated", "step, not isolated"]
    for row in result["rows"]:
        for key in ("centring_mean_deg", "centring_p95_deg", "centring_mean_px", "cross_track_mean_m",
                    "cross_track_max_m", "nav_rmse_m", "in_image_fraction"):
            assert math.isfinite(row[key]) and row[key] >= 0, (row["scenario"], key)
    rows = {r["scenario"]: r for r in result["rows"]}
    ratio = rows["step, isolated"]["nav_rmse_ratio_to_not_isolated"]
    assert ratio == pytest.approx(rows["step, isolated"]["nav_rmse_m"] / rows["step, not isolated"]["nav_rmse_m"])
    assert math.isfinite(rows["step, isolated"]["detection_delay_s"])
    assert all(math.isfinite(v) for v in result["plan"].values())
    for goal in result["goals"]:
        assert set(goal) == {"name", "target", "measured", "met"} and isinstance(goal["met"], bool)
        assert math.isfinite(goal["measured"])
    json.dumps(common._finite(result))


def test_report_prints_the_tables(result, printed):
    text = printed(tasking_feature, result)
    for heading in ("Optimised flight path", "Mission: feature centring", "Goals", "step, not isolated"):
        assert heading in text
