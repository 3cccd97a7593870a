"""agent.net.grid_codec: exact round trips of keyframes and deltas, the index coding, the keyframe fallback,
no lost update under message loss with delayed acknowledgements, one test per class of bad input (each
a valid payload changed in one respect, with the reason it must raise), and the message history.

Oracles: float32 round trips computed with numpy directly; changed cells found by a Python loop over
float32 bit patterns; deltas built by hand from the format in the module docstring."""

from __future__ import annotations

import struct
import zlib

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from agent.net import wire
from agent.net.grid_codec import (
    GRID_REASONS,
    KEYFRAME_PROBE_FRACTION,
    ZLIB_LEVEL,
    GridHistory,
    decode_grid,
    encode_grid,
    encoded_size,
    quantize,
)
from agent.net.wire import DecodeError

SHAPES = [(1, 1), (1, 9), (9, 1), (5, 7), (256, 256)]


# -- helpers -----------------------------------------------------------------------------------------
def random_layers(rng: np.random.Generator, L: int, shape, scale: float = 3.0) -> np.ndarray:
    return rng.normal(0.0, scale, (L, *shape))


def explored(rng: np.random.Generator, L: int, shape) -> np.ndarray:
    """Half of the cells hold evidence, the rest the prior 0 (what the benchmark measures too)."""
    layers = np.zeros((L, *shape))
    mask = rng.random(shape) < 0.5
    layers[:, mask] = rng.normal(0.0, 2.0, (L, int(mask.sum())))
    return layers


def change(rng: np.random.Generator, layers: np.ndarray, fraction: float) -> np.ndarray:
    out = layers.copy()
    mask = rng.random(layers.shape[1:]) < fraction
    out[:, mask] += rng.normal(0.0, 1.0, (layers.shape[0], int(mask.sum())))
    return out


def lookup(table: dict[int, np.ndarray]):
    return table.get


def decode(payload, layers: np.ndarray | tuple, base: np.ndarray | None = None, base_seq: int = 7):
    L, rows, cols = layers.shape if isinstance(layers, np.ndarray) else layers
    return decode_grid(payload, (rows, cols), L, lookup({} if base is None else {base_seq: base}))


def float32_bits_differ(a: np.ndarray, b: np.ndarray) -> list[int]:
    """Brute force: flat cells whose float32 bit pattern differs in any layer."""
    L, rows, cols = a.shape
    out = []
    for k in range(rows * cols):
        r, c = divmod(k, cols)
        if any(struct.pack("<f", a[layer, r, c]) != struct.pack("<f", b[layer, r, c]) for layer in range(L)):
            out.append(k)
    return out


def hand_delta(cur: np.ndarray, base: np.ndarray, base_seq: int) -> dict:
    """A delta written from the documented format, independently of the codec."""
    L, rows, cols = cur.shape
    flat32 = cur.astype("<f4").reshape(L, -1)
    idx = np.flatnonzero(np.any(flat32.view("<u4") != base.astype("<f4").reshape(L, -1).view("<u4"), axis=0))
    gaps = np.diff(idx, prepend=-1)
    top = int(gaps.max()) if gaps.size else 0
    dtype = "u1" if top < 2**8 else "u2" if top < 2**16 else "u4"
    return {
        "mode": "delta", "base": base_seq, "L": L, "shape": [rows, cols], "n": int(idx.size), "dtype": dtype,
        "index": zlib.compress(gaps.astype({"u1": "u1", "u2": "<u2", "u4": "<u4"}[dtype]).tobytes()),
        "values": flat32[:, idx].tobytes(),
    }


def valid_delta(L: int = 1, shape=(4, 5), cells=(1, 2, 9)) -> tuple[dict, np.ndarray, np.ndarray]:
    """(payload, baseline, expected result) of a small delta with known changed cells."""
    rng = np.random.default_rng(3)
    base = quantize(random_layers(rng, L, shape))
    cur = base.copy()
    for k in cells:
        cur.reshape(L, -1)[:, k] += 1.5
    return encode_grid(cur, base, 7), base, quantize(cur)


def expect_reason(reason: str, payload, L: int = 1, shape=(4, 5), base: np.ndarray | None = None) -> None:
    assert reason in GRID_REASONS
    with pytest.raises(DecodeError) as err:
        decode_grid(payload, shape, L, lookup({} if base is None else {7: base}))
    assert err.value.reason == reason, err.value


# -- quantization -------------------------------------------------------------------------------------
def test_quantize_is_a_float32_round_trip():
    x = np.array([0.1, -1e-30, 1e30, 3.0, -0.0, 123456789.123])
    q = quantize(x)
    assert q.dtype == np.float64
    assert np.array_equal(q, np.array([float(np.float32(v)) for v in x]))
    assert np.signbit(q[4])  # -0.0 keeps its sign
    assert np.array_equal(quantize(q), q)  # idempotent
    assert np.all(np.abs(q - x) <= np.abs(x) * 2.0**-24)
    largest = float(np.finfo(np.float32).max)
    assert quantize(np.array([largest, -largest])).tolist() == [largest, -largest]
    assert quantize(np.zeros((0, 3))).shape == (0, 3)


@pytest.mark.parametrize("bad", [np.array([np.nan]), np.array([np.inf]), np.array([1e39]), np.array([-3.5e38]),
                                 np.array([True])],
                         ids=["nan", "inf", "beyond-float32-range", "just-below-float32-range", "bool-dtype"])
def test_quantize_rejects_nan_inf_overflow_and_non_numeric(bad):
    with pytest.raises(ValueError):
        quantize(bad)


# -- round trips -------------------------------------------------------------------------------------
@pytest.mark.parametrize("L", [1, 2])
@pytest.mark.parametrize("shape", SHAPES)
def test_keyframe_round_trip_is_exact(L, shape):
    layers = random_layers(np.random.default_rng(1), L, shape)
    payload = encode_grid(layers, None, None)
    assert payload["mode"] == "key" and "base" not in payload
    out = decode(payload, layers)
    assert out.dtype == np.float64 and out.shape == layers.shape
    assert np.array_equal(out, quantize(layers))
    assert np.array_equal(out.view(np.uint64), quantize(layers).view(np.uint64))  # bit for bit


@pytest.mark.parametrize("L", [1, 2])
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("fraction", [0.0, 0.01, 0.3, 1.0], ids=["no-change", "sparse", "many", "all-cells"])
def test_delta_round_trip_is_exact(L, shape, fraction):
    rng = np.random.default_rng(2)
    base = quantize(explored(rng, L, shape))
    cur = change(rng, base, fraction) if fraction < 1.0 else base + 0.25
    payload = encode_grid(cur, base, 7)
    out = decode(payload, cur, base)
    assert np.array_equal(out.view(np.uint64), quantize(cur).view(np.uint64))
    if fraction == 0.0 and len(payload["values"]) > 100:  # a grid whose keyframe is larger than an empty delta
        assert payload["mode"] == "delta" and payload["n"] == 0 and payload["base"] == 7
    if fraction == 0.0 and shape == (1, 1):  # an empty delta (~50 bytes) is larger than this keyframe
        assert payload["mode"] == "key"


def test_delta_lists_exactly_the_cells_whose_float32_bits_changed():
    rng = np.random.default_rng(4)
    base = quantize(random_layers(rng, 2, (6, 7)))
    cur = base.copy()
    cur[0, 1, 2] += 1.0  # changed in layer 0 only
    cur[1, 5, 6] -= 2.0  # changed in layer 1 only
    cur[:, 3, 3] += 0.5  # both layers
    cur[0, 0, 0] += 1e-12  # below float32 resolution: not a change on the wire
    base[1, 4, 4], cur[1, 4, 4] = 0.0, -0.0  # same value, other bits: sent
    payload = encode_grid(cur, base, 3)
    expected = float32_bits_differ(cur, base)
    assert expected == [1 * 7 + 2, 3 * 7 + 3, 4 * 7 + 4, 5 * 7 + 6]
    gaps = np.frombuffer(zlib.decompress(payload["index"]), dtype={"u1": "u1", "u2": "<u2"}[payload["dtype"]])
    assert (np.cumsum(gaps) - 1).tolist() == expected
    values = np.frombuffer(payload["values"], "<f4").reshape(2, len(expected))  # layer-major (L, k)
    assert np.array_equal(values, cur.astype(np.float32).reshape(2, -1)[:, expected])
    out = decode(payload, cur, base, 3)
    assert np.signbit(out[1, 4, 4]) and np.array_equal(out, quantize(cur))


def test_delta_against_an_unquantized_baseline_compares_in_float32():
    """The sender may pass its float64 record; the receiver holds its quantization: same result."""
    rng = np.random.default_rng(5)
    base = random_layers(rng, 1, (8, 8))
    cur = change(rng, base, 0.2)
    out = decode(encode_grid(cur, base, 7), cur, quantize(base))
    assert np.array_equal(out, quantize(cur))


def test_decode_does_not_modify_the_baseline():
    payload, base, expected = valid_delta()
    history = GridHistory()
    history.put(7, base)
    stored = history.get(7).copy()
    out = decode_grid(payload, (4, 5), 1, history.get)
    assert np.array_equal(out, expected) and np.array_equal(history.get(7), stored)
    assert out.flags.writeable


@pytest.mark.parametrize(
    ("cells", "size", "dtype"),
    [
        ((0, 255), 600, "u1"),  # largest gap 255
        ((0, 256), 600, "u2"),  # 256
        ((3, 3 + 65535), 70_000, "u2"),  # 65535
        ((3, 3 + 65536), 70_000, "u4"),  # 65536
        ((0, 89_999), 90_000, "u4"),  # > 65535 on a 300x300 grid
    ],
)
def test_index_dtype_is_the_smallest_that_holds_the_largest_gap(cells, size, dtype):
    shape = (300, 300) if size == 90_000 else (1, size)
    base = quantize(random_layers(np.random.default_rng(size), 1, shape))  # a keyframe would be large
    cur = base.copy()
    cur.reshape(-1)[list(cells)] += 1.0
    payload = encode_grid(cur, base, 1)
    assert payload["mode"] == "delta" and payload["dtype"] == dtype and payload["n"] == 2
    assert np.array_equal(decode(payload, cur, base, 1), quantize(cur))


def test_first_changed_cell_gap_counts_from_minus_one():
    base = quantize(random_layers(np.random.default_rng(14), 1, (1, 600)))
    cur = base.copy()
    cur[0, 0, 255] += 1.0  # first index 255 -> gap 256
    assert encode_grid(cur, base, 1)["dtype"] == "u2"
    cur = base.copy()
    cur[0, 0, 254] += 1.0  # gap 255
    assert encode_grid(cur, base, 1)["dtype"] == "u1"


# -- sizes and the keyframe fallback ------------------------------------------------------------------
def test_sparse_delta_is_much_smaller_than_a_keyframe():
    rng = np.random.default_rng(6)
    base = quantize(explored(rng, 1, (256, 256)))
    cur = change(rng, base, 0.01)
    delta, key = encode_grid(cur, base, 1), encode_grid(cur, None, None)
    assert delta["mode"] == "delta"
    assert encoded_size(delta) < 0.2 * encoded_size(key)
    assert encoded_size(delta) < 0.05 * encoded_size(key)  # measured ~2.4 %


def test_empty_delta_costs_a_few_dozen_bytes():
    base = quantize(random_layers(np.random.default_rng(7), 2, (256, 256)))
    payload = encode_grid(base, base, 12345)
    assert payload["mode"] == "delta" and payload["n"] == 0
    assert encoded_size(payload) < 100


@pytest.mark.parametrize("L", [1, 2])
def test_falls_back_to_a_keyframe_when_most_cells_changed(L):
    rng = np.random.default_rng(8)
    base = quantize(explored(rng, L, (128, 128)))
    cur = change(rng, base, 0.9)
    payload = encode_grid(cur, base, 1)
    assert payload["mode"] == "key" and "base" not in payload
    assert encoded_size(payload) < encoded_size(hand_delta(cur, base, 1))
    assert payload["values"] == zlib.compress(cur.astype("<f4").tobytes(), ZLIB_LEVEL)  # the plain keyframe
    assert np.array_equal(decode(payload, cur), quantize(cur))


def test_falls_back_when_a_constant_grid_compresses_better_than_the_delta():
    base = np.zeros((1, 64, 64))
    cur = np.full((1, 64, 64), 0.847)  # every cell changed to one value: the keyframe is tiny
    payload = encode_grid(cur, base, 1)
    assert payload["mode"] == "key" and encoded_size(payload) < 200


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), fraction=st.floats(0.0, 1.0), zero_fraction=st.floats(0.0, 1.0),
       L=st.sampled_from([1, 2]))
def test_message_is_never_larger_than_a_keyframe_unless_below_the_probe_fraction(seed, fraction, zero_fraction, L):
    """The documented rule: a delta above KEYFRAME_PROBE_FRACTION of the raw keyframe is sent only if no
    larger than the keyframe; below it, the delta is sent as is."""
    rng = np.random.default_rng(seed)
    base = rng.normal(0.0, 2.0, (L, 40, 50))
    base[:, rng.random((40, 50)) < zero_fraction] = 0.0
    base = quantize(base)
    cur = change(rng, base, fraction)
    payload = encode_grid(cur, base, 1)
    key_size = encoded_size(encode_grid(cur, None, None))
    delta = hand_delta(cur, base, 1)
    delta_size = encoded_size(delta)
    if delta_size <= KEYFRAME_PROBE_FRACTION * cur.size * 4:
        assert payload == delta
    else:
        assert encoded_size(payload) == min(key_size, delta_size)
    assert np.array_equal(decode(payload, cur, base, 1), quantize(cur))


def test_keyframe_check_stops_once_the_keyframe_cannot_be_smaller():
    """The probe returns ``None`` exactly when the bytes zlib emitted so far reach ``stop_at`` (a lower
    bound of the keyframe), and the plain zlib stream otherwise."""
    from agent.net.grid_codec import PROBE_CHUNK, _deflate

    raw = np.random.default_rng(15).normal(size=PROBE_CHUNK).astype("<f4").tobytes()  # 4 chunks, incompressible
    assert _deflate(raw, None) == zlib.compress(raw, ZLIB_LEVEL)
    assert _deflate(raw, len(raw) * 2) == zlib.compress(raw, ZLIB_LEVEL)
    assert _deflate(raw, 1000) is None  # stops after a chunk, long before the 4 chunks are compressed
    zeros = bytes(len(raw))
    assert _deflate(zeros, 1000) == zlib.compress(zeros, ZLIB_LEVEL)  # compressible: never reaches 1000 bytes


def test_payload_travels_in_a_wire_envelope():
    payload, base, expected = valid_delta(L=2)
    env = wire.Envelope(kind="grid", origin="uav1", seq=8, stamp=1.0, payload={"grid": payload})
    received = wire.decode(wire.encode(env))
    assert np.array_equal(decode_grid(received.payload["grid"], (4, 5), 2, lookup({7: base})), expected)
    assert encoded_size(payload) == len(msgpack.packb(payload, use_bin_type=True))


# -- no update is lost when messages are lost -------------------------------------------------------
def simulate_lossy_link(seed: int, steps: int, loss: float, max_delay: int, L: int, shape, capacity: int = 16,
                        receiver_capacity: int | None = None):
    """Sender: each step some cells get evidence, then it sends a delta against the newest message the
    receiver acknowledged (a keyframe before any acknowledgement or once that message left its history).
    Receiver: acknowledges every message it decodes; messages and acknowledgements are lost with
    probability ``loss``; an acknowledgement arrives 1..max_delay steps later. A delta whose baseline the
    receiver no longer holds (its history shorter than the sender's, or than the acknowledgement delay) is
    rejected, never applied.
    After ``steps`` the grid stops changing and the sender keeps sending until a message is decoded.
    Returns counters of decoded keyframes/deltas, lost messages and missing baselines."""
    rng = np.random.default_rng(seed)
    local = np.zeros((L, *shape))
    sent, received = GridHistory(capacity), GridHistory(capacity if receiver_capacity is None else receiver_capacity)
    acked: int | None = None
    in_flight: list[tuple[int, int]] = []  # (arrival step, acknowledged seq)
    counts = {"delta": 0, "key": 0, "lost": 0, "missing": 0}

    def send(seq: int) -> bool:
        nonlocal acked
        for arrival, seq_acked in [a for a in in_flight if a[0] <= seq]:
            in_flight.remove((arrival, seq_acked))
            acked = seq_acked if acked is None else max(acked, seq_acked)
        base = None if acked is None else sent.get(acked)
        payload = encode_grid(local, base, None if base is None else acked)
        sent.put(seq, quantize(local))
        if rng.random() < loss:
            counts["lost"] += 1
            return False
        try:
            out = decode_grid(payload, shape, L, received.get)
        except DecodeError as err:
            assert err.reason == "grid_missing_baseline", err
            counts["missing"] += 1
            return False
        assert np.array_equal(out.view(np.uint64), sent.get(seq).view(np.uint64)), f"wrong grid at {seq}"
        received.put(seq, out)
        counts[payload["mode"]] += 1
        if rng.random() >= loss:
            in_flight.append((seq + int(rng.integers(1, max_delay + 1)), seq))
        return True

    for seq in range(steps):
        mask = rng.random(shape) < rng.choice([0.0, 0.02, 0.2, 0.8])
        local[:, mask] += rng.normal(0.0, 1.0, (L, int(mask.sum())))
        send(seq)
    seq = steps
    while not send(seq):  # the next message that arrives carries everything
        seq += 1
        assert seq < steps + 1000, "the receiver never caught up"
    assert np.array_equal(received.latest()[1], quantize(local))
    return counts


def test_no_update_is_lost_with_40_percent_loss_and_delayed_acks():
    counts = simulate_lossy_link(seed=11, steps=50, loss=0.4, max_delay=4, L=1, shape=(40, 60))
    assert counts["lost"] >= 10 and counts["delta"] >= 10 and counts["key"] >= 1, counts
    assert counts["missing"] == 0  # the receiver holds every message it acknowledged


def test_no_update_is_lost_for_a_beta_grid():
    counts = simulate_lossy_link(seed=12, steps=50, loss=0.4, max_delay=3, L=2, shape=(30, 30))
    assert counts["lost"] >= 10 and counts["delta"] >= 10 and counts["missing"] == 0, counts


def test_a_receiver_that_forgot_the_baseline_rejects_the_delta_and_catches_up():
    """A receiver history of 1 and acknowledgements 3 steps late: deltas on forgotten baselines are
    rejected (grid_missing_baseline), and the final grid still arrives exactly."""
    counts = simulate_lossy_link(seed=13, steps=30, loss=0.0, max_delay=3, L=1, shape=(10, 10), receiver_capacity=1)
    assert counts["missing"] >= 1, counts


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), steps=st.integers(1, 30), loss=st.floats(0.0, 0.8),
       max_delay=st.integers(1, 6), L=st.sampled_from([1, 2]), rows=st.integers(1, 12), cols=st.integers(1, 12),
       capacity=st.integers(1, 8), receiver_capacity=st.integers(1, 8))
@example(seed=343, steps=4, loss=0.25, max_delay=1, L=1, rows=3, cols=6, capacity=4, receiver_capacity=2)
def test_property_no_update_is_lost(seed, steps, loss, max_delay, L, rows, cols, capacity, receiver_capacity):
    """Always (inside simulate_lossy_link): every decoded grid is the sender's, exactly, and the first message
    that arrives after the grid stops changing brings all of it. No delta is rejected for a missing baseline
    when the receiver remembers as many messages as the sender (the sender's baseline is among its last
    ``capacity`` messages, the receiver decoded it and keeps its last ``receiver_capacity >= capacity``), nor
    without loss when it remembers ``max_delay`` (every acknowledgement then arrives within ``max_delay``
    steps). The acknowledgement delay alone bounds nothing under loss: lost acknowledgements keep the sender
    on an old baseline while the receiver decodes newer messages and drops it (the explicit example: receiver
    history 2 < sender history 4, delay 1; message 1 and the acknowledgements of messages 2 and 3 lost, so
    message 4 is a delta on message 0, which the receiver dropped when it decoded 3)."""
    counts = simulate_lossy_link(seed, steps, loss, max_delay, L, (rows, cols), capacity, receiver_capacity)
    if receiver_capacity >= capacity or (loss == 0.0 and receiver_capacity >= max_delay):
        assert counts["missing"] == 0, counts


# -- bad input: one defect per message ---------------------------------------------------------------
def test_grid_reasons_are_wire_reasons():
    assert GRID_REASONS <= wire.REASONS


def test_valid_delta_decodes():
    payload, base, expected = valid_delta()
    assert np.array_equal(decode_grid(payload, (4, 5), 1, lookup({7: base})), expected)


@pytest.mark.parametrize("payload", [None, [1, 2], b"\x80", "key", 3], ids=["none", "list", "bytes", "str", "int"])
def test_non_dict_payload_is_bad_mode(payload):
    expect_reason("grid_bad_mode", payload)


@pytest.mark.parametrize("mode", ["full", "", None, 1, b"key"])
def test_unknown_mode_is_bad_mode(mode):
    payload, base, _ = valid_delta()
    expect_reason("grid_bad_mode", {**payload, "mode": mode}, base=base)


def test_missing_mode_is_bad_mode():
    payload, base, _ = valid_delta()
    del payload["mode"]
    expect_reason("grid_bad_mode", payload, base=base)


def test_missing_field_is_bad_mode():
    payload, base, _ = valid_delta()
    del payload["values"]
    expect_reason("grid_bad_mode", payload, base=base)


def test_unknown_extra_field_is_bad_mode():
    payload, base, _ = valid_delta()
    expect_reason("grid_bad_mode", {**payload, "extra": 1}, base=base)


def test_keyframe_carrying_a_base_is_bad_mode():
    key = encode_grid(np.zeros((1, 4, 5)), None, None)
    expect_reason("grid_bad_mode", {**key, "base": 7})


@pytest.mark.parametrize("base", [-1, 2**64, "7", 7.0, True, None], ids=["negative", "too-big", "str", "float",
                                                                         "bool", "none"])
def test_malformed_base_seq_is_bad_mode(base):
    payload, stored, _ = valid_delta()
    expect_reason("grid_bad_mode", {**payload, "base": base}, base=stored)


def test_wrong_layer_count_is_bad_shape():
    payload, base, _ = valid_delta(L=2)
    expect_reason("grid_bad_shape", payload, L=1, base=base[:1])
    key = encode_grid(np.zeros((1, 4, 5)), None, None)
    expect_reason("grid_bad_shape", key, L=2)


@pytest.mark.parametrize("shape", [[5, 4], [4, 6], [20, 1]], ids=["transposed", "more-cols", "same-size-other-shape"])
def test_wrong_grid_shape_is_bad_shape(shape):
    payload, base, _ = valid_delta()
    expect_reason("grid_bad_shape", {**payload, "shape": shape}, base=base)


@pytest.mark.parametrize("shape", [[4], [4, 5, 1], "4x5", [4.0, 5.0], None], ids=["one-int", "three-ints", "str",
                                                                                 "floats", "none"])
def test_malformed_shape_field_is_bad_shape(shape):
    key = encode_grid(np.zeros((1, 4, 5)), None, None)
    expect_reason("grid_bad_shape", {**key, "shape": shape})


@pytest.mark.parametrize("L", ["1", 1.0, None, True], ids=["str", "float", "none", "bool"])
def test_malformed_layer_count_is_bad_shape(L):
    key = encode_grid(np.zeros((1, 4, 5)), None, None)
    expect_reason("grid_bad_shape", {**key, "L": L})


def _delta_with_gaps(gaps, dtype: str = "u1", values: int | None = None) -> dict:
    payload, _, _ = valid_delta()
    arr = np.asarray(gaps).astype({"u1": "u1", "u2": "<u2", "u4": "<u4"}[dtype])
    n = len(gaps)
    return {**payload, "n": n, "dtype": dtype, "index": zlib.compress(arr.tobytes()),
            "values": np.ones(n if values is None else values, "<f4").tobytes()}


def test_index_out_of_range_is_bad_index():
    base = valid_delta()[1]
    assert decode_grid(_delta_with_gaps([1, 19]), (4, 5), 1, lookup({7: base}))[0, 3, 4] == 1.0  # last cell: fine
    expect_reason("grid_bad_index", _delta_with_gaps([1, 20]), base=base)  # index 20 in a 20-cell grid


def test_repeated_index_zero_gap_is_bad_index():
    expect_reason("grid_bad_index", _delta_with_gaps([3, 0, 2]), base=valid_delta()[1])


def test_decreasing_index_written_as_a_wrapped_gap_is_bad_index():
    """Indices 5 then 4: the gap -1 can only be written as 2**16 - 1 in u2, which leaves the grid."""
    expect_reason("grid_bad_index", _delta_with_gaps([6, 2**16 - 1], "u2"), base=valid_delta()[1])


def test_huge_u4_gaps_do_not_wrap_around_into_the_grid():
    """Gaps summing to 2**32 + 3 would land on cell 2 modulo 2**32: rejected, not wrapped."""
    expect_reason("grid_bad_index", _delta_with_gaps([2**31, 2**31, 3], "u4"), base=valid_delta()[1])


@pytest.mark.parametrize("dtype", ["i2", "u8", "f4", "", 2, None])
def test_unknown_index_dtype_is_bad_index(dtype):
    payload, base, _ = valid_delta()
    expect_reason("grid_bad_index", {**payload, "dtype": dtype}, base=base)


@pytest.mark.parametrize("n", [-1, 21, 2**70, 3.0, "3", True, None], ids=["negative", "more-than-cells", "huge",
                                                                         "float", "str", "bool", "none"])
def test_bad_changed_cell_count_is_bad_index(n):
    payload, base, _ = valid_delta()
    expect_reason("grid_bad_index", {**payload, "n": n}, base=base)


def test_nan_value_in_a_delta_is_bad_values():
    payload, base, _ = valid_delta()
    values = np.frombuffer(payload["values"], "<f4").copy()
    values[1] = np.nan
    expect_reason("grid_bad_values", {**payload, "values": values.tobytes()}, base=base)


def test_inf_value_in_a_keyframe_is_bad_values():
    layers = np.zeros((1, 4, 5), "<f4")
    layers[0, 2, 3] = np.inf
    key = {"mode": "key", "L": 1, "shape": [4, 5], "values": zlib.compress(layers.tobytes())}
    expect_reason("grid_bad_values", key)


@pytest.mark.parametrize("count", [2, 4, 0], ids=["one-value-missing", "one-value-extra", "no-values"])
def test_value_count_not_matching_the_indices_is_bad_values(count):
    expect_reason("grid_bad_values", _delta_with_gaps([1, 2, 3], values=count), base=valid_delta()[1])


def test_two_layer_delta_with_one_layer_of_values_is_bad_values():
    payload, base, _ = valid_delta(L=2)
    half = len(payload["values"]) // 2
    expect_reason("grid_bad_values", {**payload, "values": payload["values"][:half]}, L=2, base=base)


def test_baseline_the_receiver_does_not_hold_is_missing_baseline():
    payload, base, _ = valid_delta()
    expect_reason("grid_missing_baseline", payload)  # holds nothing
    expect_reason("grid_missing_baseline", {**payload, "base": 6}, base=base)  # holds 7, not 6


def test_truncated_keyframe_bytes_are_corrupt():
    key = encode_grid(random_layers(np.random.default_rng(9), 1, (4, 5)), None, None)
    expect_reason("grid_corrupt", {**key, "values": key["values"][:-3]})


def test_truncated_index_bytes_are_corrupt():
    payload, base, _ = valid_delta()
    expect_reason("grid_corrupt", {**payload, "index": payload["index"][:-1]}, base=base)


def test_values_not_a_whole_number_of_float32_are_corrupt():
    payload, base, _ = valid_delta()
    expect_reason("grid_corrupt", {**payload, "values": payload["values"][:-1]}, base=base)


def test_bytes_that_are_not_zlib_are_corrupt():
    key = encode_grid(np.zeros((1, 4, 5)), None, None)
    expect_reason("grid_corrupt", {**key, "values": b"\x00" * 80})


def test_keyframe_of_the_wrong_byte_count_is_corrupt():
    expect_reason("grid_corrupt", {"mode": "key", "L": 1, "shape": [4, 5], "values": zlib.compress(bytes(76))})
    expect_reason("grid_corrupt", {"mode": "key", "L": 1, "shape": [4, 5], "values": zlib.compress(bytes(84))})


def test_index_bytes_not_matching_the_count_are_corrupt():
    payload = _delta_with_gaps([1, 2, 3])
    expect_reason("grid_corrupt", {**payload, "n": 2, "values": bytes(8)}, base=valid_delta()[1])


def test_trailing_bytes_after_the_zlib_stream_are_corrupt():
    key = encode_grid(np.zeros((1, 4, 5)), None, None)
    expect_reason("grid_corrupt", {**key, "values": key["values"] + b"\x00"})


def test_zlib_bomb_is_corrupt_without_inflating_it():
    bomb = zlib.compress(bytes(16 << 20), 9)  # 16 MiB of zeros in ~16 kB
    expect_reason("grid_corrupt", {"mode": "key", "L": 1, "shape": [4, 5], "values": bomb})


@pytest.mark.parametrize("field", ["values", "index"])
def test_byte_field_of_another_type_is_corrupt(field):
    payload, base, _ = valid_delta()
    expect_reason("grid_corrupt", {**payload, field: "not bytes"}, base=base)


@settings(max_examples=200, deadline=None)
@given(payload=st.one_of(
    st.dictionaries(st.sampled_from(["mode", "base", "L", "shape", "n", "dtype", "index", "values"]),
                    st.one_of(st.integers(-3, 30), st.sampled_from(["key", "delta", "u1", "u2", "u4"]),
                              st.binary(max_size=40), st.lists(st.integers(-1, 6), max_size=3), st.none())),
    st.builds(lambda f, v: {**valid_delta()[0], f: v},
              st.sampled_from(["base", "L", "shape", "n", "dtype", "index", "values"]),
              st.one_of(st.integers(-3, 30), st.binary(max_size=40), st.sampled_from(["u1", "u4"]))),
))
def test_fuzzed_payloads_raise_only_decode_error(payload):
    base = valid_delta()[1]
    try:
        out = decode_grid(payload, (4, 5), 1, lookup({7: base, 0: base}))
    except DecodeError as err:
        assert err.reason in GRID_REASONS
    else:
        assert out.shape == (1, 4, 5) and np.all(np.isfinite(out))


# -- caller errors (ValueError, not DecodeError) ------------------------------------------------------
@pytest.mark.parametrize(("shape", "layers"), [((0, 5), 1), ((4,), 1), ((4.0, 5), 1), ((4, 5), 0), ((4, 5), 1.0),
                                               ((2**20, 2**13), 1)],
                         ids=["zero-rows", "one-dim", "float-rows", "zero-layers", "float-layers", "too-many-cells"])
def test_decode_rejects_a_bad_receiver_geometry(shape, layers):
    payload, base, _ = valid_delta()
    with pytest.raises(ValueError) as err:
        decode_grid(payload, shape, layers, lookup({7: base}))
    assert not isinstance(err.value, DecodeError)


def test_decode_rejects_a_stored_baseline_of_the_wrong_shape():
    payload, base, _ = valid_delta()
    with pytest.raises(ValueError, match="baseline 7 has shape") as err:
        decode_grid(payload, (4, 5), 1, lookup({7: base[:, :2]}))
    assert not isinstance(err.value, DecodeError)


@pytest.mark.parametrize(
    ("layers", "baseline", "base_seq", "match"),
    [
        (np.full((1, 2, 2), np.nan), None, None, "NaN"),
        (np.full((1, 2, 2), 1e39), None, None, "float32"),
        (np.zeros((2, 2)), None, None, "shape"),
        (np.zeros((1, 0, 2)), None, None, "shape"),
        (np.zeros((1, 2, 2), bool), None, None, "dtype"),
        (np.zeros((1, 2, 2)), np.zeros((1, 2, 3)), 1, "baseline has shape"),
        (np.zeros((1, 2, 2)), np.zeros((1, 2, 2)), None, "base_seq"),
        (np.zeros((1, 2, 2)), np.zeros((1, 2, 2)), -1, "base_seq"),
        (np.zeros((1, 2, 2)), np.zeros((1, 2, 2)), 2**64, "base_seq"),
        (np.zeros((1, 2, 2)), np.zeros((1, 2, 2)), True, "base_seq"),
        (np.zeros((1, 2, 2)), None, 3, "without a baseline"),
    ],
    ids=["nan-layers", "overflowing-layers", "2d-layers", "empty-layers", "bool-layers", "baseline-other-shape",
         "baseline-without-seq", "negative-seq", "seq-too-big", "bool-seq", "seq-without-baseline"],
)
def test_encode_rejects_bad_input(layers, baseline, base_seq, match):
    with pytest.raises(ValueError, match=match):
        encode_grid(layers, baseline, base_seq)


# -- history -----------------------------------------------------------------------------------------
def test_history_keeps_the_newest_capacity_messages():
    h = GridHistory(capacity=3)
    assert h.latest() is None and h.get(0) is None and len(h) == 0
    for seq in (2, 5, 6, 9):
        h.put(seq, np.full((1, 2, 2), float(seq)))
    assert len(h) == 3 and h.get(2) is None
    assert [float(h.get(s)[0, 0, 0]) for s in (5, 6, 9)] == [5.0, 6.0, 9.0]
    seq, layers = h.latest()
    assert seq == 9 and layers[0, 0, 0] == 9.0
    assert h.get(np.int64(6)) is not None and h.get("6") is None


def test_history_stores_a_read_only_copy():
    h = GridHistory()
    layers = np.zeros((1, 2, 2))
    h.put(1, layers)
    layers[0, 0, 0] = 5.0
    assert h.get(1)[0, 0, 0] == 0.0
    with pytest.raises(ValueError):
        h.get(1)[0, 0, 0] = 1.0


@pytest.mark.parametrize(("seq", "layers", "match"), [
    (4, np.zeros((1, 2, 2)), "does not increase"),
    (3, np.zeros((1, 2, 2)), "does not increase"),
    (-1, np.zeros((1, 2, 2)), "seq"),
    (2**64, np.zeros((1, 2, 2)), "seq"),
    (5.0, np.zeros((1, 2, 2)), "seq"),
    (5, np.zeros((1, 2, 3)), "shape"),
    (5, np.zeros((2, 2)), r"\(L, rows, cols\)"),
    (5, np.full((1, 2, 2), np.nan), "NaN"),
], ids=["same-seq", "older-seq", "negative-seq", "seq-too-big", "float-seq", "other-shape", "2d", "nan"])
def test_history_rejects_bad_puts(seq, layers, match):
    h = GridHistory()
    h.put(4, np.zeros((1, 2, 2)))
    with pytest.raises(ValueError, match=match):
        h.put(seq, layers)
    assert len(h) == 1


@pytest.mark.parametrize("capacity", [0, -1, 2.5, True], ids=["zero", "negative", "float", "bool"])
def test_history_rejects_a_bad_capacity(capacity):
    with pytest.raises(ValueError):
        GridHistory(capacity)
