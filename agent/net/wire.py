"""The wire format (DESIGN.md §5, written out in ``docs/wire.md``): envelope, arrays, typed validation.

One job: bytes <-> validated Python objects. No Zenoh, no clocks, no belief state here.

Envelope — a MessagePack map with short keys (bandwidth is a first-class metric)::

    "v"   version  int, must equal SCHEMA_VERSION
    "k"   kind     str, one of KINDS (or of the ``kinds`` passed to encode/decode)
    "o"   origin   str agent id, [A-Za-z0-9_-]{1,64}
    "s"   seq      int in [0, 2**64)
    "t"   stamp    float seconds, finite
    "a"   acks     map agent id -> last seq received from that peer (at most MAX_ACKS entries)
    "p"   payload  map with str keys, typed per kind by :mod:`agent.net.schemas`
    "mac"          optional, 32 bytes: HMAC-SHA256 with the fleet key, always the *last* entry

The MAC covers every byte of the message before the 32 MAC bytes (map header, all fields, the "mac"
key and the bin header), so the receiver checks the exact bytes it received, never a re-encoding.

Arrays travel as MessagePack ExtType ``EXT_NDARRAY`` whose data is::

    dtype (3 ASCII bytes, one of ALLOWED_DTYPES) | ndim (u8, <= MAX_NDIM) | ndim x u32 LE dims | raw LE bytes

Decoding is done in C by msgspec against typed schemas: the envelope is the :class:`_Body` struct (every
header field's type and range declared), the payload is decoded by its kind's schema
(:data:`agent.net.schemas.PAYLOADS`), so no Python code walks the elements of a message (but for the names a
payload carries, which :mod:`agent.net.roster` checks against the fleet when ``fleet`` is given); a generic payload
is unpacked in C by msgpack with every list and map bounded (:data:`MAX_GENERIC_ITEMS`). An array is
checked once, as a whole, when msgspec meets it: the declared shape against the byte count and
MAX_ARRAY_ELEMENTS *before* it is created; the result is a writable copy, never a view of the received
buffer. Values (finiteness, definiteness) are checked vectorised by the payload's codec.

Every defect found in received bytes raises :class:`DecodeError` with ``reason`` in REASONS, and
:func:`decode` raises nothing else whatever the input.
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import math
import struct
from collections.abc import Set
from dataclasses import dataclass, field
from typing import Annotated, Any

import msgpack
import msgspec
import numpy as np

from agent.net import roster, schemas

SCHEMA_VERSION = 1
#: The Zenoh encoding every message is published with (``agent.net.zenoh_transport``): Zenoh's predefined
#: ``zenoh/bytes`` with the schema ``skymesh/<version>``, so a subscriber knows what the bytes are before it parses
#: them. Zenoh sends a predefined encoding as a number and only the schema as text: about 11 bytes a message
#: where ``application/msgpack;skymesh-wire=1`` (no predefined number: all text) cost 38 — measured on loopback,
#: per message and hop, a tenth of the fleet's bytes on the wire.
ZENOH_ENCODING = f"zenoh/bytes;skymesh/{SCHEMA_VERSION}"

#: Message kinds this module knows (those with a schema). Another module extends the set without touching
#: this one: ``decode(data, kinds=wire.KINDS | {"particles"})`` (a kind without a schema decodes as a
#: str-keyed map of plain values and arrays, which its codec validates).
KINDS: frozenset[str] = frozenset(schemas.PAYLOADS)

REASONS: frozenset[str] = frozenset(
    {
        "oversize",  # message, container, array or ack table larger than the limits
        "truncated",  # MessagePack input ends early
        "malformed",  # not MessagePack, trailing bytes, or nesting deeper than the decoder allows
        "bad_type",  # a value of the wrong type (incl. disallowed array dtype, unknown ext type)
        "bad_field",  # a field missing or unknown, or an out-of-range value (agent id, negative seq)
        "version",  # schema version other than SCHEMA_VERSION
        "bad_encoding",  # a Zenoh encoding other than ZENOH_ENCODING: another format, or another version of it
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
        "unknown_name",  # a name in the acks or the payload outside the fleet's roster (agent.net.roster)
    }
)

# Limits (all chosen here).
MAX_MESSAGE_BYTES = 1 << 20
MAX_ACKS = 256
MAX_ARRAY_ELEMENTS = 1 << 20
MAX_NDIM = 8
EXT_NDARRAY = 1
ALLOWED_DTYPES: frozenset[str] = frozenset({"<f8", "<f4", "<i4", "<i8", "|u1", "<u2"})
MAC_BYTES = 32
MAX_DEPTH = 32  # nesting of lists/maps inside a generic payload (the typed schemas fix their own)
#: Elements of one list or map inside a generic payload (chosen here: an agent's longest is its track list, <= 256;
#: bulk data travels as arrays). Judged from the container's header, before any element is read.
MAX_GENERIC_ITEMS = 4096
_HEADER = ("k", "o", "s", "t")  # kind, origin, seq, stamp: packed before the acks and the payload
#: The bytes before the MAC in a signed message: the key "mac" (fixstr 3) and a bin 8 header of 32 bytes.
_MAC_TAIL = b"\xa3mac\xc4\x20"


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
    (tuples where the schema fixes a length) and str-keyed dicts of those. (``eq=False``: payloads hold
    arrays, compare fields explicitly.)"""

    version: int = SCHEMA_VERSION
    kind: str
    origin: str
    seq: int
    stamp: float
    acks: dict[str, int] = field(default_factory=dict)
    payload: dict[str, Any] = field(default_factory=dict)


class _Body(msgspec.Struct, forbid_unknown_fields=True):
    """The envelope as msgspec validates it (field names are the wire's keys)."""

    v: int
    k: str
    o: schemas.AgentId
    s: schemas.Seq
    t: float
    a: Annotated[dict[schemas.AgentId, schemas.Seq], msgspec.Meta(max_length=MAX_ACKS)]
    p: msgspec.Raw
    mac: Any = None  # judged by decode: 32 bytes


class _Version(msgspec.Struct):
    """Only the version (the first thing judged: another version may have other fields)."""

    v: Any = msgspec.UNSET


# -- envelope ----------------------------------------------------------------------------------------
def encode(envelope: Envelope, key: bytes | None = None, *, kinds: Set[str] | None = None) -> bytes:
    """Pack an envelope, appending an HMAC-SHA256 over the packed bytes when a fleet ``key`` is given.

    The header is checked with the receiver's rules (``ValueError`` if it would be rejected) and the
    packer refuses types that have no wire form (``TypeError``, e.g. a bool array). Payload limits are
    enforced by the receiver only."""
    body = {
        "v": _plain(envelope.version),
        "k": envelope.kind,
        "o": envelope.origin,
        "s": _plain(envelope.seq),
        "t": _plain(envelope.stamp),
        "a": {peer: _plain(last) for peer, last in envelope.acks.items()},
        "p": envelope.payload,
    }
    _check_outgoing_header(body, KINDS if kinds is None else kinds)
    if key is not None:
        _check_key(key)
        body["mac"] = bytes(MAC_BYTES)  # placeholder: the MAC is the last MAC_BYTES bytes of the message
    packed = _ENCODER.encode(body)
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
    fleet: Set[str] | None = None,
) -> Envelope:
    """Validate and unpack one message. Raises only :class:`DecodeError`, whatever ``data`` holds.

    Order of checks: size, MAC (with a key, on the raw bytes before anything is parsed), envelope
    structure, version, field set, field types and ranges, kind, origin, payload schema and, given the ``fleet``'s
    names, every agent a typed payload names (:mod:`agent.net.roster`). (A ``key`` that
    is not non-empty bytes is a configuration error and raises ``ValueError`` before ``data`` is looked
    at.)"""
    if key is not None:
        _check_key(key)
    try:
        envelope = _decode(data, expected_origin, key, max_bytes, KINDS if kinds is None else kinds)
        if fleet is not None and (names := roster.strangers(envelope.kind, envelope.acks, envelope.payload, fleet)):
            raise DecodeError("unknown_name", f"names outside the fleet: {', '.join(n[:64] for n in names[:4])}")
        return envelope
    except DecodeError:
        raise
    except Exception as exc:  # a safety net: the agent must never crash on input (DESIGN.md §5)
        raise DecodeError("malformed", f"unexpected {type(exc).__name__} while validating") from None


def check_encoding(encoding: str | None) -> None:
    """:class:`DecodeError` ``bad_encoding`` unless the Zenoh encoding a message came with is :data:`ZENOH_ENCODING`
    (``None``: a transport without encodings, the in-memory bus). Checked before :func:`decode`: bytes of another
    format, or of another version of this one, are not parsed."""
    if encoding is not None and encoding != ZENOH_ENCODING:
        raise DecodeError("bad_encoding", f"Zenoh encoding {encoding[:80]!r}, expected {ZENOH_ENCODING!r}")


def encoded_size(envelope: Envelope, key: bytes | None = None) -> int:
    """Bytes on the wire for ``envelope`` (MAC included when a key is given)."""
    return len(encode(envelope, key))


def _decode(data, expected_origin, key, max_bytes, kinds) -> Envelope:
    if not isinstance(data, bytes | bytearray | memoryview):
        raise DecodeError("bad_type", f"expected bytes, got {type(data).__name__}")
    data = bytes(data)
    if len(data) > max_bytes:
        raise DecodeError("oversize", f"{len(data)} bytes > {max_bytes}")
    if key is not None:
        _verify_mac(data, key)
    body = _parse(_BODY, data, envelope=True)
    if key is None and body.mac is not None and not (isinstance(body.mac, bytes) and len(body.mac) == MAC_BYTES):
        raise DecodeError("bad_mac", "mac field is not 32 bytes")
    if body.v != SCHEMA_VERSION:
        raise DecodeError("version", f"schema version {body.v}, expected {SCHEMA_VERSION}")
    if not math.isfinite(body.t):
        raise DecodeError("non_finite", "stamp is not finite")
    if body.k not in kinds:
        raise DecodeError("unknown_kind", f"kind {body.k[:80]!r}")
    if expected_origin is not None and body.o != expected_origin:
        raise DecodeError("origin_mismatch", f"origin {body.o!r} on a key of {expected_origin!r}")
    schema = _PAYLOADS.get(body.k)
    if schema is None:
        payload = _unpack_generic(body.p)
        _check_tree(payload)
    else:
        payload = _parse(schema[0], body.p, reason=schema[1])
    return Envelope(version=body.v, kind=body.k, origin=body.o, seq=body.s, stamp=body.t, acks=body.a, payload=payload)


def _parse(decoder: msgspec.msgpack.Decoder, data, *, envelope: bool = False, reason: str | None = None):
    """Run a msgspec decoder, turning its errors into :class:`DecodeError` reasons. ``envelope``: judge a
    failed envelope by its version first; ``reason``: the kind's own reason for a payload schema violation
    (e.g. ``bad_truth``)."""
    try:
        return decoder.decode(data)
    except DecodeError:
        raise
    except msgspec.ValidationError as exc:
        if envelope:
            _check_version(data)
        raise DecodeError(reason or _validation_reason(str(exc)), str(exc)) from None
    except msgspec.DecodeError as exc:
        text = str(exc)
        raise DecodeError("truncated" if "truncated" in text else "malformed", text) from None
    except UnicodeDecodeError:
        raise DecodeError("malformed", "a str that is not UTF-8") from None
    except RecursionError:
        raise DecodeError("malformed", "nesting too deep") from None


def _unpack_generic(raw) -> dict:
    """A generic payload, unpacked in C by msgpack with every list and map bounded by :data:`MAX_GENERIC_ITEMS`: a
    longer one is ``oversize`` from its header alone (msgspec, which decodes the typed kinds, has no such bound and
    built all 10**5 elements of a hostile list first: ~5 ms, twice per message in the agent)."""
    try:
        payload = msgpack.unpackb(raw, raw=False, strict_map_key=True, ext_hook=_ext_hook,
                                  max_array_len=MAX_GENERIC_ITEMS, max_map_len=MAX_GENERIC_ITEMS)
    except DecodeError:
        raise
    except (msgpack.StackError, msgpack.ExtraData, UnicodeDecodeError, RecursionError) as exc:
        raise DecodeError("malformed", f"payload: {type(exc).__name__}") from None
    except ValueError as exc:
        raise DecodeError(_unpack_reason(str(exc)), f"payload: {str(exc)[:80]}") from None
    if not isinstance(payload, dict):
        raise DecodeError("bad_type", f"payload must be a map, got {type(payload).__name__}")
    return payload


def _unpack_reason(text: str) -> str:
    """A reason from msgpack's message (e.g. "100000 exceeds max_array_len(4096)")."""
    if "exceeds max_" in text:
        return "oversize"
    if "incomplete input" in text:
        return "truncated"
    return "bad_type" if "not allowed for map key" in text else "malformed"


def _validation_reason(text: str) -> str:
    """A schema violation's reason from msgspec's message (e.g. "Expected `int`, got `str` - at `$.s`")."""
    if "length <=" in text:
        return "oversize"
    if "missing required field" in text or "unknown field" in text or "matching regex" in text or "` >=" in text \
            or "` <=" in text or "length >=" in text:
        return "bad_field"
    return "bad_type"


def _check_version(data: bytes) -> None:
    """On a failed envelope, report a missing, mistyped or other version before anything else."""
    try:
        version = _VERSION.decode(data).v
    except (msgspec.MsgspecError, RecursionError, UnicodeDecodeError):
        return
    if version is msgspec.UNSET:
        raise DecodeError("bad_field", "missing field 'v' (version)")
    if not is_int(version):
        raise DecodeError("bad_type", "version must be an int")
    if version != SCHEMA_VERSION:
        raise DecodeError("version", f"schema version {version}, expected {SCHEMA_VERSION}")


def _check_outgoing_header(body: dict, kinds: Set[str]) -> None:
    """The receiver's header rules, for :func:`encode` (``ValueError`` naming the fault)."""
    try:
        _BODY.decode(_ENCODER.encode({**body, "p": {}}))
    except msgspec.ValidationError as exc:
        raise ValueError(f"cannot encode envelope: {exc}") from None
    except TypeError:
        raise ValueError("cannot encode envelope: a header field has no wire form") from None
    if body["v"] != SCHEMA_VERSION or not math.isfinite(body["t"]) or body["k"] not in kinds:
        raise ValueError(f"cannot encode envelope: version {body['v']}, stamp {body['t']}, kind {body['k']!r}")


@dataclass(frozen=True)
class Header:
    kind: str
    origin: str
    seq: int
    stamp: float


class _Peek(msgspec.Struct):
    """The header fields only: msgspec skips the rest (payload, acks, MAC) in C without building it."""

    k: str
    o: str
    s: schemas.Seq
    t: float


_peek_decoder = msgspec.msgpack.Decoder(_Peek)


def peek_header(data: bytes) -> Header | None:
    """Kind, origin, seq and stamp of an envelope without reading its payload, for the emulated radio
    (``None`` if unreadable; the header comes before the payload, so a cut payload does not matter).
    Nothing is validated: :func:`decode` judges the same bytes afterwards. A whole message is read by
    msgspec, skipping everything but the header; one it cannot read (e.g. cut short) field by field."""
    try:
        head = _peek_decoder.decode(data)
    except (msgspec.DecodeError, msgspec.ValidationError, ValueError):  # ValueError: e.g. a string not UTF-8
        return _peek_fields(data)
    return Header(head.k, head.o, head.s, head.t) if math.isfinite(head.t) else None


def _peek_fields(data: bytes) -> Header | None:
    """:func:`peek_header` by unpacking the map entry by entry up to the payload."""
    try:
        unpacker = msgpack.Unpacker(max_buffer_size=len(data) or 1, raw=False, strict_map_key=False)
        unpacker.feed(data)
        fields: dict = {}
        for _ in range(unpacker.read_map_header()):
            name = unpacker.unpack()
            if name == "p":
                break
            value = unpacker.unpack()
            if name in _HEADER:
                fields[name] = value
    except Exception:  # any malformed input: not ours to judge
        return None
    kind, origin, seq, stamp = (fields.get(k) for k in _HEADER)
    ok = isinstance(kind, str) and isinstance(origin, str) and is_int(seq) and seq >= 0 and (
        is_int(stamp) or isinstance(stamp, float)) and math.isfinite(stamp)
    return Header(kind, origin, seq, float(stamp)) if ok else None


def _plain(value):
    """numpy scalars as Python numbers (so an ``np.int64`` seq is accepted like an ``int``)."""
    return value.item() if isinstance(value, np.integer | np.floating) else value


def is_int(value) -> bool:
    """An int that is not a bool (MessagePack gives bools for true/false)."""
    return isinstance(value, int) and not isinstance(value, bool)


def _check_tree(payload) -> None:
    """Depth and leaf types of a generic payload, iteratively (no recursion on hostile input). Only the kinds
    that the ground station and the simulator read are generic (:mod:`agent.net.schemas`): the agents' own
    traffic never pays this walk. The element types of a container are collected in C and only containers are
    pushed: a list of MAX_GENERIC_ITEMS takes well under a millisecond (not a per-element ``isinstance`` against
    a type union built each time)."""
    stack = [(payload, 0)]
    while stack:
        node, depth = stack.pop()
        if depth >= MAX_DEPTH:
            raise DecodeError("malformed", f"payload nested deeper than {MAX_DEPTH}")
        if type(node) is dict:
            if not set(map(type, node)) <= _STR:
                raise DecodeError("bad_type", "payload map keys must be str")
            node = node.values()
        kinds = set(map(type, node))  # in C: one pass over the elements
        if not kinds <= _NODES:
            raise DecodeError("bad_type", f"payload holds a {min(t.__name__ for t in kinds - _NODES)}")
        if dict in kinds or list in kinds:
            stack.extend((child, depth + 1) for child in node if type(child) is dict or type(child) is list)


_STR = frozenset({str})
_NODES = frozenset({dict, list, type(None), bool, int, float, str, bytes, np.ndarray})  # what msgpack, _ext_hook build


# -- MAC ---------------------------------------------------------------------------------------------
def _check_key(key) -> None:
    if not isinstance(key, bytes) or not key:
        raise ValueError("the fleet key must be non-empty bytes")


def _mac(key: bytes, signed: bytes) -> bytes:
    return hmac.new(key, signed, hashlib.sha256).digest()


def _verify_mac(data: bytes, key: bytes) -> None:
    """The MAC is judged on the raw bytes, before any field is parsed: the message must end with the key
    ``"mac"``, a 32-byte bin header and the HMAC of everything before those 32 bytes."""
    if len(data) < len(_MAC_TAIL) + MAC_BYTES or data[-MAC_BYTES - len(_MAC_TAIL):-MAC_BYTES] != _MAC_TAIL:
        raise DecodeError("bad_mac", "message does not end with a 32-byte mac field but a fleet key is configured")
    if not hmac.compare_digest(data[-MAC_BYTES:], _mac(key, data[:-MAC_BYTES])):
        raise DecodeError("bad_mac", "wrong mac")


# -- arrays ------------------------------------------------------------------------------------------
def _enc_hook(obj):
    if isinstance(obj, np.ndarray):
        return msgspec.msgpack.Ext(EXT_NDARRAY, _pack_array(obj))
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    raise TypeError(f"cannot put a {type(obj).__name__} on the wire")


def _pack_array(arr: np.ndarray) -> bytes:
    header, dtype = _array_header(arr.dtype, arr.shape)
    return header + arr.astype(dtype, copy=False).tobytes(order="C")


@functools.lru_cache(maxsize=256)
def _array_header(dtype: np.dtype, shape: tuple[int, ...]) -> tuple[bytes, np.dtype]:
    """The ext payload's header for arrays of ``dtype`` and ``shape`` (dtype string, ndim, dims as uint32
    little-endian) and the little-endian dtype the values travel in; a message repeats a few shapes."""
    dtype = dtype.newbyteorder("<")
    if dtype.str not in ALLOWED_DTYPES:
        raise TypeError(f"array dtype {dtype} is not allowed on the wire ({sorted(ALLOWED_DTYPES)})")
    if len(shape) > MAX_NDIM or math.prod(shape) > MAX_ARRAY_ELEMENTS or any(d >= 1 << 32 for d in shape):
        raise ValueError(f"array of shape {shape} is too large for the wire")
    return dtype.str.encode("ascii") + struct.pack(f"<B{len(shape)}I", len(shape), *shape), dtype


def _ext_hook(code: int, data) -> np.ndarray:
    """Called by the decoder for every ExtType: the array is checked before anything is allocated."""
    if code != EXT_NDARRAY:
        raise DecodeError("bad_type", f"unknown MessagePack ext type {code}")
    if len(data) < 4:
        raise DecodeError("bad_shape", "array header shorter than 4 bytes")
    dtype, ndim = _DTYPES.get(bytes(data[:3])), data[3]
    if dtype is None:
        raise DecodeError("bad_type", f"array dtype {bytes(data[:3])!r} is not allowed")
    if ndim > MAX_NDIM or len(data) < 4 + 4 * ndim:
        raise DecodeError("bad_shape", f"array header of {ndim} dims is invalid")
    shape = _DIMS[ndim].unpack_from(data, 4)
    count = math.prod(shape)
    if count > MAX_ARRAY_ELEMENTS:
        raise DecodeError("oversize", f"array of {count} elements > {MAX_ARRAY_ELEMENTS}")
    if len(data) - 4 - 4 * ndim != count * dtype.itemsize:
        raise DecodeError("bad_shape", f"shape {shape} of {dtype.str} needs {count * dtype.itemsize} bytes, "
                                       f"got {len(data) - 4 - 4 * ndim}")
    return np.frombuffer(data, dtype, count, 4 + 4 * ndim).reshape(shape).copy()


_DTYPES = {name.encode("ascii"): np.dtype(name) for name in ALLOWED_DTYPES}
_DIMS = [struct.Struct(f"<{n}I") for n in range(MAX_NDIM + 1)]


def _dec_hook(kind: type, obj):
    """A schema's ``np.ndarray`` field accepts only what :func:`_ext_hook` built."""
    if kind is np.ndarray and isinstance(obj, np.ndarray):
        return obj
    raise msgspec.ValidationError(f"Expected an array, got `{type(obj).__name__}`")


def _decoder(schema) -> msgspec.msgpack.Decoder:
    return msgspec.msgpack.Decoder(schema, ext_hook=_ext_hook, dec_hook=_dec_hook)


_ENCODER = msgspec.msgpack.Encoder(enc_hook=_enc_hook)
_BODY = msgspec.msgpack.Decoder(_Body)
_VERSION = msgspec.msgpack.Decoder(_Version)
#: kind -> (decoder, reason) for the typed kinds; the others decode by :func:`_unpack_generic` and :func:`_check_tree`.
_PAYLOADS = {k: (_decoder(s.type), s.reason) for k, s in schemas.PAYLOADS.items() if s.type is not schemas.Generic}
