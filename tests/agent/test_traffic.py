"""An agent's traffic log: bytes by kind over the run, bytes and messages per one-second bin."""

from __future__ import annotations

from agent.traffic import TrafficLog


def test_bins_count_bytes_and_messages_per_second_and_sum_to_the_total():
    log = TrafficLog()
    for t, kind, size in ((0.0, "track", 100), (0.5, "topology", 20), (0.99, "track", 100), (2.0, "track", 50)):
        log.sent(t, kind, size)
    metrics = log.metrics()
    assert metrics["bytes_tx"] == 270 and metrics["bytes_tx_by_kind"] == {"track": 250, "topology": 20}
    assert metrics["traffic_bins"] == [[0.0, 220, 3], [2.0, 50, 1]]  # a second without a send has no bin
