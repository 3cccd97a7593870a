"""Fuzzed inputs for ``skymesh bench fuzz``: a valid seed envelope, mutated by one family at a time.

Every input starts from the case's seed with a fresh sequence number (so that it is judged on its content,
not dropped as a duplicate). Families (:data:`FAMILIES`):

* ``random`` — random bytes of a random length; ``truncated`` — the sealed message cut short;
  ``bitflip`` — 1 to 8 bits of the sealed message flipped;
* ``type`` — one node of the payload replaced by a value of another type; ``kind`` — the payload sent
  under another kind (type confusion of a whole envelope);
* ``matrix`` — one float array (or float) made NaN, ±inf, huge (× 1e300), zero, tiny (× 1e-300) or, for
  a positive-definite block (an information matrix), negative definite;
* ``huge`` — a list of 10⁵ elements, a string of 10⁶ characters or a dict of 10⁴ keys in the payload;
  ``nested`` — a node replaced by lists nested 10² to 10⁵ deep (spliced in as bytes: no packer nests so deep);
* ``origin`` — an envelope origin other than the key's; ``replay`` — the last input the agent used, again;
  ``stamp`` — the envelope stamp moved by 10³ to 10¹² s, and every ``epoch`` in the payload by 200 to 10⁹
  steps; ``seq`` — a sequence number moved forward by 1 to 2⁶⁴ (log-uniform: every magnitude alike), capped at
  2⁶⁴ − 1.

An input is *invalid* (:attr:`Input.invalid`) when its mutation guarantees that the agent must reject it:
a truncated message; with a fleet key, any change of the signed bytes; a wrong origin on a peer's key; a
replay; a non-finite number; a negative-definite information block; an epoch moved beyond the tracks'
window (:data:`agent.beliefs.tracks.FUTURE_EPOCHS`). The other families may yield valid messages.
"""

from __future__ import annotations

import hashlib
import hmac
from dataclasses import dataclass, replace

import numpy as np

from agent.net import wire
from mesh_sim.bench.fuzz_seeds import Case

FAMILIES = ("random", "truncated", "bitflip", "type", "kind", "matrix", "huge", "nested", "origin", "replay",
            "stamp", "seq")
NEST_MARKER = "\x00nest\x00"  # a payload string replaced by deep nesting once packed ...
NEST_BYTES = b"\xa6" + NEST_MARKER.encode()  # ... as MessagePack packs it (a fixstr of 6 bytes)
NEST_DEPTHS = (100, 1_000, 10_000, 100_000)
EPOCH_SHIFT = (200, 10**9)  # an epoch moved this far is outside the tracks' window (50 steps) both ways
SEQ_HEADROOM = 1 << 40  # a sender whose window is this close to 2**64 hands over to another fleet member
HUGE = ([0] * 100_000, "x" * 1_000_000, {f"k{i}": i for i in range(10_000)})  # what ``huge`` puts in a payload
OTHERS = [None, True, -1, 2**63, 1.5, "x", b"\x00", [], {}, {"a": 1}, [1, "a"], np.zeros(3),
          np.zeros((2, 2), "<i4"), np.array([1.0, np.nan])]  # what a node becomes under ``type``


@dataclass(frozen=True)
class Input:
    family: str
    key: str  # the key it arrives on
    data: bytes
    invalid: bool  # mutated so that the agent must reject it


class Mutator:
    """The inputs of one case, deterministic for a seeded ``rng``; :meth:`used` tells it what the agent used."""

    def __init__(self, case: Case, rng: np.random.Generator):
        self.case, self.rng = case, rng
        self.names = case.senders()
        self.seq, self.origin, self.renamed = case.next_seq, next(self.names), 0
        self.last_used: Input | None = None
        self.kinds = sorted(case.agent.kinds - {case.seed.kind})

    def make(self, family: str) -> Input:
        return getattr(self, f"_{family}")()

    def used(self, inp: Input) -> None:
        """The agent used ``inp``: it may be replayed, and its sequence number is spent."""
        self.last_used = inp
        header = wire.peek_header(inp.data)
        if header is None:
            return
        self.seq = max(self.seq, header.seq + 1)
        if self.seq > (1 << 64) - SEQ_HEADROOM:  # the window is spent: another member of the fleet takes over
            self.renamed += 1
            self.origin, self.seq = next(self.names, self.origin), self.case.next_seq

    # -- building -----------------------------------------------------------------------------------
    def fresh(self, **changes) -> wire.Envelope:
        self.seq += 1
        return replace(self.case.seed, **{"origin": self.origin, "seq": self.seq - 1, **changes})

    def seal(self, env: wire.Envelope) -> bytes:
        """Pack (and sign, with the case's key), splicing in deep nesting where the payload holds the marker."""
        key = self.case.fleet_key
        data = wire.encode(env, key, kinds=self.case.agent.kinds)
        if NEST_BYTES not in data:
            return data
        depth = int(self.rng.choice(NEST_DEPTHS))
        body = data[:-wire.MAC_BYTES] if key else data
        body = body.replace(NEST_BYTES, b"\x91" * depth + b"\xc0", 1)
        return body + hmac.new(key, body, hashlib.sha256).digest() if key else body

    def _input(self, family: str, env: wire.Envelope | None, invalid: bool, data: bytes | None = None) -> Input:
        """An input on the sender's key: ``env`` sealed, or ``data`` as given."""
        return Input(family, self.case.key_for(self.origin), self.seal(env) if data is None else data, invalid)

    # -- families on bytes --------------------------------------------------------------------------
    def _random(self) -> Input:
        size = int(self.rng.integers(0, 2 * len(self.seal(self.case.seed)) + 2))
        return self._input("random", None, self.case.fleet_key is not None, self.rng.bytes(size))

    def _truncated(self) -> Input:
        data = self.seal(self.fresh())
        return self._input("truncated", None, True, data[:int(self.rng.integers(0, len(data)))])

    def _bitflip(self) -> Input:
        data = bytearray(self.seal(self.fresh()))
        bits = min(8 * len(data), int(self.rng.integers(1, 9)))
        for bit in self.rng.choice(8 * len(data), bits, replace=False):  # distinct bits: never a no-op
            data[bit // 8] ^= 1 << (bit % 8)
        return self._input("bitflip", None, self.case.fleet_key is not None, bytes(data))

    # -- families on the envelope -------------------------------------------------------------------
    def _type(self) -> Input:
        paths = list(_paths(self.case.seed.payload))
        if not paths:
            return self._input("type", self.fresh(payload=OTHERS[int(self.rng.integers(len(OTHERS)))]), False)
        path = paths[int(self.rng.integers(len(paths)))]
        other = OTHERS[int(self.rng.integers(len(OTHERS)))]
        return self._input("type", self.fresh(payload=_replaced(self.case.seed.payload, path, other)), False)

    def _kind(self) -> Input:
        return self._input("kind", self.fresh(kind=self.kinds[int(self.rng.integers(len(self.kinds)))]), False)

    def _matrix(self) -> Input:
        payload = self.case.seed.payload
        paths = [p for p in _paths(payload) if _is_float(_at(payload, p))]
        if not paths:
            return self._input("matrix", self.fresh(), False)
        path = paths[int(self.rng.integers(len(paths)))]
        value, invalid = _bad_numbers(_at(payload, path), self.rng)
        return self._input("matrix", self.fresh(payload=_replaced(payload, path, value)), invalid)

    def _huge(self) -> Input:
        big = HUGE[int(self.rng.integers(len(HUGE)))]
        paths = list(_paths(self.case.seed.payload))
        if not paths or self.rng.random() < 0.3:
            payload = {**self.case.seed.payload, "zz": big}
        else:
            payload = _replaced(self.case.seed.payload, paths[int(self.rng.integers(len(paths)))], big)
        return self._input("huge", self.fresh(payload=payload), False)

    def _nested(self) -> Input:
        paths = list(_paths(self.case.seed.payload))
        if not paths:
            return self._input("nested", self.fresh(payload={"zz": NEST_MARKER}), False)
        path = paths[int(self.rng.integers(len(paths)))]
        return self._input("nested", self.fresh(payload=_replaced(self.case.seed.payload, path, NEST_MARKER)), False)

    def _origin(self) -> Input:
        """An envelope naming another agent than the sender whose key it arrives on (never the sender itself)."""
        other = f"uav{int(self.rng.integers(2, 100))}"
        env = self.fresh(origin=other if other != self.origin else "uav100")
        return self._input("origin", env, self.case.spec.kind != "truth")  # truth comes from the world, any name

    def _replay(self) -> Input:
        if self.last_used is None:
            return self._input("replay", self.fresh(), False)
        return replace(self.last_used, family="replay", invalid=True)

    def _stamp(self) -> Input:
        sign = 1 if self.rng.random() < 0.5 else -1
        stamp = self.case.now + sign * 10.0 ** self.rng.uniform(3, 12)
        shift = sign * int(self.rng.integers(*EPOCH_SHIFT))
        payload, moved = _epochs_moved(self.case.seed.payload, shift)
        return self._input("stamp", self.fresh(stamp=stamp, payload=payload), moved)

    def _seq(self) -> Input:
        env = self.fresh()
        seq = min(env.seq + int(2.0 ** self.rng.uniform(0, 64)), (1 << 64) - 1)
        return self._input("seq", replace(env, seq=seq), False)


# -- payload trees -----------------------------------------------------------------------------------
def _paths(node, path: tuple = ()):
    """Every node's path below ``node`` (dict keys and list/tuple indices), containers before their children."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list | tuple) else ()
    for key, child in items:
        yield (*path, key)
        yield from _paths(child, (*path, key))


def _at(node, path: tuple):
    for key in path:
        node = node[key]
    return node


def _replaced(node, path: tuple, value):
    """``node`` with the node at ``path`` replaced by ``value``, copying only the containers on the path."""
    if not path:
        return value
    head, rest = path[0], path[1:]
    if isinstance(node, dict):
        return {**node, head: _replaced(node[head], rest, value)}
    out = list(node)
    out[head] = _replaced(node[head], rest, value)
    return tuple(out) if isinstance(node, tuple) else out


def _is_float(value) -> bool:
    return isinstance(value, float) or isinstance(value, np.ndarray) and value.dtype.kind == "f" and value.size > 0


def _bad_numbers(value, rng: np.random.Generator):
    """``value`` (a float or float array) made bad in one of seven ways; ``True`` if it must be rejected."""
    how = ("nan", "inf", "-inf", "huge", "zero", "tiny", "negdef")[int(rng.integers(7))]
    if not isinstance(value, np.ndarray):
        out = {"nan": np.nan, "inf": np.inf, "-inf": -np.inf, "huge": value * 1e300, "zero": 0.0,
               "tiny": value * 1e-300, "negdef": -value}[how]
        return float(out), not np.isfinite(out)
    out = value.copy()
    if how in ("nan", "inf", "-inf"):
        out.flat[int(rng.integers(out.size))] = {"nan": np.nan, "inf": np.inf, "-inf": -np.inf}[how]
    elif how == "huge":
        with np.errstate(over="ignore"):
            out *= 1e300
    elif how in ("zero", "tiny"):
        out *= 0.0 if how == "zero" else 1e-300
    elif out.ndim >= 2 and out.shape[-1] == out.shape[-2]:  # negdef: one square block negated
        blocks = out.reshape(-1, *out.shape[-2:])
        i = int(rng.integers(len(blocks)))
        blocks[i] = -blocks[i]
        return out, _positive_definite(value.reshape(-1, *out.shape[-2:])[i]) or not np.isfinite(out).all()
    else:
        out = -out
    return out, not np.isfinite(out).all()


def _positive_definite(block: np.ndarray) -> bool:
    return bool(np.allclose(block, block.T) and np.isfinite(block).all() and np.linalg.eigvalsh(block).min() > 0)


def _epochs_moved(payload, shift: int):
    """``payload`` with every ``epoch`` field moved by ``shift`` steps; ``True`` if there was one."""
    paths = [p for p in _paths(payload) if p[-1] == "epoch" and isinstance(_at(payload, p), int)]
    for path in paths:
        payload = _replaced(payload, path, _at(payload, path) + shift)
    return payload, bool(paths)

