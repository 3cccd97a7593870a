"""agent.fusion_log: counts by method, causes of what was not exact, per-peer counts and first fallbacks."""

from __future__ import annotations

from agent.fusion_log import FusionLog


def test_the_log_counts_methods_causes_and_the_first_fallback_per_peer():
    log = FusionLog()
    log.record("uav1", 1.0, [("exact", None), ("exact", None)])
    log.record("uav2", 2.0, [("ci", "not_tree_edge")])
    log.record("uav1", 3.0, [("ci", "exact_failed"), ("exact", None)])
    log.record("uav1", 4.0, [("ci", "common_unknown")])
    log.record("uav2", 5.0, [("grid_exact", None), ("stale", "stale")])
    m = log.metrics()
    assert m["fusions"] == {"exact": 3, "ci": 3, "grid_exact": 1, "stale": 1}
    assert m["fusions_by_cause"] == {"ci": {"common_unknown": 1, "exact_failed": 1, "not_tree_edge": 1},
                                     "stale": {"stale": 1}}
    assert m["fusions_by_peer"] == {"uav1": {"ci": 2, "exact": 3}, "uav2": {"ci": 1, "grid_exact": 1, "stale": 1}}
    assert m["first_fallback_s"] == {"uav1": 3.0, "uav2": 2.0}
    assert m["exact_share"] == 0.5


def test_a_policy_without_exact_fusion_is_not_a_fallback_and_an_empty_log_has_no_share():
    log = FusionLog()
    assert log.metrics()["exact_share"] is None
    log.record("uav1", 1.0, [("ci", "policy"), ("naive", "policy")])
    assert log.metrics()["first_fallback_s"] == {}
    assert log.metrics()["exact_share"] == 0.0
