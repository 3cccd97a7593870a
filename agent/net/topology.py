"""What an agent knows of the communication graph, to decide which links are tree edges.

Channel filters are exact only on tree edges: links that lie on no loop (bridges of the graph;
Merino §2.5). Each agent reports the peers it heard recently in a small ``topology`` message
(``{"reports": {agent: [report time, [neighbours]]}}``, :class:`agent.net.schemas.TopologyPayload`) and
rebuilds the graph from the reports it holds to ask whether a link is a bridge.

Traffic by need (a link-state flood, as OSPF floods its link-state advertisements, with OSPF's two timers:
a hello that keeps a neighbour and a refresh that keeps a report): an agent sends its own report

* when its neighbour set changes;
* when it has broadcast nothing for :data:`BEACON_PERIOD` — a beacon, so its neighbours go on hearing it
  (any broadcast of a belief does that too: :meth:`Topology.spoke`);
* and at least every :data:`REFRESH_PERIOD`, so its report stays fresh at every peer.

It relays a report it has just learnt only when some neighbour of its own cannot have heard it already —
from the report's agent or from the peer that passed it on — and gives a new neighbour at once every fresh report
that neighbour cannot have heard from its author (OSPF's database exchange on a new adjacency: at a partition's
merge, waiting for the far side's next refresh left knowledge incomplete, and hybrid intersecting, for up to 2 s).
On a full mesh nothing is relayed, so each agent receives one small message per peer and refresh period while the
fleet talks, one per beacon period while it is silent: messages grow linearly with the fleet, not with its square
(every agent used to put every report in its telemetry at every step, then beaconed every 0.5 s: 6.5 of the 35
messages an agent received per step with 20 agents).

Knowledge is trusted only when it is complete: every agent that appears in a fresh report, as reporter
or as neighbour, has a report of its own — fresh, or not much older than that listing (:func:`listing_slack`).
Otherwise every link is treated as possibly on a loop, and ``hybrid`` fuses by intersection. An edge counts if
either end reports it (more edges, fewer bridges: the conservative side). Agents cut off by a partition stop
appearing in fresh reports, so a partitioned component can still recognise its own tree edges.
"""

from __future__ import annotations

import math

from agent.net.wire import DecodeError
from fusion.network import bridges
from fusion.resync import Edge

NEIGHBOUR_TIMEOUT = 3.0  # s without hearing a peer before it stops being a neighbour; chosen here
#: s between an agent's own reports while its neighbours do not change; chosen here: a sixth of
#: NEIGHBOUR_TIMEOUT, so a few lost beacons do not drop a silent neighbour (at 1 s the partition scenario's
#: lossy links made neighbours flap and hybrid fall back to intersection three times as often).
BEACON_PERIOD = 0.5
#: s between an agent's own reports at most, however much else it broadcasts; chosen here: a report stays
#: fresh for report_lifetime (7 s with the default timeout), so three in a row may be lost.
REFRESH_PERIOD = 2.0


def report_lifetime(timeout: float) -> float:
    """How long another agent's report stays fresh. It must outlive every listing of that agent in a report
    its lister keeps sending (a listing lasts ``timeout`` after the agent was last heard, and the report itself
    may be one :data:`REFRESH_PERIOD` and a few relay hops older), or knowledge turns "incomplete" on links that
    never changed. A lister cut off with the agent stops sending: :func:`listing_slack` covers that case."""
    return 2.0 * timeout + 1.0


def listing_slack(timeout: float) -> float:
    """How much older an agent's own report may be than the newest report that lists it as a neighbour: it is
    listed until ``timeout`` after it was last heard, and its last report may be :data:`REFRESH_PERIOD` older
    than that (its beliefs keep it heard between refreshes)."""
    return timeout + REFRESH_PERIOD


class Topology:
    def __init__(self, me: str, timeout: float = NEIGHBOUR_TIMEOUT):
        self.me = me
        self.timeout = timeout
        self._heard: dict[str, float] = {}  # peer -> last time heard
        self._reports: dict[str, tuple[float, frozenset[str]]] = {}  # agent -> (report time, its neighbours)
        self._news: dict[str, str] = {}  # agent -> the peer its newest report came from, since our last message
        self._version = 0  # counts changes of the known graph, for the edge memo
        self._sent_mine: list[str] | None = None  # our neighbours in our last message, and when we sent it
        self._sent_at = -float("inf")
        self._spoke_at = -float("inf")  # our last broadcast of any kind the peers listen to
        self._cache: tuple | None = None  # ((version, reports in use, our neighbours), bridges): they change rarely
        self._memo: tuple | None = None  # ((t, version), bridges or None when incomplete): see edge

    def heard(self, peer: str, t: float) -> None:
        old = self._heard.get(peer)
        new = t if old is None else max(t, old)
        self._heard[peer] = new
        if self._memo is not None and new != old:  # does this change our neighbours at the memo's time?
            at = self._memo[0][0]
            if old is None or (at - old <= self.timeout) != (at - new <= self.timeout):
                self._memo = None

    def neighbours(self, t: float) -> list[str]:
        return sorted(p for p, last in self._heard.items() if t - last <= self.timeout)

    def receive(self, sender: str, reports: dict, t: float) -> None:
        """Merge the ``reports`` ``{agent: (report time, [neighbours])}`` of a topology message from
        ``sender`` (types checked by the wire's schema; newest wins); a report new to us is queued for
        relaying (:meth:`outgoing`). A report time that is not finite rejects the message (``non_finite``; an
        infinite one would never be superseded): nothing of it is kept."""
        if not all(math.isfinite(when) for when, _ in reports.values()):
            raise DecodeError("non_finite", "a topology report time is not finite")
        for agent, (when, neighbours) in reports.items():
            if agent == self.me or (agent in self._reports and when <= self._reports[agent][0]):
                continue
            known = self._reports.get(agent)
            self._reports[agent] = (float(when), frozenset(neighbours))
            self._news[agent] = sender
            lifetime = report_lifetime(self.timeout)
            if known is None or known[1] != self._reports[agent][1] or t - known[0] > lifetime:
                self._version += 1  # the graph may differ: a beacon that repeats a fresh report leaves it
            elif self._memo is not None and self._memo[0][0] - known[0] > lifetime >= self._memo[0][0] - when:
                self._memo = None  # the report was stale at the memo's time and is fresh there now

    def spoke(self, t: float) -> None:
        """This agent broadcast a message its peers listen to (a belief) at ``t``: they heard it, no beacon is
        needed for :data:`BEACON_PERIOD`."""
        self._spoke_at = max(self._spoke_at, t)

    def outgoing(self, t: float) -> dict | None:
        """The topology message due at ``t``, or ``None``: our own report when our neighbours changed, when we
        have been silent for a beacon period or when the refresh period has passed, with the reports learnt
        since our last message that some neighbour of ours cannot have heard (see the module docstring)."""
        mine = self.neighbours(t)
        relaying = {agent for agent, sender in self._news.items() if self._worth_relaying(agent, sender, mine, t)}
        relaying |= self._for_new_neighbours(set(mine) - set(self._sent_mine or ()), t)
        relay = {agent: [self._reports[agent][0], sorted(self._reports[agent][1])] for agent in sorted(relaying)}
        self._news.clear()
        silent = t - max(self._sent_at, self._spoke_at) >= BEACON_PERIOD - 1e-9
        if not relay and mine == self._sent_mine and not silent and t - self._sent_at < REFRESH_PERIOD - 1e-9:
            return None
        self._sent_mine, self._sent_at = mine, t
        return {"reports": {**relay, self.me: [t, mine]}}

    def _for_new_neighbours(self, new: set[str], t: float) -> set[str]:
        """The fresh reports a new neighbour cannot have heard from their authors (it is not one of their
        neighbours): it gets them at once, as OSPF neighbours exchange their databases on a new adjacency.
        Otherwise, at a partition's merge, an agent would wait for the far side's next refresh (up to
        :data:`REFRESH_PERIOD`) with knowledge incomplete, and hybrid would intersect meanwhile."""
        return {agent for agent, (_, theirs) in self._fresh(t).items()
                if any(n != agent and n not in theirs for n in new)}

    def _worth_relaying(self, agent: str, sender: str, mine: list[str], t: float) -> bool:
        """Does a neighbour of ours lack ``agent``'s report? Not if it is ``agent`` or ``sender`` or one of
        their neighbours: it heard the report from them."""
        covered = self.neighbours_of(agent, t) | self.neighbours_of(sender, t) | {agent, sender}
        return any(n not in covered for n in mine)

    def metrics(self) -> dict:
        """When each peer was last heard: a peer stops being a neighbour ``neighbour_timeout`` later, which is
        when this agent notices that the peer was lost (:func:`mesh_sim.results.losses`)."""
        return {"peers_last_heard": dict(sorted(self._heard.items())), "neighbour_timeout": self.timeout}

    def neighbours_of(self, agent: str, t: float) -> frozenset[str]:
        """``agent``'s neighbours by its fresh report (our own for ``self.me``; empty if none is known)."""
        if agent == self.me:
            return frozenset(self.neighbours(t))
        when, neighbours = self._reports.get(agent, (None, frozenset()))
        return neighbours if when is not None and t - when <= report_lifetime(self.timeout) else frozenset()

    def edge(self, peer: str, t: float) -> Edge:
        """What ``(me, peer)`` is in the graph known at ``t``: ``TREE`` (a bridge) or ``LOOP`` when that knowledge
        is complete, ``UNKNOWN`` when it is not. Computed once per step and state of knowledge (every message
        received in a step asks): the memo holds for its time and graph version until :meth:`heard` changes
        who our neighbours are at that time."""
        key = (t, self._version)
        if self._memo is None or self._memo[0] != key:
            self._memo = (key, self._bridges(t, frozenset(self.neighbours(t))))
        found = self._memo[1]
        if found is None:
            return Edge.UNKNOWN
        return Edge.TREE if frozenset((self.me, peer)) in found else Edge.LOOP

    def _bridges(self, t: float, mine: frozenset[str]) -> frozenset | None:
        """The bridges of the graph known at ``t``, or ``None`` when that knowledge is incomplete. The graph is
        a function of the graph version, which reports are in use (:meth:`_in_use`) and our own neighbours: it
        is rebuilt (O(N^2) for N agents) only when one of those changes, not at every step."""
        in_use = self._in_use(t, mine)
        key = (self._version, in_use, mine)
        if self._cache is None or self._cache[0] != key:
            self._cache = (key, self._bridges_of({a: self._reports[a][1] for a in in_use} | {self.me: mine}))
        return self._cache[1]

    def _in_use(self, t: float, mine: frozenset[str]) -> frozenset[str]:
        """The agents whose reports describe the graph at ``t``: the fresh ones, and an expired one while a fresh
        report (or our own neighbours) lists its agent, if it is at most :func:`listing_slack` older than the
        newest such listing. An agent's report is that much older than the last report that lists it, in the
        worst case (it is listed until ``timeout`` after it was last heard, and reports at least every
        :data:`REFRESH_PERIOD`), so its own report expires first: cut off together with a neighbour, it left
        knowledge incomplete — and hybrid intersecting on links that never changed — for up to that long (on
        ``partition``'s line, uav2 about uav0 through uav1's report, 6 s into the partition)."""
        fresh = self._fresh(t)
        listed_at = dict.fromkeys(mine, t)
        for when, theirs in fresh.values():
            for n in theirs:
                listed_at[n] = max(listed_at.get(n, when), when)
        slack = listing_slack(self.timeout)
        return frozenset(fresh.keys() | {a for a, w in listed_at.items()
                                         if a not in fresh and a in self._reports and self._reports[a][0] >= w - slack})

    def _fresh(self, t: float) -> dict[str, tuple[float, frozenset[str]]]:
        """The reports still fresh at ``t`` (:func:`report_lifetime`)."""
        lifetime = report_lifetime(self.timeout)
        return {agent: report for agent, report in self._reports.items() if t - report[0] <= lifetime}

    @staticmethod
    def _bridges_of(reports: dict[str, frozenset[str]]) -> frozenset | None:
        seen = set(reports) | {n for ns in reports.values() for n in ns}
        if not seen <= set(reports):
            return None
        graph = {frozenset((a, n)) for a, ns in reports.items() for n in ns if n != a}
        names = sorted(seen)
        index = {name: i for i, name in enumerate(names)}
        found = bridges(len(names), [tuple(index[x] for x in e) for e in graph])
        return frozenset(frozenset(names[i] for i in e) for e in found)
