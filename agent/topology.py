"""What an agent knows of the communication graph, to decide which links are tree edges.

Channel filters are exact only on tree edges: links that lie on no loop (bridges of the graph;
Merino §2.5). Each agent reports in its telemetry the peers it heard recently; from its own and its
peers' reports it rebuilds the graph and asks whether a link is a bridge. Knowledge is only trusted
when it is complete — a fresh report from every live agent — otherwise every link is treated as
possibly on a loop, and ``hybrid`` fuses by intersection. An edge counts if either end reports it
(more edges, fewer bridges: the conservative side).
"""

from __future__ import annotations

from fusion.network import bridges

NEIGHBOUR_TIMEOUT = 3.0  # s without hearing a peer before it stops being a neighbour; chosen here


class Topology:
    def __init__(self, me: str, timeout: float = NEIGHBOUR_TIMEOUT):
        self.me = me
        self.timeout = timeout
        self._heard: dict[str, float] = {}  # peer -> last time heard
        self._reports: dict[str, tuple[float, frozenset[str]]] = {}  # peer -> (time, its neighbours)

    def heard(self, peer: str, t: float) -> None:
        self._heard[peer] = max(t, self._heard.get(peer, t))

    def report(self, peer: str, t: float, neighbours) -> None:
        self._reports[peer] = (t, frozenset(str(n) for n in neighbours))

    def neighbours(self, t: float) -> list[str]:
        return sorted(p for p, last in self._heard.items() if t - last <= self.timeout)

    def is_tree_edge(self, peer: str, t: float, alive: set[str]) -> bool:
        """True if ``(me, peer)`` is a bridge of the graph known at ``t`` and that knowledge is complete."""
        agents = set(alive) | {self.me} | set(self.neighbours(t))
        fresh = {p: n for p, (when, n) in self._reports.items() if t - when <= self.timeout}
        if any(a not in fresh for a in agents - {self.me}):
            return False
        edges = {frozenset((self.me, n)) for n in self.neighbours(t)}
        for p, reported in fresh.items():
            edges |= {frozenset((p, n)) for n in reported if n != p}
        names = sorted(agents | {x for e in edges for x in e})
        index = {name: i for i, name in enumerate(names)}
        numbered = [tuple(index[x] for x in e) for e in edges]
        return frozenset((index[self.me], index[peer])) in bridges(len(names), numbered)
