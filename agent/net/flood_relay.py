"""Flooding of independent information increments: exact fusion on any connected graph.

Channel filters (:mod:`fusion.channel_filter`) are exact only on a tree. On a graph with loops — or one
whose links change — the information two neighbours share cannot be known from the link alone, and
intersection gives away accuracy to stay consistent. Flooding avoids the question: every agent sends only
its *own* new information, as independent increments (here: its detections), each tagged ``(origin, n)``
with ``n`` counting the origin's increments; every agent applies each increment once, whichever way it
arrived, and relays it to the neighbours that do not have it yet. Each measurement is then counted exactly
once in every belief, like in the centralized filter, whatever the topology — the decentralized
equivalent of the centralized information filter's additive measurement update (Merino (2.26)):
``Y = Y_prior + sum_k H_k^T R_k^-1 H_k`` over every agent's measurements ``k``.

**Acknowledgements.** Every message carries, per origin, which increments its sender holds: the highest
``n`` and a bitmask of the :data:`ACK_SPAN` numbers below it (:class:`Held`). A neighbour holds an
increment when it acknowledged it or sent it to us.

An agent with acknowledgements but no increment to send waits ``ack_delay`` after its first unacknowledged
receipt before it broadcasts them alone (:meth:`FloodRelay.acks_due`), so that the receipts of a few steps
share one message. On a full mesh every agent hears every increment: with 20 agents, 7 detections a step
across the fleet and no delay, every agent acknowledged at every step, two thirds of its flood messages
carrying nothing else (997 of 1509 in 15 s), and each was received by the 19 others. ``ack_timeout`` must
cover that wait on top of the round trip, or the origin retransmits what was received
(:class:`agent.net.sending.SendConfig` checks ``ack_delay < ack_timeout``).

**When to send** (:meth:`FloodRelay.due`). An increment is broadcast when a current neighbour does not hold
it, and

* it is new here and some such neighbour cannot have heard it where it came from (it is not a
  neighbour of the agent we got it from, by the topology reports): sent in the same step, so information
  ``k`` hops away arrives within about ``k`` agent steps;
* or nobody acknowledged it within ``ack_timeout`` of its last broadcast, or within ``RELAY_BACKOFF``
  times that of its arrival for one a neighbour should have heard directly: a retransmission, which covers
  loss. What a neighbour should have heard from its origin is the origin's to send again first (one
  broadcast, after ``ack_timeout``); the others step in only once that retransmission has had its own round
  trip. Otherwise every neighbour of a peer that is merely late — its acknowledgements delayed, not lost —
  relays the origin's increments to it at once: N - 1 copies of each on a full mesh, more work for every
  agent, later acknowledgements still, and a fleet near its CPU limit tips into a retransmission storm
  (measured live with 16 agents on 2 cores: about 200 relays per agent in 20 s on a full mesh).

Increments older than ``horizon`` seconds are dropped: no belief can use them any more (they fall outside
every trajectory window).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import msgspec

from agent.net.schemas import HeldWire

ACK_SPAN = 64  # increments acknowledged below the highest one, per origin; chosen here (>> a window)
RELAY_BACKOFF = 2.0  # x ack_timeout before relaying what a neighbour should have heard from the origin (see above)
_MASK_LIMIT = 1 << ACK_SPAN


def holds(high: int, mask: int, n: int) -> bool:
    """Is increment ``n`` among those acknowledged by ``[high, mask]`` (:class:`Held`)?"""
    if n > high:
        return False
    if n == high or high - 1 - n >= ACK_SPAN:
        return True
    return bool(mask >> (high - 1 - n) & 1)


class Held:
    """The increments of one origin that an agent holds: the highest number and a bitmask of the
    :data:`ACK_SPAN` numbers below it (bit ``i``: number ``high - 1 - i``); anything older counts as held."""

    def __init__(self, high: int = -1, mask: int = 0):
        self.high, self.mask = high, mask

    def add(self, n: int) -> bool:
        """Record increment ``n``; ``True`` if it was not held before."""
        if self.has(n):
            return False
        if n > self.high:
            shift = n - self.high  # a jump past the span leaves no bit: never shift by it (n may be near 2**64)
            fits = self.high >= 0 and shift <= ACK_SPAN
            self.mask = ((self.mask << shift) | (1 << (shift - 1))) & ((1 << ACK_SPAN) - 1) if fits else 0
            self.high = n
        else:
            self.mask |= 1 << (self.high - 1 - n)
        return True

    def has(self, n: int) -> bool:
        return holds(self.high, self.mask, n)

    def wire(self) -> list[int]:
        return [self.high, self.mask]


_ACKS = dict[str, HeldWire]


def acks_from_wire(acks) -> dict[str, tuple[int, int]]:
    """A message's acknowledgements, ``{origin: [highest, mask]}``, checked in C (msgspec, against the wire's
    :data:`agent.net.schemas.HeldWire`) and kept as ``(highest, mask)`` pairs: on every message of every
    step, N of them, so no object per entry. ``ValueError`` naming the fault if it is not a map of origin
    names to two integers in range (``highest >= -1``, ``0 <= mask < 2^ACK_SPAN``)."""
    try:
        pairs = msgspec.convert(acks, _ACKS)
    except msgspec.ValidationError as err:
        raise ValueError(f"an acknowledgement must be [highest >= -1, mask >= 0]: {err}") from None
    if pairs and max(mask for _, mask in pairs.values()) >= _MASK_LIMIT:
        raise ValueError(f"an acknowledgement mask must be below 2^{ACK_SPAN}")
    return pairs


@dataclass
class Increment:
    """One origin's increment as held here: its tag, the time of its information, the opaque data, where it
    came from (``source``: the neighbour that sent it, or the origin itself) and when it was last broadcast."""

    origin: str
    n: int
    t: float
    data: object
    source: str
    arrived: float
    last_sent: float | None = None
    holders: set[str] = field(default_factory=set)  # neighbours known to hold it (they sent or acknowledged it)
    settled: frozenset[str] | None = None  # a neighbour set that was found to hold it all (holding only grows)


class FloodRelay:
    """The flooding state of one agent: its own increments and the ones it relays, with the neighbours'
    acknowledgements."""

    def __init__(self, me: str, ack_timeout: float, horizon: float, first: int = 0, ack_delay: float = 0.0):
        if not ack_timeout > 0 or not horizon > 0:
            raise ValueError(f"ack_timeout and horizon must be positive, got {ack_timeout}, {horizon}")
        if not 0 <= ack_delay < ack_timeout:
            raise ValueError(f"ack_delay must be in [0, ack_timeout = {ack_timeout}), got {ack_delay}")
        self.me, self.ack_timeout, self.horizon, self.ack_delay = me, ack_timeout, horizon, ack_delay
        self._count = first  # our increments' numbers start here: after a restart, above the old life's
        self._held: dict[tuple[str, int], Increment] = {}
        self._mine: dict[str, Held] = {}  # origin -> what this agent holds
        self._theirs: dict[str, dict[str, tuple[int, int]]] = {}  # neighbour -> origin -> (highest, mask) it acked
        self._unacked_since: float | None = None  # when the oldest receipt not yet in a broadcast arrived
        self.relayed = 0  # increments broadcast that originated elsewhere
        self.retransmitted = 0  # broadcasts of an increment after its first

    # -- in ---------------------------------------------------------------------------------------
    def originate(self, t: float, data) -> Increment:
        """A new increment of this agent's own."""
        inc = Increment(self.me, self._count, t, data, self.me, t)
        self._count += 1
        self._mine.setdefault(self.me, Held()).add(inc.n)
        self._held[(inc.origin, inc.n)] = inc
        return inc

    def accept(self, sender: str, now: float, origin: str, n: int, t: float, data) -> bool:
        """An increment received from neighbour ``sender``; ``True`` if it is new here (apply it then)."""
        key = (origin, n)
        if key in self._held:
            self._held[key].holders.add(sender)
            return False
        if origin == self.me or not self._mine.setdefault(origin, Held()).add(n):
            return False  # ours coming back, or one already applied and since expired
        if self._unacked_since is None:
            self._unacked_since = now
        if now - t > self.horizon:
            return True  # new, but too old to be worth relaying: the caller decides whether it can still use it
        self._held[key] = Increment(origin, n, t, data, sender, now, holders={sender})
        return True

    def learn(self, sender: str, acks: dict[str, tuple[int, int]]) -> None:
        """The acknowledgements in ``sender``'s latest message, as :func:`acks_from_wire` gives them (they
        supersede its earlier ones)."""
        self._theirs[sender] = acks

    # -- out --------------------------------------------------------------------------------------
    def _holds(self, neighbour: str, inc: Increment) -> bool:
        if neighbour == inc.origin or neighbour in inc.holders:
            return True
        held = self._theirs.get(neighbour, {}).get(inc.origin)
        return held is not None and holds(held[0], held[1], inc.n)

    def due(self, now: float, neighbours: Iterable[str],
            neighbours_of: Callable[[str], frozenset[str]]) -> list[Increment]:
        """The increments to broadcast now (see the module docstring), oldest first."""
        self._expire(now)
        neighbours = list(neighbours)
        everyone = frozenset(neighbours)
        out = []
        covered: dict[str, bool] = {}  # source -> is every neighbour of ours the source or one of its neighbours?
        for inc in self._held.values():
            if inc.settled == everyone:  # every current neighbour holds it: nothing to check (O(1) per step)
                continue
            if not self._may_be_due(inc, now, everyone, neighbours_of, covered):
                continue  # whoever lacks it, it is not due now: no acknowledgement to look up (N per increment)
            unknown = everyone.difference(inc.holders)
            missing = [p for p in neighbours if p in unknown and not self._holds(p, inc)]
            inc.holders.update(unknown.difference(missing))  # found to hold it by their acks: holding only grows
            if not missing:
                inc.settled = everyone
                continue
            if inc.last_sent is not None:
                if now - inc.last_sent >= self.ack_timeout - 1e-9:
                    out.append(inc)
            elif inc.source == self.me or not set(missing) <= neighbours_of(inc.source):
                out.append(inc)
            elif now - inc.arrived >= RELAY_BACKOFF * self.ack_timeout - 1e-9:
                out.append(inc)
        return sorted(out, key=lambda inc: inc.t)

    def _may_be_due(self, inc: Increment, now: float, everyone: frozenset[str],
                    neighbours_of: Callable[[str], frozenset[str]], covered: dict[str, bool]) -> bool:
        """Could :meth:`due` send ``inc`` now if a neighbour lacked it? Only when its acknowledgement timeout has
        passed (``RELAY_BACKOFF`` times it for a relay), when it is our own and new, or when it is new and some
        neighbour of ours is not a neighbour of the agent it came from (who else could lack it is then exactly
        :meth:`due`'s question)."""
        if inc.last_sent is not None:
            return now - inc.last_sent >= self.ack_timeout - 1e-9
        if inc.source == self.me or now - inc.arrived >= RELAY_BACKOFF * self.ack_timeout - 1e-9:
            return True
        if inc.source not in covered:
            covered[inc.source] = everyone - {inc.source} <= neighbours_of(inc.source)
        return not covered[inc.source]

    def sent(self, now: float, increments: Iterable[Increment]) -> None:
        """``increments`` left in a broadcast at ``now``."""
        for inc in increments:
            if inc.last_sent is not None:
                self.retransmitted += 1
            elif inc.origin != self.me:
                self.relayed += 1
            inc.last_sent = now
        self._unacked_since = None  # every broadcast carries all our acknowledgements

    def acks(self) -> dict[str, list[int]]:
        """What this agent holds, per origin, for its next message."""
        return {origin: held.wire() for origin, held in self._mine.items()}

    def acks_due(self, now: float) -> bool:
        """Should this agent broadcast its acknowledgements even with no increment due? Yes once it has held
        something unacknowledged for ``ack_delay`` (see the module docstring)."""
        return self._unacked_since is not None and now - self._unacked_since >= self.ack_delay - 1e-9

    def _expire(self, now: float) -> None:
        for key in [k for k, inc in self._held.items() if now - inc.t > self.horizon]:
            del self._held[key]

    def metrics(self) -> dict:
        return {"held": len(self._held), "originated": self._count, "relayed": self.relayed,
                "retransmitted": self.retransmitted}
