"""agent.net.radio: the emulated radio as a transport wrapper. Its decisions equal the link emulator's
called directly on the same messages in the same order (the oracle); what is not radio traffic passes;
delayed messages arrive after the on-time ones; the range check sees positions as they are when each
message is admitted; a header that cannot be read is left to the agent's decoder."""

from __future__ import annotations

import msgpack
import numpy as np

from agent.net import wire
from agent.net.bus import InMemoryBus
from agent.net.link_emulator import LinkEmulator
from agent.net.radio import RadioTransport
from agent.net.wire import Header, peek_header

AGENTS = ["uav0", "uav1", "uav2"]


def plan(default=None, **extra) -> dict:
    return {"agents": AGENTS, "seed": 3, "default": default or {}, **extra}


def envelope(origin: str, seq: int, stamp: float, kind: str = "telemetry", size: int = 10) -> bytes:
    return wire.encode(wire.Envelope(kind=kind, origin=origin, seq=seq, stamp=stamp,
                                     payload={"x": np.zeros(size)}), b"k" * 32)


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def radio(link_plan: dict, positions=dict) -> tuple[RadioTransport, object, Clock]:
    bus = InMemoryBus()
    sender = bus.endpoint("tx", [])
    clock = Clock()
    return RadioTransport(bus.endpoint("uav0", ["**"]), LinkEmulator("uav0", link_plan), clock, positions), \
        sender, clock


def test_peek_reads_the_header_of_a_real_envelope_and_nothing_of_garbage():
    data = envelope("uav1", 42, 3.5, "track")
    assert peek_header(data) == Header("track", "uav1", 42, 3.5)
    assert peek_header(b"") is None  # empty bytes
    assert peek_header(b"\xc1garbage") is None  # not msgpack
    assert peek_header(data[:5]) is None  # truncated before the sequence number
    assert peek_header(wire.encode(wire.Envelope(kind="track", origin="uav1", seq=1, stamp=0.0))[:-1]) is not None


def test_the_fast_peek_reads_what_the_field_by_field_peek_reads():
    """Oracle: the field-by-field unpacking (``wire._peek_fields``). Every prefix and 400 one-byte mutations of a
    real flood message, plus headers of the wrong types (a bool seq, a negative seq, a string stamp, an infinite
    stamp, no kind), get the same header, or None from both."""
    data = wire.encode(wire.Envelope(kind="track", origin="uav1", seq=7, stamp=2.5, payload={
        "increments": [["uav1", 3, np.ones((2, 9))]], "acks": {f"uav{i}": [5, 7] for i in range(8)}}))
    rng = np.random.default_rng(0)
    mutated = []
    for _ in range(400):
        b = bytearray(data)
        b[rng.integers(len(b))] = rng.integers(256)
        mutated.append(bytes(b))
    odd = [msgpack.packb(m) for m in (
        {"k": "track", "o": "uav1", "s": True, "t": 1.0}, {"k": "track", "o": "uav1", "s": -1, "t": 1.0},
        {"k": "track", "o": "uav1", "s": 1, "t": "1.0"}, {"k": "track", "o": "uav1", "s": 1, "t": float("inf")},
        {"o": "uav1", "s": 1, "t": 1.0}, {"k": "track", "o": "uav1", "s": 1, "t": 2}, [1, 2, 3])]
    for case in [data[:n] for n in range(len(data) + 1)] + mutated + odd:
        assert peek_header(case) == wire._peek_fields(case), case


def test_decisions_equal_the_link_emulator_called_directly():
    """40 % loss and a rate cap: the wrapper passes exactly what a second emulator, the oracle, admits."""
    link_plan = plan({"loss": 0.4, "rate": 2000.0, "burst": 3000})
    transport, sender, clock = radio(link_plan)
    oracle = LinkEmulator("uav0", link_plan)
    expected = []
    for k in range(200):
        origin = AGENTS[1 + k % 2]
        data = envelope(origin, k, 0.01 * k, size=20 + k % 7)
        sender.publish(f"x/{origin}", data)
        if oracle.admit(origin, k, len(data), 0.01 * k).cause is None:
            expected.append(data)
    clock.t = 10.0
    got = [item.data for item in transport.drain()]
    assert got == expected
    assert sum(transport.drops.values()) == 200 - len(expected) > 0
    assert {cause for (_, cause) in transport.drops} <= {"loss", "rate"}


def test_truth_foreign_origins_own_echoes_and_unreadable_headers_pass_untouched():
    transport, sender, clock = radio(plan({"loss": 1.0}))  # every radio message is lost
    items = [envelope("world", 1, 0.0, "truth"), envelope("ground", 1, 0.0), envelope("uav0", 1, 0.0),
             b"\x00not an envelope", envelope("uav1", 1, 0.0)]
    for data in items:
        sender.publish("k", data)
    assert [item.data for item in transport.drain()] == items[:4]
    assert transport.drops == {("uav1", "loss"): 1}


def test_delayed_messages_come_after_the_on_time_ones_once_due():
    transport, sender, clock = radio(plan({"delay_ms": 150.0}))
    early = envelope("uav1", 1, 0.0)
    sender.publish("k", early)
    clock.t = 0.1
    assert list(transport.drain()) == []  # due at 0.15
    late = envelope("uav2", 1, 0.05)
    sender.publish("k", late)
    clock.t = 0.3
    assert [item.data for item in transport.drain()] == [late, early]  # late was on time at this drain


def test_range_is_checked_with_the_positions_known_when_each_message_is_admitted():
    where = {"uav0": np.zeros(3), "uav1": np.array([500.0, 0.0, 0.0])}
    transport, sender, clock = radio(plan(range=100.0), positions=lambda: dict(where))
    for seq in (1, 2):
        sender.publish("k", envelope("uav1", seq, 0.0))
    passed = []
    for item in transport.drain():
        passed.append(item.data)
    assert passed == [] and transport.drops == {("uav1", "range"): 2}
    where["uav1"] = np.array([50.0, 0.0, 0.0])  # uav1 comes within range
    for seq in (3, 4):
        sender.publish("k", envelope("uav1", seq, 0.0))
    drained = transport.drain()
    assert peek_header(next(drained).data).seq == 3
    where["uav1"] = np.array([500.0, 0.0, 0.0])  # ... and leaves before the next message is admitted
    assert list(drained) == []
    assert transport.drops[("uav1", "range")] == 3
