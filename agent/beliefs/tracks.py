"""The ``"track"`` belief exchange: targets tracked from bearings and shared as trajectory beliefs.

The plug-in (:class:`agent.plugins.BeliefExchange`) around :class:`agent.beliefs.tracking.Tracker`:

* **absorb**: the step's bearings that the trajectory window can still take are associated and applied
  (Merino (3.52)/(3.64)); the others are counted as ``bearing_outside_window``, never applied. The raw
  bearings also go to the simulator's centralized oracle (simulation only, not radio traffic);
* **outgoing**: every ``[sending] period`` the confirmed tracks of which a receiver's prediction lacks
  ``info_gain`` nats, or that were silent for ``max_silence`` (:mod:`agent.net.sending`), each charged to the
  link budget; each entry carries the per-track acknowledgement of the peer's last copy fused here;
* **receive**: decode every track (:mod:`agent.net.wire`), reject a track that is not observable or is
  stamped more than :data:`FUTURE_EPOCHS` steps ahead of ours or :data:`PAST_EPOCHS` behind (a clock
  fault), fuse through the per-track channel filters (exact on tree edges, intersection elsewhere;
  :mod:`fusion.channel_filter`). Under ``hybrid`` a message over a link whose place in the graph is not
  known yet (:attr:`fusion.resync.Edge.UNKNOWN`: a new neighbour whose topology report, or its neighbours',
  has not arrived — every merge of a partition) waits up to :data:`EDGE_WAIT_S` for that knowledge in
  :meth:`TrackExchange.settle` instead of being intersected at once: an intersection gives up the channel's
  exactness until a re-synchronisation, and with it what the two sides learnt apart;
* **view**: the confirmed tracks' positions, for planners; **evaluate**: RMSE/ANEES against the truth.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from agent.beliefs.tracking import RemoteTrack, Tracker
from agent.beliefs.tracking_config import TrackerConfig
from agent.evaluation import TrackEvaluator
from agent.net import wire
from agent.net.gaussian_codec import decode_trajectory, encode_trajectory
from agent.net.sending import SendScheduler
from agent.plugins import Observations, Outbox, Outgoing
from agent.sensors.bearing import Bearing
from agent.sensors.truth import TruthSnapshot
from fusion.channel_filter import Freshness
from fusion.gaussian import UninformativeBeliefError
from fusion.resync import Edge
from tasking.base import TrackView

FUTURE_EPOCHS = 50  # a peer's belief this many steps ahead of ours is rejected as a clock fault (chosen here)
PAST_EPOCHS = 50  # ... and this many behind: predicting it to now would stall the loop (chosen here)
TRACK_ENTRY_BYTES = 5000  # budget charged per track sent: an 8-state trajectory encodes to ~4.8 kB
EDGE_WAIT_S = 1.0  # s a hybrid message may wait for its link's place in the graph; chosen here: topology reports
# cross a hop per step, so 5 steps cover a line of 6 (measured at a merge on the 4-line: 0.2-0.6 s)


def _check_observable(belief) -> None:
    """A shared track must say where its target is: the newest state's marginal needs a finite mean and
    covariance (an all-zero or vanishingly small information matrix would break association and planning
    later); ``DecodeError("uninformative")`` otherwise."""
    try:
        current = belief.current()
        ok = bool(np.all(np.isfinite(current.mean)) and np.all(np.isfinite(current.cov)))
    except (UninformativeBeliefError, np.linalg.LinAlgError, FloatingPointError, ValueError) as err:
        raise wire.DecodeError("uninformative", f"a track whose newest state is not observable: {err}") from None
    if not ok:
        raise wire.DecodeError("uninformative", "a track whose newest state has a non-finite mean or covariance")


def _seq_map(value) -> bool:
    """Is ``value`` a map from peer names to sequence numbers (non-negative integers, not booleans)?"""
    return isinstance(value, dict) and all(
        isinstance(k, str) and isinstance(v, int) and not isinstance(v, bool) and v >= 0 for k, v in value.items())


class TrackExchange:
    """Tracks of one agent, exchanged with its peers. ``unused`` counts observations it could not use."""

    kind = "track"
    needs_edge = True  # channel filters: exact on tree edges, intersection on loops

    def __init__(self, me: str, config: TrackerConfig, step: float, terrain, seed: int, sender: SendScheduler,
                 outbox: Outbox, unused: Counter, topology=None, fusions=None):
        self.me = me
        self.topology = topology  # agent.net.topology.Topology: asked again for the links of waiting messages
        self.fusions = fusions  # agent.fusion_log.FusionLog: where the fusions of waiting messages are recorded
        self.waiting: dict[str, tuple] = {}  # origin -> (since, seq, stamp, remote tracks): hybrid, link not known
        self.tracker = Tracker(config, step, terrain, seed=seed + 104729, me=me)
        self.sender = sender
        self.outbox = outbox
        self.unused = unused
        self.evaluator = TrackEvaluator()
        self.latencies: list[float] = []  # stamp-to-fusion delays of received beliefs [s of simulation time]
        self.last_bearings: list[Bearing] = []

    def sensors(self) -> list:
        """Tracks bring no sensor of their own: they use the ``[sensor]`` section's bearings."""
        return []

    def planning_hints(self) -> dict:
        return {}

    # -- local ------------------------------------------------------------------------------------
    def absorb(self, t: float, observations: Observations) -> None:
        self.tracker.update(self.own_bearings(t, observations))

    def own_bearings(self, t: float, observations: Observations) -> list[Bearing]:
        """The step's bearings the trajectory window can take, once the tracker has advanced to ``t``; they are
        kept for telemetry and reported raw to the simulator's centralized oracle (simulation only, not radio
        traffic)."""
        self.tracker.advance(self.tracker.model.epoch_of(t))
        bearings = self.last_bearings = self._usable(observations.get("bearings", []))
        self.outbox.to_simulator("measurement", t, {"bearings": [
            {"t": b.t, "sensor": b.sensor, "azel": b.azel, "R": b.R, "truth": b.truth_id} for b in bearings]})
        return bearings

    def settle(self, t: float) -> None:
        """Fuse the waiting messages whose link is now known, or that waited :data:`EDGE_WAIT_S`: the latter as
        before, by intersection."""
        for origin, (since, seq, stamp, remote) in list(self.waiting.items()):
            edge = self.topology.edge(origin, t)
            if edge is Edge.UNKNOWN and t - since < EDGE_WAIT_S - 1e-9:
                continue
            del self.waiting[origin]
            self.fusions.record(origin, t, self._fuse(origin, seq, stamp, remote, edge, t))

    def _usable(self, bearings: list[Bearing]) -> list[Bearing]:
        """Bearings the trajectory window can still take (a camera that waited for a late pose may hand
        over some from before it)."""
        oldest = self.tracker.epoch - self.tracker.model.window + 1
        keep = []
        for b in bearings:
            if oldest <= self.tracker.model.epoch_of(b.t) <= self.tracker.epoch:
                keep.append(b)
            else:
                self.unused["bearing_outside_window"] += 1
        return keep

    # -- sending ----------------------------------------------------------------------------------
    def outgoing(self, t: float, neighbours: list[str]) -> Outgoing | None:
        if not self.sender.due(t):
            return None
        chosen = self.sender.choose(t, self.tracker.confirmed(), TRACK_ENTRY_BYTES, self.tracker.model.motion,
                                    neighbours)
        if not chosen:
            return None
        tracks = [self._entry(tr) for tr in chosen]
        return Outgoing({"tracks": tracks}, prepaid=True, context=chosen)

    def _entry(self, tr) -> dict:
        """One track on the wire: its belief (after adopting an agreed re-sync baseline), acknowledgements,
        re-sync flags per peer and freshness (:mod:`fusion.resync`, :class:`fusion.channel_filter.Freshness`)."""
        resync = self.tracker.prepare_send(tr)
        entry = {"id": tr.id, "belief": encode_trajectory(tr.belief), "last_measured": tr.last_measured,
                 "acks": dict(tr.acks)}
        if resync:
            entry["resync"] = resync
        if tr.channels.freshness:
            entry["fresh"] = int(tr.channels.freshness)
        return entry

    def sent(self, seq: int, message: Outgoing) -> None:
        self.tracker.record_sent(message.context, seq)

    def thinned(self, message: Outgoing) -> None:
        """Never called: track entries are charged to the budget one by one when chosen."""

    # -- receiving --------------------------------------------------------------------------------
    def receive(self, origin: str, seq: int, stamp: float, payload: dict, edge: Edge,
                t: float) -> list[tuple[str, str | None]]:
        remote = self._decode(payload)
        if any(r.belief.epoch > self.tracker.epoch + FUTURE_EPOCHS for r in remote):
            raise wire.DecodeError("future_epoch", f"a track more than {FUTURE_EPOCHS} steps ahead of ours")
        if any(r.belief.epoch < self.tracker.epoch - PAST_EPOCHS for r in remote):
            raise wire.DecodeError("past_epoch", f"a track more than {PAST_EPOCHS} steps behind ours")
        if edge is Edge.UNKNOWN and self.tracker.config.policy == "hybrid" and self.topology is not None:
            # one message per origin waits, the newest: it carries all its sender holds (an older one is as if
            # lost, which the acknowledgements cover), so the wait is bounded by the fleet
            since = self.waiting.get(origin, (t,))[0]
            self.waiting[origin] = (since, seq, stamp, remote)
            return []
        return self._fuse(origin, seq, stamp, remote, edge, t)

    def _fuse(self, origin: str, seq: int, stamp: float, remote: list[RemoteTrack], edge: Edge,
              t: float) -> list[tuple[str, str | None]]:
        methods = [(out.method, out.cause) for out in self.tracker.fuse_remote(origin, remote, seq, edge)]
        self.latencies.append(t - stamp)
        return methods

    def peer_restarted(self, peer: str) -> None:
        """A restarted peer: see :meth:`agent.beliefs.tracking.Tracker.peer_restarted` (its waiting messages
        belong to its old life)."""
        self.waiting.pop(peer, None)
        self.tracker.peer_restarted(peer)

    def _decode(self, payload: dict) -> list[RemoteTrack]:
        tracks = payload.get("tracks")
        if not isinstance(tracks, list):
            raise wire.DecodeError("bad_field", "payload.tracks must be a list")
        out = []
        for entry in tracks:
            if not isinstance(entry, dict) or not isinstance(entry.get("id"), int) or "belief" not in entry:
                raise wire.DecodeError("bad_field", "each track needs an integer id and a belief")
            last, acks = entry.get("last_measured"), entry.get("acks", {})
            if isinstance(last, bool) or not isinstance(last, int | float) or not np.isfinite(last):
                raise wire.DecodeError("bad_field", "each track needs a finite last_measured time")
            if not _seq_map(acks):
                raise wire.DecodeError("bad_field", "track acks must map peers to sequence numbers")
            resync, fresh = entry.get("resync", {}), entry.get("fresh", 0)
            if not _seq_map(resync):
                raise wire.DecodeError("bad_field", "track resync must map peers to sequence numbers")
            if isinstance(fresh, bool) or fresh not in tuple(Freshness):
                raise wire.DecodeError("bad_field", f"track fresh must be one of {[int(f) for f in Freshness]}")
            belief = decode_trajectory(entry["belief"], self.tracker.model)
            _check_observable(belief)
            out.append(RemoteTrack(entry["id"], belief, float(last), acks.get(self.me), resync.get(self.me),
                                   Freshness(fresh)))
        return out

    # -- views and results ------------------------------------------------------------------------
    def view(self) -> TrackView:
        estimates = self.tracker.estimates()
        return TrackView([(tid, est.mean[:2]) for tid, est in estimates],
                         {tid: est.mean[3:5] for tid, est in estimates if len(est.mean) >= 6})

    def telemetry(self) -> dict:
        out = {
            "bearings": np.array([b.azel for b in self.last_bearings]).reshape(-1, 2),
            "tracks": [{"id": tid, "mean": est.mean, "cov": est.cov} for tid, est in self.tracker.estimates()],
        }
        if self.tracker.initiator is not None:
            out["particles"] = self.tracker.initiator.points()
        return out

    def evaluate(self, t: float, truth: TruthSnapshot) -> None:
        if truth.targets is not None:
            self.evaluator.record(t, truth.targets, self.tracker.estimates())

    def metrics(self) -> dict:
        lat = np.asarray(self.latencies, float)
        out = {
            "tracks_thinned": self.sender.thinned,
            "belief_latency_s": {
                "mean": float(lat.mean()) if lat.size else None,
                "p95": float(np.percentile(lat, 95)) if lat.size else None,
                "count": int(lat.size),
            },
            "targets": self.evaluator.summary(),
        }
        if self.tracker.initiator is not None:
            out["particle_init"] = self.tracker.initiator.metrics()
        return out
