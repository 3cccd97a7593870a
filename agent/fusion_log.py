"""What the agent's fusions were, for ``metrics.json``: counts by method, the causes of every fusion that
was not exact (:data:`fusion.channel_filter.CAUSES`), per peer how fusions went, and per peer the time the
channel spent exact (issue 11, item 6) — so a run shows whether, where and when channel filters kept the
promise of exact fusion on tree edges, lost it, and got it back.

**Channel timeline.** Each message from a peer is classed by the outcomes of the beliefs it carried: a
*fallback* when any belief fell back from exact fusion (a cause in :data:`FALLBACKS`), *exact* when none
did and at least one fused exactly (no cause: ``exact``, ``grid_exact``), and otherwise (a ci/naive
policy, a stale message, nothing fused) it leaves the timeline alone. Consecutive exact messages form an
*exact span* ``[first, last]``; a span ends at a fallback, or at a silence longer than ``silence_s`` (a
link that was down is not time spent exact). A *fallback time* is a message that fell back while the
channel was exact or before it ever was; a *return time* is the first exact message after a fallback.
``exact_s``, the sum of span lengths, counts from the first to the last exact message of each span, so a
span of one message adds nothing (it under-counts by up to one sending period per span)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

#: Causes that mean a channel lost exact fusion (the others: a ci/naive policy, a stale message).
FALLBACKS = frozenset({"not_tree_edge", "common_unknown", "ack_not_in_history", "exact_failed"})


@dataclass
class _Timeline:
    spans: list[list[float]] = field(default_factory=list)  # [first, last] exact message of each span
    fallbacks: list[float] = field(default_factory=list)
    returns: list[float] = field(default_factory=list)
    state: str | None = None  # "exact" or "fallback": the class of the last classed message

    def exact(self, t: float, silence_s: float) -> None:
        if self.state == "exact" and t - self.spans[-1][1] <= silence_s:
            self.spans[-1][1] = t
            return
        if self.state == "fallback":
            self.returns.append(t)
        self.spans.append([t, t])
        self.state = "exact"

    def fallback(self, t: float) -> None:
        if self.state != "fallback":
            self.fallbacks.append(t)
        self.state = "fallback"

    def metrics(self) -> dict:
        return {
            "first_exact_s": self.spans[0][0] if self.spans else None,
            "last_exact_s": self.spans[-1][1] if self.spans else None,
            "exact_s": sum(b - a for a, b in self.spans),
            "exact_spans_s": [list(s) for s in self.spans],
            "fallbacks_s": list(self.fallbacks),
            "returns_s": list(self.returns),
        }


class FusionLog:
    """The agent's fusion record; ``silence_s``: the silence [s] that ends an exact span (the agent passes
    twice its ``sending.max_silence``, so that a peer holding tracks on an up, lossless link never falls
    that silent; chosen here)."""

    def __init__(self, silence_s: float):
        if not silence_s > 0:
            raise ValueError(f"silence_s must be positive, got {silence_s!r}")
        self.silence_s = silence_s
        self.by_method: Counter = Counter()  # method -> beliefs fused
        self.by_cause: Counter = Counter()  # (method, cause) -> beliefs fused otherwise than exactly
        self.by_peer: Counter = Counter()  # (peer, method) -> beliefs fused
        self.first_fallback: dict[str, float] = {}  # peer -> time of its first fallback from exact
        self.timelines: dict[str, _Timeline] = {}  # peer -> when its channel was exact

    def record(self, peer: str, t: float, fused: list[tuple[str, str | None]]) -> None:
        for method, cause in fused:
            self.by_method[method] += 1
            self.by_peer[(peer, method)] += 1
            if cause is not None:
                self.by_cause[(method, cause)] += 1
                if cause in FALLBACKS:
                    self.first_fallback.setdefault(peer, t)
        if any(cause in FALLBACKS for _, cause in fused):
            self.timelines.setdefault(peer, _Timeline()).fallback(t)
        elif any(cause is None for _, cause in fused):
            self.timelines.setdefault(peer, _Timeline()).exact(t, self.silence_s)

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
            "channels": {peer: line.metrics() for peer, line in sorted(self.timelines.items())},
            "exact_share": exact / (exact + ci) if exact + ci else None,
        }
