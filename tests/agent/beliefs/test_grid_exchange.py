"""The grid exchange protocol: deltas against acknowledged messages, keyframes, loss, late joiners."""

from __future__ import annotations

import numpy as np
import pytest

from agent.beliefs.grid_exchange import GridReceiver, GridSender
from agent.net import wire
from agent.net.grid_codec import quantize

SHAPE = (20, 30)


def _grid_walk(rng, steps: int, layers: int = 1):
    """A grid that changes in a few cells per step, like a camera sweeping over a map."""
    grid = np.zeros((layers, *SHAPE))
    for _ in range(steps):
        cells = rng.integers(0, grid[0].size, size=15)
        for layer in range(layers):
            grid[layer].flat[cells] += rng.normal(0.0, 1.0, size=cells.size)
        yield grid.copy()


def test_first_message_is_a_keyframe_then_deltas_once_acknowledged():
    sender, receiver = GridSender(keyframe_every=100), GridReceiver(SHAPE, 1)
    grids = list(_grid_walk(np.random.default_rng(1), 4))
    modes = []
    for seq, grid in enumerate(grids, start=1):
        payload, quantized = sender.encode(grid, ["b"])
        sender.sent_as(seq, quantized, payload)
        np.testing.assert_array_equal(receiver.decode("a", seq, payload), quantize(grid))
        sender.acknowledge("b", receiver.acks()["a"])
        modes.append(payload["mode"])
    assert modes == ["key", "delta", "delta", "delta"]


def test_no_update_is_lost_when_messages_and_acknowledgements_are_lost():
    """40 % of grid messages and 40 % of the acknowledgements are dropped: every decoded grid equals the
    sender's grid of that message, and the last one that arrives brings everything."""
    rng = np.random.default_rng(7)
    sender, receiver = GridSender(keyframe_every=1000), GridReceiver(SHAPE, 2)
    decoded = 0
    for seq, grid in enumerate(_grid_walk(rng, 60, layers=2), start=1):
        payload, quantized = sender.encode(grid, ["b"])
        sender.sent_as(seq, quantized, payload)
        if rng.random() < 0.4 and seq < 60:
            continue  # the message is lost
        np.testing.assert_array_equal(receiver.decode("a", seq, payload), quantize(grid))
        decoded += 1
        if rng.random() >= 0.4:
            sender.acknowledge("b", receiver.acks()["a"])
    assert decoded >= 25
    assert receiver.acks()["a"] == 60


def test_baseline_is_the_newest_message_every_neighbour_acknowledged():
    sender = GridSender(keyframe_every=100)
    grid = np.zeros((1, *SHAPE))
    for seq in (1, 2, 3):
        payload, quantized = sender.encode(grid + seq, [])
        sender.sent_as(seq, quantized, payload)
    sender.acknowledge("b", 2)
    sender.acknowledge("b", 3)
    sender.acknowledge("c", 2)
    assert sender.baseline(["b", "c"])[0] == 2  # the oldest of the latest acknowledgements, acknowledged by both
    assert sender.baseline(["b"])[0] == 3
    assert sender.baseline(["b", "d"]) is None  # d acknowledged nothing yet: keyframe
    sender.acknowledge("e", 3)
    assert sender.baseline(["c", "e"]) is None  # no message both acknowledged: keyframe


def test_a_newer_acknowledgement_does_not_prove_an_older_message_is_held():
    """b lost message 2 and acknowledged 3; c acknowledged 2 last. A delta on 2 would be rejected by b
    (grid_missing_baseline): the baseline is 1, which both acknowledged, and both decode the delta."""
    sender = GridSender(keyframe_every=100)
    b, c = GridReceiver(SHAPE, 1), GridReceiver(SHAPE, 1)
    grids = list(_grid_walk(np.random.default_rng(5), 4))
    for seq, grid in enumerate(grids[:3], start=1):
        payload, quantized = sender.encode(grid, ["b", "c"])
        sender.sent_as(seq, quantized, payload)
        for name, receiver in (("b", b), ("c", c)):
            if (name, seq) != ("b", 2):  # b loses message 2
                receiver.decode("a", seq, payload)
            if seq == 1 or (name, seq) in {("b", 3), ("c", 2)}:  # the acknowledgements that arrive
                sender.acknowledge(name, receiver.acks()["a"])
    assert sender.baseline(["b", "c"])[0] == 1
    payload, quantized = sender.encode(grids[3], ["b", "c"])
    sender.sent_as(4, quantized, payload)
    assert payload["mode"] == "delta" and payload["base"] == 1
    for receiver in (b, c):
        np.testing.assert_array_equal(receiver.decode("a", 4, payload), quantize(grids[3]))


def test_neighbours_losing_messages_independently_never_miss_a_baseline():
    """Three neighbours, each losing 40 % of the messages and 40 % of its acknowledgements on its own,
    acknowledgements 1..4 messages late, neighbours coming and going, histories of 1..6 (the same on both
    sides): a current neighbour is never sent a delta on a message it does not hold, and every grid decoded
    is the sender's exactly (a peer out of the neighbour set may miss a baseline: it acknowledged nothing)."""
    rng = np.random.default_rng(21)
    peers = ["b", "c", "d"]
    for _ in range(60):
        history = int(rng.integers(1, 7))
        sender = GridSender(keyframe_every=int(rng.integers(2, 12)), history=history)
        receivers = {p: GridReceiver(SHAPE, 1, history=history) for p in peers}
        in_flight: list[tuple[int, str, int]] = []  # (arrival seq, peer, acknowledged seq)
        for seq, grid in enumerate(_grid_walk(rng, 30), start=1):
            for item in [f for f in in_flight if f[0] <= seq]:
                in_flight.remove(item)
                sender.acknowledge(item[1], item[2])
            neighbours = [p for p in peers if rng.random() < 0.8]
            payload, quantized = sender.encode(grid, neighbours)
            sender.sent_as(seq, quantized, payload)
            for peer in peers:  # a peer the sender does not count as a neighbour may hear the message too
                if rng.random() < 0.4:
                    continue  # the message is lost
                try:
                    np.testing.assert_array_equal(receivers[peer].decode("a", seq, payload), quantized)
                except wire.DecodeError as err:
                    assert err.reason == "grid_missing_baseline" and peer not in neighbours, (seq, peer, err)
                    continue
                if rng.random() >= 0.4:
                    in_flight.append((seq + int(rng.integers(1, 5)), peer, receivers[peer].acks()["a"]))


def test_keyframes_every_n_messages_and_when_delta_is_off():
    for delta, expected in ((True, ["key", "delta", "delta", "key", "delta"]), (False, ["key"] * 5)):
        sender = GridSender(keyframe_every=3, delta=delta)
        grid = np.zeros((1, *SHAPE))
        modes = []
        for seq in range(1, 6):
            grid[0, seq, seq] = seq  # one cell changes: a delta is far smaller than a keyframe
            payload, quantized = sender.encode(grid, ["b"])
            sender.sent_as(seq, quantized, payload)
            sender.acknowledge("b", seq)
            modes.append(payload["mode"])
        assert modes == expected


def test_a_late_joiner_waits_for_a_keyframe_and_is_never_given_a_wrong_grid():
    """Receiver c starts listening at message 3 (a delta on message 2, which c never saw)."""
    sender, b, c = GridSender(keyframe_every=4), GridReceiver(SHAPE, 1), GridReceiver(SHAPE, 1)
    grids = list(_grid_walk(np.random.default_rng(3), 6))
    for seq, grid in enumerate(grids, start=1):
        payload, quantized = sender.encode(grid, ["b"])
        sender.sent_as(seq, quantized, payload)
        b.decode("a", seq, payload)
        sender.acknowledge("b", seq)
        if seq >= 3:
            if payload["mode"] == "delta" and "a" not in c.acks():
                with pytest.raises(wire.DecodeError) as err:
                    c.decode("a", seq, payload)
                assert err.value.reason == "grid_missing_baseline"
            else:
                np.testing.assert_array_equal(c.decode("a", seq, payload), quantize(grid))
    assert c.acks()["a"] == 6


def test_a_repeated_or_older_message_is_rejected_as_stale():
    sender, receiver = GridSender(), GridReceiver(SHAPE, 1)
    payload, quantized = sender.encode(np.ones((1, *SHAPE)), [])
    receiver.decode("a", 5, payload)
    for seq in (5, 4):
        with pytest.raises(wire.DecodeError) as err:
            receiver.decode("a", seq, payload)
        assert err.value.reason == "grid_stale"


def test_keyframe_every_must_be_positive():
    with pytest.raises(ValueError, match="keyframe_every"):
        GridSender(keyframe_every=0)
