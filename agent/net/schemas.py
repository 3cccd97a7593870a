"""The payload schema of every message kind, as types msgspec validates in C (``docs/wire.md``).

One job: say what each kind's payload (``"p"`` of :mod:`agent.net.wire`'s envelope) may hold. A schema
fixes the field names, the types of every element, the lengths of tuples and the bounds of sequence
numbers; arrays are ``np.ndarray`` fields (the wire's ``EXT_NDARRAY``), whose dtype and shape the kind's
codec then checks together with their values, vectorised (finite, positive definite). A payload that
does not match its schema is rejected before any Python code touches it: ``bad_field`` (a field missing,
a value out of range), ``bad_type`` (a wrong type), ``oversize`` (a list above its bound) — or the kind's
own ``reason`` (the world's truth: ``bad_truth``).

Kinds that peers exchange are typed to the last element, so a list longer than the kind allows (a grid's
``shape`` of 10⁵ elements) is rejected in C before any Python code walks it. Kinds that only the ground
station or the simulator read (``telemetry`` with the fields of every plug-in, ``measurement``, ``clock``,
``grid_evidence``) and the particle kind whose codec parses byte buffers are ``Generic``: a str-keyed map
of plain values and arrays, decoded in C and validated by their codecs.

Unknown payload fields of a typed kind are ignored (a newer sender may add optional fields).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, NotRequired, Required, TypedDict

import msgspec
import numpy as np

AGENT_ID_PATTERN = r"^[A-Za-z0-9_-]{1,64}\Z"
AgentId = Annotated[str, msgspec.Meta(pattern=AGENT_ID_PATTERN)]  # the envelope's origin and acks
#: A peer named inside a payload: bounded, not pattern-matched (a regex per name costs ~1.5 µs in msgspec, and
#: a name that is no agent's only ever misses a lookup).
PeerName = Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
Seq = Annotated[int, msgspec.Meta(ge=0)]  # MessagePack integers stop below 2**64
Vec3 = tuple[float, float, float]
MAX_TRACKS = 256  # tracks in one message (chosen here; a fleet tracks tens)
MAX_INCREMENTS = 1024  # flooded increments in one message (chosen here; one per agent and step at most)
MAX_PEERS = 256  # entries of a per-peer map (= wire.MAX_ACKS)
MAX_TARGETS = 4096  # targets in the world's truth (chosen here)

Generic = dict[str, Any]


class TrajectoryPayload(TypedDict):
    """A trajectory belief in information form, its band only (:func:`agent.net.gaussian_codec.encode_trajectory`)."""

    epoch: int
    n: int
    L: int
    y: np.ndarray  # (L*n,) float
    diag: np.ndarray  # (L, n, n) float
    off: np.ndarray  # (L-1, n, n) float


class TrackEntry(TypedDict, total=False):
    """One shared track under a channel-filter policy (:mod:`agent.beliefs.tracks`)."""

    id: Required[int]
    belief: Required[TrajectoryPayload]
    last_measured: Required[float]
    acks: Annotated[dict[PeerName, Seq], msgspec.Meta(max_length=MAX_PEERS)]
    resync: Annotated[dict[PeerName, Seq], msgspec.Meta(max_length=MAX_PEERS)]
    fresh: int


#: ``[origin, n, bearings]``: one flooded increment (:mod:`agent.beliefs.flood`); bearings a (k, 9) array.
Increment = tuple[PeerName, Seq, np.ndarray]
#: ``[highest, mask]``: the increments of one origin a sender holds (:class:`agent.net.flood_relay.Held`).
HeldWire = tuple[Annotated[int, msgspec.Meta(ge=-1)], Annotated[int, msgspec.Meta(ge=0)]]


class TrackPayload(TypedDict, total=False):
    """Kind ``track``: shared tracks (channel filters) or, under ``policy = "flood"``, flooded detections
    with their acknowledgements. The receiving exchange requires the fields of its policy."""

    tracks: Annotated[list[TrackEntry], msgspec.Meta(max_length=MAX_TRACKS)]
    increments: Annotated[list[Increment], msgspec.Meta(max_length=MAX_INCREMENTS)]
    acks: Annotated[dict[PeerName, HeldWire], msgspec.Meta(max_length=MAX_PEERS)]


class TopologyPayload(TypedDict):
    """Kind ``topology``: who hears whom (:mod:`agent.net.topology`), ``{agent: [report time, [neighbours]]}``."""

    reports: Annotated[dict[PeerName, tuple[float, Annotated[list[PeerName], msgspec.Meta(max_length=MAX_PEERS)]]],
                       msgspec.Meta(max_length=MAX_PEERS)]


MAX_TASKS = 1024  # tasks in one bid message (chosen here: tracks plus search cells)
TaskKey = Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
#: ``[key, north, east, winner, bid]``: one task's winner as the sender knows it (``key`` "track": matched by position)
TaskBid = tuple[TaskKey, float, float, PeerName, float]


class TasksPayload(TypedDict):
    """Kind ``tasks``: CBBA bids (:mod:`agent.beliefs.assignment`): the sender's (north, east), its timestamps
    ``s_ik`` per vehicle, and per task the winner and winning bid it knows; ``v`` its velocity (north, east),
    from which peers dead-reckon its position. Without ``stamps`` and ``tasks`` it is the sender's motion only
    (bids unchanged, a crowding peer's separation layer needs where it is); one of the two without the other
    is refused by the receiver."""

    at: tuple[float, float]
    v: NotRequired[tuple[float, float]]
    stamps: NotRequired[Annotated[dict[PeerName, float], msgspec.Meta(max_length=MAX_PEERS)]]
    tasks: NotRequired[Annotated[list[TaskBid], msgspec.Meta(max_length=MAX_TASKS)]]


class TargetTruth(TypedDict):
    id: str
    position: Vec3
    velocity: Vec3


class TruthPayload(TypedDict, total=False):
    """Kind ``truth`` (the world, simulation only): target states, where every UAV is, and the fire."""

    targets: Annotated[list[TargetTruth], msgspec.Meta(max_length=MAX_TARGETS)]
    uavs: Annotated[dict[str, Vec3], msgspec.Meta(max_length=MAX_PEERS)]
    fire: NotRequired[Generic]  # agent.net.fire_truth validates it (bad_fire)
    #: advisory ``[north, east, probability]``: malformed entries are ignored (agent.sensors.truth)
    decoys: NotRequired[list[list[float | bool | str | None]]]


GridName = Annotated[str, msgspec.Meta(max_length=64)]  # a grid mode, dtype or belief name
Pair = tuple[float, float]


class GridGeometryPayload(TypedDict, total=False):
    """A grid's geometry (:meth:`fusion.grid_geometry.GridGeometry.to_dict`)."""

    origin: Pair
    cell: float
    shape: tuple[int, int]
    height: float


class GridCodecPayload(TypedDict, total=False):
    """The codec's keyframe or delta (:func:`agent.net.grid_codec.decode_grid` says which fields each mode needs)."""

    mode: GridName
    L: int
    shape: tuple[int, int]
    values: bytes
    base: int
    n: int
    dtype: GridName
    index: bytes
    q: float
    vtype: GridName


class GridPayload(TypedDict, total=False):
    """Kind ``grid`` (:mod:`agent.beliefs.grid_exchange`): the sender's grid geometry, belief name, the codec's
    payload (:mod:`agent.net.grid_codec`) and its acknowledgements. Every field is optional here: the exchange and
    the codec report a missing one with their own reasons (``grid_geometry``, ``grid_bad_mode``)."""

    geometry: GridGeometryPayload
    belief: GridName
    grid: GridCodecPayload
    acks: Annotated[dict[PeerName, Seq], msgspec.Meta(max_length=MAX_PEERS)]
    position: Pair  # the sender's (north, east) [m] when it sent (tasking.alarm_watch)


@dataclass(frozen=True)
class Schema:
    type: Any
    reason: str | None = None  # the kind's own reason for a schema violation (None: by the fault)


PAYLOADS: dict[str, Schema] = {
    "track": Schema(TrackPayload),
    "topology": Schema(TopologyPayload),
    "tasks": Schema(TasksPayload),
    "truth": Schema(TruthPayload, reason="bad_truth"),
    "telemetry": Schema(Generic),
    "measurement": Schema(Generic),
    "clock": Schema(Generic),
    "grid": Schema(GridPayload),
    "grid_evidence": Schema(Generic),
}
