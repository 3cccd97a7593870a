"""Flooding of increments (agent.net.flood_relay): acknowledgements, prompt relays, no double counting, loss."""

from __future__ import annotations

import random

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.net.flood_relay import ACK_SPAN, RELAY_BACKOFF, FloodRelay, Held, acks_from_wire, holds

STEP = 0.2


@given(st.lists(st.integers(0, 300), max_size=80))
def test_held_agrees_with_a_set_within_its_span(numbers):
    held, model = Held(), set()
    for n in numbers:
        assert held.add(n) == (n not in model and not (held.high - 1 - n >= ACK_SPAN))
        model.add(n)
    high, mask = acks_from_wire({"o": held.wire()})["o"]  # as a neighbour reads it from our message
    for n in range(0, 310):
        inside = held.high < 0 or held.high - 1 - n < ACK_SPAN
        if inside:
            assert holds(high, mask, n) == (n in model), n
        else:
            assert holds(high, mask, n)  # older than the span: counts as held


@pytest.mark.parametrize("entry", [None, [1], [1, 2, 3], ["1", 0], [1.5, 0], [True, 0], [-2, 0], [3, -1],
                                   [3, 1 << ACK_SPAN]])
def test_a_malformed_acknowledgement_is_refused_with_a_reason(entry):
    """None, too short, too long, a string, a float, a bool, highest below -1, a negative mask, a mask too wide."""
    with pytest.raises(ValueError, match="acknowledgement"):
        acks_from_wire({"uav1": [5, 1], "uav2": entry})


@pytest.mark.parametrize("acks", [[[5, 1]], {3: [5, 1]}, "uav1"])
def test_acknowledgements_must_be_a_map_of_origin_names(acks):
    """A list, an integer origin, a string."""
    with pytest.raises(ValueError, match="acknowledgement"):
        acks_from_wire(acks)


def test_a_relay_needs_a_positive_timeout_and_horizon():
    with pytest.raises(ValueError, match="positive"):
        FloodRelay("a", 0.0, 1.0)


class Net:
    """Relays on a graph, stepped like the agents: each step every relay broadcasts what is due to its
    neighbours (each copy lost with probability ``loss``); receipts are handled at the next step."""

    def __init__(self, edges, loss=0.0, seed=0, ack_timeout=3 * STEP, horizon=1.4, ack_delay=0.0):
        self.adj: dict[str, set[str]] = {}
        for a, b in sorted(edges):  # sorted: set order varies with the hash seed, and the loss draws follow it
            self.adj.setdefault(a, set()).add(b)
            self.adj.setdefault(b, set()).add(a)
        self.relays = {n: FloodRelay(n, ack_timeout, horizon, ack_delay=ack_delay) for n in self.adj}
        self.applied = {n: [] for n in self.adj}  # what each node applied, in order
        self.inbox: dict[str, list] = {n: [] for n in self.adj}
        self.loss, self.rng = loss, random.Random(seed)
        self.broadcasts = 0
        self.t = 0.0

    def step(self, originate=()):
        for node in originate:
            inc = self.relays[node].originate(self.t, f"{node}@{self.t:.1f}")
            self.applied[node].append((inc.origin, inc.n))
        inboxes, self.inbox = self.inbox, {n: [] for n in self.adj}
        for node, messages in inboxes.items():
            relay = self.relays[node]
            for sender, increments, acks in messages:
                relay.learn(sender, acks_from_wire(acks))
                for origin, n, when, data in increments:
                    if relay.accept(sender, self.t, origin, n, when, data):
                        self.applied[node].append((origin, n))
        for node, relay in self.relays.items():
            due = relay.due(self.t, sorted(self.adj[node]), lambda a: frozenset(self.adj[a]))
            if not due and not relay.acks_due(self.t):
                continue
            message = (node, [(i.origin, i.n, i.t, i.data) for i in due], relay.acks())
            relay.sent(self.t, due)
            self.broadcasts += 1
            for peer in sorted(self.adj[node]):
                if self.rng.random() >= self.loss:
                    self.inbox[peer].append(message)
        self.t += STEP


def _reference_due(relay: FloodRelay, now: float, neighbours: list[str], neighbours_of) -> list:
    """The rule of the module docstring, applied to every held increment without shortcuts (the oracle)."""
    out = []
    for inc in relay._held.values():
        if now - inc.t > relay.horizon:
            continue  # expired: due() drops it first
        missing = [p for p in neighbours if not relay._holds(p, inc)]
        if not missing:
            continue
        if inc.last_sent is not None:
            if now - inc.last_sent >= relay.ack_timeout - 1e-9:
                out.append(inc)
        elif inc.source == relay.me or not set(missing) <= neighbours_of(inc.source):
            out.append(inc)
        elif now - inc.arrived >= RELAY_BACKOFF * relay.ack_timeout - 1e-9:
            out.append(inc)
    return sorted(out, key=lambda inc: inc.t)


class CheckedNet(Net):
    """A :class:`Net` whose every ``due`` is compared with the reference rule."""

    checked = 0

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        for relay in self.relays.values():
            relay.due = self._checked(relay, relay.due)

    @staticmethod
    def _checked(relay, original):
        def due(now, neighbours, neighbours_of):
            neighbours = list(neighbours)
            expected = [(i.origin, i.n) for i in _reference_due(relay, now, neighbours, neighbours_of)]
            got = original(now, neighbours, neighbours_of)
            assert [(i.origin, i.n) for i in got] == expected
            CheckedNet.checked += 1
            return got

        return due


@pytest.mark.parametrize("seed", range(3))
def test_due_sends_exactly_what_the_rule_says_on_lossy_graphs_with_loops(seed):
    """Oracle: the rule evaluated without shortcuts (no settled sets, no remembered holders, no skipping of
    increments that cannot be due). Seven nodes on a ring plus chords, 30 % loss, a full mesh of four."""
    rng = random.Random(seed)
    nodes = [f"n{i}" for i in range(7)]
    ring = {(nodes[i], nodes[(i + 1) % 7]) for i in range(7)} | {tuple(rng.sample(nodes, 2)) for _ in range(3)}
    mesh = {(a, b) for a in "abcd" for b in "abcd" if a < b}
    for edges, names in ((ring, nodes), (mesh, list("abcd"))):
        net = CheckedNet(edges, loss=0.3, seed=seed, ack_timeout=2 * STEP)
        for _ in range(30):
            net.step(originate=rng.sample(names, 2))
        for _ in range(6):
            net.step()
    assert CheckedNet.checked > 300


class LateNet(Net):
    """A :class:`Net` in which one node's messages reach its neighbours ``lag`` steps late (a slow agent: its
    acknowledgements are delayed, not lost)."""

    def __init__(self, edges, late: str, lag: int, **kwargs):
        super().__init__(edges, **kwargs)
        self.late, self.lag, self.pipe = late, lag, []

    def step(self, originate=()):
        super().step(originate)
        now = [(peer, m) for peer, box in self.inbox.items() for m in box if m[0] == self.late]
        for peer, m in now:
            self.inbox[peer].remove(m)
        self.pipe.append(now)
        if len(self.pipe) > self.lag:
            for peer, m in self.pipe.pop(0):
                self.inbox[peer].append(m)


def test_a_late_peer_on_a_full_mesh_gets_one_retransmission_from_the_origin_and_no_relays():
    """Five agents on a full mesh, one of them 3 steps late with everything it sends: the origins retransmit
    to it once their acknowledgement timeout (2 steps) has passed, but nobody relays the origins' increments
    — N - 1 copies of each, the storm that tipped a loaded fleet over (``RELAY_BACKOFF``)."""
    names = "abcde"
    net = LateNet({(x, y) for x in names for y in names if x < y}, late="e", lag=3)
    for _ in range(12):
        net.step(originate=["a", "b"])
    for _ in range(6):
        net.step()
    assert all(r.relayed == 0 for r in net.relays.values())
    assert net.relays["a"].retransmitted > 0 and net.relays["b"].retransmitted > 0
    assert all(len(set(applied)) == 24 for applied in net.applied.values())


def test_on_a_line_information_k_hops_away_arrives_in_k_steps():
    net = Net([("a", "b"), ("b", "c"), ("c", "d")])
    net.step(originate=["a"])
    arrivals = {}
    for k in range(1, 6):
        net.step()
        for node in "bcd":
            if ("a", 0) in net.applied[node]:
                arrivals.setdefault(node, k)
    assert arrivals == {"b": 1, "c": 2, "d": 3}


def test_on_a_full_mesh_nobody_relays_what_every_neighbour_heard_from_the_source():
    net = Net([("a", "b"), ("a", "c"), ("b", "c"), ("a", "d"), ("b", "d"), ("c", "d")])
    for _ in range(10):
        net.step(originate=["a", "b"])
    for _ in range(5):
        net.step()
    assert all(r.relayed == 0 and r.retransmitted == 0 for r in net.relays.values())
    assert all(len(applied) == 20 for applied in net.applied.values())


def lossy_mesh(seed: int, ack_timeout: float) -> tuple[Net, list[str]]:
    """Seven nodes on a ring plus three chords (every link on a loop), 30 % loss, 40 steps of increments."""
    rng = random.Random(seed)
    nodes = [f"n{i}" for i in range(7)]
    edges = {(nodes[i], nodes[(i + 1) % 7]) for i in range(7)}
    edges |= {tuple(rng.sample(nodes, 2)) for _ in range(3)}
    net = Net(edges, loss=0.3, seed=seed, ack_timeout=ack_timeout)
    for _ in range(40):
        net.step(originate=rng.sample(nodes, 3))
    for _ in range(8):
        net.step()
    return net, nodes


def delivered(net: Net, nodes: list[str]) -> float:
    created = {(o, n) for o in nodes for n in range(net.relays[o].metrics()["originated"])}
    for node, applied in net.applied.items():
        assert len(applied) == len(set(applied)), f"{node} applied an increment twice"
        assert set(applied) <= created
    return min(len(set(applied)) for applied in net.applied.values()) / len(created)


@pytest.mark.parametrize("delay_steps", [1, 2])
def test_acknowledgements_alone_wait_to_share_a_message_and_still_beat_the_origins_timeout(delay_steps):
    """Bad input for the old rule (no wait): on a full mesh of five where one vehicle detects at every step,
    the four others acknowledged at every step, four messages a step carrying nothing else. With the wait, a
    receiver broadcasts its acknowledgements once per ``delay_steps + 1`` steps, and as the wait plus a round
    trip is within ``ack_timeout`` the origin retransmits nothing."""
    nodes = "abcde"
    edges = [(x, y) for i, x in enumerate(nodes) for y in nodes[i + 1:]]
    delay = delay_steps * STEP
    runs = {}
    for wait in (0.0, delay):
        net = Net(edges, ack_timeout=delay + 2 * STEP, ack_delay=wait)
        for _ in range(30):
            net.step(originate=["a"])
        net.step()
        runs[wait] = net
    eager, patient = runs[0.0], runs[delay]
    assert all(r.retransmitted == 0 and r.relayed == 0 for r in patient.relays.values())
    assert all(len(applied) == 30 for applied in patient.applied.values())
    acks_only = {wait: net.broadcasts - 30 for wait, net in runs.items()}  # a's own 30 carry increments
    assert acks_only[0.0] == 4 * 30
    assert acks_only[delay] <= 4 * (30 // (delay_steps + 1) + 1)
    assert eager.relays["a"].retransmitted == 0


def test_acknowledgements_that_wait_as_long_as_the_timeout_are_refused():
    """Bad configuration: acknowledgements waiting ack_timeout or longer would always arrive too late."""
    with pytest.raises(ValueError, match="ack_delay"):
        FloodRelay("a", 0.4, 1.0, ack_delay=0.4)
    with pytest.raises(ValueError, match="ack_delay"):
        FloodRelay("a", 0.4, 1.0, ack_delay=-0.1)


@pytest.mark.parametrize("seed", range(4))
def test_with_loops_and_loss_every_increment_is_applied_once_and_retransmissions_repair_loss(seed):
    net, nodes = lossy_mesh(seed, ack_timeout=2 * STEP)
    without, _ = lossy_mesh(seed, ack_timeout=100.0)  # never retransmits
    assert sum(r.retransmitted for r in net.relays.values()) > 0
    assert delivered(net, nodes) >= 0.85  # the worst node; measured 0.88-1.0 over seeds 0-11
    assert delivered(net, nodes) > delivered(without, nodes)


def test_a_lost_broadcast_is_retransmitted_after_the_timeout_and_stops_once_acknowledged():
    net = Net([("a", "b")], loss=1.0)
    net.step(originate=["a"])  # lost
    net.loss = 0.0
    for _ in range(3):
        net.step()
    assert ("a", 0) not in net.applied["b"]  # not yet: re-sent after 3 steps, received at the next
    net.step()
    assert ("a", 0) in net.applied["b"] and net.relays["a"].retransmitted == 1
    for _ in range(6):
        net.step()
    assert net.relays["a"].retransmitted == 1  # b's acknowledgement stopped it


def test_increments_older_than_the_horizon_are_forgotten():
    relay = FloodRelay("a", 0.6, horizon=1.0)
    relay.originate(0.0, "x")
    assert relay.due(0.2, ["b"], lambda _: frozenset())
    assert relay.due(1.2, ["b"], lambda _: frozenset()) == [] and relay.metrics()["held"] == 0


def test_an_increment_number_far_ahead_is_recorded_without_shifting_the_mask_by_it():
    """Bad input (skymesh bench fuzz: a flooded increment numbered 2**63 crashed the agent with a MemoryError,
    the mask shifted left by 2**63 bits). Only the 64 numbers below the highest have bits."""
    held = Held()
    for n in (0, 1, 3):
        held.add(n)
    assert held.add(2**63) and held.high == 2**63 and held.mask == 0
    assert held.has(3) and not held.has(2**63 + 1)  # anything older than the span counts as held
    held.add(2**63 + 64)
    assert held.mask == 1 << 63  # 2**63, 64 below the new highest: the last bit of the span
