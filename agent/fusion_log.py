"""What the agent's fusions were, for ``metrics.json``: counts by method, the causes of every fusion that
was not exact (:data:`fusion.channel_filter.CAUSES`), and per peer how fusions went and when the first
fell back from exact to intersection — so a run shows whether, where and from when channel filters kept
the promise of exact fusion on tree edges."""

from __future__ import annotations

from collections import Counter

#: Causes that mean a channel lost exact fusion (the others: a ci/naive policy, a stale message).
FALLBACKS = frozenset({"not_tree_edge", "common_unknown", "ack_not_in_history", "exact_failed"})


class FusionLog:
    def __init__(self):
        self.by_method: Counter = Counter()  # method -> beliefs fused
        self.by_cause: Counter = Counter()  # (method, cause) -> beliefs fused otherwise than exactly
        self.by_peer: Counter = Counter()  # (peer, method) -> beliefs fused
        self.first_fallback: dict[str, float] = {}  # peer -> time of its first fallback from exact

    def record(self, peer: str, t: float, fused: list[tuple[str, str | None]]) -> None:
        for method, cause in fused:
            self.by_method[method] += 1
            self.by_peer[(peer, method)] += 1
            if cause is not None:
                self.by_cause[(method, cause)] += 1
                if cause in FALLBACKS:
                    self.first_fallback.setdefault(peer, t)

    def metrics(self) -> dict:
        by_cause: dict[str, dict[str, int]] = {}
        for (method, cause), n in sorted(self.by_cause.items()):
            by_cause.setdefault(method, {})[cause] = n
        by_peer: dict[str, dict[str, int]] = {}
        for (peer, method), n in sorted(self.by_peer.items()):
            by_peer.setdefault(peer, {})[method] = n
        exact, ci = self.by_method["exact"], self.by_method["ci"]
        return {
            "fusions": dict(self.by_method),
            "fusions_by_cause": by_cause,
            "fusions_by_peer": by_peer,
            "first_fallback_s": dict(sorted(self.first_fallback.items())),
            "exact_share": exact / (exact + ci) if exact + ci else None,
        }
