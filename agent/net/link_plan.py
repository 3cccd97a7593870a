"""The link plan: who can hear whom, when, through which impairments (DESIGN.md §6; anchors §9 and §12 item 9).

The mesh simulator compiles a scenario's ``[radio]`` section into a *link plan* (plain data, see
:class:`LinkPlan`); each agent enforces it in its own transport (:mod:`agent.net.link_emulator`). The agent
does not import ``mesh_sim``: the plan is data, checked by :mod:`agent.net.plan_checks` (which
``mesh_sim.radio`` uses for ``[radio]`` too).

Parameters are named after ``tc netem`` so a scenario can be replayed on a real network
(:func:`netem_command` prints the equivalent ``tc`` line; it is never executed here):

``loss``
    Bernoulli loss probability per message, 0..1 (netem ``loss X%``).
``delay_ms``, ``jitter_ms``
    One-way latency. The jitter is *normally* distributed with standard deviation ``jitter_ms`` around
    ``delay_ms`` (netem ``delay X Y distribution normal``) and the total delay is clipped at >= 0 (netem
    would send a packet with a negative delay at once, which is the same thing). Because of the clip, the
    mean delay exceeds ``delay_ms`` slightly when ``jitter_ms`` is not small next to ``delay_ms``.
``rate``, ``burst``
    Bandwidth cap in **bytes/s** (0 or None = unlimited) and the token-bucket depth in bytes (default
    ``max(64 KiB, 0.1 s * rate)``). netem's ``rate`` is a shaper (it queues); here the receive side
    *polices* (drops what exceeds the bucket) and the send side is expected to keep under
    :meth:`LinkPlan.sender_budget`; in the long run both pass ``rate`` bytes/s. ``burst`` has no netem
    equivalent and is left out of :func:`netem_command`.
``queue``
    Bytes a rate-limited link holds while they wait for tokens (default 0: the bucket polices). Above 0 the
    link is a shaper, Linux ``tc-tbf(8)``'s ``limit`` (:class:`agent.net.link_emulator.Shaper`): what does not
    find tokens waits in order, what does not fit the queue is dropped. Left out of :func:`netem_command`
    (netem's ``limit`` counts packets).
``ge``
    Gilbert–Elliott loss (:class:`GilbertElliott`), netem's ``loss gemodel p r 1-h 1-k``. As in netem a
    link has one loss model: ``ge`` and a non-zero ``loss`` are exclusive.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, fields

import numpy as np

from agent.net.plan_checks import AgentNames, check_keys, check_number, lose_node

KIB = 1024
DEFAULT_BURST_MIN = 64 * KIB  # bytes; chosen here
DEFAULT_BURST_SECONDS = 0.1  # default bucket depth = this many seconds at the link rate; chosen here
MIN_BURST = 1500  # bytes: one Ethernet MTU; a smaller bucket would pass almost nothing
MBIT = 1e6 / 8  # bytes/s in one Mbit/s


def default_burst(rate: float) -> float:
    """The token-bucket depth (bytes) of a ``rate`` bytes/s link when none is given: max(64 KiB, 0.1 s · rate)."""
    return max(float(DEFAULT_BURST_MIN), rate * DEFAULT_BURST_SECONDS)


# --------------------------------------------------------------------------------------------------
# Parameters


@dataclass(frozen=True)
class GilbertElliott:
    """netem's ``loss gemodel p r 1-h 1-k``: a two-state Markov chain stepped once per message.

    ``p`` = P(good → bad), ``r`` = P(bad → good), ``one_minus_h`` = loss probability in the bad state,
    ``one_minus_k`` = loss probability in the good state (netem's defaults for the last two: 1 and 0).
    With π_bad = p / (p + r) and π_good = 1 - π_bad the long-run loss is

        mean_loss = π_bad · (1-h) + π_good · (1-k)

    and a bad period lasts 1/r messages on average (geometric); when 1-h = 1 and 1-k = 0 a bad period
    is exactly a burst of consecutive losses, so the mean loss-burst length is 1/r. With p = r = 0 the
    chain never leaves its initial (good) state. Unlike netem, ``r`` has no default (netem uses 1-p).
    """

    p: float
    r: float
    one_minus_h: float = 1.0
    one_minus_k: float = 0.0

    def __post_init__(self):
        for f in fields(self):
            object.__setattr__(self, f.name, check_number(f"ge.{f.name}", getattr(self, f.name), lo=0.0, hi=1.0))

    @property
    def stationary_bad(self) -> float:
        return self.p / (self.p + self.r) if self.p + self.r > 0 else 0.0

    @property
    def mean_loss(self) -> float:
        pb = self.stationary_bad
        return pb * self.one_minus_h + (1.0 - pb) * self.one_minus_k

    @property
    def mean_bad_run(self) -> float:
        """Mean length of a bad period in messages (= mean loss burst when 1-h = 1 and 1-k = 0)."""
        return 1.0 / self.r if self.r > 0 else math.inf

    @classmethod
    def from_dict(cls, d: dict, where: str = "ge") -> GilbertElliott:
        check_keys(where, d, {"p", "r", "one_minus_h", "one_minus_k"}, required=("p", "r"))
        try:
            return cls(**d)
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None

    def to_dict(self) -> dict:
        return {"p": self.p, "r": self.r, "one_minus_h": self.one_minus_h, "one_minus_k": self.one_minus_k}


@dataclass(frozen=True)
class LinkParams:
    """One directed link's impairments, named like ``tc netem`` (units in the module docstring).

    ``rate`` 0 is stored as None (unlimited). ``burst`` None means the default depth
    (:attr:`bucket_depth`); a burst or queue given with an unlimited rate is ignored. A message larger than the
    bucket depth can never pass a rate-limited link.
    """

    loss: float = 0.0
    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    rate: float | None = None
    burst: float | None = None
    queue: float = 0.0
    ge: GilbertElliott | None = None

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "loss", check_number("loss", self.loss, lo=0.0, hi=1.0))
        set_(self, "delay_ms", check_number("delay_ms", self.delay_ms, lo=0.0))
        set_(self, "jitter_ms", check_number("jitter_ms", self.jitter_ms, lo=0.0))
        if self.rate is not None:
            rate = check_number("rate", self.rate, lo=0.0)
            set_(self, "rate", rate if rate > 0 else None)
        if self.burst is not None:
            burst = check_number("burst", self.burst)
            if burst < MIN_BURST:
                raise ValueError(f"burst: must be >= {MIN_BURST} bytes (one MTU), got {burst:g}")
            set_(self, "burst", burst)
        set_(self, "queue", check_number("queue", self.queue, lo=0.0))
        if self.ge is not None and not isinstance(self.ge, GilbertElliott):
            raise ValueError(f"ge: must be a GilbertElliott or None, got {type(self.ge).__name__}")
        if self.ge is not None and self.loss > 0:
            raise ValueError("loss: a link has one loss model (as in netem): give loss = 0 with ge, or no ge")

    @property
    def bucket_depth(self) -> float | None:
        if self.rate is None:
            return None
        if self.burst is not None:
            return self.burst
        return default_burst(self.rate)

    @property
    def mean_loss(self) -> float:
        return self.ge.mean_loss if self.ge is not None else self.loss

    @classmethod
    def from_dict(cls, d: dict, where: str = "link") -> LinkParams:
        """From plain data: the field names of this class; ``ge`` a dict of :class:`GilbertElliott` or None."""
        check_keys(where, d, {f.name for f in fields(cls)})
        d = dict(d)
        ge = d.get("ge")
        if ge is not None:
            d["ge"] = ge if isinstance(ge, GilbertElliott) else GilbertElliott.from_dict(ge, f"{where}.ge")
        try:
            return cls(**d)
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None

    def to_dict(self) -> dict:
        return {
            "loss": self.loss,
            "delay_ms": self.delay_ms,
            "jitter_ms": self.jitter_ms,
            "rate": self.rate,
            "burst": self.burst,
            "queue": self.queue,
            "ge": None if self.ge is None else self.ge.to_dict(),
        }


#: Link profiles. ``wifi`` and ``cellular`` are the osrf/zenoh_evaluation Mininet links (anchors §9):
#: robot 802.11n Wi-Fi 60 Mbit/s, 2 ms, 0.14 % loss; cellular backhaul 100 Mbit/s, 100 ms, 0.5 % loss.
#: ``lossy`` (30 % loss, 10 ms) is a stress profile chosen here.
PRESETS: dict[str, LinkParams] = {
    "ideal": LinkParams(),
    "wifi": LinkParams(loss=0.0014, delay_ms=2.0, rate=60 * MBIT),
    "cellular": LinkParams(loss=0.005, delay_ms=100.0, rate=100 * MBIT),
    "lossy": LinkParams(loss=0.30, delay_ms=10.0),
}


def _fmt(x: float) -> str:
    return f"{x:.10g}"


def _fmt_rate(bytes_per_s: float) -> str:
    bits = round(bytes_per_s * 8)
    for unit, scale in (("gbit", 10**9), ("mbit", 10**6), ("kbit", 10**3)):
        if bits >= scale and bits % scale == 0:
            return f"{bits // scale}{unit}"
    return f"{bits}bit"


def netem_command(dev: str, params: LinkParams) -> str:
    """The ``tc qdisc add dev DEV root netem ...`` line equivalent to ``params`` (a string; never run here).

    ``delay Xms [Yms distribution normal]``, ``loss X%`` or ``loss gemodel p% r% 1-h% 1-k%``, ``rate
    Nbit`` (k/m/gbit are SI multiples, as in tc). The token-bucket ``burst`` has no netem equivalent.
    """
    if not isinstance(dev, str) or not dev or any(c.isspace() for c in dev):
        raise ValueError(f"dev: must be an interface name without spaces, got {dev!r}")
    parts = [f"tc qdisc add dev {dev} root netem"]
    if params.delay_ms > 0 or params.jitter_ms > 0:
        parts.append(f"delay {_fmt(params.delay_ms)}ms")
        if params.jitter_ms > 0:
            parts.append(f"{_fmt(params.jitter_ms)}ms distribution normal")
    if params.ge is not None:
        ge = params.ge
        pct = " ".join(f"{_fmt(100 * v)}%" for v in (ge.p, ge.r, ge.one_minus_h, ge.one_minus_k))
        parts.append(f"loss gemodel {pct}")
    elif params.loss > 0:
        parts.append(f"loss {_fmt(100 * params.loss)}%")
    if params.rate is not None:
        parts.append(f"rate {_fmt_rate(params.rate)}")
    return " ".join(parts)



# --------------------------------------------------------------------------------------------------
# The plan


@dataclass(frozen=True)
class _Phase:
    t: float
    edges: frozenset | None  # undirected edges as frozensets; None = every pair
    cut: frozenset  # directed (src, dst) links down in this phase


class LinkPlan:
    """Who can hear whom, when, and through which impairments. Built from plain data (``from_dict``)::

        {
          "agents": ["uav0", "uav1", ...],       # required: unique non-empty names
          "seed": 7,                             # required: int, seeds every loss/jitter draw
          "default": {LinkParams fields},        # optional (ideal): every directed link
          "links": [                             # optional: per directed link, fields override "default"
            {"src": "uav0", "dst": "uav1", "loss": 0.1, ...}, ...],
          "range": 300.0,                        # optional: metres, or null (no range limit)
          "phases": [                            # optional (default: one phase, every pair connected)
            {"t": 0.0, "edges": "all" | [["uav0", "uav1"], ...],   # undirected edges
             "cut": [["uav0", "uav1"], ...]},    # optional: directed links down although the edge is up
            {"t": 30.0, "edges": [...]}, ...],   # times strictly increasing; a phase holds until the next
          "down_nodes": [{"t": 12.0, "node": "uav2"}, ...]   # optional: node lost from t on, for good
        }

    Before the first phase's time the first phase applies. A lost node neither sends nor receives.
    Every problem (unknown field, unknown agent, self-loop, times not increasing, duplicate link or node)
    is a ValueError that says where it is.
    """

    KEYS = frozenset({"agents", "seed", "default", "links", "range", "phases", "down_nodes"})

    def __init__(self, agents, seed, default, links, range_, phases, down_nodes):
        self.agents: tuple[str, ...] = tuple(agents)
        self.seed: int = seed
        self.default: LinkParams = default
        self.links: dict[tuple[str, str], LinkParams] = dict(links)
        self.range: float | None = range_
        self._phases: list[_Phase] = list(phases)
        self._phase_times = [ph.t for ph in self._phases]
        self.down_nodes: dict[str, float] = dict(down_nodes)
        self._all_edges = frozenset(
            frozenset((a, b)) for i, a in enumerate(self.agents) for b in self.agents[i + 1:]
        )

    # ---- construction ------------------------------------------------------------------------------

    @classmethod
    def from_dict(cls, d: dict) -> LinkPlan:
        if isinstance(d, LinkPlan):
            return d
        check_keys("link plan", d, cls.KEYS, required=("agents", "seed"))
        names = AgentNames("link plan", d["agents"])

        seed = d["seed"]
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
            raise ValueError(f"link plan: seed must be an int, got {seed!r}")
        default_d = d.get("default") or {}
        default = LinkParams.from_dict(default_d, "link plan: default")

        links = {}
        for i, entry in enumerate(d.get("links") or []):
            where = f"link plan: links[{i}]"
            check_keys(where, entry, {"src", "dst"} | {f.name for f in fields(LinkParams)}, required=("src", "dst"))
            src, dst = names.pair((entry["src"], entry["dst"]), where)
            if (src, dst) in links:
                raise ValueError(f"{where}: link {src}->{dst} given twice")
            over = {k: v for k, v in entry.items() if k not in ("src", "dst")}
            merged = {**default.to_dict(), **over}
            if over.get("ge") is not None and "loss" not in over:
                merged["loss"] = 0.0  # a link-level ge replaces the default's Bernoulli loss ...
            if "loss" in over and "ge" not in over:
                merged["ge"] = None  # ... and a link-level loss replaces the default's ge
            links[(src, dst)] = LinkParams.from_dict(merged, where)

        range_ = d.get("range")
        if range_ is not None:
            range_ = check_number("link plan: range", range_)
            if range_ <= 0:
                raise ValueError(f"link plan: range must be > 0 metres or null, got {range_:g}")

        phases = []
        for i, ph in enumerate(d.get("phases") or [{"t": 0.0, "edges": "all"}]):
            where = f"link plan: phases[{i}]"
            check_keys(where, ph, {"t", "edges", "cut"}, required=("t", "edges"))
            t = check_number(f"{where}.t", ph["t"])
            if phases and t <= phases[-1].t:
                raise ValueError(f"{where}: t = {t:g} is not after the previous phase (t = {phases[-1].t:g})")
            if ph["edges"] == "all":
                edges = None
            elif isinstance(ph["edges"], list | tuple):
                edges = frozenset(frozenset(names.pair(e, f"{where}.edges")) for e in ph["edges"])
            else:
                raise ValueError(f"{where}.edges: must be \"all\" or a list of [a, b] pairs, got {ph['edges']!r}")
            cut = frozenset(names.pair(c, f"{where}.cut") for c in ph.get("cut") or [])
            phases.append(_Phase(t, edges, cut))

        down = {}
        for i, entry in enumerate(d.get("down_nodes") or []):
            where = f"link plan: down_nodes[{i}]"
            check_keys(where, entry, {"t", "node"}, required=("t", "node"))
            lose_node(down, names.agent(entry["node"], where), check_number(f"{where}.t", entry["t"]), where)

        return cls(names.names, int(seed), default, links, range_, phases, down)

    # ---- queries -----------------------------------------------------------------------------------

    def params(self, src: str, dst: str) -> LinkParams:
        return self.links.get((src, dst), self.default)

    def _phase(self, t: float) -> _Phase:
        return self._phases[max(0, bisect.bisect_right(self._phase_times, t) - 1)]

    def node_up(self, node: str, t: float) -> bool:
        lost = self.down_nodes.get(node)
        return lost is None or t < lost

    def is_up(self, src: str, dst: str, t: float) -> bool:
        """True if the directed link src → dst exists at ``t`` (edge present, not cut, both nodes alive)."""
        if src == dst or not (self.node_up(src, t) and self.node_up(dst, t)):
            return False
        ph = self._phase(t)
        if ph.edges is not None and frozenset((src, dst)) not in ph.edges:
            return False
        return (src, dst) not in ph.cut

    def senders_to(self, me: str) -> tuple[str, ...] | None:
        """The agents whose messages can ever reach ``me`` — a link to ``me`` in some phase, not cut in all of them —
        or None when every agent can (a phase with every pair connected, or a ``range``: who is in range is known
        only at run time). What an agent need not even receive (:meth:`agent.net.keys.Keys.agent_subscriptions`)."""
        if me not in self.agents:
            raise ValueError(f"agent {me!r} is not in the link plan {list(self.agents)}")
        if self.range is not None or any(ph.edges is None for ph in self._phases):
            return None
        return tuple(src for src in self.agents if src != me and any(
            frozenset((src, me)) in ph.edges and (src, me) not in ph.cut for ph in self._phases))

    def edges_at(self, t: float) -> set[frozenset]:
        """Undirected edges usable at ``t`` in at least one direction (lost nodes have none)."""
        ph = self._phase(t)
        edges = self._all_edges if ph.edges is None else ph.edges
        out = set()
        for e in edges:
            a, b = sorted(e)
            if self.is_up(a, b, t) or self.is_up(b, a, t):
                out.add(e)
        return out

    def sender_budget(self, me: str) -> float | None:
        """The tightest rate (bytes/s) over ``me``'s outgoing links, or None if all are unlimited."""
        rates = [self.params(me, b).rate for b in self.agents if b != me]
        rates = [r for r in rates if r is not None]
        return min(rates) if rates else None

