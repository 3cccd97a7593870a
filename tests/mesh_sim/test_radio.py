"""Compiling ``[radio]`` into the link plan (mesh_sim/radio.py): topologies, events, errors."""

import json
import tomllib
from collections import Counter

import pytest

from agent.net.link_emulator import LinkEmulator
from agent.net.link_plan import GilbertElliott, LinkParams, LinkPlan
from mesh_sim.radio import compile_plan, topology_edges

AGENTS = [f"uav{i}" for i in range(8)]


def degrees(edges, agents=AGENTS):
    deg = Counter({a: 0 for a in agents})
    for e in edges:
        for a in e:
            deg[a] += 1
    return deg


def connected(edges, agents=AGENTS):
    adj = {a: set() for a in agents}
    for a, b in (tuple(e) for e in edges):
        adj[a].add(b)
        adj[b].add(a)
    seen, todo = {agents[0]}, [agents[0]]
    while todo:
        for b in adj[todo.pop()] - seen:
            seen.add(b)
            todo.append(b)
    return seen == set(agents)


def phase_edges(plan, i, agents=AGENTS):
    edges = plan["phases"][i]["edges"]
    if edges == "all":
        return topology_edges("full", agents, 0)
    return {frozenset(e) for e in edges}


# ---- topologies ------------------------------------------------------------------------------------


def test_full():
    edges = topology_edges("full", AGENTS, 1)
    assert len(edges) == 28 and set(degrees(edges).values()) == {7}


def test_ring():
    edges = topology_edges("ring", AGENTS, 1)
    assert len(edges) == 8 and set(degrees(edges).values()) == {2} and connected(edges)
    assert frozenset(("uav7", "uav0")) in edges
    assert topology_edges("ring", ["a", "b"], 1) == {frozenset("ab")}
    assert topology_edges("ring", ["a"], 1) == set()


def test_star():
    edges = topology_edges("star", AGENTS, 1)
    deg = degrees(edges)
    assert len(edges) == 7 and deg["uav0"] == 7 and all(deg[a] == 1 for a in AGENTS[1:])
    assert degrees(topology_edges("star", AGENTS, 1, hub="uav5"))["uav5"] == 7


def test_line():
    edges = topology_edges("line", AGENTS, 1)
    deg = degrees(edges)
    assert len(edges) == 7 and connected(edges)
    assert deg["uav0"] == deg["uav7"] == 1 and all(deg[a] == 2 for a in AGENTS[1:-1])


def test_tree_is_a_random_spanning_tree():
    trees = set()
    for seed in range(30):
        edges = topology_edges("tree", AGENTS, seed)
        assert len(edges) == 7 and connected(edges)
        assert edges == topology_edges("tree", AGENTS, seed)  # from the seed
        trees.add(frozenset(edges))
    assert len(trees) > 25  # 8^6 labelled trees: seeds give different ones


def test_random_is_connected_with_requested_mean_degree():
    agents = [f"n{i}" for i in range(20)]
    for seed in range(20):
        edges = topology_edges("random", agents, seed, mean_degree=4.0)
        assert connected(edges, agents)
        assert 2 * len(edges) / len(agents) == pytest.approx(4.0, abs=0.1)
    sparse = topology_edges("random", agents, 3, mean_degree=2 * 19 / 20)  # exactly a tree
    assert len(sparse) == 19 and connected(sparse, agents)
    dense = topology_edges("random", agents, 3, mean_degree=19)
    assert len(dense) == 190
    assert topology_edges("random", agents, 1, mean_degree=4) != topology_edges("random", agents, 2, mean_degree=4)


def test_disk_has_no_fixed_edges_only_range():
    plan = compile_plan({"topology": "disk", "range": 150.0}, AGENTS, 1)
    assert plan["phases"] == [{"t": 0.0, "edges": "all"}] and plan["range"] == 150.0
    em = LinkEmulator("uav0", plan)
    assert em.admit("uav1", 1, 10, 0.0, {"uav0": [0, 0, 0], "uav1": [149, 0, 0]}).delivered
    assert em.admit("uav1", 2, 10, 0.0, {"uav0": [0, 0, 0], "uav1": [151, 0, 0]}).cause == "range"


# ---- link parameters ---------------------------------------------------------------------------------


def test_preset_and_netem_named_overrides():
    plan = compile_plan({"preset": "wifi", "delay_ms": 5.0, "jitter_ms": 1.0}, AGENTS, 1)
    params = LinkPlan.from_dict(plan).params("uav0", "uav1")
    assert params == LinkParams(loss=0.0014, delay_ms=5.0, jitter_ms=1.0, rate=7.5e6)
    assert LinkPlan.from_dict(compile_plan({}, AGENTS, 1)).default == LinkParams()


def test_gilbert_elliott_replaces_preset_loss():
    radio = {"preset": "cellular", "gilbert_elliott": {"p": 0.05, "r": 0.25, "one_minus_h": 0.9}}
    params = LinkPlan.from_dict(compile_plan(radio, AGENTS, 1)).default
    assert params.loss == 0.0 and params.ge == GilbertElliott(0.05, 0.25, 0.9, 0.0) and params.delay_ms == 100.0


def test_per_link_overrides_from_toml():
    radio = tomllib.loads(
        """
        [radio]
        preset = "wifi"
        [[radio.links]]
        src = "uav0"
        dst = "uav1"
        loss = 0.5
        [[radio.links]]
        src = "uav2"
        dst = "uav1"
        gilbert_elliott = { p = 0.1, r = 0.2 }
        """
    )["radio"]
    lp = LinkPlan.from_dict(compile_plan(radio, AGENTS, 1))
    assert lp.params("uav0", "uav1").loss == 0.5 and lp.params("uav1", "uav0").loss == 0.0014
    assert lp.params("uav2", "uav1").ge == GilbertElliott(0.1, 0.2) and lp.params("uav2", "uav1").loss == 0.0


# ---- events ------------------------------------------------------------------------------------------


def test_partition_removes_exactly_the_crossing_edges_and_merge_restores():
    radio = {
        "topology": "ring",
        "events": [
            {"t": 10.0, "kind": "partition", "groups": [["uav0", "uav1", "uav2"], ["uav3", "uav4", "uav5"]]},
            {"t": 20.0, "kind": "merge"},
        ],
    }
    plan = compile_plan(radio, AGENTS, 1)
    assert [ph["t"] for ph in plan["phases"]] == [0.0, 10.0, 20.0]
    base = topology_edges("ring", AGENTS, 1)
    group = {a: 0 for a in AGENTS[:3]} | {a: 1 for a in AGENTS[3:6]} | {a: 2 for a in AGENTS[6:]}
    crossing = {e for e in base if len({group[a] for a in e}) == 2}
    assert crossing == {frozenset(p) for p in (("uav2", "uav3"), ("uav5", "uav6"), ("uav7", "uav0"))}
    assert phase_edges(plan, 0) == base
    assert phase_edges(plan, 1) == base - crossing
    assert phase_edges(plan, 2) == base
    lp = LinkPlan.from_dict(plan)
    assert lp.edges_at(15.0) == base - crossing and lp.edges_at(25.0) == base


def test_partition_of_a_full_graph():
    plan = compile_plan({"events": [{"t": 5, "kind": "partition", "groups": [AGENTS[:4], AGENTS[4:]]}]}, AGENTS, 1)
    assert plan["phases"][0]["edges"] == "all"
    assert len(phase_edges(plan, 1)) == 2 * 6
    em = LinkEmulator("uav0", plan)
    assert em.admit("uav5", 1, 10, 4.0).delivered and em.admit("uav5", 2, 10, 5.0).cause == "down"
    assert em.admit("uav3", 1, 10, 6.0).delivered


def test_link_down_up_and_directed():
    radio = {
        "topology": "line",
        "events": [
            {"t": 1.0, "kind": "link_down", "link": ["uav3", "uav4"]},
            {"t": 2.0, "kind": "link_up", "link": ["uav4", "uav3"]},
            {"t": 3.0, "kind": "link_up", "link": ["uav0", "uav7"]},  # outside the line: added
            {"t": 4.0, "kind": "link_down", "link": ["uav1", "uav2"], "directed": True},
            {"t": 5.0, "kind": "merge"},
        ],
    }
    plan = compile_plan(radio, AGENTS, 1)
    base = topology_edges("line", AGENTS, 1)
    e34, e07 = frozenset(("uav3", "uav4")), frozenset(("uav0", "uav7"))
    assert phase_edges(plan, 1) == base - {e34}
    assert phase_edges(plan, 2) == base
    assert phase_edges(plan, 3) == base | {e07}
    lp = LinkPlan.from_dict(plan)
    assert not lp.is_up("uav1", "uav2", 4.5) and lp.is_up("uav2", "uav1", 4.5)
    assert lp.is_up("uav1", "uav2", 5.0) and lp.edges_at(5.0) == base


def test_node_loss_and_same_time_events_make_one_phase():
    radio = {
        "events": [
            {"t": 3.0, "kind": "node_loss", "node": "uav2"},
            {"t": 7.0, "kind": "link_down", "link": ["uav0", "uav1"]},
            {"t": 7.0, "kind": "link_down", "link": ["uav0", "uav3"]},
        ]
    }
    plan = compile_plan(radio, AGENTS, 1)
    assert plan["down_nodes"] == [{"t": 3.0, "node": "uav2"}]
    assert [ph["t"] for ph in plan["phases"]] == [0.0, 7.0]  # node loss changes no edge set
    assert phase_edges(plan, 1) == topology_edges("full", AGENTS, 1) - {frozenset(("uav0", "uav1")),
                                                                         frozenset(("uav0", "uav3"))}
    lp = LinkPlan.from_dict(plan)
    assert not lp.is_up("uav2", "uav0", 3.0) and lp.is_up("uav2", "uav0", 2.9)
    assert len(lp.edges_at(4.0)) == 28 - 7


def test_plan_is_json_and_deterministic():
    radio = {"topology": "random", "mean_degree": 3.0, "preset": "lossy", "range": 400.0,
             "events": [{"t": 1.0, "kind": "partition", "groups": [["uav0"]]}]}
    a, b = compile_plan(radio, AGENTS, 9), compile_plan(radio, AGENTS, 9)
    assert json.dumps(a) == json.dumps(b)
    assert LinkPlan.from_dict(json.loads(json.dumps(a))).edges_at(2.0) == {
        e for e in LinkPlan.from_dict(a).edges_at(0.0) if "uav0" not in e
    }


# ---- errors ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("radio", "message"),
    [
        ({"topolgy": "ring"}, "topolgy"),
        ({"topology": "mesh"}, "mesh"),
        ({"preset": "5g"}, "5g"),
        ({"topology": "disk"}, "range"),
        ({"topology": "random"}, "mean_degree"),
        ({"topology": "random", "mean_degree": 1.0}, "mean_degree"),
        ({"topology": "random", "mean_degree": 9.0}, "mean_degree"),
        ({"topology": "ring", "mean_degree": 3.0}, "mean_degree"),
        ({"topology": "ring", "hub": "uav0"}, "hub"),
        ({"topology": "star", "hub": "uav9"}, "uav9"),
        ({"loss": 1.5}, "loss"),
        ({"rate": -1}, "rate"),
        ({"loss": 0.1, "gilbert_elliott": {"p": 0.1, "r": 0.2}}, "one loss model"),
        ({"gilbert_elliott": {"p": 0.1}}, "gilbert_elliott"),
        ({"links": [{"src": "uav0", "dst": "uav9"}]}, r"radio\.links\[0\]: unknown agent 'uav9'"),
        ({"links": [{"src": "uav0", "dst": "uav1", "drop": 1}]}, "drop"),
        ({"links": [{"src": "uav0"}]}, r"radio\.links\[0\]: missing key\(s\) \['dst'\]"),
        ({"links": [{"src": "uav0", "dst": "uav0"}]}, r"radio\.links\[0\]: .* joins an agent to itself"),
        ({"events": [{"t": 1, "kind": "explode"}]}, "explode"),
        ({"events": [{"t": 1, "kind": "merge", "groups": []}]}, "groups"),
        ({"events": [{"kind": "merge"}]}, "missing"),
        ({"events": [{"t": -1, "kind": "merge"}]}, r"events\[0\] \(merge\)\.t: must be >= 0, got -1"),
        ({"events": [{"t": 1, "kind": "partition", "groups": [["uav0", "ghost"]]}]}, "ghost"),
        ({"events": [{"t": 1, "kind": "partition", "groups": [["uav0"], ["uav0", "uav1"]]}]}, "more than one group"),
        ({"events": [{"t": 1, "kind": "link_down", "link": ["uav0", "uav9"]}]}, "uav9"),
        ({"events": [{"t": 1, "kind": "link_down", "link": ["uav0"]}]}, "pair"),
        ({"topology": "ring", "events": [{"t": 1, "kind": "link_down", "link": ["uav0", "uav4"]}]}, "not in the ring"),
        ({"events": [{"t": 1, "kind": "node_loss", "node": "uav8"}]}, "uav8"),
        ({"events": [{"t": 1, "kind": "node_loss", "node": "uav1"}, {"t": 2, "kind": "node_loss", "node": "uav1"}]},
         r"events\[1\] \(node_loss\): node 'uav1' is lost twice"),
        ({"events": [{"t": 5, "kind": "merge"}, {"t": 4, "kind": "merge"}]}, r"events\[1\].*before the previous"),
    ],
)
def test_errors_name_the_problem(radio, message):
    with pytest.raises(ValueError, match=message):
        compile_plan(radio, AGENTS, 1)


def test_bad_agent_lists():
    with pytest.raises(ValueError, match="unique"):
        compile_plan({}, ["a", "a"], 1)
    with pytest.raises(ValueError, match="unique"):
        topology_edges("ring", ["a", "a"], 1)
