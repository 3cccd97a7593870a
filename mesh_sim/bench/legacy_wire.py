"""Today's baseline: the pure-Python msgpack decoder of wire format v1 as it was before the typed schema
(issue 12), kept frozen for two uses only — the baseline of ``skymesh bench transport``'s decode timing
(measured in the same run as :mod:`agent.net.wire`), and the reference that
``tests/agent/net/test_wire_corpus.py`` checks the new decoder against (both must reject the same corpus
of bad messages). The agents never import it. The byte format it reads is the one :mod:`agent.net.wire`
writes (``docs/wire.md``).

Validation: msgpack-python unpacks the whole message into Python objects, then a Python walk visits every
element of the payload tree (its leaf types and depth) — the per-element cost the typed decoder removes.
"""

from __future__ import annotations

import hmac
import math
import re
from collections.abc import Set

import msgpack

from agent.net.wire import (
    KINDS,
    MAC_BYTES,
    MAX_ACKS,
    MAX_MESSAGE_BYTES,
    SCHEMA_VERSION,
    DecodeError,
    Envelope,
    _check_key,
    _check_tree,
    _ext_hook,
    _mac,
    is_int,
)

# The v1 decoder's own limits (the typed schemas bound each kind's lists instead).
MAX_CONTAINER_LEN = 4096  # MessagePack array length
MAX_MAP_LEN = 1024
_AGENT_ID = re.compile(r"[A-Za-z0-9_-]{1,64}")
_FIELDS = {"v": "version", "k": "kind", "o": "origin", "s": "seq", "t": "stamp", "a": "acks", "p": "payload"}
_SEQ_LIMIT = 1 << 64


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

    Order of checks: size, msgpack structure, MAC (with a key, before any field is interpreted),
    version, field set, field types and ranges, kind, origin, payload tree. (A ``key`` that is not
    non-empty bytes is a configuration error and raises ``ValueError`` before ``data`` is looked at.)
    ``fleet`` is taken as :func:`agent.net.wire.decode` takes it, so the agent can call either, and ignored:
    the v1 decoder did not judge the names inside a message (:mod:`agent.net.roster` came later)."""
    if key is not None:
        _check_key(key)
    try:
        return _decode(data, expected_origin, key, max_bytes, KINDS if kinds is None else kinds)
    except DecodeError:
        raise
    except Exception as exc:  # a safety net: the agent must never crash on input (DESIGN.md §5)
        raise DecodeError("malformed", f"unexpected {type(exc).__name__} while validating") from None


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
    _check_tree(obj["p"])
    return Envelope(
        version=obj["v"],
        kind=obj["k"],
        origin=obj["o"],
        seq=obj["s"],
        stamp=float(obj["t"]),
        acks=obj["a"],
        payload=obj["p"],
    )


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


def _verify_mac(obj: dict, data: bytes, key: bytes) -> None:
    mac = obj.get("mac")
    if mac is None:
        raise DecodeError("bad_mac", "message carries no mac but a fleet key is configured")
    if not isinstance(mac, bytes) or len(mac) != MAC_BYTES or next(reversed(obj)) != "mac" or data[-MAC_BYTES:] != mac:
        raise DecodeError("bad_mac", "mac must be the last field and 32 bytes")
    if not hmac.compare_digest(mac, _mac(key, data[:-MAC_BYTES])):
        raise DecodeError("bad_mac", "wrong mac")
