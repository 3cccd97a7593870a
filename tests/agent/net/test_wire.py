"""agent.net.wire: envelope round trips, one test per class of bad input (each with its reason), and
fuzzing that decode (followed by the belief codecs) raises only DecodeError.

Every bad message below is a valid message changed in exactly one respect (``_valid_body`` decodes),
so the reason a test expects is the only defect the message has."""

from __future__ import annotations

import math
import struct

import msgpack
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from agent.net import wire
from agent.net.gaussian_codec import decode_gaussian, decode_trajectory, encode_gaussian, encode_trajectory
from agent.net.wire import KINDS, DecodeError, decode, encode, encoded_size
from tests.agent.net.builders import (
    DELETE,
    FUZZ,
    MODEL,
    changed,
    envelope,
    leaves,
    only_decode_errors,
    random_gaussian,
    random_trajectory,
)

KEY = b"fleet-key-for-tests"


# -- builders ----------------------------------------------------------------------------------------
def ext(dtype: str, shape, raw: bytes, ndim: int | None = None) -> msgpack.ExtType:
    """An array ExtType written from the format spec in the module docstring (not with wire's packer)."""
    ndim = len(shape) if ndim is None else ndim
    return msgpack.ExtType(1, dtype.encode() + struct.pack(f"<B{len(shape)}I", ndim, *shape) + raw)


def arr_ext(a: np.ndarray) -> msgpack.ExtType:
    return ext(a.dtype.str, a.shape, a.tobytes())


def _valid_body() -> dict:
    """The raw map of a valid message (with a Gaussian payload as ExtTypes), to be spoiled by one edit."""
    g = random_gaussian(np.random.default_rng(0), 3)
    return {
        "v": 1,
        "k": "clock",
        "o": "uav-01",
        "s": 42,
        "t": 12.5,
        "a": {"uav-02": 7},
        "p": {"y": arr_ext(g.y), "Y": arr_ext(g.Y)},
    }


def pack(body) -> bytes:
    return msgpack.packb(body, use_bin_type=True)


def body_with(**changes) -> bytes:
    return pack(changed(_valid_body(), **changes))


def reason_of(data: bytes, **kwargs) -> str:
    with pytest.raises(DecodeError) as info:
        decode(data, **kwargs)
    return info.value.reason


def test_the_base_message_for_all_bad_cases_is_valid():
    env = decode(pack(_valid_body()), expected_origin="uav-01")
    assert decode_gaussian(env.payload, dim=3).dim == 3


# -- round trips -------------------------------------------------------------------------------------
def test_envelope_round_trip_with_arrays_of_every_allowed_dtype_and_plain_values():
    rng = np.random.default_rng(1)
    arrays = {dt: (rng.standard_normal((2, 3, 4)) * 100).astype(dt) for dt in sorted(wire.ALLOWED_DTYPES)}
    payload = {
        "arrays": arrays,
        "scalar0d": np.array(3.5),
        "empty": np.zeros((0, 5)),
        "nested": [1, -2, 2**64 - 1, 1.5, "text", b"\x00bytes", None, True, {"inner": [np.arange(3)]}],
    }
    env = envelope(payload)
    out = decode(encode(env), expected_origin="uav-01")
    assert (out.version, out.kind, out.origin, out.seq, out.stamp) == (1, "clock", "uav-01", 42, 12.5)
    assert out.acks == env.acks
    for dt, a in arrays.items():
        b = out.payload["arrays"][dt]
        assert b.dtype.str == dt and b.shape == a.shape and np.array_equal(a, b)
        assert b.flags.writeable and b.flags.owndata  # a copy, never a view of the received buffer
    assert out.payload["scalar0d"].shape == () and out.payload["scalar0d"] == 3.5
    assert out.payload["empty"].shape == (0, 5)
    assert out.payload["nested"][:8] == payload["nested"][:8]
    assert np.array_equal(out.payload["nested"][8]["inner"][0], np.arange(3))


def test_big_endian_non_contiguous_arrays_and_numpy_scalars_are_sent_little_endian():
    a = np.arange(12, dtype=">f8").reshape(3, 4)[:, ::2]
    env = envelope({"a": a, "n": np.int64(5), "x": np.float32(0.25), "b": np.bool_(True)}, seq=np.int64(9))
    out = decode(encode(env))
    assert out.payload["a"].dtype.str == "<f8" and np.array_equal(out.payload["a"], a)
    assert (out.payload["n"], out.payload["x"], out.payload["b"], out.seq) == (5, 0.25, True, 9)


def test_hmac_round_trip_and_a_signed_message_still_decodes_without_a_key():
    data = encode(envelope({"x": np.ones(3)}), key=KEY)
    assert decode(data, key=KEY).seq == 42
    assert decode(data).seq == 42
    assert len(data) == len(encode(envelope({"x": np.ones(3)}))) + 4 + 2 + 32  # "mac" key + bin8 header + digest


def test_extended_kinds_are_accepted_when_passed_explicitly():
    kinds = KINDS | {"particles"}
    data = encode(envelope(kind="particles"), kinds=kinds)
    assert decode(data, kinds=kinds).kind == "particles"
    assert reason_of(data) == "unknown_kind"


def test_encoded_size_matches_encode_and_the_belief_messages_are_compact():
    g = envelope(encode_gaussian(random_gaussian(np.random.default_rng(4))), acks={})
    t = envelope(encode_trajectory(random_trajectory(np.random.default_rng(5))), acks={})
    assert encoded_size(g) == len(encode(g))
    assert encoded_size(g, KEY) == encoded_size(g) + 38
    assert encoded_size(g) < 6 * 8 + 36 * 8 + 80
    assert encoded_size(t) < (48 + 8 * 36 + 7 * 36) * 8 + 120


def test_encode_refuses_what_a_receiver_would_reject():
    """Bad header values and types without a wire form fail at the sender, not at every receiver."""
    for bad in (dict(origin="no spaces"), dict(seq=-1), dict(stamp=math.nan), dict(kind="nope"), dict(version=2)):
        with pytest.raises(ValueError):
            encode(envelope(**bad))
    with pytest.raises(TypeError):
        encode(envelope({"mask": np.ones(3, dtype=bool)}))
    with pytest.raises(TypeError):
        encode(envelope({"z": np.ones(3, dtype=complex)}))
    with pytest.raises(ValueError):
        encode(envelope(), key=b"")


# -- rejected bytes: framing and size ----------------------------------------------------------------
def test_every_proper_prefix_of_a_valid_message_is_truncated_and_of_a_signed_one_bad_mac():
    """Unsigned, the parser finds the cut; signed, the MAC is judged on the raw bytes before any parsing, and
    a cut message no longer ends with its MAC."""
    payload = encode_gaussian(random_gaussian(np.random.default_rng(6)))
    data, signed = encode(envelope(payload)), encode(envelope(payload), key=KEY)
    for cut in range(1, len(data)):
        assert reason_of(data[:cut]) == "truncated", cut
    for cut in range(len(signed)):
        assert reason_of(signed[:cut], key=KEY) == "bad_mac", cut


def test_trailing_garbage_after_a_valid_message_is_malformed():
    assert reason_of(pack(_valid_body()) + b"\x00") == "malformed"


def test_bytes_that_are_not_msgpack_are_malformed():
    assert reason_of(b"\xc1") == "malformed"  # 0xc1 is never used in msgpack
    assert reason_of(b"\x81\xa2\xff\xfe\xc0") == "malformed"  # a map whose key is not UTF-8


def test_input_that_is_not_bytes_is_bad_type():
    assert reason_of("a str, not bytes") == "bad_type"


def test_a_top_level_value_that_is_not_a_map_is_bad_type():
    assert reason_of(pack([1, "track"])) == "bad_type"


def test_a_message_larger_than_max_bytes_is_oversize():
    data = encode(envelope({"blob": np.zeros(200_000)}))
    assert reason_of(data) == "oversize"
    assert reason_of(pack(_valid_body()), max_bytes=64) == "oversize"


def test_container_headers_beyond_the_input_are_refused_before_allocation():
    """msgspec checks a container's declared length against the bytes left before it allocates."""
    assert reason_of(b"\xdd\xff\xff\xff\xff") == "bad_type"  # array32 of 4 billion entries: not an envelope
    assert reason_of(b"\xdf\xff\xff\xff\xff") == "truncated"  # map32 of 4 billion entries


def test_more_than_256_acks_is_oversize():
    assert reason_of(body_with(a={f"uav-{i}": i for i in range(257)})) == "oversize"


def test_nesting_deeper_than_the_limit_is_malformed():
    deep: list = []
    for _ in range(wire.MAX_DEPTH + 1):
        deep = [deep]
    assert reason_of(body_with(p={"deep": deep})) == "malformed"
    assert reason_of(b"\x81\xa1p" + b"\x91" * 5000 + b"\x00") == "malformed"  # deeper than the decoder's stack


# -- rejected bytes: header fields -------------------------------------------------------------------
@pytest.mark.parametrize(
    "field, value",
    [
        ("v", "1"),
        ("v", True),
        ("k", 3),
        ("o", b"uav-01"),
        ("s", 1.5),
        ("s", True),
        ("t", "now"),
        ("t", None),
        ("a", ["uav-02", 7]),
        ("a", {"uav-02": "7"}),
        ("p", [1, 2]),
        ("p", {b"y": 1}),
        ("p", {"when": msgpack.Timestamp(1, 0)}),
        ("p", {"ext": msgpack.ExtType(7, b"\x00")}),
    ],
    ids=lambda x: repr(x)[:30],
)
def test_a_field_of_the_wrong_type_is_bad_type(field, value):
    assert reason_of(body_with(**{field: value})) == "bad_type"


@pytest.mark.parametrize(
    "field, value",
    [
        ("o", "bad id!"),
        ("o", ""),
        ("o", "x" * 65),
        ("o", "uav-01\n"),
        ("s", -1),
        ("a", {"no spaces here": 1}),
        ("a", {"uav-02": -5}),
    ],
    ids=lambda x: repr(x)[:30],
)
def test_a_field_with_an_out_of_range_value_is_bad_field(field, value):
    assert reason_of(body_with(**{field: value})) == "bad_field"


@pytest.mark.parametrize("field", ["v", "k", "o", "s", "t", "a", "p"])
def test_a_missing_field_is_bad_field(field):
    assert reason_of(body_with(**{field: DELETE})) == "bad_field"


def test_an_unknown_field_is_bad_field():
    assert reason_of(body_with(extra=1)) == "bad_field"


@pytest.mark.parametrize("stamp", [math.nan, math.inf, -math.inf])
def test_a_non_finite_stamp_is_non_finite(stamp):
    assert reason_of(body_with(t=stamp)) == "non_finite"


@pytest.mark.parametrize("version", [0, 2, 2**63])
def test_an_unknown_schema_version_is_version(version):
    assert reason_of(body_with(v=version)) == "version"


def test_an_unknown_kind_is_unknown_kind():
    assert reason_of(body_with(k="weather")) == "unknown_kind"


def test_an_origin_other_than_the_expected_one_is_origin_mismatch():
    data = pack(_valid_body())
    assert reason_of(data, expected_origin="uav-03") == "origin_mismatch"
    assert decode(data, expected_origin="uav-01").origin == "uav-01"


# -- rejected bytes: MAC -----------------------------------------------------------------------------
def test_an_unsigned_message_is_bad_mac_when_a_key_is_configured():
    assert reason_of(encode(envelope()), key=KEY) == "bad_mac"


def test_a_message_signed_with_another_key_is_bad_mac():
    assert reason_of(encode(envelope(), key=b"another fleet"), key=KEY) == "bad_mac"


def test_a_signed_message_with_one_flipped_payload_byte_is_bad_mac():
    data = bytearray(encode(envelope({"x": np.full(4, 1.0)}), key=KEY))
    i = bytes(data).index(np.full(4, 1.0).tobytes()) + 3  # inside the raw float bytes: structure stays valid
    data[i] ^= 0x01
    assert reason_of(bytes(data), key=KEY) == "bad_mac"
    assert decode(bytes(data)).payload["x"][0] != 1.0  # without the key the change goes unnoticed


@pytest.mark.parametrize(
    "mac", [b"\x00" * 31, b"\x00" * 33, "a str of thirty-two characters!!", None], ids=["31B", "33B", "str", "nil"]
)
def test_a_mac_of_the_wrong_length_or_type_is_bad_mac(mac):
    data = body_with(mac=mac)
    assert reason_of(data, key=KEY) == "bad_mac"
    if mac is not None:
        assert reason_of(data) == "bad_mac"


def test_a_mac_that_is_not_the_last_field_is_bad_mac():
    signed = msgpack.unpackb(encode(envelope(), key=KEY), raw=False)
    reordered = {"mac": signed.pop("mac"), **signed}
    assert reason_of(pack(reordered), key=KEY) == "bad_mac"


# -- rejected bytes: arrays --------------------------------------------------------------------------
def test_an_array_whose_shape_does_not_match_its_byte_count_is_bad_shape():
    assert reason_of(body_with(p={"x": ext("<f8", (3, 3), bytes(64))})) == "bad_shape"
    assert reason_of(body_with(p={"x": ext("<f8", (3, 3), bytes(80))})) == "bad_shape"


def test_an_array_header_that_is_cut_short_is_bad_shape():
    assert reason_of(body_with(p={"x": msgpack.ExtType(1, b"<f8")})) == "bad_shape"
    assert reason_of(body_with(p={"x": ext("<f8", (2,), b"", ndim=3)})) == "bad_shape"  # 3 dims declared, 1 given
    assert reason_of(body_with(p={"x": ext("<f8", (1,) * 9, bytes(8))})) == "bad_shape"  # ndim above MAX_NDIM


def test_an_array_declaring_more_elements_than_the_cap_is_oversize_without_allocating():
    assert reason_of(body_with(p={"x": ext("<f8", (2**32 - 1, 2**32 - 1), bytes(8))})) == "oversize"
    huge = ext("|u1", (wire.MAX_ARRAY_ELEMENTS + 1,), bytes(wire.MAX_ARRAY_ELEMENTS + 1))
    assert reason_of(body_with(p={"x": huge}), max_bytes=4 << 20) == "oversize"


@pytest.mark.parametrize("dtype", [">f8", "<c1", "|b1", "<f2", "|O8", "|V8", "\xff\xfe\xfd"])
def test_an_array_with_a_disallowed_dtype_is_bad_type(dtype):
    data = pack(_valid_body()).replace(b"<f8", dtype.encode("latin-1")[:3].ljust(3, b" "), 1)
    assert reason_of(data) == "bad_type"


def test_decoding_leaves_the_received_buffer_untouched():
    data = bytearray(encode(envelope({"x": np.arange(5.0)})))
    before = bytes(data)
    out = decode(data)
    out.payload["x"][:] = -1.0
    assert bytes(data) == before


# -- fuzzing: decode raises DecodeError and nothing else ---------------------------------------------
def _full_pipeline(data: bytes, key=None, expected_origin=None) -> None:
    env = only_decode_errors(decode, data, key=key, expected_origin=expected_origin)
    if env is not None:
        only_decode_errors(decode_gaussian, env.payload)
        only_decode_errors(decode_trajectory, env.payload, MODEL)


_VALID = [
    (encode(envelope(encode_gaussian(random_gaussian(np.random.default_rng(10))))), None),
    (encode(envelope(encode_trajectory(random_trajectory(np.random.default_rng(11))))), None),
    (encode(envelope({"a": np.arange(6, dtype="<i4").reshape(2, 3), "s": "x", "l": [1, 2.0, None]})), None),
    (encode(envelope(encode_gaussian(random_gaussian(np.random.default_rng(12), 2))), key=KEY), KEY),
]


@FUZZ
@given(data=st.binary(max_size=2048), keyed=st.booleans())
def test_fuzz_arbitrary_bytes_only_raise_decode_error(data, keyed):
    _full_pipeline(data, key=KEY if keyed else None, expected_origin="uav-01")


_mutation = st.one_of(
    st.tuples(st.just("flip"), st.integers(0, 10**6), st.integers(1, 255)),
    st.tuples(st.just("truncate"), st.integers(0, 10**6), st.just(0)),
    st.tuples(st.just("insert"), st.integers(0, 10**6), st.binary(min_size=1, max_size=8)),
    st.tuples(st.just("delete"), st.integers(0, 10**6), st.integers(1, 8)),
)


@FUZZ
@given(which=st.integers(0, len(_VALID) - 1), mutations=st.lists(_mutation, min_size=1, max_size=4))
def test_fuzz_mutated_valid_messages_only_raise_decode_error(which, mutations):
    data, key = _VALID[which]
    data = bytearray(data)
    for op, pos, arg in mutations:
        i = pos % (len(data) + 1)
        if op == "flip" and i < len(data):
            data[i] ^= arg
        elif op == "truncate":
            del data[i:]
        elif op == "insert":
            data[i:i] = arg
        elif op == "delete":
            del data[i : i + arg]
    _full_pipeline(bytes(data), key=key)


_trees = st.recursive(
    leaves,
    lambda children: st.lists(children, max_size=5) | st.dictionaries(st.text(max_size=5), children, max_size=5),
    max_leaves=30,
)
_arrays = hnp.arrays(
    dtype=st.sampled_from(["<f8", "<f4", "<i8"]),
    shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=8),
)


@FUZZ
@given(tree=_trees)
def test_fuzz_arbitrary_msgpack_structures_only_raise_decode_error(tree):
    _full_pipeline(pack(tree))


@FUZZ
@given(
    fields=st.dictionaries(
        st.sampled_from(["v", "k", "o", "s", "t", "a", "p", "mac", "x"]), _trees | _arrays.map(arr_ext), max_size=9
    ),
    keep_valid=st.booleans(),
)
def test_fuzz_envelopes_with_arbitrary_field_values_only_raise_decode_error(fields, keep_valid):
    body = {**_valid_body(), **fields} if keep_valid else fields
    _full_pipeline(pack(body), key=KEY if "mac" in fields else None)


@pytest.mark.parametrize("payload", [{"zz": [0] * 100_000}, {"zz": {f"k{i}": i for i in range(10_000)}},
                                     {"zz": [[0] * (wire.MAX_GENERIC_ITEMS + 1)]}])
def test_a_generic_payload_with_a_container_beyond_the_bound_is_oversize_from_its_header(payload):
    """Bad input (skymesh bench fuzz): a telemetry payload holding a list of 10**5 ints (100 kB, within the size
    limit) took 0.5-0.7 s to validate, then ~5 ms (msgspec built every element, then the tree walk read them),
    twice per message in the agent: the slowest inputs of every generic kind. msgpack judges each list's and map's
    length from its header against MAX_GENERIC_ITEMS, before reading an element."""
    data = msgpack.packb({"v": wire.SCHEMA_VERSION, "k": "telemetry", "o": "uav1", "s": 1, "t": 0.0, "a": {},
                          "p": payload})
    with pytest.raises(DecodeError) as err:
        decode(data)
    assert err.value.reason == "oversize"


@pytest.mark.parametrize("payload, reason", [(b"\x92\x01\x02", "bad_type"), (b"\x81\x01\x02", "bad_type"),
                                             (b"\x81\xa1a\xa1\xff", "malformed"),
                                             (b"\x81\xa1a" + b"\x91" * 2000 + b"\xc0", "malformed"),
                                             (b"\x81\xa1a\xc7\x01\x05x", "bad_type")])
def test_a_generic_payload_that_is_no_str_keyed_map_of_wire_values_is_rejected_by_reason(payload, reason):
    """A list, an int key, a str that is not UTF-8, 2,000 nested lists, an unknown ext type."""
    head = msgpack.packb({"v": wire.SCHEMA_VERSION, "k": "telemetry", "o": "uav1", "s": 1, "t": 0.0, "a": {}})
    data = bytes([head[0] + 1]) + head[1:] + b"\xa1p" + payload
    with pytest.raises(DecodeError) as err:
        decode(data)
    assert err.value.reason == reason


@pytest.mark.parametrize("payload", [{"geometry": {"shape": [0] * 100_000}}, {"grid": {"shape": [0] * 100_000}},
                                     {"geometry": {"origin": [0.0] * 100_000}}])
def test_a_grid_payload_with_a_list_longer_than_its_kind_allows_is_rejected_by_the_schema(payload):
    """Bad input (skymesh bench fuzz): a grid message whose geometry held a list of 10**5 ints passed the decoder
    (grid payloads were generic) and took the agent 57 ms, most of it spelling the list out in the geometry's
    error message. The grid's schema fixes every pair's length, so msgspec rejects it before any element is read."""
    data = msgpack.packb({"v": wire.SCHEMA_VERSION, "k": "grid", "o": "uav1", "s": 1, "t": 0.0, "a": {}, "p": payload})
    with pytest.raises(DecodeError) as err:
        decode(data)
    assert err.value.reason == "bad_type" and "length 2" in err.value.detail
