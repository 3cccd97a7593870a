"""What an agent knows of the communication graph (agent/net/topology.py).

``Topology.edge`` (TREE / LOOP / UNKNOWN) is checked against a brute-force oracle: an edge is a bridge iff
removing it leaves its two ends disconnected (breadth-first search),
on random graphs that reach the agent as gossip reports. The
completeness rule, the report lifetime, the neighbour timeout and the handling of malformed gossip are
checked on small hand-built cases.
"""

from collections import deque

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.net.topology import NEIGHBOUR_TIMEOUT, Topology, report_lifetime
from fusion.resync import Edge

ME = "a0"


def connected(edges: set[frozenset], a: str, b: str) -> bool:
    """Breadth-first search from ``a`` over undirected ``edges``."""
    seen, todo = {a}, deque([a])
    while todo:
        u = todo.popleft()
        for e in edges:
            if u in e:
                (v,) = e - {u}
                if v not in seen:
                    seen.add(v)
                    todo.append(v)
    return b in seen


def brute_force_bridge(edges: set[frozenset], a: str, b: str) -> bool:
    e = frozenset((a, b))
    return e in edges and not connected(edges - {e}, a, b)


def topology_from(reports: dict[str, list[str]], heard: list[str], t: float, timeout=NEIGHBOUR_TIMEOUT) -> Topology:
    """A :class:`Topology` for ``ME`` that heard ``heard`` at ``t`` and was told ``reports`` (all made at ``t``)."""
    topo = Topology(ME, timeout)
    for peer in heard:
        topo.heard(peer, t)
    topo.learn({a: [t, ns] for a, ns in reports.items()})
    return topo


@st.composite
def gossiped_graphs(draw):
    """A random graph over a0..a{n-1}, each edge reported by one end or both, and some agents silent (no report).

    Returns (agents, reports, heard, expected): what the other agents report, whom ME heard, and the
    expected :meth:`Topology.edge` per peer, from the stated rules (an edge counts if either end
    reports it; knowledge is complete iff everyone mentioned has a report) and the brute-force bridge test.
    """
    n = draw(st.integers(2, 8))
    agents = [f"a{i}" for i in range(n)]
    pairs = [(agents[i], agents[j]) for i in range(n) for j in range(i + 1, n)]
    edges = draw(st.lists(st.sampled_from(pairs), unique=True, max_size=len(pairs)))
    silent = set(draw(st.lists(st.sampled_from(agents[1:]), unique=True, max_size=2)))
    lists: dict[str, set[str]] = {a: set() for a in agents}
    for u, v in edges:
        by = draw(st.sampled_from(["u", "v", "both"]))
        if by in ("u", "both"):
            lists[u].add(v)
        if by in ("v", "both"):
            lists[v].add(u)
    reports = {a: sorted(lists[a]) for a in agents[1:] if a not in silent}
    heard = sorted(lists[ME])
    known = {ME: heard, **reports}
    graph = {frozenset((a, b)) for a, ns in known.items() for b in ns}
    mentioned = set(known) | {b for ns in known.values() for b in ns}
    complete = mentioned <= set(known)
    expected = {p: (Edge.TREE if brute_force_bridge(graph, ME, p) else Edge.LOOP) if complete else Edge.UNKNOWN
                for p in agents[1:]}
    return agents, reports, heard, expected


@settings(max_examples=300, deadline=None)
@given(gossiped_graphs(), gossiped_graphs())
def test_edge_matches_brute_force_bridges(first, second):
    _, reports, heard, expected = first
    topo = topology_from(reports, heard, 10.0)
    assert {p: topo.edge(p, 10.0) for p in expected} == expected
    # later, another graph: at t = 20 the first one's reports (lifetime 7 s) and neighbours (timeout 3 s)
    # have all expired, so only the second graph is known; the cached bridges must not be reused
    _, reports, heard, expected = second
    for peer in heard:
        topo.heard(peer, 20.0)
    topo.learn({a: [20.0, ns] for a, ns in reports.items()})
    assert {p: topo.edge(p, 20.0) for p in expected} == expected


def test_line_tree_edges_and_a_loop_removes_them():
    # a0 - a1 - a2: every edge is a bridge
    topo = topology_from({"a1": [ME, "a2"], "a2": ["a1"]}, ["a1"], 0.0)
    assert topo.edge("a1", 0.0) is Edge.TREE
    assert topo.edge("a2", 0.0) is Edge.LOOP  # not a neighbour of a0: not a bridge of the known graph
    # close the loop a0 - a1 - a2 - a0 (only a2 reports the new edge): no edge of a0 is a bridge
    topo.learn({"a2": [1.0, ["a1", ME]]})
    assert topo.edge("a1", 1.0) is Edge.LOOP


def test_an_agent_mentioned_without_a_report_makes_knowledge_incomplete():
    # a1 reports a neighbour a2 that never reported: a2 might close a loop, so nothing is trusted
    topo = topology_from({"a1": [ME, "a2"]}, ["a1"], 0.0)
    assert topo.edge("a1", 0.0) is Edge.UNKNOWN
    topo.learn({"a2": [0.0, ["a1"]]})
    assert topo.edge("a1", 0.0) is Edge.TREE
    # a neighbour ME hears but that has no report of its own
    topo.heard("a3", 0.0)
    assert topo.edge("a1", 0.0) is Edge.UNKNOWN


def test_report_lifetime():
    timeout = 2.0
    lifetime = report_lifetime(timeout)
    assert lifetime == 2 * timeout + 1.0
    topo = Topology(ME, timeout)
    topo.learn({"a1": [10.0, [ME]]})
    for t in (10.0, 10.0 + lifetime):
        topo.heard("a1", t)
        assert topo.edge("a1", t) is Edge.TREE
        assert "a1" in topo.gossip(t)
    t = 10.0 + lifetime + 0.01  # a1's report has expired: a1 is heard, but unknown
    topo.heard("a1", t)
    assert topo.edge("a1", t) is Edge.UNKNOWN
    assert set(topo.gossip(t)) == {ME}


def test_newest_report_wins():
    topo = Topology(ME)
    topo.learn({"a1": [5.0, [ME]]})
    topo.learn({"a1": [4.0, [ME, "a2"]]})  # older: ignored
    assert topo.gossip(5.0)["a1"] == [5.0, [ME]]
    topo.learn({"a1": [6.0, ["a2"]]})
    assert topo.gossip(6.0)["a1"] == [6.0, ["a2"]]


def test_gossip_carries_own_report_and_fresh_ones():
    topo = Topology(ME)
    topo.heard("a2", 1.0)
    topo.heard("a1", 2.0)
    topo.learn({"a1": [1.5, [ME]], "a3": [-100.0, ["a1"]]})  # a3's report is long expired
    assert topo.gossip(2.0) == {ME: [2.0, ["a1", "a2"]], "a1": [1.5, [ME]]}


# Each bad entry is newer (t = 1) than a1's good report (t = 0) and, were it accepted, would replace it or
# mention an agent a5 that never reported, making the knowledge incomplete: edge would turn UNKNOWN.
@pytest.mark.parametrize(
    "bad",
    [
        pytest.param(["a1", [1.0, [ME, "a5"]]], id="gossip is a list, not a dict"),
        pytest.param(None, id="gossip is None"),
        pytest.param("a1", id="gossip is a string"),
        pytest.param({"a1": "1.0 a0 a5"}, id="entry is a string, not [time, neighbours]"),
        pytest.param({"a1": [1.0]}, id="entry has one element"),
        pytest.param({"a1": [1.0, [ME, "a5"], "extra"]}, id="entry has three elements"),
        pytest.param({"a1": ["1.0", [ME, "a5"]]}, id="time is a string"),
        pytest.param({"a1": [None, [ME, "a5"]]}, id="time is None"),
        pytest.param({"a1": [1.0, "a5"]}, id="neighbours is a string, not a list"),
        pytest.param({"a1": [1.0, None]}, id="neighbours is None"),
        pytest.param({"a5": [1.0, {ME: 1}]}, id="neighbours is a dict"),
        pytest.param({ME: [1.0, ["a1", "a5"]]}, id="a report about me (only I know my neighbours)"),
    ],
)
def test_malformed_gossip_is_ignored(bad):
    topo = topology_from({"a1": [ME]}, ["a1"], 0.0)
    before = topo.gossip(1.0)
    topo.learn(bad)
    assert topo.gossip(1.0) == before
    assert topo.edge("a1", 1.0) is Edge.TREE


def test_malformed_entries_do_not_stop_good_ones():
    topo = Topology(ME)
    topo.heard("a1", 0.0)
    topo.learn({"a2": ["now", [ME]], "a1": [0.0, [ME]]})  # a2's time is a string; a1's entry is fine
    assert set(topo.gossip(0.0)) == {ME, "a1"}
    assert topo.edge("a1", 0.0) is Edge.TREE


def test_neighbour_timeout():
    topo = Topology(ME, timeout=3.0)
    topo.heard("a1", 10.0)
    topo.heard("a1", 8.0)  # an older stamp does not move the last-heard time back
    topo.heard("a2", 11.0)
    assert topo.neighbours(13.0) == ["a1", "a2"]
    assert topo.neighbours(14.0) == ["a2"]  # a2 heard exactly ``timeout`` ago; a1 timed out
    assert topo.neighbours(14.01) == []
    assert Topology(ME).timeout == NEIGHBOUR_TIMEOUT
