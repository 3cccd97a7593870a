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


def test_baseline_is_the_oldest_acknowledgement_among_neighbours():
    sender = GridSender(keyframe_every=100)
    grid = np.zeros((1, *SHAPE))
    for seq in (1, 2, 3):
        payload, quantized = sender.encode(grid + seq, [])
        sender.sent_as(seq, quantized, payload)
    sender.acknowledge("b", 3)
    sender.acknowledge("c", 2)
    assert sender.baseline(["b", "c"])[0] == 2
    assert sender.baseline(["b"])[0] == 3
    assert sender.baseline(["b", "d"]) is None  # d acknowledged nothing yet: keyframe


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
