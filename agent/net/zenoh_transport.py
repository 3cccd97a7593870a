"""The agent's transport over Eclipse Zenoh (DESIGN.md §5).

Key space ``skymesh/<fleet>/...``: ``belief/<kind>/<agent>``, ``telemetry/<agent>``,
``sim/{truth,clock,measurement/<agent>}`` and liveliness tokens ``alive/<agent>``. The fleet name
isolates concurrent runs on one machine.

By default a process connects as a Zenoh *client* to a router on loopback with multicast scouting off
(peers do not relay for each other; a router does — see ``../shared/specs/dependencies.md`` §0). On
real hardware a standard Zenoh JSON5 file is given instead (``--zenoh-config``), e.g. connecting to
``zenohd`` routers across machines.

Received samples wait in one bounded Zenoh ``RingChannel`` per subscription and are pulled by the agent
loop's ``drain`` (``try_recv`` until empty), so that fusion never runs concurrently with itself and no
Python callback thread competes with the loop for the GIL (``../shared/specs/dependencies.md`` §2.2: a
callback waits up to a switch interval whenever the loop runs Python, and a slow callback leaves stale data
in the socket buffers). A ring keeps the newest ``queue_limit`` samples: when the loop falls that far
behind, the oldest are overwritten (a slow agent must not grow without bound). Zenoh does not say how many;
``dropped`` counts the drains that pulled a full ring's worth from one subscription, where the oldest may
have been overwritten.

Every sample is published with the encoding :data:`agent.net.wire.ZENOH_ENCODING` (the format and its version) and
handed over with the encoding it arrived with, which the receiver checks (``wire.check_encoding``).
"""

from __future__ import annotations

import json
import re
import threading
import time

import zenoh

from agent.net.keys import Incoming, Keys
from agent.net.wire import ZENOH_ENCODING

QUEUE_LIMIT = 10_000  # samples per subscription; chosen here (40 agents at 5 Hz send an agent ~300 per second)
KEEP_ALIVE = 4  # keep-alives per lease (Zenoh's default), when a lease is set


def client_config(connect: list[str], lease_ms: int | None = None) -> zenoh.Config:
    """Client mode to the given router endpoints, multicast scouting off (no external service)."""
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps("client"))
    c.insert_json5("scouting/multicast/enabled", json.dumps(False))
    c.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if lease_ms is not None:
        c.insert_json5("transport/link/tx/lease", json.dumps(lease_ms))
        c.insert_json5("transport/link/tx/keep_alive", json.dumps(KEEP_ALIVE))
    return c


def router_config(listen: list[str]) -> zenoh.Config:
    """The launcher's router: listens on loopback, multicast scouting off, no timestamps on what it forwards (about 25
    bytes a message that nothing reads: ``deploy/uav-router.json5``)."""
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps("router"))
    c.insert_json5("scouting/multicast/enabled", json.dumps(False))
    c.insert_json5("timestamping/enabled", json.dumps(False))
    c.insert_json5("listen/endpoints", json.dumps(list(listen)))
    return c


def zenoh_message(err: Exception) -> str:
    """Zenoh's error text on one line for a user: without the Rust source locations it appends, and a JSON5
    syntax error's caret drawing folded into one line."""
    return " ".join(re.sub(r"\s+at \S+\.rs:\d+\.?", "", str(err)).split())


def load_config(connect: list[str] | None, config_file: str | None) -> zenoh.Config:
    if config_file:
        try:
            return zenoh.Config.from_file(config_file)
        except Exception as err:  # zenoh raises its own ZError; say which file was wrong
            raise ValueError(f"cannot read Zenoh config {config_file}: {zenoh_message(err)}") from None
    if not connect:
        raise ValueError("give a router endpoint to connect to (--connect) or a Zenoh config file (--zenoh-config)")
    return client_config(connect)


class SessionError(ConnectionError):
    """Zenoh could not open a session: no router answered at the endpoints, or an endpoint to listen on is taken.
    An ``OSError`` (a bad environment, like a full disk), whose message is one line for a user."""


def open_session(config: zenoh.Config) -> zenoh.Session:
    """``zenoh.open(config)``, its failure a :class:`SessionError` saying in one line what went wrong (Zenoh's
    own message, without the Rust source locations it appends)."""
    try:
        return zenoh.open(config)
    except zenoh.ZError as err:
        text = zenoh_message(err)
        if text.startswith("Unable to connect"):
            raise SessionError(f"the Zenoh router could not be reached ({text})") from None
        raise SessionError(f"cannot open the Zenoh session ({text})") from None


class ZenohTransport:
    """Publish bytes on keys, queue what arrives on subscribed keys, track who is alive."""

    def __init__(self, name: str, keys: Keys, config: zenoh.Config, subscribe: list[str], liveliness: bool = True,
                 queue_limit: int = QUEUE_LIMIT):
        if queue_limit < 1:
            raise ValueError(f"queue_limit must be at least 1, got {queue_limit}")
        zenoh.init_log_from_env_or("error")
        self.name = name
        self.keys = keys
        self.session = open_session(config)
        self._lock = threading.Lock()  # the liveliness callback's set
        self.dropped = 0  # drains that pulled a full ring from one subscription (its oldest may have been lost)
        self._limit = queue_limit
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._encoding = zenoh.Encoding(ZENOH_ENCODING)  # what the bytes are; receivers check it (wire.decode)
        self._subscribers = [self.session.declare_subscriber(k, zenoh.handlers.RingChannel(queue_limit))
                             for k in subscribe]
        self._alive: set[str] = set()
        self._token = None
        self._liveliness_sub = None
        if liveliness:
            self._token = self.session.liveliness().declare_token(keys.alive(name))
            self._liveliness_sub = self.session.liveliness().declare_subscriber(
                keys.alive("*"), self._on_liveliness, history=True
            )

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
            pub = self._publishers[key] = self.session.declare_publisher(key, encoding=self._encoding)
        pub.put(data)

    def drain(self) -> list[Incoming]:
        """Everything received since the last drain, subscription by subscription, oldest first in each."""
        now = time.time()
        items: list[Incoming] = []
        for sub in self._subscribers:
            start = len(items)
            while (sample := sub.try_recv()) is not None:
                items.append(Incoming(str(sample.key_expr), sample.payload.to_bytes(), now, str(sample.encoding)))
            if len(items) - start >= self._limit:
                self.dropped += 1
        return items

    def alive(self) -> set[str]:
        with self._lock:
            return set(self._alive) - {self.name}

    def close(self) -> None:
        try:
            self.session.close()
        except Exception:  # closing twice or after the router vanished must not mask the real exit
            pass
