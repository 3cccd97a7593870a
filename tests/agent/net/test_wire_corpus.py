"""The typed decoder (agent.net.wire + agent.net.schemas) against today's v1 decoder
(mesh_sim.bench.legacy_wire): on the agent's whole receive path — decode, then the exchange's codec —
both reject the same corpus of bad messages and accept the same valid ones.

Every message is built as raw MessagePack bytes from the format in ``docs/wire.md`` (not with either
decoder's encoder), so both judge exactly the same bytes. Two agents receive each message, identical but
for ``agent.net.wire.decode``, which the second has replaced by the v1 decoder: a message is rejected when
the agent counts a rejection and applies nothing. Reasons may differ where the typed schema judges a type
before the codec judges a value (documented in docs/wire.md); acceptance may not.
"""

from __future__ import annotations

import itertools
import struct
import uuid

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from agent import agent as agent_module
from agent.agent import Agent
from agent.config import AgentScenario
from agent.net import roster, wire
from agent.net.bus import InMemoryBus
from agent.net.gaussian_codec import encode_trajectory
from agent.net.keys import Incoming, Keys
from fusion.trajectory import Trajectory
from mesh_sim.bench import legacy_wire


def ext(a: np.ndarray) -> msgpack.ExtType:
    return msgpack.ExtType(1, a.dtype.str.encode() + struct.pack(f"<B{a.ndim}I", a.ndim, *a.shape) + a.tobytes())


BEARINGS = np.array([[0.4, 10.0, 5.0, -80.0, 0.3, -1.2, 1e-4, 0.0, 1e-4]])


def flood_payload() -> dict:
    return {"increments": [["uav1", 3, ext(BEARINGS)]], "acks": {"uav1": [3, 0]}}


def track_payload(model) -> dict:
    prior = Trajectory.prior(model, 0)
    n = model.window * model.state_dim
    band = encode_trajectory(Trajectory(prior.y, prior.Y + np.eye(n), 0, model))
    belief = {k: ext(v) if isinstance(v, np.ndarray) else v for k, v in band.items()}
    return {"tracks": [{"id": 1, "belief": belief, "last_measured": 0.0, "acks": {}}]}


TRUTH = {"targets": [{"id": "car", "position": [1.0, 2.0, 0.0], "velocity": [0.5, 0.0, 0.0]}],
         "uavs": {"uav1": [0.0, 0.0, -80.0]}}


def body(kind: str, payload, **changes) -> dict:
    out = {"v": 1, "k": kind, "o": "uav1" if kind != "truth" else "world", "s": 7, "t": 0.4, "a": {}, "p": payload}
    out.update(changes)
    return {k: v for k, v in out.items() if v is not DELETE}


DELETE = object()


def pack(value) -> bytes:
    return msgpack.packb(value, use_bin_type=True)


class Receiver:
    """An agent of policy ``policy`` whose wire decoder is the typed one or the v1 one."""

    def __init__(self, policy: str, legacy: bool):
        self.keys = Keys(f"corpus-{uuid.uuid4().hex[:8]}")
        scenario = AgentScenario.from_dict({"agents": 2, "tracking": {"policy": policy}})
        self.agent = Agent("uav0", 0, scenario, InMemoryBus().endpoint("uav0", []), self.keys, seed=0)
        self.legacy = legacy

    def accepts(self, kind: str, data: bytes, monkeypatch) -> tuple[bool, str | None]:
        key = self.keys.sim("truth") if kind == "truth" else self.keys.belief("track", "uav1")
        before = self.agent.rejected.copy()
        with monkeypatch.context() as patch:
            if self.legacy:
                patch.setattr(agent_module.wire, "decode", legacy_wire.decode)
            self.agent.receive(Incoming(key, data, 0.0), 0.4)
        new = self.agent.rejected - before
        return (not new, next(iter(new), None))


@pytest.fixture(scope="module")
def model():
    return Receiver("hybrid", False).agent.exchanges["track"].tracker.model


def bad_corpus(model) -> list[tuple[str, str, str, bytes]]:
    """(name, policy, kind, bytes): each a valid message spoiled in one respect."""
    flood, track = flood_payload(), track_payload(model)
    belief = track["tracks"][0]["belief"]

    def in_track(**entry):
        return {"tracks": [{**track["tracks"][0], **entry}]}

    def in_belief(**fields):
        return in_track(belief={**belief, **fields})

    cases = [
        ("version 2", "flood", "track", pack(body("track", flood, v=2))),
        ("version missing", "flood", "track", pack(body("track", flood, v=DELETE))),
        ("an unknown envelope field", "flood", "track", pack(body("track", flood, x=1))),
        ("origin not an agent id", "flood", "track", pack(body("track", flood, o="uav 1"))),
        ("negative seq", "flood", "track", pack(body("track", flood, s=-1))),
        ("bool seq", "flood", "track", pack(body("track", flood, s=True))),
        ("NaN stamp", "flood", "track", pack(body("track", flood, t=float("nan")))),
        ("stamp a string", "flood", "track", pack(body("track", flood, t="0.4"))),
        ("257 acks", "flood", "track", pack(body("track", flood, a={f"u{i}": i for i in range(257)}))),
        ("payload a list", "flood", "track", pack(body("track", [flood]))),
        ("unknown kind", "flood", "track", pack(body("tracks", flood))),
        ("trailing byte", "flood", "track", pack(body("track", flood)) + b"\x00"),
        ("truncated", "flood", "track", pack(body("track", flood))[:-3]),
        ("not msgpack", "flood", "track", b"\xc1\x00"),
        ("ext type 7", "flood", "track", pack(body("track", {
            "increments": [["uav1", 3, msgpack.ExtType(7, b"ab")]], "acks": {}}))),
        ("array dtype >f8", "flood", "track", pack(body("track", {
            "increments": [["uav1", 3, ext(BEARINGS.astype(">f8"))]], "acks": {}}))),
        ("array shape vs bytes", "flood", "track", pack(body("track", {
            "increments": [["uav1", 3, msgpack.ExtType(1, ext(BEARINGS).data[:-8])]], "acks": {}}))),
        ("increment of two fields", "flood", "track", pack(body("track", {"increments": [["uav1", 3]], "acks": {}}))),
        ("increment number negative", "flood", "track", pack(body("track", {
            "increments": [["uav1", -3, ext(BEARINGS)]], "acks": {}}))),
        ("increment number a float", "flood", "track", pack(body("track", {
            "increments": [["uav1", 3.0, ext(BEARINGS)]], "acks": {}}))),
        ("bearings a list", "flood", "track", pack(body("track", {
            "increments": [["uav1", 3, BEARINGS.tolist()]], "acks": {}}))),
        ("bearings of 8 columns", "flood", "track", pack(body("track", {
            "increments": [["uav1", 3, ext(BEARINGS[:, :8].copy())]], "acks": {}}))),
        ("a NaN bearing", "flood", "track", pack(body("track", {
            "increments": [["uav1", 3, ext(np.full((1, 9), np.nan))]], "acks": {}}))),
        ("acks of three numbers", "flood", "track", pack(body("track", {**flood, "acks": {"uav1": [3, 0, 1]}}))),
        ("acks mask negative", "flood", "track", pack(body("track", {**flood, "acks": {"uav1": [3, -1]}}))),
        ("acks a list", "flood", "track", pack(body("track", {**flood, "acks": [["uav1", 3, 0]]}))),
        ("no increments", "flood", "track", pack(body("track", {"acks": {}}))),
        ("track id a string", "hybrid", "track", pack(body("track", in_track(id="1")))),
        ("track without belief", "hybrid", "track", pack(body("track", {"tracks": [{"id": 1, "last_measured": 0.0}]}))),
        ("last_measured a string", "hybrid", "track", pack(body("track", in_track(last_measured="0")))),
        ("track acks negative", "hybrid", "track", pack(body("track", in_track(acks={"uav0": -1})))),
        ("resync a bool", "hybrid", "track", pack(body("track", in_track(resync={"uav0": True})))),
        ("fresh a string", "hybrid", "track", pack(body("track", in_track(fresh="2")))),
        ("tracks a map", "hybrid", "track", pack(body("track", {"tracks": {"1": 1}}))),
        ("belief y of ints", "hybrid", "track", pack(body("track", in_belief(
            y=ext(np.zeros(model.window * model.state_dim, "<i8")))))),
        ("belief n wrong", "hybrid", "track", pack(body("track", in_belief(n=model.state_dim + 1)))),
        ("belief diag NaN", "hybrid", "track", pack(body("track", in_belief(
            diag=ext(np.full((model.window, model.state_dim, model.state_dim), np.nan)))))),
        ("belief indefinite", "hybrid", "track", pack(body("track", in_belief(
            diag=ext(-np.tile(np.eye(model.state_dim), (model.window, 1, 1))))))),
        ("truth position of two numbers", "hybrid", "truth", pack(body("truth", {
            "targets": [{**TRUTH["targets"][0], "position": [1.0, 2.0]}]}))),
        ("truth position a string", "hybrid", "truth", pack(body("truth", {
            "targets": [{**TRUTH["targets"][0], "position": "1 2 0"}]}))),
        ("truth target id a number", "hybrid", "truth", pack(body("truth", {
            "targets": [{**TRUTH["targets"][0], "id": 5}]}))),
        ("truth targets a map", "hybrid", "truth", pack(body("truth", {"targets": {"car": 1}}))),
        ("truth uav position of bools", "hybrid", "truth", pack(body("truth", {"uavs": {"uav1": [True, 0.0, 0.0]}}))),
        ("deep nesting", "hybrid", "truth", pack(body("truth", {"decoys": nested(40)}))),
    ]
    return cases


def nested(depth: int) -> list:
    value: list = [0]
    for _ in range(depth):
        value = [value]
    return value


VALID = ("flood", "hybrid")


@pytest.mark.parametrize("policy", VALID)
def test_both_decoders_accept_the_valid_messages(policy, model, monkeypatch):
    payload = flood_payload() if policy == "flood" else track_payload(model)
    for legacy in (False, True):
        receiver = Receiver(policy, legacy)
        assert receiver.accepts("track", pack(body("track", payload)), monkeypatch) == (True, None), legacy
        assert receiver.accepts("truth", pack(body("truth", TRUTH)), monkeypatch) == (True, None), legacy


def test_both_decoders_reject_the_same_corpus_of_bad_messages(model, monkeypatch):
    receivers = {(policy, legacy): Receiver(policy, legacy) for policy in VALID for legacy in (False, True)}
    verdicts = {}
    for name, policy, kind, data in bad_corpus(model):
        new = receivers[(policy, False)].accepts(kind, data, monkeypatch)
        old = receivers[(policy, True)].accepts(kind, data, monkeypatch)
        verdicts[name] = (new, old)
    accepted = {name: v for name, v in verdicts.items() if v[0][0] or v[1][0]}
    assert not accepted, f"accepted by a decoder (typed, v1): {accepted}"


_MUTATION = st.tuples(st.sampled_from(["flip", "delete", "insert"]), st.integers(0, 10_000), st.integers(0, 255))


_SEQ = itertools.count(100)  # a new sequence number per example: the shared receivers never see a duplicate
_RECEIVERS: dict[tuple[str, bool], Receiver] = {}


def receiver(policy: str, legacy: bool) -> Receiver:
    if (policy, legacy) not in _RECEIVERS:
        _RECEIVERS[(policy, legacy)] = Receiver(policy, legacy)
    return _RECEIVERS[(policy, legacy)]


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(which=st.sampled_from(["flood", "hybrid", "truth"]), mutations=st.lists(_MUTATION, min_size=1, max_size=3))
def test_mutated_messages_are_accepted_by_both_decoders_or_by_neither(which, mutations, model, monkeypatch):
    """Random byte edits of valid messages (a flipped byte, one deleted or inserted): the typed decoder must
    not accept what the v1 path rejected, nor the reverse — but for the two documented differences: a field
    nobody reads (v1 refused it), and a name outside the fleet that an edit made (v1 did not judge names)."""
    policy = "flood" if which == "flood" else "hybrid"
    kind = "truth" if which == "truth" else "track"
    payload = {"flood": flood_payload, "hybrid": lambda: track_payload(model), "truth": lambda: TRUTH}[which]()
    data = bytearray(pack(body(kind, payload, s=next(_SEQ))))
    for op, at, value in mutations:
        at %= len(data) + (op == "insert")
        if op == "flip" and at < len(data):
            data[at] = value
        elif op == "delete" and at < len(data):
            del data[at]
        elif op == "insert":
            data.insert(at, value)
    new = receiver(policy, False).accepts(kind, bytes(data), monkeypatch)
    old = receiver(policy, True).accepts(kind, bytes(data), monkeypatch)
    if new[0] and not old[0]:  # a documented difference: the v1 decoder refused a field nobody reads
        assert has_unknown_field(bytes(data)), (new, old)
    elif old[0] and new == (False, "unknown_name"):  # the other: v1 did not judge names (agent.net.roster)
        envelope = wire.decode(bytes(data))  # what the edit made of the message's names (the receivers' fleet: 2)
        assert roster.strangers(envelope.kind, envelope.acks, envelope.payload, {"uav0", "uav1"}), (new, old)
    else:
        assert new[0] == old[0], (new, old)


KNOWN = {  # the fields of the typed payloads (agent.net.schemas), by the map they appear in
    "payload": {b"tracks", b"increments", b"acks", b"targets", b"uavs", b"fire", b"decoys"},
    "track": {b"id", b"belief", b"last_measured", b"acks", b"resync", b"fresh"},
    "belief": {b"epoch", b"n", b"L", b"y", b"diag", b"off"},
    "target": {b"id", b"position", b"velocity"},
}


def has_unknown_field(data: bytes) -> bool:
    """Does the payload hold a field its typed schema does not know (read with raw keys: a key need not be
    UTF-8)?"""
    try:
        payload = msgpack.unpackb(data, raw=True, strict_map_key=False).get(b"p")
    except Exception:
        return False
    if not isinstance(payload, dict):
        return False
    maps = [("payload", payload)]
    for entry in payload.get(b"tracks", []) if isinstance(payload.get(b"tracks"), list) else []:
        if isinstance(entry, dict):
            maps.append(("track", entry))
            if isinstance(entry.get(b"belief"), dict):
                maps.append(("belief", entry[b"belief"]))
    for entry in payload.get(b"targets", []) if isinstance(payload.get(b"targets"), list) else []:
        if isinstance(entry, dict):
            maps.append(("target", entry))
    return any(set(fields) - KNOWN[name] for name, fields in maps)


def test_an_unknown_field_of_a_typed_payload_is_skipped_unread(monkeypatch):
    """The one documented difference (docs/wire.md): a typed kind skips payload fields it does not know (a newer
    sender's optional fields) without building them, so even an unknown ext type there costs nothing; the v1
    decoder built every value and refused the ext type. Fields it knows are judged in full."""
    data = pack(body("track", {**flood_payload(), "x": msgpack.ExtType(7, b"ab")}))
    assert Receiver("flood", False).accepts("track", data, monkeypatch) == (True, None)
    assert Receiver("flood", True).accepts("track", data, monkeypatch) == (False, "bad_type")
