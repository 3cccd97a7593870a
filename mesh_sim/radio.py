"""Compile a scenario's ``[radio]`` section into the agents' link plan (DESIGN.md §6).

The plan is plain data (schema in :class:`agent.net.link_plan.LinkPlan`); every agent enforces it in its own
transport. The section is checked with the plan's own checks (:mod:`agent.net.plan_checks`). A ``[radio]``
section, all keys optional::

    [radio]
    topology = "ring"          # full (default) | ring | star | line | tree | random | disk
    mean_degree = 3.0          # random only: mean node degree (connected: a random spanning tree + edges)
    hub = "uav0"               # star only: the hub (default: the first agent)
    range = 250.0              # metres; required by "disk" (no fixed edges, only range), optional otherwise
    preset = "wifi"            # ideal (default) | wifi | cellular | lossy  (agent.net.link_plan.PRESETS)
    loss = 0.01                # netem-named overrides of the preset: loss (0..1), delay_ms, jitter_ms,
    delay_ms = 5.0             #   rate (bytes/s, 0 = unlimited), burst (bytes), queue (bytes; 0 = police)
    [radio.gilbert_elliott]    # netem "loss gemodel p r 1-h 1-k"; replaces the Bernoulli loss
    p = 0.05                   #   (giving loss as well is an error)
    r = 0.25
    one_minus_h = 1.0
    one_minus_k = 0.0
    [[radio.links]]            # per directed link overrides: src, dst and any of the netem-named keys
    src = "uav0"
    dst = "uav1"
    loss = 0.2
    [[radio.events]]           # scheduled changes, times (s) non-decreasing
    t = 20.0
    kind = "partition"         # partition | merge | link_down | link_up | node_loss
    groups = [["uav0", "uav1"], ["uav2"]]   # agents in no group form one more group together

Events: ``partition`` removes every edge between different groups (until the next partition or a
merge); ``merge`` restores the base topology (ends the partition and undoes link_down/link_up);
``link_down`` / ``link_up`` take ``link = [a, b]`` and remove/restore that edge (``link_up`` of a pair
outside the base topology adds it); with ``directed = true`` only the link a → b goes down or up;
``node_loss`` takes ``node`` and loses that agent for the rest of the run. Events at the same time
apply in file order and make one phase. Random topologies are drawn from the scenario seed.
"""

from __future__ import annotations

import random
from dataclasses import fields
from itertools import combinations

from agent.net.link_plan import PRESETS, GilbertElliott, LinkParams, LinkPlan
from agent.net.plan_checks import AgentNames, check_keys, check_number, lose_node

TOPOLOGIES = ("full", "ring", "star", "line", "tree", "random", "disk")
PARAM_KEYS = tuple(f.name for f in fields(LinkParams) if f.name != "ge")  # [radio] spells ge gilbert_elliott
RADIO_KEYS = frozenset(
    {"topology", "preset", "range", "mean_degree", "hub", "gilbert_elliott", "links", "events", *PARAM_KEYS}
)
EVENT_KEYS = {
    "partition": frozenset({"groups"}),
    "merge": frozenset(),
    "link_down": frozenset({"link", "directed"}),
    "link_up": frozenset({"link", "directed"}),
    "node_loss": frozenset({"node"}),
}
EVENT_REQUIRED = {"partition": ("groups",), "link_down": ("link",), "link_up": ("link",), "node_loss": ("node",)}


def _edge(a: str, b: str) -> frozenset:
    return frozenset((a, b))


def _prufer_tree(agents: list[str], rng: random.Random) -> set[frozenset]:
    """A uniformly random labelled spanning tree (decoded from a random Prüfer sequence)."""
    n = len(agents)
    if n < 2:
        return set()
    if n == 2:
        return {_edge(*agents)}
    seq = [rng.randrange(n) for _ in range(n - 2)]
    degree = [1] * n
    for i in seq:
        degree[i] += 1
    edges = set()
    for i in seq:
        leaf = min(j for j in range(n) if degree[j] == 1)
        edges.add(_edge(agents[leaf], agents[i]))
        degree[leaf] -= 1
        degree[i] -= 1
    u, v = (j for j in range(n) if degree[j] == 1)
    edges.add(_edge(agents[u], agents[v]))
    return edges


def topology_edges(
    kind: str, agents: list[str], seed: int, mean_degree: float | None = None, hub: str | None = None
) -> set[frozenset]:
    """The undirected edges of a scripted topology over ``agents`` (in their given order).

    full/disk: every pair (disk is then limited by range at run time); ring: a cycle (n edges for
    n >= 3); star: ``hub`` (default the first agent) to every other; line: a path; tree: a uniformly
    random spanning tree drawn from ``seed``; random: a random spanning tree plus uniformly chosen extra
    edges up to round(mean_degree · n / 2) edges, so the graph is always connected.
    """
    if kind not in TOPOLOGIES:
        raise ValueError(f"radio.topology: unknown topology {kind!r}; known: {list(TOPOLOGIES)}")
    agents = list(agents)
    names = AgentNames("radio", agents)
    n = len(agents)
    if mean_degree is not None and kind != "random":
        raise ValueError(f"radio.mean_degree: only applies to topology = \"random\", not {kind!r}")
    if hub is not None and kind != "star":
        raise ValueError(f"radio.hub: only applies to topology = \"star\", not {kind!r}")
    rng = random.Random(f"skymesh.radio.{kind}:{int(seed)}")
    if kind in ("full", "disk"):
        return {_edge(a, b) for a, b in combinations(agents, 2)}
    if kind == "ring":
        if n < 3:
            return {_edge(a, b) for a, b in zip(agents, agents[1:], strict=False)}
        return {_edge(agents[i], agents[(i + 1) % n]) for i in range(n)}
    if kind == "line":
        return {_edge(a, b) for a, b in zip(agents, agents[1:], strict=False)}
    if kind == "star":
        centre = agents[0] if hub is None else names.agent(hub, "radio.hub")
        return {_edge(centre, a) for a in agents if a != centre}
    if kind == "tree":
        return _prufer_tree(agents, rng)
    # random
    if mean_degree is None:
        raise ValueError("radio.mean_degree: required by topology = \"random\"")
    mean_degree = check_number("radio.mean_degree", mean_degree)
    m = round(mean_degree * n / 2)
    lo, hi = n - 1, n * (n - 1) // 2
    if not lo <= m <= hi:
        raise ValueError(
            f"radio.mean_degree: {mean_degree:g} gives {m} edges for {n} agents; a connected simple graph has "
            f"{lo}..{hi} (mean degree {2 * lo / n:.3g}..{n - 1})"
        )
    edges = _prufer_tree(agents, rng)
    others = [_edge(a, b) for a, b in combinations(agents, 2) if _edge(a, b) not in edges]
    edges |= set(rng.sample(others, m - len(edges)))
    return edges


def _params(radio: dict) -> dict:
    preset = radio.get("preset", "ideal")
    if preset not in PRESETS:
        raise ValueError(f"radio.preset: unknown preset {preset!r}; known: {sorted(PRESETS)}")
    d = PRESETS[preset].to_dict()
    for k in PARAM_KEYS:
        if k in radio:
            d[k] = radio[k]
    ge = radio.get("gilbert_elliott")
    if ge is not None:
        d["ge"] = GilbertElliott.from_dict(ge, "radio.gilbert_elliott").to_dict()
        if "loss" not in radio:
            d["loss"] = 0.0  # the Gilbert–Elliott model replaces the preset's Bernoulli loss
    return LinkParams.from_dict(d, "radio").to_dict()


class _State:
    """The edge set while events are replayed."""

    def __init__(self, agents: list[str], base: set[frozenset]):
        self.agents = agents
        self.base = base
        self.removed: set[frozenset] = set()
        self.extra: set[frozenset] = set()
        self.cut: set[tuple[str, str]] = set()
        self.group: dict[str, int] | None = None

    def edges(self) -> set[frozenset]:
        edges = (self.base - self.removed) | self.extra
        if self.group is not None:
            edges = {e for e in edges if len({self.group[a] for a in e}) == 1}
        return edges

    def phase(self, t: float) -> dict:
        edges = self.edges()
        every = len(edges) == len(self.agents) * (len(self.agents) - 1) // 2
        out = {"t": t, "edges": "all" if every else sorted(sorted(e) for e in edges)}
        if self.cut:
            out["cut"] = sorted(list(c) for c in self.cut)
        return out


def compile_plan(radio: dict, agents: list[str], seed: int) -> dict:
    """The link plan (plain data, see :class:`agent.net.link_plan.LinkPlan`) for a ``[radio]`` section.

    Raises ValueError naming the problem: unknown keys, topologies, presets, event kinds or agent names,
    event times that go backwards, and anything :class:`agent.net.link_plan.LinkPlan` rejects.
    """
    radio = {} if radio is None else radio
    check_keys("radio", radio, RADIO_KEYS)
    agents = list(agents)
    names = AgentNames("radio", agents)

    kind = radio.get("topology", "full")
    range_ = radio.get("range")
    if kind == "disk" and range_ is None:
        raise ValueError("radio.range: required by topology = \"disk\"")
    base = topology_edges(kind, agents, seed, radio.get("mean_degree"), radio.get("hub"))
    default = _params(radio)

    links = []
    for i, entry in enumerate(radio.get("links") or []):
        where = f"radio.links[{i}]"
        check_keys(where, entry, {"src", "dst", "gilbert_elliott", *PARAM_KEYS}, required=("src", "dst"))
        names.pair((entry["src"], entry["dst"]), where)
        entry = dict(entry)
        if "gilbert_elliott" in entry:
            entry["ge"] = GilbertElliott.from_dict(entry.pop("gilbert_elliott"), f"{where}.gilbert_elliott").to_dict()
        links.append(entry)

    state = _State(agents, base)
    phases = [state.phase(0.0)]
    lost: dict[str, float] = {}  # node -> time lost
    events = radio.get("events") or []
    if not isinstance(events, list):
        raise ValueError("radio.events: must be an array of tables ([[radio.events]])")
    last_t = 0.0
    for i, ev in enumerate(events):
        where = f"radio.events[{i}]"
        if not isinstance(ev, dict):
            raise ValueError(f"{where}: must be a table")
        ev_kind = ev.get("kind")
        if ev_kind not in EVENT_KEYS:
            raise ValueError(f"{where}: unknown kind {ev_kind!r}; known: {sorted(EVENT_KEYS)}")
        where = f"{where} ({ev_kind})"
        check_keys(where, ev, {"t", "kind", *EVENT_KEYS[ev_kind]}, required=("t", *EVENT_REQUIRED.get(ev_kind, ())))
        t = check_number(f"{where}.t", ev["t"], lo=0.0)
        if t < last_t:
            raise ValueError(
                f"{where}: t = {t:g} is before the previous event (t = {last_t:g}); times must not decrease"
            )
        last_t = t

        if ev_kind == "partition":
            groups = ev["groups"]
            if not isinstance(groups, list) or not groups:
                raise ValueError(f"{where}: groups must be a non-empty list of lists of agent names")
            group: dict[str, int] = {}
            for g, members in enumerate(groups):
                if not isinstance(members, list) or not members:
                    raise ValueError(f"{where}: groups[{g}] must be a non-empty list of agent names")
                for name in members:
                    names.agent(name, where)
                    if name in group:
                        raise ValueError(f"{where}: agent {name!r} is in more than one group")
                    group[name] = g
            for name in agents:
                group.setdefault(name, len(groups))  # the unlisted agents form one more group
            state.group = group
        elif ev_kind == "merge":
            state.group = None
            state.removed.clear()
            state.extra.clear()
            state.cut.clear()
        elif ev_kind in ("link_down", "link_up"):
            a, b = names.pair(ev["link"], where)
            directed = ev.get("directed", False)
            if not isinstance(directed, bool):
                raise ValueError(f"{where}: directed must be true or false, got {directed!r}")
            e = _edge(a, b)
            if ev_kind == "link_down":
                if e not in state.base and e not in state.extra:
                    raise ValueError(f"{where}: link [{a!r}, {b!r}] is not in the {kind} topology")
                if directed:
                    state.cut.add((a, b))
                else:
                    state.removed.add(e)
                    state.extra.discard(e)
            else:
                state.cut.discard((a, b))
                if not directed:
                    state.cut.discard((b, a))
                    state.removed.discard(e)
                    if e not in state.base:
                        state.extra.add(e)
        else:  # node_loss
            lose_node(lost, names.agent(ev["node"], where), t, where)

        ph = state.phase(t)
        if ph["t"] == phases[-1]["t"]:
            phases[-1] = ph  # events at one time make one phase
        elif {k: v for k, v in ph.items() if k != "t"} != {k: v for k, v in phases[-1].items() if k != "t"}:
            phases.append(ph)

    plan = {
        "agents": agents,
        "seed": int(seed),
        "default": default,
        "links": links,
        "range": range_,
        "phases": phases,
        "down_nodes": [{"t": when, "node": node} for node, when in lost.items()],
    }
    LinkPlan.from_dict(plan)  # validate the whole plan here, where the scenario can still be named
    return plan
