"""The msgpack wire format (DESIGN.md §5): envelope, arrays and strict validation.

One job: bytes <-> validated Python objects. No Zenoh, no clocks, no beliefs state here.

Envelope — a msgpack map with short keys (bandwidth is a first-class metric)::

    "v"   version  int, must equal SCHEMA_VERSION
    "k"   kind     str, one of KINDS (or of the ``kinds`` passed to encode/decode)
    "o"   origin   str agent id, [A-Za-z0-9_-]{1,64}
    "s"   seq      int in [0, 2**64)
    "t"   stamp    float seconds, finite
    "a"   acks     map agent id -> last seq received from that peer (at most MAX_ACKS entries)
    "p"   payload  map with str keys (the kind's codec defines its content)
    "mac"          optional, 32 bytes: HMAC-SHA256 with the fleet key, always the *last* entry

The MAC covers every byte of the message before the 32 MAC bytes (map header, all fields, the "mac"
key and the bin header), so the receiver checks the exact bytes it received, never a re-encoding.

Payload codecs live beside this module: :mod:`agent.net.gaussian_codec` (Gaussian and trajectory
beliefs), :mod:`agent.net.grid_codec`, :mod:`agent.net.particle_wire` and :mod:`agent.net.fire_truth`.

Arrays travel as msgpack ExtType ``EXT_NDARRAY`` whose data is::

    dtype (3 ASCII bytes, one of ALLOWED_DTYPES) | ndim (u8, <= MAX_NDIM) | ndim x u32 LE dims | raw LE bytes

The decoder checks the declared shape against the byte count and MAX_ARRAY_ELEMENTS *before* it
creates the array, and returns a writable copy (never a view of the received buffer).

Every defect found in received bytes raises :class:`DecodeError` with ``reason`` in REASONS, and
:func:`decode` raises nothing else whatever the input.
"""

from __future__ import annotations

import hashlib
import hmac
import math
import re
import struct
from collections.abc import Set
from dataclasses import dataclass, field
from typing import Any

import msgpack
import numpy as np

SCHEMA_VERSION = 1

#: Message kinds this module knows. Another module extends the set without touching this one:
#: ``decode(data, kinds=wire.KINDS | {"particles"})``.
KINDS: frozenset[str] = frozenset({"track", "telemetry", "measurement", "truth", "clock", "grid", "grid_evidence"})

REASONS: frozenset[str] = frozenset(
    {
        "oversize",  # message, container, array or ack table larger than the limits
        "truncated",  # msgpack input ends early
        "malformed",  # not msgpack, trailing bytes, or nesting deeper than MAX_DEPTH
        "bad_type",  # a value of the wrong type (incl. disallowed array dtype, unknown ext type)
        "bad_field",  # a field missing or unknown, or an out-of-range value (agent id, negative seq)
        "version",  # schema version other than SCHEMA_VERSION
        "unknown_kind",
        "bad_shape",  # array shape wrong for its role, or not matching its byte count
        "non_finite",  # NaN or inf
        "indefinite",  # information matrix not symmetric positive semi-definite
        "origin_mismatch",  # origin differs from the one the transport expected (the key's agent)
        "bad_mac",  # HMAC missing, malformed or wrong while a fleet key is configured
        # grid messages (agent.net.grid_codec, agent.beliefs.grid_exchange)
        "grid_bad_mode",  # neither a keyframe nor a delta
        "grid_bad_shape",  # layers or cells other than the receiver's grid geometry
        "grid_bad_index",  # delta cell indices out of range, not increasing, or of a bad dtype
        "grid_bad_values",  # NaN/inf values, or a value count that does not match the indices
        "grid_missing_baseline",  # a delta on a message the receiver does not hold
        "grid_corrupt",  # compressed bytes that do not decompress, or byte counts that do not add up
        "grid_stale",  # a grid message not newer than the last one decoded from that origin
        "grid_geometry",  # a grid whose geometry differs from the receiver's
        "bad_fire",  # malformed fire truth (agent.net.fire_truth)
        "future_epoch",  # a track stamped too far ahead of the receiver's clock (agent.beliefs.tracks)
        "uninformative",  # a track whose newest state is not observable (agent.beliefs.tracks)
        "past_epoch",  # a track stamped too far behind the receiver's clock (agent.beliefs.tracks)
        "bad_truth",  # malformed target states or UAV positions in the world's truth (agent.sensors.truth)
    }
)

# Limits (all chosen here). MAX_CONTAINER_LEN bounds msgpack's pre-allocation per array header, so a
# hostile message of nested headers costs at most ~30 MB transiently before it is rejected.
MAX_MESSAGE_BYTES = 1 << 20
MAX_ACKS = 256
MAX_ARRAY_ELEMENTS = 1 << 20
MAX_NDIM = 8
MAX_DEPTH = 32  # nesting of lists/maps inside the payload
MAX_CONTAINER_LEN = 4096  # msgpack array length
MAX_MAP_LEN = 1024
EXT_NDARRAY = 1
ALLOWED_DTYPES: frozenset[str] = frozenset({"<f8", "<f4", "<i4", "<i8", "|u1", "<u2"})
MAC_BYTES = 32

_AGENT_ID = re.compile(r"[A-Za-z0-9_-]{1,64}")
_FIELDS = {"v": "version", "k": "kind", "o": "origin", "s": "seq", "t": "stamp", "a": "acks", "p": "payload"}
_SEQ_LIMIT = 1 << 64
_HEADER = ("k", "o", "s", "t")  # kind, origin, seq, stamp: packed before the acks and the payload


class DecodeError(ValueError):
    """Received bytes were rejected; ``reason`` (one of REASONS) is what a receiver counts."""

    def __init__(self, reason: str, detail: str = ""):
        if reason not in REASONS:
            raise ValueError(f"unknown decode-error reason {reason!r}")
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.detail = detail


@dataclass(frozen=True, kw_only=True, eq=False)
class Envelope:
    """One message. ``payload`` values may be None, bool, int, float, str, bytes, numpy arrays, lists
    and str-keyed dicts of those. (``eq=False``: payloads hold arrays, compare fields explicitly.)"""

    version: int = SCHEMA_VERSION
    kind: str
    origin: str
    seq: int
    stamp: float
    acks: dict[str, int] = field(default_factory=dict)
    payload: dict[str, Any] = field(default_factory=dict)


# -- envelope ----------------------------------------------------------------------------------------
def encode(envelope: Envelope, key: bytes | None = None, *, kinds: Set[str] | None = None) -> bytes:
    """Pack an envelope, appending an HMAC-SHA256 over the packed bytes when a fleet ``key`` is given.

    The header is checked with the receiver's rules (``ValueError`` if it would be rejected) and the
    packer refuses types that have no wire form (``TypeError``, e.g. a bool array). Payload limits
    (MAX_DEPTH, MAX_CONTAINER_LEN, MAX_MAP_LEN, MAX_MESSAGE_BYTES) are enforced by the receiver only."""
    body = {
        "v": _plain(envelope.version),
        "k": envelope.kind,
        "o": envelope.origin,
        "s": _plain(envelope.seq),
        "t": _plain(envelope.stamp),
        "a": {peer: _plain(last) for peer, last in envelope.acks.items()},
        "p": envelope.payload,
    }
    try:
        _check_header(body, KINDS if kinds is None else kinds)
    except DecodeError as exc:
        raise ValueError(f"cannot encode envelope: {exc}") from None
    if key is not None:
        _check_key(key)
        body["mac"] = bytes(MAC_BYTES)  # placeholder: the MAC is the last MAC_BYTES bytes of the message
    packed = msgpack.packb(body, default=_pack_default, use_bin_type=True, use_single_float=False)
    if key is not None:
        packed = packed[:-MAC_BYTES] + _mac(key, packed[:-MAC_BYTES])
    return packed


def decode(
    data: bytes,
    *,
    expected_origin: str | None = None,
    key: bytes | None = None,
    max_bytes: int = MAX_MESSAGE_BYTES,
    kinds: Set[str] | None = None,
) -> Envelope:
    """Validate and unpack one message. Raises only :class:`DecodeError`, whatever ``data`` holds.

    Order of checks: size, msgpack structure, MAC (with a key, before any field is interpreted),
    version, field set, field types and ranges, kind, origin, payload tree. (A ``key`` that is not
    non-empty bytes is a configuration error and raises ``ValueError`` before ``data`` is looked at.)"""
    if key is not None:
        _check_key(key)
    try:
        return _decode(data, expected_origin, key, max_bytes, KINDS if kinds is None else kinds)
    except DecodeError:
        raise
    except Exception as exc:  # a safety net: the agent must never crash on input (DESIGN.md §5)
        raise DecodeError("malformed", f"unexpected {type(exc).__name__} while validating") from None


def encoded_size(envelope: Envelope, key: bytes | None = None) -> int:
    """Bytes on the wire for ``envelope`` (MAC included when a key is given)."""
    return len(encode(envelope, key))


def _decode(data, expected_origin, key, max_bytes, kinds) -> Envelope:
    if not isinstance(data, bytes | bytearray | memoryview):
        raise DecodeError("bad_type", f"expected bytes, got {type(data).__name__}")
    data = bytes(data)
    if len(data) > max_bytes:
        raise DecodeError("oversize", f"{len(data)} bytes > {max_bytes}")
    obj = _unpack(data, max_bytes)
    if not isinstance(obj, dict):
        raise DecodeError("bad_type", f"envelope must be a map, got {type(obj).__name__}")
    if key is not None:
        _verify_mac(obj, data, key)
    elif "mac" in obj and not (isinstance(obj["mac"], bytes) and len(obj["mac"]) == MAC_BYTES):
        raise DecodeError("bad_mac", "mac field is not 32 bytes")
    obj.pop("mac", None)
    _check_header(obj, kinds)
    if expected_origin is not None and obj["o"] != expected_origin:
        raise DecodeError("origin_mismatch", f"origin {obj['o']!r} on a key of {expected_origin!r}")
    _check_payload(obj["p"])
    return Envelope(
        version=obj["v"],
        kind=obj["k"],
        origin=obj["o"],
        seq=obj["s"],
        stamp=float(obj["t"]),
        acks=obj["a"],
        payload=obj["p"],
    )


@dataclass(frozen=True)
class Header:
    kind: str
    origin: str
    seq: int
    stamp: float


def peek_header(data: bytes) -> Header | None:
    """Kind, origin, seq and stamp of an envelope without decoding its payload, for the emulated radio
    (``None`` if unreadable). Nothing is validated: :func:`decode` judges the same bytes afterwards."""
    try:
        unpacker = msgpack.Unpacker(max_buffer_size=len(data) or 1, raw=False, strict_map_key=False)
        unpacker.feed(data)
        fields: dict = {}
        for _ in range(unpacker.read_map_header()):
            key = unpacker.unpack()
            if key == "p":
                break
            value = unpacker.unpack()
            if key in _HEADER:
                fields[key] = value
    except Exception:  # any malformed input: not ours to judge
        return None
    kind, origin, seq, stamp = (fields.get(k) for k in _HEADER)
    ok = isinstance(kind, str) and isinstance(origin, str) and is_int(seq) and seq >= 0 and (
        is_int(stamp) or isinstance(stamp, float)) and math.isfinite(stamp)
    return Header(kind, origin, seq, float(stamp)) if ok else None


def _unpack(data: bytes, max_bytes: int):
    try:
        return msgpack.unpackb(
            data,
            raw=False,
            strict_map_key=True,
            ext_hook=_ext_hook,
            max_bin_len=max_bytes,
            max_str_len=max_bytes,
            max_ext_len=max_bytes,
            max_array_len=MAX_CONTAINER_LEN,
            max_map_len=MAX_MAP_LEN,
        )
    except DecodeError:
        raise
    except msgpack.ExtraData:
        raise DecodeError("malformed", "trailing bytes after the message") from None
    except msgpack.StackError:
        raise DecodeError("malformed", "nesting too deep") from None
    except Exception as exc:
        text = str(exc)
        if "incomplete input" in text:
            raise DecodeError("truncated", "input ends inside a msgpack object") from None
        if "exceeds max_" in text:
            raise DecodeError("oversize", text) from None
        raise DecodeError("malformed", f"not msgpack ({type(exc).__name__})") from None


def _check_header(obj: dict, kinds: Set[str]) -> None:
    """Version first (another version may have other fields), then the field set, types and ranges."""
    if "v" not in obj:
        raise DecodeError("bad_field", "missing field 'v' (version)")
    if not is_int(obj["v"]):
        raise DecodeError("bad_type", "version must be an int")
    if obj["v"] != SCHEMA_VERSION:
        raise DecodeError("version", f"schema version {obj['v']}, expected {SCHEMA_VERSION}")
    missing = [f"{k!r} ({v})" for k, v in _FIELDS.items() if k not in obj]
    unknown = sorted(repr(k) for k in obj if k not in _FIELDS)
    if missing or unknown:
        raise DecodeError("bad_field", f"missing {', '.join(missing) or '-'}; unknown {', '.join(unknown) or '-'}")
    kind, origin, seq, stamp, acks, payload = (obj[k] for k in "kostap")
    if not isinstance(kind, str) or not isinstance(origin, str) or not isinstance(payload, dict):
        raise DecodeError("bad_type", "kind and origin must be str, payload a map")
    if not is_int(seq) or isinstance(stamp, bool) or not isinstance(stamp, int | float) or not isinstance(acks, dict):
        raise DecodeError("bad_type", "seq must be an int, stamp a number, acks a map")
    if not _AGENT_ID.fullmatch(origin):
        raise DecodeError("bad_field", f"origin {origin[:80]!r} is not an agent id")
    if not 0 <= seq < _SEQ_LIMIT:
        raise DecodeError("bad_field", f"seq {seq} outside [0, 2**64)")
    if not math.isfinite(stamp):
        raise DecodeError("non_finite", "stamp is not finite")
    if len(acks) > MAX_ACKS:
        raise DecodeError("oversize", f"{len(acks)} acks > {MAX_ACKS}")
    for peer, last in acks.items():
        if not isinstance(peer, str) or not is_int(last):
            raise DecodeError("bad_type", "acks must map str agent ids to int seqs")
        if not _AGENT_ID.fullmatch(peer) or not 0 <= last < _SEQ_LIMIT:
            raise DecodeError("bad_field", f"ack {peer[:80]!r}: {last} is not an agent id and a seq")
    if kind not in kinds:
        raise DecodeError("unknown_kind", f"kind {kind[:80]!r}")
    if any(not isinstance(k, str) for k in payload):
        raise DecodeError("bad_type", "payload keys must be str")


def _check_payload(payload) -> None:
    """Depth and leaf types of the payload tree, iteratively (no recursion on hostile input)."""
    stack = [(payload, 0)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, dict | list):
            if depth >= MAX_DEPTH:
                raise DecodeError("malformed", f"payload nested deeper than {MAX_DEPTH}")
            if isinstance(node, dict):
                if any(not isinstance(k, str) for k in node):
                    raise DecodeError("bad_type", "payload map keys must be str")
                node = node.values()
            stack.extend((child, depth + 1) for child in node)
        elif not (node is None or isinstance(node, bool | int | float | str | bytes | np.ndarray)):
            raise DecodeError("bad_type", f"payload holds a {type(node).__name__}")


def _plain(value):
    """numpy scalars as Python numbers (so an ``np.int64`` seq is accepted like an ``int``)."""
    return value.item() if isinstance(value, np.integer | np.floating) else value


def is_int(value) -> bool:
    """An int that is not a bool (msgpack gives bools for true/false)."""
    return isinstance(value, int) and not isinstance(value, bool)


# -- MAC ---------------------------------------------------------------------------------------------
def _check_key(key) -> None:
    if not isinstance(key, bytes) or not key:
        raise ValueError("the fleet key must be non-empty bytes")


def _mac(key: bytes, signed: bytes) -> bytes:
    return hmac.new(key, signed, hashlib.sha256).digest()


def _verify_mac(obj: dict, data: bytes, key: bytes) -> None:
    mac = obj.get("mac")
    if mac is None:
        raise DecodeError("bad_mac", "message carries no mac but a fleet key is configured")
    if not isinstance(mac, bytes) or len(mac) != MAC_BYTES or next(reversed(obj)) != "mac" or data[-MAC_BYTES:] != mac:
        raise DecodeError("bad_mac", "mac must be the last field and 32 bytes")
    if not hmac.compare_digest(mac, _mac(key, data[:-MAC_BYTES])):
        raise DecodeError("bad_mac", "wrong mac")


# -- arrays ------------------------------------------------------------------------------------------
def _pack_default(obj):
    if isinstance(obj, np.ndarray):
        return msgpack.ExtType(EXT_NDARRAY, _pack_array(obj))
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    raise TypeError(f"cannot put a {type(obj).__name__} on the wire")


def _pack_array(arr: np.ndarray) -> bytes:
    dtype = arr.dtype.newbyteorder("<")
    if dtype.str not in ALLOWED_DTYPES:
        raise TypeError(f"array dtype {arr.dtype} is not allowed on the wire ({sorted(ALLOWED_DTYPES)})")
    if arr.ndim > MAX_NDIM or arr.size > MAX_ARRAY_ELEMENTS or any(d >= 1 << 32 for d in arr.shape):
        raise ValueError(f"array of shape {arr.shape} is too large for the wire")
    header = dtype.str.encode("ascii") + struct.pack(f"<B{arr.ndim}I", arr.ndim, *arr.shape)
    return header + arr.astype(dtype, copy=False).tobytes(order="C")


def _ext_hook(code: int, data: bytes) -> np.ndarray:
    """Called by msgpack for every ExtType: the array is checked before anything is allocated."""
    if code != EXT_NDARRAY:
        raise DecodeError("bad_type", f"unknown msgpack ext type {code}")
    if len(data) < 4:
        raise DecodeError("bad_shape", "array header shorter than 4 bytes")
    dtype_str, ndim = data[:3].decode("ascii", "replace"), data[3]
    if dtype_str not in ALLOWED_DTYPES:
        raise DecodeError("bad_type", f"array dtype {dtype_str!r} is not allowed")
    if ndim > MAX_NDIM or len(data) < 4 + 4 * ndim:
        raise DecodeError("bad_shape", f"array header of {ndim} dims is invalid")
    shape = struct.unpack_from(f"<{ndim}I", data, 4)
    count = math.prod(shape)
    if count > MAX_ARRAY_ELEMENTS:
        raise DecodeError("oversize", f"array of {count} elements > {MAX_ARRAY_ELEMENTS}")
    dtype = np.dtype(dtype_str)
    raw = memoryview(data)[4 + 4 * ndim :]
    if len(raw) != count * dtype.itemsize:
        raise DecodeError(
            "bad_shape", f"shape {shape} of {dtype_str} needs {count * dtype.itemsize} bytes, got {len(raw)}"
        )
    return np.frombuffer(raw, dtype=dtype, count=count).reshape(shape).copy()
