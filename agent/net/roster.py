"""The agent names a message speaks of, checked against the fleet's roster.

A receiver refuses a message from an origin outside the fleet before it keeps anything about it
(``unknown_origin``, :mod:`agent.agent`). A message from a member can still *name* others: the envelope's
acknowledgements, a topology report's agents and neighbours, the origins of flooded increments, a track's or a
grid's acknowledgements, a bid's timestamps and winners. Each of those names becomes per-peer state at the
receiver (a node of its topology graph, a relay table, a CBBA winner), so a name outside the roster — a bug, a
peer from another fleet's configuration, a garbled field that still passed the schema — would make the receiver
keep state about a vehicle that does not exist, and, in the topology graph, change which links it thinks are
bridges (:mod:`agent.net.topology`). :func:`strangers` lists such names so that :func:`agent.net.wire.decode`
rejects the message as ``unknown_name`` (the schema, :mod:`agent.net.schemas`, already bounds their number and
length; membership is the fleet's, known only at run time).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Set


def _track(payload: dict) -> Iterator[str]:
    """Channel-filter tracks: each track's acks and resync tables; flooding: increments' origins and the acks."""
    for track in payload.get("tracks", ()):
        yield from track.get("acks", {})
        yield from track.get("resync", {})
    yield from (origin for origin, _, _ in payload.get("increments", ()))
    yield from payload.get("acks", {})


def _topology(payload: dict) -> Iterator[str]:
    """Every reporting agent and every neighbour it reports."""
    for agent, (_, neighbours) in payload["reports"].items():
        yield agent
        yield from neighbours


def _tasks(payload: dict) -> Iterator[str]:
    """The vehicles with a CBBA timestamp, and each task's winner."""
    yield from payload.get("stamps", ())
    yield from (winner for _, _, _, winner, _ in payload.get("tasks", ()))


def _grid(payload: dict) -> Iterator[str]:
    """A grid message's acknowledgement table."""
    return iter(payload.get("acks", {}))


#: kind -> the agent names inside its (schema-validated) payload that are checked; kinds absent here carry none
#: (the world's truth names the UAVs it simulates: that is the world's word, not a peer's)
NAMES: dict[str, Callable[[dict], Iterable[str]]] = {
    "track": _track,
    "topology": _topology,
    "tasks": _tasks,
    "grid": _grid,
}


def strangers(kind: str, acks: dict, payload: dict, fleet: Set[str]) -> list[str]:
    """The names in a message of ``kind`` (envelope ``acks`` and payload) that are not in ``fleet``, sorted."""
    named = set(acks)
    named.update(NAMES.get(kind, lambda p: ())(payload))
    return sorted(named - fleet)
