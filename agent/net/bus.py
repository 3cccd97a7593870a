"""An in-memory bus with the transport interface of ``agent.net.zenoh_transport.ZenohTransport``.

For deterministic, single-process runs (the lockstep harness and tests): every endpoint publishes on
a key and receives, at its next ``drain()``, whatever was published on the keys it subscribed to.
Key expressions follow Zenoh's: ``*`` matches one chunk, ``**`` any number of chunks.
"""

from __future__ import annotations

import time

from agent.net.keys import Incoming


def key_matches(pattern: str, key: str) -> bool:
    """Zenoh-style key-expression matching for ``*`` and ``**``."""
    return _match(pattern.split("/"), key.split("/"))


def _match(pattern: list[str], key: list[str]) -> bool:
    if not pattern:
        return not key
    head, rest = pattern[0], pattern[1:]
    if head == "**":
        return any(_match(rest, key[i:]) for i in range(len(key) + 1))
    return bool(key) and (head == "*" or head == key[0]) and _match(rest, key[1:])


class InMemoryBus:
    """Routes published bytes to the endpoints whose subscriptions match the key."""

    def __init__(self):
        self._endpoints: list[BusEndpoint] = []
        self._routes: dict[str, list[BusEndpoint]] = {}  # key -> the endpoints subscribed to it (keys repeat)

    def endpoint(self, name: str, subscribe: list[str]) -> BusEndpoint:
        ep = BusEndpoint(self, name, list(subscribe))
        self._endpoints.append(ep)
        self._routes.clear()
        return ep

    def deliver(self, sender: str, key: str, data: bytes) -> None:
        now = time.time()
        route = self._routes.get(key)
        if route is None:
            route = self._routes[key] = [ep for ep in self._endpoints if any(key_matches(p, key) for p in ep.subscribe)]
        for ep in route:
            ep.inbox.append(Incoming(key, data, now))


class BusEndpoint:
    def __init__(self, bus: InMemoryBus, name: str, subscribe: list[str]):
        self.bus, self.name, self.subscribe = bus, name, subscribe
        self.inbox: list[Incoming] = []
        self.dropped = 0

    def publish(self, key: str, data: bytes) -> None:
        self.bus.deliver(self.name, key, data)

    def drain(self) -> list[Incoming]:
        items, self.inbox = self.inbox, []
        return items

    def alive(self) -> set[str]:
        return {ep.name for ep in self.bus._endpoints} - {self.name}

    def close(self) -> None:
        pass
