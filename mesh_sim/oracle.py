"""The centralized references a run is judged against.

* :class:`Oracle` — one tracker that receives every agent's raw bearings without loss
  (``sim/measurement/<agent>``) and associates them by their true labels: same models, same
  measurements, no network (``targets`` in ``oracle.json``; the run's ratio is to it). A decentralized
  agent can at best approach it: information still travelling through the mesh is only at its source.
  Beside it, the same tracker with an interacting multiple model matched to the targets
  (``imm_targets``: ``[tracking] motion = "imm"`` with the scenario's ``[tracking.imm]`` modes,
  :mod:`fusion.imm_window`) is the *consistent* reference. No single linear motion model with positive
  process noise can be consistent on every shipped target: on a target that truly has no process noise
  (static or constant velocity) a filter in steady state reports a covariance of which a fixed share is
  the process noise it assumes, whatever its size, so its NEES settles below 1 (about 0.5 measured, for
  any ``q`` from 1e-4 to 3 m^2/s^3); and a noise small enough never to reach that steady state in a run
  leaves the figure-8 (2.6 m/s^2 of acceleration) hopelessly overconfident. A quiet mode without process
  noise and a manoeuvring mode cover all three (the agents' ANEES below 1 with a single model is their
  motion model's, not the fusion's; agents under ``flood`` may use the IMM too).
* :class:`InFlightOracle` — per agent, the centralized filter holding exactly the information that
  could have reached that agent by now: origin ``o``'s bearings of step ``k`` reach agent ``a`` at step
  ``k + d(o, a)``, ``d`` the hop distance in the radio graph of the time (one step per hop: an agent
  drains its receive queue once per step and relays in the same step; issue 11's "equal to the
  centralized filter up to the information still in flight"). Links are taken as lossless; an
  agent out of reach gets nothing. On a lossless graph an exact decentralized scheme matches it, so
  ``agent ÷ in-flight oracle`` isolates the fusion's own loss from the network's latency.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from agent.beliefs.tracking import Tracker
from agent.beliefs.tracks import FUTURE_EPOCHS
from agent.evaluation import TrackEvaluator
from agent.net import wire
from agent.sensors.bearing import Bearing
from fusion import validation
from fusion.network import hop_distances
from mesh_sim.target_set import truth_snapshot
from perception.terrain import terrain_from_config


class Oracle:
    """Centralized tracking of every agent's bearings, associated by truth label: ``tracker`` with the agents'
    own models (scored in ``evaluator``) and, with ``imm=True``, an interacting multiple model matched to
    the targets (scored in ``imm_evaluator``)."""

    def __init__(self, scenario, imm: bool = False):
        terrain = terrain_from_config(scenario.terrain)
        self.tracker = Tracker(scenario.tracking, scenario.step, terrain)
        imm_config = replace(scenario.tracking, motion="imm", policy="flood", measurement="bearing")
        self.imm = Tracker(imm_config, scenario.step, terrain) if imm else None
        self.evaluator = TrackEvaluator()
        self.imm_evaluator = TrackEvaluator()
        self.late = 0
        self.rejected = 0
        self.held: list[tuple[float, list[Bearing]]] = []  # (stamp, bearings) of each message since the last evaluate

    def add(self, env: wire.Envelope, now: float) -> None:
        """Hold one agent's bearings for :meth:`evaluate`, which applies every held scan at the epoch it was
        taken (``now``: the world's simulation time; bearings stamped far after it are a clock fault and
        rejected)."""
        try:
            bearings = [parse_bearing(b, env.stamp) for b in env.payload["bearings"]]
        except (KeyError, TypeError, ValueError, AttributeError):
            self.rejected += 1
            return
        if self.tracker.model.epoch_of(env.stamp) > self.tracker.model.epoch_of(now) + FUTURE_EPOCHS:
            self.rejected += 1
            return
        self.held.append((env.stamp, bearings))

    def _apply_held(self) -> None:
        """Every held scan in one update per tracker, at the newest message's epoch
        (:meth:`agent.beliefs.tracking.Tracker.catch_up`); a message with a bearing older than the window (a
        camera bearing that waited for its pose that long) is counted in ``late``, that bearing left out."""
        held, self.held = self.held, []
        if not held:
            return
        epoch = max(self.tracker.model.epoch_of(stamp) for stamp, _ in held)
        scans = [bearings for _, bearings in held]
        self.late += sum(dropped > 0 for dropped in self.tracker.catch_up(scans, epoch, by_label=True))
        if self.imm is not None:
            self.imm.catch_up(scans, epoch, by_label=True)

    def evaluate(self, targets) -> None:
        """Apply the held bearings, then score both trackers against the truth."""
        self._apply_held()
        t = self.tracker.epoch * self.tracker.model.step
        truth = truth_snapshot(targets, t)
        self.evaluator.record(t, truth, self.tracker.estimates())
        if self.imm is not None:
            self.imm_evaluator.record(t, truth, self.imm.estimates())


def parse_bearing(entry: dict, stamp: float) -> Bearing:
    """One bearing of a ``measurement`` message; ``ValueError`` unless its sensor position, azimuth/elevation
    and positive-definite covariance are finite arrays of shapes 3, 2 and 2x2."""
    sensor, azel = np.asarray(entry["sensor"], float), np.asarray(entry["azel"], float)
    R = validation.as_pd(entry["R"], "bearing covariance R", 2)
    if sensor.shape != (3,) or azel.shape != (2,) or not (np.isfinite(sensor).all() and np.isfinite(azel).all()):
        raise ValueError("a bearing needs a finite sensor position (3) and azimuth/elevation (2)")
    return Bearing(_stamp(entry.get("t", stamp)), sensor, azel, R, entry["truth"])


def _stamp(value) -> float:
    """A bearing's own time (a camera's bearings may be older than the message that carries them)."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
        raise ValueError(f"bad bearing time {value!r}")
    return float(value)



class InFlightOracle:
    """One :class:`Oracle` per agent, fed every bearing after the hops it needs to reach that agent."""

    def __init__(self, scenario):
        self.names = [f"uav{i}" for i in range(scenario.agents)]
        self.plan = scenario.radio_plan  # None: every agent hears every other (one hop)
        self.step = scenario.step
        self.oracles = {name: Oracle(scenario) for name in self.names}
        self._pending: list[tuple[int, str, wire.Envelope]] = []  # (release step, agent, bearings)
        self._graph: tuple[int, object] | None = None  # (step, the radio graph's edges then): once per step

    def _edges(self, k: int, t: float):
        if self._graph is None or self._graph[0] != k:
            edges = ([(a, b) for i, a in enumerate(self.names) for b in self.names[i + 1:]] if self.plan is None
                     else self.plan.edges_at(t))
            self._graph = (k, edges)
        return self._graph[1]

    def add(self, env: wire.Envelope, now: float) -> None:
        k = int(round(now / self.step))
        for name, hops in hop_distances(self._edges(k, now), env.origin).items():
            if name in self.oracles:
                self._pending.append((k + hops, name, env))

    def evaluate(self, targets, now: float) -> None:
        """Release what has arrived by ``now`` and score every agent's reference."""
        k = int(round(now / self.step))
        due = [p for p in self._pending if p[0] <= k]
        self._pending = [p for p in self._pending if p[0] > k]
        for _, name, env in due:
            self.oracles[name].add(env, now)
        for oracle in self.oracles.values():
            oracle.evaluate(targets)

    def summary(self) -> dict:
        return {name: oracle.evaluator.summary() for name, oracle in self.oracles.items()}
