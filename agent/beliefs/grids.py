"""The ``"grid"`` belief exchange — the agent's fire map: a certainty grid built from its thermal camera
and fused with its neighbours'.

Merino Alg. 4.3 (log-odds) / Alg. 4.5 (Beta), with the generic channel filter of
:mod:`fusion.channel_filter` in place of the thesis's "on send, ``l_ij = l_i``": a neighbour is assumed
to hold only what it acknowledged. On a tree the map equals the centralized one; on loops (``hybrid``
on a non-bridge link, or ``ci``) the grids are combined by a conservative rule instead — the per-cell
weighted log-odds at the Chernoff point, or Merino's max rules (4.5)/(4.39).

* **absorb**: one thermal frame -> per-cell evidence (:class:`agent.sensors.fire_camera.ThermalSensor`, the
  sensor this belief brings to the agent) -> the local update (Alg. 4.2 / Alg. 4.4 lines 5-6); the frame's
  evidence also goes to the simulator's centralized map (simulation only);
* **send**: every ``period`` a grid message, a delta against what every neighbour acknowledged
  (:mod:`agent.beliefs.grid_exchange`); the channel filter records the *quantized* grid as sent, exactly what
  the receivers rebuild;
* **receive**: decode (geometry and belief type must match ours), fuse through the channel filter;
* **view**: the map the explorer plans on (:class:`tasking.base.MapView`);
* **alarms**: every ``alarm_period`` the fused grid is thresholded into Gaussian alarms (Merino (4.20),
  :func:`fusion.grid_alarms.extract_alarms`) with their class probability. They are re-extracted from the grid
  each time, never accumulated, so the grid's evidence is not counted twice.
* **hand-off** (``handoff``, Merino Ch. 8): the thermal camera's hot spots inside an alarm's gate go to the
  agent's tracker as bearings (:mod:`agent.sensors.hot_spots`), whose tracks are fused with the peers' like
  target tracks; every alarm is reported (telemetry, metrics) at its track's position
  (:mod:`agent.beliefs.alarm_handoff`). Position and class are separate filters, as in (8.1): the grid only
  gates which blobs count, and nothing of the tracks goes back into the grid, so nothing is counted twice.
"""

from __future__ import annotations

import math
from collections import Counter
from numbers import Real

import numpy as np

from agent.beliefs.alarm_handoff import located_alarms
from agent.beliefs.grid_config import GridConfig
from agent.beliefs.grid_exchange import HISTORY, GridReceiver, GridSender
from agent.beliefs.tracking import Tracker
from agent.net import wire
from agent.net.grid_codec import encoded_size
from agent.net.sending import Every
from agent.plugins import Observations, Outbox, Outgoing
from agent.sensors.fire_camera import FireCamera, ThermalSensor
from agent.sensors.hot_spots import HotSpots
from agent.sensors.truth import TruthSnapshot
from fusion.channel_filter import ChannelFilter
from fusion.fire_spread import FireSpreadModel
from fusion.grid_alarms import Alarm, extract_alarms
from fusion.grid_geometry import GridGeometry
from fusion.grid_intersect import chernoff_intersect, half_intersect, max_intersect
from fusion.resync import Edge
from tasking.base import MapView

PEER_FRESH = 5  # grid periods: a peer not heard for longer is not counted on to watch an alarm (chosen here)
INTERSECT_RULES = {"chernoff": chernoff_intersect, "max": max_intersect, "half": half_intersect}


class GridExchange:
    """One agent's fire map: local evidence, exchange with neighbours through channel filters, alarms."""

    kind = "grid"
    needs_edge = True  # channel filters: exact on tree edges, intersection on loops

    def __init__(self, me: str, config: GridConfig, area: tuple[float, float, float, float], terrain, seed: int,
                 outbox: Outbox, tracker: Tracker | None = None, vehicle=None):
        self.me = me
        self.vehicle = vehicle  # where the map's author is: sent with every grid message (None: not sent)
        self.peers: dict[str, tuple[float, np.ndarray]] = {}  # peer -> (time heard, its (north, east) then)
        self.now = 0.0  # s: the last frame's time
        self.config = config
        self.outbox = outbox
        self.geometry = config.geometry(area, terrain)
        self.beliefs = config.layers(self.geometry)
        self.grid = self.beliefs.uniform()
        # the channel filters remember as many sent grids as the exchange does: a whole grid per message
        self.channels = ChannelFilter(self.beliefs.uniform(), config.policy, INTERSECT_RULES[config.intersect],
                                      history=HISTORY)
        self.sender = GridSender(config.keyframe_every, config.delta, tolerance=config.delta_tolerance)
        self.receiver = GridReceiver(self.geometry.shape, self.beliefs.layers)
        camera = FireCamera(config.camera, config.detection, config.pose_noise, seed)
        if config.handoff and tracker is None:
            raise ValueError("grid.handoff needs the agent's tracker to locate the alarms")
        self.tracker = tracker if config.handoff else None
        hot_spots = HotSpots(camera.intrinsics, config.pose_noise.attitude_sigma, self.geometry.cell,
                             terrain) if config.handoff else None
        self.sensor = ThermalSensor(camera, self.geometry.centres_ned(), self.geometry.cell, terrain, hot_spots,
                                    alarms=self.current_alarms)
        self.alarms: list[Alarm] = []
        self.located: list[dict] = []  # the alarms where they are reported: agent.beliefs.alarm_handoff
        self._send_timer = Every(config.period)
        self._alarm_timer = Every(config.alarm_period)
        self.fusions: Counter = Counter()  # method -> grids fused
        self.message_bytes: list[int] = []  # payload bytes of each grid message sent
        self.keyframes = 0
        self.grids_thinned = 0

    def sensors(self) -> list[ThermalSensor]:
        """The sensor this belief brings: the down-looking thermal camera of ``[grid]``."""
        return [self.sensor]

    def planning_hints(self) -> dict:
        """A planner on this map scores looks with the thermal camera's ``(P_D, P_F)`` (Merino (4.23))."""
        return {"detection": (self.config.detection.pd, self.config.detection.pf)}

    # -- local evidence ---------------------------------------------------------------------------
    def absorb(self, t: float, observations: Observations) -> None:
        """One frame's cell evidence updates the local grid (first advanced to the tick of ``t``: forgetting,
        :mod:`fusion.grid_forgetting`) and goes to the simulator's centralized map."""
        self.now = t
        self._advance(t)
        ev = observations["fire_evidence"]
        if self.config.belief == "logodds":
            self.grid = self.grid.update_cells(ev.index, ev.llr)
        else:
            self.grid = self.grid.update_cells(ev.index, ev.m, ev.n)
        self.outbox.to_simulator("grid_evidence", t, {"index": ev.index.astype(np.int32), "llr": ev.llr,
                                                      "m": ev.m, "n": ev.n})

    def _advance(self, t: float) -> None:
        """The grid and the layers it reads to the tick of ``t`` (never back: a grid from a peer whose clock is
        ahead may have moved ours on already)."""
        if self.grid.epoch is not None:
            self.beliefs.epoch = max(self.beliefs.epoch_of(t), self.grid.epoch)
            self.grid = self.grid.advanced_to(self.beliefs.epoch)

    def probability(self) -> np.ndarray:
        return self.grid.probability()

    def planning_probability(self) -> np.ndarray:
        """The map the explorer plans on: with ``plan_spread`` the known fire — cells above the alarm
        threshold — is predicted to spread ``plan_steps`` steps (Merino (6.5)-(6.6), noisy-OR), and each
        cell takes the larger of its probability and that prediction, so the cells around known fires
        regain entropy and get revisited as the front moves. Unexplored cells (p = 0.5) are not treated as
        burning: the thesis's prediction assumes a small fire prior, not the grid's 0.5. Only the plan sees
        the prediction; the shared map stays static, which keeps channel filters exact."""
        p = self.probability()
        if self.config.plan_spread == 0.0:
            return p
        known = np.where(p > self.config.alarm_threshold, p, 0.0)
        model = FireSpreadModel(burn=0.0, spread=self.config.plan_spread)
        return np.maximum(p, model.predict(known, np.zeros_like(p), self.config.plan_steps)[0])

    def current_alarms(self) -> list[Alarm]:
        """The alarms of the last extraction: the gates the hot spots are looked for in."""
        return self.alarms

    def update_alarms(self, t: float) -> list[Alarm]:
        """Every ``alarm_period``, the grid's alarms (4.20); every step, where they are: with ``handoff``, at their
        tracks (:func:`agent.beliefs.alarm_handoff.located_alarms`)."""
        if self._alarm_timer.due(t):
            self.alarms = extract_alarms(self.probability(), self.geometry, self.config.alarm_threshold)
        tracks = self.tracker.estimates() if self.tracker is not None else []
        self.located = located_alarms(self.alarms, tracks, self.geometry.cell)
        return self.alarms

    # -- exchange ---------------------------------------------------------------------------------
    def outgoing(self, t: float, neighbours: list[str]) -> Outgoing | None:
        """Every ``period``: the grid as a delta against what every current neighbour acknowledged (the
        alarms are refreshed first, every ``alarm_period``)."""
        self.update_alarms(t)
        if not self._send_timer.due(t):
            return None
        codec, quantized = self.sender.encode(self.beliefs.to_layers(self.grid), neighbours)
        payload = {"geometry": self.geometry.to_dict(), "belief": self.config.belief, "grid": codec,
                   "acks": self.receiver.acks()}
        if self.vehicle is not None:
            payload["position"] = [float(v) for v in self.vehicle.state().position[:2]]
        return Outgoing(payload, context=quantized)  # the layers receivers rebuild

    def sent(self, seq: int, message: Outgoing) -> None:
        """Message ``seq`` left: the channel filters now assume neighbours that acknowledge it hold it."""
        codec, quantized = message.payload["grid"], message.context
        self.sender.sent_as(seq, quantized, codec)
        self.channels.on_send(self.beliefs.from_layers(quantized), seq)
        self.message_bytes.append(encoded_size(codec))
        self.keyframes += codec.get("mode") == "key"

    def thinned(self, message: Outgoing) -> None:
        self.grids_thinned += 1

    def settle(self, t: float) -> None:
        """Nothing held back: received grids are fused as they arrive."""

    def receive(self, origin: str, seq: int, stamp: float, payload: dict, edge: Edge,
                t: float) -> list[tuple[str, str | None]]:
        """Decode and fuse a neighbour's grid message. Raises :class:`agent.net.wire.DecodeError` on a bad
        message (nothing is changed then)."""
        belief = payload.get("belief") if isinstance(payload, dict) else None
        if not isinstance(belief, str) or belief != self.config.belief:  # an array's != is no bool
            raise wire.DecodeError("grid_geometry", f"expected a {self.config.belief} grid")
        try:
            GridGeometry.from_dict(payload.get("geometry")).check_same(self.geometry)
        except (ValueError, TypeError, AttributeError) as err:
            raise wire.DecodeError("grid_geometry", str(err)) from None
        acks = payload.get("acks", {})
        if not isinstance(acks, dict) or not all(isinstance(v, int) and v >= 0 for v in acks.values()):
            raise wire.DecodeError("bad_field", "grid acks must map peers to sequence numbers")
        position = _sender_position(payload.get("position"))
        layers = self.receiver.decode(origin, seq, payload.get("grid"))
        try:
            received = self.beliefs.from_layers(layers, self.beliefs.epoch_of(stamp))  # the tick it was sent at
        except ValueError as err:  # e.g. negative Beta counts
            raise wire.DecodeError("grid_bad_values", str(err)) from None
        ours = acks.get(self.me)
        if ours is not None:
            self.sender.acknowledge(origin, ours)
        if position is not None:
            self.peers[origin] = (t, position)
        out = self.channels.on_receive(origin, self.grid, received, ours, seq, edge)
        self.grid = out.fused
        self._advance(t)  # a peer's clock ahead of ours moved the grid on: what we send is read at its tick
        self.fusions[out.method] += 1
        return [(f"grid_{out.method}", out.cause)]

    def peer_restarted(self, peer: str) -> None:
        """A restarted peer (:mod:`agent.net.incarnation`) holds none of our grid messages and none of our
        grid: its acknowledgements are forgotten (our next message to it is a keyframe) and its channel starts
        afresh from the common prior."""
        self.sender.held.pop(peer, None)
        if peer in self.channels.neighbours():
            self.channels.reset(peer)

    # -- views and results ------------------------------------------------------------------------
    def view(self) -> MapView:
        """The map to plan on, the alarms where they are reported, and the peers heard within the last
        ``PEER_FRESH`` grid periods (a peer gone silent is left out of the watch assignment,
        :mod:`tasking.alarm_watch`)."""
        beta = self.grid.shape_parameters() if self.config.belief == "beta" else None
        alarms = tuple(np.asarray(a["mean"], float) for a in self.located)
        fresh = {p: ne for p, (heard, ne) in self.peers.items() if self.now - heard <= PEER_FRESH * self.config.period}
        return MapView(self.planning_probability(), self.geometry.centres(), beta, alarms, fresh)

    def telemetry(self) -> dict:
        return {"alarms": self.located}

    def evaluate(self, t: float, truth: TruthSnapshot) -> None:
        """The map is scored by the simulator against its centralized map (:mod:`mesh_sim.grid_oracle`)."""

    def metrics(self) -> dict:
        sizes = np.asarray(self.message_bytes, float)
        return {"grid": {
            "belief": self.config.belief,
            "shape": list(self.geometry.shape),
            **self.sensor.metrics(),
            "grid_messages": int(sizes.size),
            "grid_keyframes": int(self.keyframes),
            "grid_bytes": int(sizes.sum()),
            "grid_message_bytes_mean": float(sizes.mean()) if sizes.size else None,
            "grid_message_bytes_max": int(sizes.max()) if sizes.size else None,
            "grid_fusions": dict(self.fusions),
            "alarms": [{"mean": a.mean.tolist(), "cov": a.cov.tolist(), "probability": a.probability,
                        "cells": a.cells} for a in self.alarms],
            "located_alarms": [{"mean": a["mean"].tolist(), "cov": a["cov"].tolist(), "track": a["track"]}
                               for a in self.located],
            "thinned": self.grids_thinned,
        }}


def _sender_position(value) -> np.ndarray | None:
    """A grid message's ``position``: absent (``None``), or the sender's (north, east) as two finite numbers;
    anything else is a :class:`agent.net.wire.DecodeError` (``bad_field``)."""
    if value is None:
        return None
    if (isinstance(value, list | tuple) and len(value) == 2
            and all(isinstance(v, Real) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
        return np.array(value, float)
    raise wire.DecodeError("bad_field", f"a grid's sender position must be two finite numbers, got {value!r}")
