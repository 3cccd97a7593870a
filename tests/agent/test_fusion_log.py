"""agent.fusion_log: counts by method, causes of what was not exact, per-peer counts and first fallbacks, and
each channel's timeline (exact spans, fallback and return times, time spent exact)."""

from __future__ import annotations

import pytest

from agent.fusion_log import FusionLog

EXACT, GRID_EXACT = ("exact", None), ("grid_exact", None)
LOOP, DESYNC, FAILED = ("ci", "not_tree_edge"), ("ci", "common_unknown"), ("ci", "exact_failed")
STALE, POLICY = ("stale", "stale"), ("ci", "policy")


def test_the_log_counts_methods_causes_and_the_first_fallback_per_peer():
    log = FusionLog(silence_s=6.0)
    log.record("uav1", 1.0, [EXACT, EXACT])
    log.record("uav2", 2.0, [LOOP])
    log.record("uav1", 3.0, [FAILED, EXACT])
    log.record("uav1", 4.0, [DESYNC])
    log.record("uav2", 5.0, [GRID_EXACT, STALE])
    m = log.metrics()
    assert m["fusions"] == {"exact": 3, "ci": 3, "grid_exact": 1, "stale": 1}
    assert m["fusions_by_cause"] == {"ci": {"common_unknown": 1, "exact_failed": 1, "not_tree_edge": 1},
                                     "stale": {"stale": 1}}
    assert m["fusions_by_peer"] == {"uav1": {"ci": 2, "exact": 3}, "uav2": {"ci": 1, "grid_exact": 1, "stale": 1}}
    assert m["first_fallback_s"] == {"uav1": 3.0, "uav2": 2.0}
    assert m["exact_share"] == 0.5


def test_a_policy_without_exact_fusion_is_not_a_fallback_and_an_empty_log_has_no_share():
    log = FusionLog(silence_s=6.0)
    assert log.metrics()["exact_share"] is None
    log.record("uav1", 1.0, [POLICY, ("naive", "policy")])
    assert log.metrics()["first_fallback_s"] == {}
    assert log.metrics()["channels"] == {}  # a policy outcome leaves the timeline alone
    assert log.metrics()["exact_share"] == 0.0


def test_a_channel_timeline_gives_exact_spans_fallbacks_returns_and_time_spent_exact():
    log = FusionLog(silence_s=6.0)
    for t in (1.0, 2.0, 4.0):  # exact from 1 s to 4 s
        log.record("uav1", t, [EXACT])
    log.record("uav1", 5.0, [EXACT, DESYNC])  # one track fell back: the channel is not exact any more
    log.record("uav1", 6.0, [DESYNC])  # still fallen back: no second fallback time
    log.record("uav1", 7.0, [STALE])  # a stale message changes nothing
    log.record("uav1", 9.0, [EXACT])  # back to exact: a return
    log.record("uav1", 10.5, [EXACT])
    c = log.metrics()["channels"]["uav1"]
    assert c["exact_spans_s"] == [[1.0, 4.0], [9.0, 10.5]]
    assert c["fallbacks_s"] == [5.0] and c["returns_s"] == [9.0]
    assert (c["first_exact_s"], c["last_exact_s"]) == (1.0, 10.5)
    assert c["exact_s"] == pytest.approx(3.0 + 1.5)


def test_a_silence_longer_than_the_limit_ends_an_exact_span_without_a_fallback():
    log = FusionLog(silence_s=6.0)
    for t in (1.0, 3.0, 9.0, 20.0, 21.0):  # 3 -> 9 is 6 s (kept), 9 -> 20 is 11 s (a link that was down)
        log.record("uav2", t, [GRID_EXACT])
    c = log.metrics()["channels"]["uav2"]
    assert c["exact_spans_s"] == [[1.0, 9.0], [20.0, 21.0]]
    assert c["fallbacks_s"] == [] and c["returns_s"] == [] and c["exact_s"] == pytest.approx(9.0)


def test_a_channel_that_starts_on_intersection_records_its_first_fallback_and_its_return():
    log = FusionLog(silence_s=6.0)
    log.record("uav3", 2.0, [LOOP])
    log.record("uav3", 30.0, [EXACT])  # after any silence, a first exact message after a fallback is a return
    c = log.metrics()["channels"]["uav3"]
    assert c["fallbacks_s"] == [2.0] and c["returns_s"] == [30.0] and c["exact_spans_s"] == [[30.0, 30.0]]
    assert c["exact_s"] == 0.0


def test_the_silence_limit_must_be_positive():
    with pytest.raises(ValueError, match="silence_s must be positive"):
        FusionLog(silence_s=0.0)
