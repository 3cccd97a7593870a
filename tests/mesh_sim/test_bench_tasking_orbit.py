"""Smoke test of the orbit benchmark (spec 004 reproductions): keys, finite numbers, and the report."""

from __future__ import annotations

import math

import pytest

from mesh_sim.bench import tasking_orbit

pytestmark = pytest.mark.slow  # benchmark run


def test_quick_run_is_well_formed(printed):
    result = tasking_orbit.run(quick=True, repeats=1)
    assert result["benchmark"] == tasking_orbit.NAME
    assert {r["experiment"] for r in result["rows"]} == {"E1", "E2", "E3", "E4", "E1 loss", "E2 loss"}
    lossy = [r for r in result["rows"] if r["experiment"].endswith(" loss")]
    assert sorted({r["loss"] for r in lossy}) == [0.0, *tasking_orbit.LOSSES]
    assert all(r["ratio_to_lossless"] > 0 for r in lossy)
    for row in result["rows"]:
        for key, value in row.items():
            if isinstance(value, float) and key not in (
                "sigma_a",
                "rendezvous_time_median_s",
                "rmse_m",
                "steady_state_s",
                "rmse_predicted_m",
                "nees_position",
                "ratio_to_dynamic",
                "mean_error_se",  # a standard error needs two runs
                "final_distance_mean_m",  # no run with every UAV orbiting
                "final_distance_max_m",
            ):
                assert math.isfinite(value), (key, row)
    assert result["goals"] and all({"name", "target", "measured", "met"} <= set(g) for g in result["goals"])
    assert all(isinstance(g["met"], bool) for g in result["goals"])
    text = printed(tasking_orbit, result)
    assert "E1 figure-8" in text and "Goals" in text and "kappa = 6.0" in text
    assert "skymesh EIF (centralized, same bearings)" in text
    assert "under Bernoulli message loss" in text and "man-like" in text
    eif = [r for r in result["rows"] if r["algorithm"] in (tasking_orbit.EIF_CV, tasking_orbit.EIF_DAMPED)]
    dynamic = [r for r in result["rows"] if r["algorithm"] == "dynamic" and r["experiment"] in ("E1", "E2")]
    assert len(eif) == 2 * len(dynamic) == 2 * (len(result["settings"]["ns"]) + len(result["settings"]["speeds"]))
    assert all(r["ratio_to_dynamic"] > 0 for r in eif if r["lost_runs"] == 0)
    assert not any(g["name"].startswith("skymesh") for g in result["goals"])  # informative rows only
    assert all(math.isfinite(r["rmse_m"]) for r in result["rows"] if r.get("lost_runs") == 0 and "rmse_m" in r)
