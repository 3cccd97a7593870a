"""Every message travels with the Zenoh encoding ``zenoh/bytes;skymesh/1`` (the format and its version), and a
receiver rejects another one as a malformed message (``bad_encoding``) without losing anything else (issue 18,
item 4). The bad inputs: the same bytes under ``zenoh/bytes`` (Zenoh's default), under ``skymesh/2`` (a newer
version) and under the format's earlier name ``application/msgpack;skymesh-wire=1``."""

from __future__ import annotations

import threading
import time
import uuid

import pytest
import zenoh

from agent.agent import Agent
from agent.net import wire
from agent.net.keys import Keys
from agent.net.zenoh_transport import ZenohTransport, client_config
from mesh_sim.scenario import load

WRONG = ("zenoh/bytes", "zenoh/bytes;skymesh/2", "application/msgpack;skymesh-wire=1")  # none, next version, old name


def _envelope() -> bytes:
    return wire.encode(wire.Envelope(kind="topology", origin="uav1", seq=1, stamp=0.0,
                                     payload={"reports": {"uav1": [0.0, []]}}))


def test_the_encoding_names_the_format_and_its_version():
    assert wire.ZENOH_ENCODING == f"zenoh/bytes;skymesh/{wire.SCHEMA_VERSION}" == "zenoh/bytes;skymesh/1"


@pytest.mark.parametrize("encoding", WRONG)
def test_a_wrong_encoding_is_rejected_with_its_reason(encoding):
    with pytest.raises(wire.DecodeError) as err:
        wire.check_encoding(encoding)
    assert err.value.reason == "bad_encoding"
    assert str(err.value) == f"bad_encoding: Zenoh encoding {encoding!r}, expected 'zenoh/bytes;skymesh/1'"
    wire.check_encoding(wire.ZENOH_ENCODING)
    wire.check_encoding(None)  # the in-memory bus has no encoding: nothing to check


def _drain_until(transport: ZenohTransport, key: str, count: int, timeout: float = 20.0) -> list:
    """Everything received until ``count`` samples on ``key`` are among it (or ``timeout`` s passed)."""
    items, deadline = [], time.monotonic() + timeout
    while sum(item.key == key for item in items) < count and time.monotonic() < deadline:
        items += transport.drain()
        time.sleep(0.02)
    return items


def test_over_real_sessions_the_encoding_travels_and_a_wrong_one_is_counted_not_fused(zenoh_router):
    """Agent uav1 publishes over Zenoh; a spy session sees its encoding, then replays uav1's topology message
    under each wrong encoding; agent uav0 rejects those copies as ``bad_encoding`` and uses uav1's own."""
    scenario = load("default", agents=2).agent
    keys = Keys(f"enc-{uuid.uuid4().hex[:8]}")
    spy = zenoh.open(client_config([zenoh_router]))
    seen: list[tuple[bytes, str]] = []
    lock = threading.Lock()

    def on_sample(sample):
        with lock:
            seen.append((sample.payload.to_bytes(), str(sample.encoding)))

    spy_sub = spy.declare_subscriber(keys.topology("uav1"), on_sample)
    receiver = ZenohTransport("uav0", keys, client_config([zenoh_router]), keys.agent_subscriptions(), liveliness=False)
    sender = ZenohTransport("uav1", keys, client_config([zenoh_router]), keys.agent_subscriptions(), liveliness=False)
    try:
        time.sleep(0.5)  # subscriptions reach the router
        uav0 = Agent("uav0", 0, scenario, receiver, keys, seed=0)
        uav1 = Agent("uav1", 1, scenario, sender, keys, seed=1)
        uav1.step(0.0)  # a topology beacon, among others
        deadline = time.monotonic() + 20
        while not seen and time.monotonic() < deadline:
            time.sleep(0.02)
        with lock:
            data, encoding = seen[0]
        assert encoding == "zenoh/bytes;skymesh/1"
        for wrong in WRONG:
            spy.put(keys.topology("uav1"), data, encoding=zenoh.Encoding(wrong))
        items = _drain_until(receiver, keys.topology("uav1"), 1 + len(WRONG))
        topology = [item for item in items if item.key == keys.topology("uav1")]
        assert sorted(item.encoding for item in topology) == sorted([wire.ZENOH_ENCODING, *WRONG])
        for item in items:
            uav0.receive(item, 0.0)
        assert uav0.rejected == {"bad_encoding": len(WRONG)}
        assert uav0.bytes_rx[("uav1", "topology")] == len(data)  # uav1's own copy was used, whatever the order
    finally:
        spy_sub.undeclare()
        spy.close()
        receiver.close()
        sender.close()
