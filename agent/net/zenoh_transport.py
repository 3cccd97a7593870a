"""The agent's transport over Eclipse Zenoh (DESIGN.md §5).

Key space ``skymesh/<fleet>/...``: ``belief/<kind>/<agent>``, ``telemetry/<agent>``,
``sim/{truth,clock,measurement/<agent>}`` and liveliness tokens ``alive/<agent>``. The fleet name
isolates concurrent runs on one machine.

By default a process connects as a Zenoh *client* to a router on loopback with multicast scouting off
(peers do not relay for each other; a router does — see ``../shared/specs/dependencies.md`` §0). On
real hardware a standard Zenoh JSON5 file is given instead (``--zenoh-config``), e.g. connecting to
``zenohd`` routers across machines.

Received samples are queued by Zenoh's callback thread and drained by the agent loop, so that fusion
never runs concurrently with itself. The queue is bounded: when the loop falls behind, the oldest
samples are dropped and counted (a slow agent must not grow without bound).
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque

import zenoh

from agent.net.keys import Incoming, Keys

QUEUE_LIMIT = 10_000  # samples; chosen here (a 32-agent fleet at 5 Hz produces ~300 per second)


def client_config(connect: list[str], lease_ms: int | None = None) -> zenoh.Config:
    """Client mode to the given router endpoints, multicast scouting off (no external service)."""
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps("client"))
    c.insert_json5("scouting/multicast/enabled", json.dumps(False))
    c.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if lease_ms is not None:
        c.insert_json5("transport/link/tx/lease", json.dumps(lease_ms))
        c.insert_json5("transport/link/tx/keep_alive", json.dumps(4))
    return c


def router_config(listen: list[str]) -> zenoh.Config:
    """The launcher's router: listens on loopback, multicast scouting off."""
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps("router"))
    c.insert_json5("scouting/multicast/enabled", json.dumps(False))
    c.insert_json5("listen/endpoints", json.dumps(list(listen)))
    return c


def load_config(connect: list[str] | None, config_file: str | None) -> zenoh.Config:
    if config_file:
        try:
            return zenoh.Config.from_file(config_file)
        except Exception as err:  # zenoh raises its own ZError; say which file was wrong
            raise ValueError(f"cannot read Zenoh config {config_file}: {err}") from None
    if not connect:
        raise ValueError("give a router endpoint to connect to (--connect) or a Zenoh config file (--zenoh-config)")
    return client_config(connect)


class ZenohTransport:
    """Publish bytes on keys, queue what arrives on subscribed keys, track who is alive."""

    def __init__(self, name: str, keys: Keys, config: zenoh.Config, subscribe: list[str], liveliness: bool = True):
        zenoh.init_log_from_env_or("error")
        self.name = name
        self.keys = keys
        self.session = zenoh.open(config)
        self._queue: deque[Incoming] = deque()
        self._lock = threading.Lock()
        self.dropped = 0
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._subscribers = [self.session.declare_subscriber(k, self._on_sample) for k in subscribe]
        self._alive: set[str] = set()
        self._token = None
        self._liveliness_sub = None
        if liveliness:
            self._token = self.session.liveliness().declare_token(keys.alive(name))
            self._liveliness_sub = self.session.liveliness().declare_subscriber(
                keys.alive("*"), self._on_liveliness, history=True
            )

    def _on_sample(self, sample: zenoh.Sample) -> None:
        item = Incoming(str(sample.key_expr), sample.payload.to_bytes(), time.time())
        with self._lock:
            if len(self._queue) >= QUEUE_LIMIT:
                self._queue.popleft()
                self.dropped += 1
            self._queue.append(item)

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        agent = str(sample.key_expr).rsplit("/", 1)[-1]
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self._alive.add(agent)
            else:
                self._alive.discard(agent)

    def publish(self, key: str, data: bytes) -> None:
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._publishers[key] = self.session.declare_publisher(key)
        pub.put(data)

    def drain(self) -> list[Incoming]:
        with self._lock:
            items = list(self._queue)
            self._queue.clear()
        return items

    def alive(self) -> set[str]:
        with self._lock:
            return set(self._alive) - {self.name}

    def close(self) -> None:
        try:
            self.session.close()
        except Exception:  # closing twice or after the router vanished must not mask the real exit
            pass
