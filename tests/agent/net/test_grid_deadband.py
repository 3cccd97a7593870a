"""The send-on-delta deadband of agent.net.grid_codec (``tolerance``) and of GridSender.

Oracles: the cells that must travel are found by a Python loop over the documented rule
``|x - b| > q max(1, |b|)``; what a receiver holds is checked against the sender's true grid with the bound
the module docstring states; malformed deltas are still rejected with their reasons."""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.beliefs.grid_exchange import GridReceiver, GridSender
from agent.net.grid_codec import GRID_REASONS, MAX_TOLERANCE, decode_grid, encode_grid, quantize
from agent.net.wire import DecodeError

SHAPE = (12, 15)


def outside_deadband(cur: np.ndarray, base: np.ndarray, q: float) -> list[int]:
    """Brute force: flat cells where some layer moved by more than ``q max(1, |b|)``."""
    L = cur.shape[0]
    flat_cur, flat_base = cur.reshape(L, -1), base.reshape(L, -1)
    return [k for k in range(flat_cur.shape[1])
            if any(abs(flat_cur[i, k] - flat_base[i, k]) > q * max(1.0, abs(flat_base[i, k])) for i in range(L))]


def within_bound(truth: np.ndarray, held: np.ndarray, base: np.ndarray, q: float) -> bool:
    """The module docstring's bound: ``|x - r| <= q max(1, |b|)`` per cell and layer (``b`` the baseline),
    plus float32 rounding."""
    return bool(np.all(np.abs(truth - held) <= q * np.maximum(1.0, np.abs(base)) + 2.0**-23 * np.abs(truth)))


@pytest.mark.parametrize("L", [1, 2])
@pytest.mark.parametrize("q", [0.01, 0.05, 0.2])
def test_a_delta_carries_exactly_the_cells_that_left_the_deadband(L, q):
    rng = np.random.default_rng(11)
    base = quantize(rng.normal(0.0, 5.0, (L, *SHAPE)))
    cur = base * (1.0 + rng.normal(0.0, q, base.shape)) + rng.normal(0.0, q, base.shape)
    payload = encode_grid(cur, base, 3, tolerance=q)
    expected = outside_deadband(cur, base, q)
    assert 0 < len(expected) < cur[0].size  # the draw puts cells on both sides of the deadband
    held = decode_grid(payload, SHAPE, L, {3: base}.get)
    moved = np.flatnonzero(np.any((held != base).reshape(L, -1), axis=0))
    assert payload["n"] == len(expected) and moved.tolist() == expected
    flat_held, flat_cur, flat_base = held.reshape(L, -1), cur.reshape(L, -1), base.reshape(L, -1)
    step = q * np.maximum(1.0, np.abs(flat_base[:, expected]))  # sent cells: the nearest whole number of steps
    rebuilt = flat_base[:, expected] + np.rint((flat_cur[:, expected] - flat_base[:, expected]) / step) * step
    crossed = (np.sign(rebuilt) == -np.sign(flat_base[:, expected])) & (np.abs(rebuilt) <= step / 2)
    np.testing.assert_array_equal(flat_held[:, expected], quantize(np.where(crossed, 0.0, rebuilt)))
    kept = np.setdiff1d(np.arange(cur[0].size), expected)
    np.testing.assert_array_equal(flat_held[:, kept], flat_base[:, kept])  # the rest keep the baseline's value
    assert within_bound(cur, held, base, q)


@pytest.mark.parametrize("q", [0.01, 0.1, 0.5])
def test_counts_never_become_negative_by_rounding(q):
    """Non-negative counts moving anywhere in [0, 3], zero included: no rebuilt count is negative (a step
    rounding past zero from a positive baseline gives 0); values of either sign: within the bound."""
    rng = np.random.default_rng(int(q * 100))
    for _ in range(30):
        base = quantize(rng.uniform(0.0, 3.0, (2, *SHAPE)) * (rng.random((2, *SHAPE)) < 0.7))
        cur = rng.uniform(0.0, 3.0, base.shape) * (rng.random(base.shape) < 0.5)
        held = decode_grid(encode_grid(cur, base, 1, tolerance=q), SHAPE, 2, {1: base}.get)
        assert held.min() >= 0.0 and within_bound(cur, held, base, q)
        signed = quantize(rng.normal(0.0, 2.0, base.shape))
        moved = signed + rng.normal(0.0, 1.0, base.shape)
        held = decode_grid(encode_grid(moved, signed, 1, tolerance=q), SHAPE, 2, {1: signed}.get)
        assert within_bound(moved, held, signed, q)


def test_zero_tolerance_sends_every_float32_change():
    rng = np.random.default_rng(2)
    base = quantize(rng.normal(0.0, 5.0, (1, *SHAPE)))
    cur = base + 1e-5
    held = decode_grid(encode_grid(cur, base, 1, tolerance=0.0), SHAPE, 1, {1: base}.get)
    np.testing.assert_array_equal(held, quantize(cur))
    held = decode_grid(encode_grid(cur, base, 1, tolerance=1e-3), SHAPE, 1, {1: base}.get)
    np.testing.assert_array_equal(held, base)  # every move below the deadband: nothing travels


def test_a_slow_drift_travels_once_it_leaves_the_deadband_and_never_lags_more():
    """Every cell drifts by 0.1 q to 0.5 q per message (relative to 1 or its magnitude): the receiver's copy
    never lags beyond the bound, and a cell travels every few messages, not every message."""
    q = 0.05
    rng = np.random.default_rng(4)
    sender, receiver = GridSender(keyframe_every=1000, tolerance=q), GridReceiver(SHAPE, 1)
    grid = rng.normal(0.0, 3.0, (1, *SHAPE))
    rate = rng.uniform(0.1, 0.5, SHAPE) * q
    travelled, before = 0, np.zeros_like(grid)
    for seq in range(1, 41):
        grid = grid + rate * np.maximum(1.0, np.abs(grid))
        payload, held = sender.encode(grid, ["b"])
        sender.sent_as(seq, held, payload)
        decoded = receiver.decode("a", seq, payload)
        np.testing.assert_array_equal(decoded, held)  # the sender records exactly what the receiver holds
        assert within_bound(grid, decoded, before, q) or payload["mode"] == "key"
        before = decoded
        sender.acknowledge("b", receiver.acks()["a"])
        travelled += payload["n"] if payload["mode"] == "step" else grid.size
    assert travelled < 0.5 * 40 * grid.size  # a cell travels on average less than every other message


def test_a_keyframe_is_exact_whatever_the_tolerance():
    sender = GridSender(keyframe_every=2, tolerance=0.2)
    grid = np.random.default_rng(8).normal(0.0, 3.0, (2, *SHAPE))
    payload, held = sender.encode(grid, [])
    assert payload["mode"] == "key"
    np.testing.assert_array_equal(held, quantize(grid))


@pytest.mark.parametrize("bad", [-0.01, MAX_TOLERANCE + 0.01, float("nan"), float("inf"), True, "0.1", None])
def test_a_bad_tolerance_is_a_value_error_naming_it(bad):
    base = np.zeros((1, *SHAPE))
    with pytest.raises(ValueError, match="tolerance"):
        encode_grid(base, base, 1, tolerance=bad)
    with pytest.raises(ValueError, match="tolerance"):
        GridSender(tolerance=bad)


def test_a_malformed_deadband_delta_is_still_rejected_with_its_reason():
    """A deadband delta, changed in one respect each time: the decoder's checks do not depend on the tolerance."""
    rng = np.random.default_rng(6)
    base = quantize(rng.normal(0.0, 5.0, (1, *SHAPE)))
    cur = base.copy()
    cur[0, 2, 3:9] = 2.0 * cur[0, 2, 3:9] + 1.0  # six cells leave the deadband
    cur[0, 5] *= 1.01  # a row that stays inside it
    good = encode_grid(cur, base, 9, tolerance=0.05)
    assert good["mode"] == "step" and good["n"] == 6 and good["vtype"] == "i1"
    for change, reason in [
        ({"n": good["n"] + 1}, "grid_corrupt"),  # the index then holds too few gaps
        ({"values": zlib.compress(bytes(5))}, "grid_corrupt"),  # five steps for six cells
        ({"values": b"not zlib"}, "grid_corrupt"),
        ({"values": [1, 2]}, "grid_corrupt"),
        ({"q": float("nan")}, "grid_bad_values"), ({"q": 0.0}, "grid_bad_values"), ({"q": 0.9}, "grid_bad_values"),
        ({"q": "0.05"}, "grid_bad_values"), ({"vtype": "f4"}, "grid_bad_values"),
        ({"base": 8}, "grid_missing_baseline"), ({"dtype": "f4"}, "grid_bad_index"),
        ({"shape": [SHAPE[0], SHAPE[1] + 1]}, "grid_bad_shape"),
        ({"mode": "delta"}, "grid_bad_mode"),  # a float32 delta has no q nor vtype
        ({"tolerance": 0.05}, "grid_bad_mode"),
    ]:
        with pytest.raises(DecodeError) as err:
            decode_grid({**good, **change}, SHAPE, 1, {9: base}.get)
        assert err.value.reason == reason, (change, err.value)


def test_steps_that_rebuild_a_value_beyond_float32_are_bad_values():
    base = quantize(np.random.default_rng(1).normal(0.0, 5.0, (1, *SHAPE)))
    base[0, 0, 0] = 3e38  # a step of 1.5e38 at q = 0.5
    cur = base.copy()
    cur[0, 0, 0] = 3.3e38
    good = encode_grid(cur, base, 2, tolerance=0.05)
    assert good["mode"] == "step" and good["n"] == 1
    overflow = {**good, "q": 0.5, "values": zlib.compress(np.array([1], "i1").tobytes())}  # 3e38 + 1.5e38
    with pytest.raises(DecodeError) as err:
        decode_grid(overflow, SHAPE, 1, {2: base}.get)
    assert err.value.reason == "grid_bad_values"


def test_a_jump_too_large_for_32_bit_steps_travels_as_float32():
    base = quantize(np.random.default_rng(2).uniform(-0.5, 0.5, (1, *SHAPE)))
    cur = base.copy()
    cur[0, 3, 4] = 1e8  # 1e8 / (0.01 * 1) steps > 2**31
    payload = encode_grid(cur, base, 2, tolerance=0.01)
    assert payload["mode"] == "delta" and payload["n"] == 1
    np.testing.assert_array_equal(decode_grid(payload, SHAPE, 1, {2: base}.get), quantize(cur))


def _valid_step() -> tuple[dict, np.ndarray]:
    base = quantize(np.random.default_rng(12).normal(0.0, 5.0, (1, *SHAPE)))
    cur = base.copy()
    cur[0, 4, 2:7] += 3.0
    payload = encode_grid(cur, base, 9, tolerance=0.05)
    assert payload["mode"] == "step" and payload["n"] == 5
    return payload, base


@settings(max_examples=200, deadline=None)
@given(field=st.sampled_from(["base", "L", "shape", "n", "dtype", "index", "values", "q", "vtype", "mode"]),
       value=st.one_of(st.integers(-3, 300), st.floats(allow_nan=True), st.binary(max_size=40),
                       st.sampled_from(["i1", "i2", "i4", "u1", "step", "delta"]), st.none()))
def test_fuzzed_step_deltas_raise_only_decode_error(field, value):
    good, base = _valid_step()
    try:
        out = decode_grid({**good, field: value}, SHAPE, 1, {9: base}.get)
    except DecodeError as err:
        assert err.reason in GRID_REASONS
    else:
        assert out.shape == (1, *SHAPE) and np.all(np.isfinite(out))
