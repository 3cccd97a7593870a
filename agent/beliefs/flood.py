"""The ``"track"`` exchange under ``policy = "flood"``: detections flooded, every agent a centralized tracker.

Each agent floods its own detections — the independent information increments of the fleet — through
:class:`agent.net.flood_relay.FloodRelay`: tagged ``(origin, n)``, relayed once per neighbour that lacks
them, acknowledged and de-duplicated, so every agent applies every detection it receives exactly once, at
the time it was taken (a trajectory window takes a late one, Merino (3.29)-(3.30); with ``motion = "imm"`` an
IMM window re-filters, :mod:`fusion.imm_window`). Every agent then runs
the same tracker on the fleet's detections — association (Merino (3.64)), initiation, extended
information updates (3.52) — as the centralized filter does, and no belief is ever exchanged, so nothing
can be counted twice on any graph, with loops, loss or changing links. Its cost grows with the fleet:
every agent processes every agent's detections (about 72 bytes each on the wire, against ~4.8 kB for one
trajectory belief). To keep that cost down, a step's detections — this agent's own, then each received
batch in the order it arrived — are held and applied together once every message of the step is in
(:meth:`FloodExchange.settle`, :meth:`agent.beliefs.tracking.Tracker.update_scans`): one scan at a time
as before, against marginals and gate distances computed once per step.

Messages: ``{"increments": [[origin, n, bearings], ...], "acks": {origin: [highest, mask]}}`` with the
bearings as in :mod:`agent.beliefs.bearing_codec`. A message is sent when an increment is due
(:meth:`FloodRelay.due`) or this agent has held something unacknowledged for ``ack_delay``
(:meth:`FloodRelay.acks_due`: its acknowledgements stop the neighbours' retransmissions).
"""

from __future__ import annotations

from agent.beliefs.bearing_codec import bearings_from_table, check_bearings, encode_bearings
from agent.beliefs.tracks import FUTURE_EPOCHS, TrackExchange
from agent.net import wire
from agent.net.flood_relay import FloodRelay, acks_from_wire
from agent.net.incarnation import first_number
from agent.plugins import Observations, Outgoing
from agent.sensors.bearing import Bearing
from fusion.resync import Edge


class FloodExchange(TrackExchange):
    """Tracks of one agent, built from every agent's detections; see the module docstring."""

    needs_edge = False  # flooded detections are exact on any graph

    def __init__(self, *args, incarnation: int = 0, **kwargs):
        super().__init__(*args, **kwargs)
        model = self.tracker.model
        config = self.sender.config
        self.relay = FloodRelay(self.me, config.ack_timeout, (model.window - 1) * model.step,
                                first=first_number(incarnation), ack_delay=config.ack_delay)
        self.too_old = 0  # received detections that no longer fit the trajectory window
        self.held: list[list[Bearing]] = []  # this step's scans, applied by settle

    def absorb(self, t: float, observations: Observations) -> None:
        """This step's own detections: flooded now, applied with the peers' ones in :meth:`settle`."""
        bearings = self.own_bearings(t, observations)
        if bearings:
            self.relay.originate(min(b.t for b in bearings), encode_bearings(bearings))
            self.held.append(bearings)

    # -- sending ----------------------------------------------------------------------------------
    def outgoing(self, t: float, neighbours: list[str]) -> Outgoing | None:
        due = self.relay.due(t, neighbours, lambda agent: self.topology.neighbours_of(agent, t))
        if not due and not self.relay.acks_due(t):
            return None
        payload = {"increments": [[inc.origin, inc.n, inc.data] for inc in due], "acks": self.relay.acks()}
        return Outgoing(payload, context=(t, due))

    def sent(self, seq: int, message: Outgoing) -> None:
        t, due = message.context
        self.relay.sent(t, due)

    def thinned(self, message: Outgoing) -> None:
        """Nothing to undo: what did not fit stays due and goes in a later message."""

    # -- receiving --------------------------------------------------------------------------------
    def receive(self, origin: str, seq: int, stamp: float, payload: dict, edge: Edge | None,
                t: float) -> list[tuple[str, str | None]]:
        increments, acks = self._decode(payload)
        self.relay.learn(origin, acks)
        methods = []
        for source, n, rows, table in increments:
            when = min(r[0] for r in table)
            if self.relay.accept(origin, t, source, n, when, rows):  # Bearing objects only for what is new here
                self.held.append(bearings_from_table(table))
                self.latencies.append(t - when)
                methods.append(("exact", None))
        return methods

    def settle(self, t: float) -> None:
        """Apply the step's held scans, each at its own time, once the tracker has advanced to the newest of
        them (a peer's clock may be a little ahead); a detection the window no longer reaches is counted in
        ``too_old`` and dropped (:meth:`agent.beliefs.tracking.Tracker.catch_up`)."""
        scans, self.held = self.held, []
        if scans:
            newest = max(self.tracker.model.epoch_of(b.t) for scan in scans for b in scan)
            self.too_old += sum(self.tracker.catch_up(scans, newest))

    def _decode(self, payload: dict) -> tuple[list, dict[str, tuple[int, int]]]:
        """Everything checked before anything is applied: a bad message changes nothing. The wire's schema
        (:class:`agent.net.schemas.TrackPayload`) has fixed the types; here the fields of this policy must be
        there, the acknowledgement masks in range and the bearings well formed."""
        increments, acks = payload.get("increments"), payload.get("acks")
        if not isinstance(increments, list) or not isinstance(acks, dict):
            raise wire.DecodeError("bad_field", "a flood message needs an increments list and an acks map")
        try:
            held = acks_from_wire(acks)
        except ValueError as err:
            raise wire.DecodeError("bad_field", f"acks: {err}") from None
        out = []
        newest = (self.tracker.epoch + FUTURE_EPOCHS) * self.tracker.model.step
        for entry in increments:
            if len(entry) != 3 or not wire.is_int(entry[1]) or entry[1] < 0:  # the schema's rule, for any caller
                raise wire.DecodeError("bad_field", "an increment is [origin, number >= 0, bearings]")
            origin, n, rows = entry
            table = check_bearings(rows)
            if max(r[0] for r in table) > newest:
                raise wire.DecodeError("future_epoch", f"detections more than {FUTURE_EPOCHS} steps ahead of ours")
            out.append((origin, n, rows, table))
        return out, held

    def metrics(self) -> dict:
        return {**super().metrics(), "flood": {**self.relay.metrics(), "too_old": self.too_old}}
