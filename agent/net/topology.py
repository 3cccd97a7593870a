"""What an agent knows of the communication graph, to decide which links are tree edges.

Channel filters are exact only on tree edges: links that lie on no loop (bridges of the graph;
Merino §2.5). Each agent reports the peers it heard recently, and its telemetry carries every fresh
report it knows (its own and what it learnt from others), so reports spread over several hops. From
them an agent rebuilds the graph and asks whether a link is a bridge.

Knowledge is trusted only when it is complete: every agent that appears in a fresh report, as reporter
or as neighbour, has a fresh report of its own. Otherwise every link is treated as possibly on a loop,
and ``hybrid`` fuses by intersection. An edge counts if either end reports it (more edges, fewer
bridges: the conservative side). Agents cut off by a partition stop appearing in fresh reports, so a
partitioned component can still recognise its own tree edges.
"""

from __future__ import annotations

from fusion.network import bridges
from fusion.resync import Edge

NEIGHBOUR_TIMEOUT = 3.0  # s without hearing a peer before it stops being a neighbour; chosen here


def report_lifetime(timeout: float) -> float:
    """How long another agent's report stays fresh. It must outlive every listing of that agent as
    someone's neighbour (a listing lasts ``timeout`` after the agent was last heard, and the report
    itself may be one gossip hop older), or knowledge turns "incomplete" on links that never changed."""
    return 2.0 * timeout + 1.0


class Topology:
    def __init__(self, me: str, timeout: float = NEIGHBOUR_TIMEOUT):
        self.me = me
        self.timeout = timeout
        self._heard: dict[str, float] = {}  # peer -> last time heard
        self._reports: dict[str, tuple[float, frozenset[str]]] = {}  # agent -> (report time, its neighbours)
        self._cache: tuple[frozenset, frozenset] | None = None  # (known graph, its bridges): graphs change rarely

    def heard(self, peer: str, t: float) -> None:
        self._heard[peer] = max(t, self._heard.get(peer, t))

    def neighbours(self, t: float) -> list[str]:
        return sorted(p for p, last in self._heard.items() if t - last <= self.timeout)

    def learn(self, gossip) -> None:
        """Merge reports ``{agent: [report time, [neighbours]]}`` received from a peer (newest wins).
        Malformed entries are ignored: this is advisory data from the wire."""
        if not isinstance(gossip, dict):
            return
        for agent, entry in gossip.items():
            if agent == self.me or not isinstance(entry, list | tuple) or len(entry) != 2:
                continue
            when, neighbours = entry
            if isinstance(when, int | float) and isinstance(neighbours, list | tuple):
                if agent not in self._reports or when > self._reports[agent][0]:
                    self._reports[agent] = (float(when), frozenset(str(n) for n in neighbours))

    def gossip(self, t: float) -> dict:
        """Every fresh report this agent knows, its own included, for its telemetry."""
        lifetime = report_lifetime(self.timeout)
        fresh = {a: [w, sorted(n)] for a, (w, n) in self._reports.items() if t - w <= lifetime}
        fresh[self.me] = [t, self.neighbours(t)]
        return fresh

    def neighbours_of(self, agent: str, t: float) -> frozenset[str]:
        """``agent``'s neighbours by its fresh report (our own for ``self.me``; empty if none is known)."""
        if agent == self.me:
            return frozenset(self.neighbours(t))
        when, neighbours = self._reports.get(agent, (None, frozenset()))
        return neighbours if when is not None and t - when <= report_lifetime(self.timeout) else frozenset()

    def edge(self, peer: str, t: float) -> Edge:
        """What ``(me, peer)`` is in the graph known at ``t``: ``TREE`` (a bridge) or ``LOOP`` when that knowledge
        is complete, ``UNKNOWN`` when it is not."""
        lifetime = report_lifetime(self.timeout)
        reports = {a: n for a, (w, n) in self._reports.items() if t - w <= lifetime}
        reports[self.me] = frozenset(self.neighbours(t))
        seen = set(reports) | {n for ns in reports.values() for n in ns}
        if not seen <= set(reports):
            return Edge.UNKNOWN
        graph = frozenset(frozenset((a, n)) for a, ns in reports.items() for n in ns if n != a)
        if self._cache is None or self._cache[0] != graph:
            names = sorted(seen)
            index = {name: i for i, name in enumerate(names)}
            found = bridges(len(names), [tuple(index[x] for x in e) for e in graph])
            self._cache = (graph, frozenset(frozenset(names[i] for i in e) for e in found))
        return Edge.TREE if frozenset((self.me, peer)) in self._cache[1] else Edge.LOOP
