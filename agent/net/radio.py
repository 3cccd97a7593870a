"""The emulated radio as a wrapper around any transport (DESIGN.md §6: the link state is enforced inside
each agent's transport, at the receive side).

:class:`RadioTransport` wraps the real transport (Zenoh, or the in-memory bus) and lets through only what
the radio of the scenario would deliver: for every message from a peer of the link plan it asks the
:class:`~agent.net.link_emulator.LinkEmulator` whether (link down, out of range, lost, over the rate) and when
(latency and jitter) the message arrives. A dropped message is counted by (peer, cause) and never reaches
the agent; a delayed one is held and handed over at the first drain at or after its delivery time, after
the messages that arrived on time — the order a receiver would see.

The decision needs the sender's name, sequence number and stamp, which sit in the envelope's header;
:func:`agent.net.wire.peek_header` reads just those. The
full, validated decoding stays with the agent: a message whose header cannot be read is passed on
untouched, and the agent rejects it by reason. Messages from outside the plan (the world's truth, a
ground station) and the agent's own echoes are not radio traffic and pass through.

:meth:`RadioTransport.drain` is lazy: the agent handles each message before the next is admitted, so the
range check always sees the UAV positions the agent last received (asked for only when the plan has a range
limit: building them for every message cost a full mesh of 24 agents 3 % of a step).
"""

from __future__ import annotations

import heapq
from collections import Counter
from collections.abc import Callable, Iterator

from agent.net.keys import Incoming
from agent.net.link_emulator import LinkEmulator
from agent.net.wire import peek_header


class RadioTransport:
    """Any transport, seen through the emulated radio of receiver ``me``.

    ``clock()`` gives the current simulation time; ``positions()`` the UAV positions known now (for the
    plan's range limit)."""

    def __init__(self, inner, emulator: LinkEmulator, clock: Callable[[], float],
                 positions: Callable[[], dict]):
        self.inner = inner
        self.link = emulator
        self.clock = clock
        self.positions = positions
        self.drops: Counter = Counter()  # (peer, cause) -> messages the radio dropped
        self._held: list = []  # (deliver_at, order, item): messages the radio delays
        self._order = 0

    @property
    def dropped(self) -> int:
        return self.inner.dropped

    def publish(self, key: str, data: bytes) -> None:
        self.inner.publish(key, data)

    def alive(self) -> set[str]:
        return self.inner.alive()

    def close(self) -> None:
        self.inner.close()

    def drain(self) -> Iterator[Incoming]:
        now = self.clock()
        for item in self.inner.drain():
            header = peek_header(item.data)
            if header is None or header.kind == "truth" or header.origin == self.link.me \
                    or header.origin not in self.link.plan.agents:
                yield item
                continue
            positions = None if self.link.plan.range is None else self.positions()  # only a range limit needs them
            verdict = self.link.admit(header.origin, header.seq, len(item.data), header.stamp, positions)
            if verdict.cause is not None:
                self.drops[(header.origin, verdict.cause)] += 1
            elif verdict.deliver_at > now:
                heapq.heappush(self._held, (verdict.deliver_at, self._order, item))
                self._order += 1
            else:
                yield item
        while self._held and self._held[0][0] <= now:
            yield heapq.heappop(self._held)[2]
