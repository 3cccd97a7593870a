"""A network of filters in memory, for tests and benchmarks of the fusion layer (no transport).

Nodes sit on an undirected graph; each holds a belief and a :class:`~fusion.channel_filter.ChannelFilter`.
A round of :meth:`FilterNetwork.exchange` is synchronous: every node broadcasts its belief with a
fresh sequence number and, per neighbour, the last sequence number it received from that neighbour
(the acknowledgement), its re-sync flag (:mod:`fusion.resync`) and its freshness; every message is then
lost with probability ``loss`` or fused by its receiver. Node ``i`` is named ``i``; links are known exactly
(:class:`~fusion.resync.Edge` ``TREE`` or ``LOOP``). :meth:`FilterNetwork.restart` restarts a node. A link
that returns after an outage during which its ends were joined by other links (at once or in turn) is
a new link to both ends' filters (:meth:`~fusion.channel_filter.ChannelFilter.forget`).
The real runtime (agents over Zenoh, or the lockstep bus) does the same through its transport.
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Callable, Iterable

import numpy as np

from fusion.channel_filter import ChannelFilter, Policy
from fusion.resync import Edge


def bridges(n: int, edges: Iterable[tuple[int, int]]) -> set[frozenset]:
    """The edges whose removal disconnects the graph: exactly the edges that lie on no loop.

    Tarjan's bridge-finding algorithm (1974), O(V + E): in a depth-first search, tree edge (u, v) is a
    bridge iff no vertex in v's subtree reaches u or above by a back edge, i.e. ``low[v] > disc[u]``.
    Iterative, so deep graphs do not hit Python's recursion limit; parallel edges are not bridges."""
    adjacency: dict[int, list[tuple[int, int]]] = {i: [] for i in range(n)}
    for index, (u, v) in enumerate(tuple(e) for e in edges):
        adjacency[u].append((v, index))
        adjacency[v].append((u, index))
    disc, low = [-1] * n, [0] * n
    result: set[frozenset] = set()
    clock = 0
    for root in range(n):
        if disc[root] >= 0:
            continue
        disc[root] = low[root] = clock
        clock += 1
        stack = [(root, -1, iter(adjacency[root]))]  # (vertex, index of the edge we came by, neighbours left)
        while stack:
            u, via, neighbours = stack[-1]
            for v, index in neighbours:
                if index == via:
                    continue
                if disc[v] < 0:
                    disc[v] = low[v] = clock
                    clock += 1
                    stack.append((v, index, iter(adjacency[v])))
                    break
                low[u] = min(low[u], disc[v])
            else:
                stack.pop()
                if stack:
                    parent = stack[-1][0]
                    low[parent] = min(low[parent], low[u])
                    if low[u] > disc[parent]:
                        result.add(frozenset((parent, u)))
    return result


def hop_distances(edges: Iterable, source) -> dict:
    """Breadth-first hop counts from ``source`` over undirected ``edges`` (pairs of nodes); nodes out of reach
    are absent."""
    neighbours: dict = {}
    for edge in edges:
        a, b = tuple(edge)
        neighbours.setdefault(a, set()).add(b)
        neighbours.setdefault(b, set()).add(a)
    distance, frontier = {source: 0}, deque([source])
    while frontier:
        node = frontier.popleft()
        for peer in sorted(neighbours.get(node, ())):
            if peer not in distance:
                distance[peer] = distance[node] + 1
                frontier.append(peer)
    return distance


def _connected(edges: Iterable[tuple[int, int]], a: int, b: int) -> bool:
    """Is ``b`` reachable from ``a`` over ``edges``? Over the union of the graphs seen during an outage this
    says whether information may have passed between the two ends by other paths, even paths that never
    existed all at once (a relay that met one end, then the other)."""
    return b in hop_distances(edges, a)


class FilterNetwork:
    """``n`` nodes with beliefs starting at ``prior``, linked by ``edges``, fusing with ``policy``."""

    def __init__(
        self,
        n: int,
        edges: Iterable[tuple[int, int]],
        prior,
        policy: Policy | str = Policy.HYBRID,
        loss: float = 0.0,
        seed: int = 0,
        intersect: Callable | None = None,
    ):
        if not 0.0 <= loss <= 1.0:
            raise ValueError(f"loss must be a probability, got {loss}")
        self.n = n
        self.loss = loss
        self.rng = np.random.default_rng(seed)
        self.prior, self.policy, self.intersect = prior, policy, intersect
        self.beliefs = [prior] * n
        self.filters = [self._filter(i) for i in range(n)]
        self.edges: list[tuple[int, int]] = []
        self._outages: dict[tuple[int, int], set] = {}  # a link that is down -> every link up since it went down
        self.set_edges(edges)
        for u, v in self.edges:  # links there from the start, when every node held only the prior
            self.filters[u].reset(v)
            self.filters[v].reset(u)
        self._seq = [0] * n
        self._last_received: list[dict[int, int]] = [{} for _ in range(n)]
        self.methods: Counter = Counter()

    def _filter(self, i: int) -> ChannelFilter:
        return ChannelFilter(self.prior, self.policy, self.intersect, me=i)

    def restart(self, i: int) -> None:
        """Node ``i`` restarts from the prior with fresh channel filters and sequence numbers; its
        neighbours hear it and restart their channels with it (it holds nothing of theirs)."""
        self.beliefs[i], self.filters[i] = self.prior, self._filter(i)
        self._seq[i], self._last_received[i] = 0, {}
        for k in range(self.n):
            if k != i:
                self.filters[k].reset(i)
                self._last_received[k].pop(i, None)

    def set_edges(self, edges: Iterable[tuple[int, int]]) -> None:
        """Change the topology (links appear, disappear, loops form or break)."""
        edges = sorted({tuple(sorted(e)) for e in edges})
        if any(u == v or not (0 <= u < self.n and 0 <= v < self.n) for u, v in edges):
            raise ValueError(f"edges must join two distinct nodes among 0..{self.n - 1}")
        old, new = set(self.edges), set(edges)
        for e in old - new:
            self._outages[e] = set()
        for e, seen in self._outages.items():
            seen |= new - {e}
        for u, v in new - old:  # a returning link whose ends may have exchanged information meanwhile is new
            if (u, v) in self._outages and _connected(self._outages.pop((u, v)), u, v):
                self.filters[u].forget(v)
                self.filters[v].forget(u)
        self.edges = edges
        self.tree_edges = bridges(self.n, edges)

    def neighbours(self, i: int) -> list[int]:
        return [v if u == i else u for u, v in self.edges if i in (u, v)]

    def apply(self, i: int, update: Callable) -> None:
        """Apply a local update (a function of the belief) at node ``i``."""
        self.beliefs[i] = update(self.beliefs[i])

    def advance(self, epoch) -> None:
        """Advance every node's belief to ``epoch`` (trajectory beliefs; timeless ones are unchanged)."""
        self.beliefs = [b.advanced_to(epoch) for b in self.beliefs]

    def exchange(self) -> None:
        """One synchronous round: every node sends to every neighbour, then every receiver fuses."""
        outbox = []
        for i in range(self.n):
            self._seq[i] += 1
            self.beliefs[i], flags = self.filters[i].prepare_send(self.beliefs[i])
            fresh = self.filters[i].freshness
            self.filters[i].on_send(self.beliefs[i], self._seq[i])
            for j in self.neighbours(i):
                outbox.append((j, i, self.beliefs[i], self._seq[i], self._last_received[i].get(j), flags.get(j),
                               fresh))
        for receiver, sender, belief, seq, ack, flag, fresh in sorted(outbox, key=lambda m: (m[0], m[1])):
            if self.loss and self.rng.random() < self.loss:
                self.methods["lost"] += 1
                continue
            edge = Edge.TREE if frozenset((receiver, sender)) in self.tree_edges else Edge.LOOP
            out = self.filters[receiver].on_receive(
                sender, self.beliefs[receiver], belief, ack, seq=seq, tree_edge=edge, resync=flag,
                fresh=fresh,
            )
            self.beliefs[receiver] = out.fused
            self._last_received[receiver][sender] = seq
            self.methods[out.method] += 1
