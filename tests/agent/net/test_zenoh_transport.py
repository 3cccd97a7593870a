"""The agent's Zenoh transport (agent.net.zenoh_transport) between two real sessions through a real router on a
unique loopback port: samples arrive in order through the bounded ring of each subscription, and a receiver that
falls behind keeps the newest ``queue_limit`` samples and says it lost some."""

from __future__ import annotations

import time
import uuid

import pytest

from agent.net.keys import Keys
from agent.net.zenoh_transport import ZenohTransport, client_config
from tests.zenoh_probe import first_sample

pytestmark = pytest.mark.slow  # Zenoh sessions


@pytest.fixture()
def pair(zenoh_router, request):
    keys = Keys(f"t{uuid.uuid4().hex[:12]}")
    receiver = ZenohTransport("rx", keys, client_config([zenoh_router]), [keys.belief("track", "*")], liveliness=False,
                              queue_limit=request.param)
    sender = ZenohTransport("tx", keys, client_config([zenoh_router]), [], liveliness=False)
    try:
        key = keys.belief("track", "tx")
        sender.publish(key, b"warm-up")  # declares the publisher; wait until the subscription is matched
        deadline = time.monotonic() + 10.0
        while not sender._publishers[key].matching_status.matching:
            assert time.monotonic() < deadline, "the receiver's subscription never reached the sender"
            time.sleep(0.02)
        time.sleep(0.2)
        receiver.drain()  # the warm-up, if it arrived
        yield sender, receiver, key
    finally:
        sender.close()
        receiver.close()


def _publish_and_settle(sender, key, count: int) -> None:
    for k in range(count):
        sender.publish(key, b"m%03d" % k)
    time.sleep(1.0)  # loopback: every sample is in the receiver's ring well within this


@pytest.mark.parametrize("pair", [100], indirect=True)
def test_samples_arrive_in_order_and_nothing_is_lost_below_the_limit(pair):
    sender, receiver, key = pair
    _publish_and_settle(sender, key, 30)
    items = receiver.drain()
    assert [i.data for i in items] == [b"m%03d" % k for k in range(30)]
    assert {i.key for i in items} == {key} and receiver.dropped == 0
    assert receiver.drain() == []  # drained: nothing twice


@pytest.mark.parametrize("pair", [8], indirect=True)
def test_a_receiver_that_falls_behind_keeps_the_newest_and_counts_a_loss(pair):
    sender, receiver, key = pair
    _publish_and_settle(sender, key, 50)  # 50 samples into a ring of 8, nobody draining
    assert [i.data for i in receiver.drain()] == [b"m%03d" % k for k in range(42, 50)]
    assert receiver.dropped == 1


def test_a_ring_needs_room_for_one_sample(zenoh_router):
    with pytest.raises(ValueError, match="queue_limit must be at least 1"):
        ZenohTransport("rx", Keys("t"), client_config([zenoh_router]), [], liveliness=False, queue_limit=0)


def test_the_launchers_router_forwards_without_a_timestamp(zenoh_router):
    """``router_config``'s router (the ``zenoh_router`` fixture) adds no Zenoh timestamp to what it forwards: about
    25 bytes a message that nothing reads (a Zenoh router stamps by default)."""
    import zenoh

    with zenoh.open(client_config([zenoh_router])) as listener, zenoh.open(client_config([zenoh_router])) as talker:
        assert first_sample(listener, talker, f"t{uuid.uuid4().hex[:12]}/stamp").timestamp is None
