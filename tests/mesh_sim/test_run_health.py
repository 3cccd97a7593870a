"""Honest status (issue 18, item 5): a run whose agents missed more than 1 % of their deadlines, or whose video
source failed, is "completed with warnings", one line per agent and problem (``mesh_sim.run_health``). The bad
inputs: agents' metrics with 18 of 151 deadlines missed, with 2 of 151 (just over 1 %), and a failed source."""

from __future__ import annotations

import json

from mesh_sim.run_health import WITH_WARNINGS, judge, warnings


def _metrics(*agents: dict, status: str = "completed") -> dict:
    return {"status": status, "agents": [{"id": f"uav{i}", **a} for i, a in enumerate(agents)]}


def test_more_than_one_percent_of_deadlines_missed_is_a_warning_naming_the_agent():
    metrics = _metrics({"steps": 151, "deadline_misses": 1}, {"steps": 151, "deadline_misses": 2},
                       {"steps": 151, "deadline_misses": 18})
    assert warnings(metrics) == ["uav1 missed 1.3 % of its deadlines (2 of 151 steps)",
                                 "uav2 missed 12 % of its deadlines (18 of 151 steps)"]


def test_a_failed_video_source_is_a_warning_with_its_time():
    metrics = _metrics({"steps": 10, "deadline_misses": 0, "sensor": {"video_failed": True, "video_failed_at": 3.14}})
    assert warnings(metrics) == ["uav0's video source failed at t = 3.1 s; no bearings from it since"]


def test_a_healthy_run_is_left_as_it_is(tmp_path):
    metrics = _metrics({"steps": 300, "deadline_misses": 3, "sensor": {"video_failed": False}}, {"status": "died"})
    assert judge(tmp_path, metrics) is metrics and metrics["status"] == "completed" and "warnings" not in metrics
    assert not (tmp_path / "metrics.json").exists()


def test_judging_rewrites_metrics_json_with_the_status_and_the_warnings(tmp_path):
    judged = judge(tmp_path, _metrics({"steps": 100, "deadline_misses": 50}))
    assert judged["status"] == WITH_WARNINGS == "completed with warnings"
    assert json.loads((tmp_path / "metrics.json").read_text()) == judged
    assert judged["warnings"] == ["uav0 missed 50 % of its deadlines (50 of 100 steps)"]


def test_a_run_that_did_not_complete_keeps_its_status(tmp_path):
    judged = judge(tmp_path, _metrics({"steps": 100, "deadline_misses": 50}, status="interrupted"))
    assert judged["status"] == "interrupted" and len(judged["warnings"]) == 1
