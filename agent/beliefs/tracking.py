"""Multi-target tracking from bearings, fused with peers through channel filters.

Each target is a trajectory belief (``fusion.trajectory``, a sliding window on the agent's time grid),
so that exact channel-filter fusion works for moving targets (Merino (3.41)-(3.42)). The default motion
model is ``DampedVelocity`` (integrated Ornstein–Uhlenbeck velocity): its stationary speed distribution
is part of every node's prior, so no node adds a velocity prior of its own. With the constant-velocity
model (Merino (3.58)-(3.59)) a new track needs a velocity pseudo-prior, which two agents initiating the
same target both bring (after exact fusion that weak prior counts twice: a small, documented
overconfidence in early velocity). Under ``policy = "flood"``, where no belief is ever fused, ``motion =
"imm"`` makes each track an interacting multiple model instead (a quiet and a manoeuvring mode,
``[tracking.imm]``) on a window that takes late bearings by reprocessing (:mod:`fusion.imm_window`): the model
the centralized reference uses, matched to static, constant-velocity and manoeuvring targets alike.

Measurements are used either as bearings (extended information update, Merino (3.52)) or, with
``measurement = "position"``, as geolocated positions: the ray cast onto the terrain with an
unscented-transform covariance (Merino (3.60)-(3.61)). The latter is linear in the state, so on a tree
decentralized fusion equals the centralized filter exactly.

* **Scan-to-track** (Merino (3.64)): the predicted bearing of every track is compared with every
  detection by ``d^2 = nu^T S^-1 nu``, ``S = H P H^T + R``, gated at ``d^2 <= 9`` (Merino's threshold);
  the assignment minimising the total ``d^2`` is found with the Hungarian method, which for one
  detection per track is Merino's "minimum ``d^2``" rule made globally consistent (crossing targets).
  Confirmed tracks have the first claim on the detections inside their gates.
* **Initiation**: a detection outside every gate starts a *tentative* track at the ground point of
  its ray (``perception.geolocation``), with an unscented-transform covariance and a broad velocity
  prior — with ``start_hits = 2`` (the default) only once a detection of another scan falls in its gate;
  until then it is held as a candidate, a ground point with no trajectory (:mod:`agent.beliefs.track_candidates`),
  and the track then starts from it as it would have at its detection. With ``initiation = "particles"`` it
  starts a particle candidate along the ray instead, which becomes a track once it has converged to one compact
  cloud (:mod:`agent.beliefs.particle_init`, Merino §5.3).
  A track is confirmed after ``confirm_hits`` updates and is only then shared; one that is
  confirmed inside the track-to-track gate of another confirmed track is a duplicate and is dropped.
* **Track-to-track** (Merino (3.65)): a peer's track is matched to the local track minimising
  ``(mu_i - mu_j)^T (P_i + P_j)^-1 (mu_i - mu_j)`` over positions, gated; the match is kept in a
  persistent remote -> local label table. A peer track that matches nothing is adopted as a new track.
* **Deletion**: every track carries the time of the newest measurement in it (the maximum over
  everything fused into it, so peers' measurements count). A tentative track not confirmed in time,
  a track nobody has measured for ``stale_after`` seconds, or one whose position standard deviation
  grows past ``max_position_std`` is deleted: peers echoing each other cannot keep a ghost alive.
* **Merging**: two confirmed tracks whose positions pass the track-to-track gate are one target seen
  twice (e.g. initiated by two agents before they heard each other); they are merged by the configured
  intersection rule (``[tracking] intersection``: ci, fast_ci or ici), labels move to the surviving track
  and its channels fall back to intersection (its common information with each peer is no longer known)
  until they re-synchronise (:mod:`fusion.resync`).
* **Sharing**: under the channel-filter policies peers' tracks arrive through :meth:`Tracker.fuse_remote`;
  under ``flood`` (:mod:`agent.beliefs.flood`) peers' detections arrive and go through :meth:`Tracker.update`
  like this agent's own, associated at their own time.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np
from scipy.optimize import linear_sum_assignment

from agent.beliefs.particle_init import ParticleInitiator
from agent.beliefs.track_candidates import Candidate, Candidates, position_spread
from agent.beliefs.tracking_config import TrackerConfig
from agent.sensors.bearing import Bearing
from fusion import lapack
from fusion.channel_filter import ChannelFilter, Received
from fusion.gaussian import Gaussian, UninformativeBeliefError
from fusion.imm_window import ImmWindow, ImmWindowModel
from fusion.measurement import Bearing3D, PositionMeasurement, bearing3d_information, bearing_gate_distances
from fusion.motion import ConstantVelocity, DampedVelocity
from fusion.resync import Edge
from fusion.trajectory import Trajectory, TrajectoryModel, intersect_on_newest
from perception.geolocation import geolocate

STATE_DIM = 6  # (north, east, down, v_north, v_east, v_down)
_UNASSIGNED = 1e9


@dataclass(frozen=True)
class RemoteTrack:
    """A peer's track as received: its id, belief, newest measurement time, and the seq of *our* message
    whose copy of this track the peer had fused (``None``: nothing of ours) — a per-track acknowledgement,
    so that a message that carries only some tracks (bandwidth thinning) never confuses the channel filter."""

    id: int
    belief: Trajectory
    last_measured: float
    ack: int | None
    resync: int | None = None  # the peer's re-sync flag for us (fusion.resync), None if it sent none
    fresh: int = 0  # the peer's fusion.channel_filter.Freshness of this track when it sent it


@dataclass
class Track:
    id: int
    belief: Trajectory | ImmWindow  # ImmWindow: motion = "imm", under flood only
    channels: ChannelFilter | None  # per-peer channel filters (None: the flood policy shares no beliefs)
    created_epoch: int
    hits: int = 1
    confirmed: bool = False
    acks: dict = field(default_factory=dict)  # peer -> seq of the peer's message whose copy of this track we fused
    last_measured: float = 0.0  # simulation time of the newest measurement fused into this track
    truth_id: str | None = None  # only the oracle, which associates by label, sets this
    fusions: dict = field(default_factory=dict)  # method -> count

    def estimate(self) -> Gaussian:
        """The newest-state marginal (computed once per belief: :meth:`Trajectory.state`)."""
        return self.belief.current()


class Tracker:
    """All tracks of one agent (or of the centralized oracle, with ``by_label=True`` updates)."""

    def __init__(self, config: TrackerConfig, step: float, terrain, seed: int = 0, me: str | None = None):
        self.config = config
        self.me = me  # the agent's name: turns on channel re-synchronisation (fusion.resync)
        self.initiator = ParticleInitiator(config.particle_init, seed) if config.initiation == "particles" else None
        self.terrain = terrain
        if config.motion == "imm":
            self.model = ImmWindowModel(config.imm.model(), step, config.window)
        else:
            motion = (DampedVelocity(3, config.speed_std, config.tau, config.vertical_speed_std)
                      if config.motion == "damped" else ConstantVelocity(3, config.q, config.vertical_q))
            self.model = TrajectoryModel(motion, step, config.window)
        self.epoch = 0
        #: a new track's velocity prior: the stationary velocity of ``damped`` and the pseudo-prior of
        #: ``constant_velocity`` alike
        self.speed_cov = np.diag([config.speed_std**2, config.speed_std**2, config.vertical_speed_std**2])
        self.candidates = self._candidates(config)
        self._scan = 0  # numbers the scans of _apply_scan: a candidate's partner comes from another scan
        self.tracks: dict[int, Track] = {}
        self.labels: dict[tuple[str, int], int] = {}  # (peer, remote track id) -> local track id
        self._next_id = 0
        self._held: dict[int, list[tuple[Bearing, int]]] = {}  # track id -> (bearing, offset): see _add_held
        self._predicted: dict[int, Trajectory | ImmWindow] = {}  # track id -> its belief at this epoch's start
        self._gated: dict[int, dict[int, float]] = {}  # id(bearing) -> {track id: d^2}, for one update
        self._priors: dict[tuple[int, int], tuple | None] = {}  # (track id, offset) -> predicted position, one update
        self._pending: list[Bearing] = []  # every bearing of the update under way (update_scans)

    # -- time -----------------------------------------------------------------------------------
    def advance(self, epoch: int) -> None:
        """Predict every track to grid index ``epoch`` and delete the ones nobody sees any more."""
        new_epoch = epoch > self.epoch
        self.epoch = max(self.epoch, epoch)
        for track in list(self.tracks.values()):
            if self._timed_out(track):  # before predicting it: a track about to go needs no prediction
                self._delete(track.id)
                continue
            track.belief = track.belief.advanced_to(self.epoch)
            if self._too_uncertain(track):
                self._delete(track.id)
        if new_epoch:
            self._predicted = {tid: track.belief for tid, track in self.tracks.items()}
        if self.candidates is not None:
            self.candidates.expire(self.epoch, self.epoch - self.model.window + 1)

    def _candidates(self, config: TrackerConfig) -> Candidates | None:
        """Two-detection start-up (``start_hits = 2``) on the ray's ground point, for a trajectory belief (not the
        IMM's, nor the particle initiator's own candidates): :mod:`agent.beliefs.track_candidates`."""
        if config.start_hits == 1 or config.motion == "imm" or self.initiator is not None:
            return None
        spread = position_spread(self.model.F, self.model.motion.noise(self.model.step), self.speed_cov,
                                 config.confirm_within + config.window)
        return Candidates(spread, config.confirm_within, config.max_position_std)

    def _timed_out(self, track: Track) -> bool:
        """Tentative for longer than ``confirm_within`` steps, or measured by nobody for ``stale_after`` seconds."""
        if not track.confirmed and self.epoch - track.created_epoch >= self.config.confirm_within:
            return True
        return self.epoch * self.model.step - track.last_measured > self.config.stale_after

    def _too_uncertain(self, track: Track) -> bool:
        """Its position is unobservable, or its largest standard deviation exceeds ``max_position_std``."""
        try:
            cov = track.estimate().cov
        except UninformativeBeliefError:
            return True
        # the largest position standard deviation is at most s exactly when s^2 I - P_pos is positive
        # (semi)definite: one Cholesky factorisation instead of an eigendecomposition
        margin = self.config.max_position_std**2 * np.eye(3) - cov[:3, :3]
        return lapack.cholesky(margin) is None

    def _delete(self, track_id: int) -> None:
        del self.tracks[track_id]
        self.labels = {k: v for k, v in self.labels.items() if v != track_id}

    # -- own measurements -----------------------------------------------------------------------
    def update(self, bearings: list[Bearing], by_label: bool = False) -> dict[str, int]:
        """Associate and apply one scan of bearings (one sensor's detections of one time). Returns counts of
        what happened to them."""
        return self.update_scans([bearings], by_label)

    def update_scans(self, scans: list[list[Bearing]], by_label: bool = False) -> dict[str, int]:
        """Associate and apply several scans in turn — e.g. every agent's detections received in one step
        under ``flood`` — each as :meth:`update` would: one detection per track and scan (Hungarian on
        Merino (3.64)), then initiation from the detections outside every gate. Gating uses the epoch's
        predictions (:meth:`_prediction`), so the distances of every scan against the tracks that exist at
        the start are computed together, in one vectorised call. Returns counts of what happened."""
        counts = {"updated": 0, "initiated": 0, "unused": 0}
        if self.initiator is not None or self.candidates is not None:
            counts["candidate"] = 0
        self._gated, self._priors = {}, {}
        self._pending = [b for scan in scans for b in scan]  # a track started mid-update is gated against all at once
        if not by_label:
            self._distances(self._pending)
        for bearings in scans:
            self._apply_scan(bearings, by_label, counts)
        self._pending = []
        self._add_held()
        if self.initiator is not None:
            for handover in self.initiator.ready(self.epoch * self.model.step):
                self._hand_over(handover)
                counts["initiated"] += 1
        return counts

    def catch_up(self, scans: list[list[Bearing]], epoch: int, by_label: bool = False) -> list[int]:
        """Scans gathered over a step or a tick (a peer's clock may be a little ahead, a camera's bearing a
        little late): advance to grid index ``epoch`` if it is newer, leave out the bearings the window no longer
        reaches (or that are newer than it), and apply the rest with :meth:`update_scans`. Returns how many
        bearings of each scan were left out."""
        if epoch > self.epoch:
            self.advance(epoch)
        oldest = self.epoch - self.model.window + 1
        usable = [[b for b in scan if oldest <= self.model.epoch_of(b.t) <= self.epoch] for scan in scans]
        self.update_scans([scan for scan in usable if scan], by_label)
        return [len(scan) - len(kept) for scan, kept in zip(scans, usable, strict=True)]

    def _apply_scan(self, bearings: list[Bearing], by_label: bool, counts: dict[str, int]) -> None:
        self._scan += 1
        pairs = self._pairs_by_label(bearings) if by_label else self._pairs_by_distance(bearings)
        used = set()
        for b_index, track_id in pairs:
            used.add(b_index)
            self._use(self.tracks.get(track_id), bearings[b_index], by_label, counts)
        for b_index, bearing in enumerate(bearings):
            if b_index in used:
                continue
            if (by_label and bearing.truth_id is None) or (not by_label and self._inside_any_gate(bearing)):
                counts["unused"] += 1
            elif self.initiator is not None and not by_label:
                self.initiator.offer(bearing)
                counts["candidate"] += 1
            elif self.candidates is not None and not by_label:
                self._start_or_hold(bearing, counts)
            elif self._initiate(bearing) is not None:
                counts["initiated"] += 1
            else:
                counts["unused"] += 1

    def _use(self, track: Track | None, bearing: Bearing, by_label: bool, counts: dict[str, int]) -> None:
        """Apply an associated detection to its track (None: deleted as lost by a duplicate confirmed before it)
        and confirm the track at ``confirm_hits``."""
        if track is None or not self._measure(track, bearing):
            counts["unused"] += 1
            return
        track.hits += 1
        track.last_measured = max(track.last_measured, bearing.t)
        if not track.confirmed and track.hits >= self.config.confirm_hits:
            track.confirmed = True
            self._add_held()  # the duplicate test compares the tracks' estimates
            if not by_label and self._duplicate(track):
                self._delete(track.id)
        counts["updated"] += 1

    def _start_or_hold(self, bearing: Bearing, counts: dict[str, int]) -> None:
        """A detection outside every gate: the partner of a held candidate — the tentative track starts from the
        candidate, as it would have at the candidate's detection, and takes this one — or a candidate itself."""
        candidate = self.candidates.take(bearing, self.model.epoch_of(bearing.t), self._scan, self.config.gate)
        if candidate is not None:
            track = self._start_track(candidate.position, candidate.cov, self._offset(candidate.bearing),
                                      candidate.bearing.truth_id, candidate.bearing.t)
            track.created_epoch = candidate.created
            counts["initiated"] += 1
            self._use(track, bearing, False, counts)
            return
        located = self._geolocate(bearing)
        if located is None:
            counts["unused"] += 1
            return
        self.candidates.hold(Candidate(bearing, located[0], located[1], self.model.epoch_of(bearing.t), self.epoch,
                                       self._scan))
        counts["candidate"] += 1

    def _hand_over(self, handover) -> None:
        """A converged particle candidate becomes a track: its Gaussian is the first position measurement."""
        track = self._start_track(handover.position.mean, handover.position.cov, 0, handover.truth_id,
                                  handover.last_measured)
        track.hits = handover.hits
        if track.hits >= self.config.confirm_hits:
            track.confirmed = True
            if self._duplicate(track):
                self._delete(track.id)

    def _duplicate(self, track: Track) -> bool:
        """Does a track that has just been confirmed pass the track-to-track gate with another confirmed
        track? Then it is that target seen twice (started by a run of its detections that fell outside its
        gate) and is dropped rather than merged: a merge would desynchronize the other's channel filters.

        Unless the other is *lost*: nobody has measured it since this one started — it coasted through a
        manoeuvre its motion model does not cover, and the target's detections now fall outside its gate
        (which is why this one started). Then this one continues it and the lost one is deleted: keeping
        the lost one would report an estimate tens of metres off, under a covariance broad enough to be
        matched, until it went stale."""
        started = track.created_epoch * self.model.step
        for other in list(self.tracks.values()):
            if other.id == track.id or not other.confirmed:
                continue
            try:
                same = self._track_distance(other.estimate(), track.estimate()) < self.config.track_gate
            except UninformativeBeliefError:
                continue
            if same and other.last_measured < started:
                self._delete(other.id)
            elif same:
                return True
        return False

    def _measure(self, track: Track, bearing: Bearing) -> bool:
        """Apply one detection to a track, as a bearing or as a geolocated position; ``False`` when it cannot
        be: the ray misses the terrain, so a position cannot be formed, or the detection is older than the
        belief's window (an IMM track younger than the detection).

        A bearing on a trajectory is held and added with the update's others (:meth:`_add_held`), linearised
        at the epoch's prediction; an IMM window linearises each of its modes itself, at once."""
        belief = track.belief
        offset = self._offset(bearing)
        if belief.epoch - offset < belief.oldest:
            return False
        if self.config.measurement == "bearing" and isinstance(belief, Trajectory):
            self._held.setdefault(track.id, []).append((bearing, offset))
            return True
        if self.config.measurement == "bearing":
            track.belief = belief.eif_update(Bearing3D(STATE_DIM, bearing.sensor, bearing.R), bearing.azel, offset)
            return True
        located = self._geolocate(bearing)
        if located is None:
            return False
        where = PositionMeasurement(STATE_DIM, located[1])
        track.belief = belief.update(where.H, where.R_inv, located[0], offset)
        return True

    def _add_held(self) -> None:
        """Add the held bearings to their tracks, all at once: the extended information update (Merino (3.52))
        ``Y += H^T R^-1 H``, ``y += H^T R^-1 [z - h(mu_bar) + H mu_bar]`` with ``h``, ``H`` those of
        :class:`fusion.measurement.Bearing3D` at the epoch's prediction ``mu_bar`` (:meth:`_prediction`),
        computed for every bearing in one vectorised call, then one copy of each track's window
        (:meth:`fusion.trajectory.Trajectory.add_information`)."""
        held = [(self.tracks[tid], b, offset) for tid, items in self._held.items() if tid in self.tracks
                for b, offset in items]
        self._held = {}
        if not held:
            return
        infos, vectors = bearing3d_information(  # defined: each pair passed its gate at the prediction
            np.array([self._prediction(track, offset).mean[:3] for track, _, offset in held]),
            np.array([b.sensor for _, b, _ in held]), np.array([b.azel for _, b, _ in held]),
            np.array([b.R for _, b, _ in held]))
        by_track: dict[int, list[int]] = {}
        for j, (track, _, _) in enumerate(held):
            by_track.setdefault(track.id, []).append(j)
        offsets = np.array([offset for _, _, offset in held])
        for tid, rows in by_track.items():
            track = self.tracks[tid]
            track.belief = track.belief.add_information(offsets[rows], infos[rows], vectors[rows])

    def _geolocate(self, bearing: Bearing):
        return geolocate(bearing.sensor, bearing.azel, bearing.R, self.terrain,
                         sensor_sigma=self.config.sensor_sigma, terrain_sigma=self.config.terrain_sigma)

    def _prediction(self, track: Track, offset: int) -> Gaussian:
        """The track's marginal on the state ``offset`` steps before the newest as it stood when the tracker
        advanced to this epoch (or when the track started): for ``offset = 0`` the prediction ``mu_bar_t,
        P_bar_t``.

        Every detection of one epoch is gated (Merino (3.64)) and linearised ((3.52)) against it, as the
        extended information filter linearises all of a step's measurements at the prediction — so its
        contributions add up whatever their order or grouping. Otherwise each peer's detections flooded in
        (:mod:`agent.beliefs.flood`) would recompute the window's marginal after every update: N of them per
        step for N agents. (A belief computes each marginal once.)"""
        start = self._predicted.get(track.id)
        if start is None or start.epoch != track.belief.epoch:  # started this epoch, or moved by a peer's belief
            start = self._predicted[track.id] = track.belief
        return start.state(offset)

    def _offset(self, bearing: Bearing) -> int:
        offset = self.epoch - self.model.epoch_of(bearing.t)
        if not 0 <= offset < self.model.window:
            raise ValueError(f"bearing at t={bearing.t} is outside the window ending at epoch {self.epoch}")
        return offset

    def _distances(self, bearings: list[Bearing]) -> tuple[list[int], list[list[float]]]:
        """Merino (3.64) of every bearing against every track's predicted state at the bearing's time (a peer's
        bearing may be older; :meth:`_prediction`): the track ids and the ``(m, tracks)`` costs, row by row,
        ``_UNASSIGNED`` where a distance does not exist (the state is not observable, the bearing is outside
        the window or undefined there). Pairs are kept for the rest of the update: each is computed once, and
        those missing are computed together (:func:`fusion.measurement.bearing_gate_distances`)."""
        ids = list(self.tracks)
        known = [self._gated.setdefault(id(b), {}) for b in bearings]
        missing = {t for got in known for t in ids if t not in got}
        if missing:  # new tracks: against every bearing of the update in one call, not again for each scan
            self._gate(self._pending or bearings, [t for t in ids if t in missing])
        return ids, [[got[t] for t in ids] for got in known]

    def _gate(self, bearings: list[Bearing], ids: list[int]) -> None:
        """Fill ``_gated`` for every pair of ``bearings`` and tracks ``ids``, one vectorised call per state offset,
        against the tracks' predicted positions (:meth:`_position_prior`)."""
        by_offset: dict[int, list[Bearing]] = {}
        for b in bearings:
            try:
                by_offset.setdefault(self._offset(b), []).append(b)
            except ValueError:  # outside the window: no distance to anything
                self._gated.setdefault(id(b), {}).update(dict.fromkeys(ids, _UNASSIGNED))
        for offset, rows in by_offset.items():
            priors = [(t, self._position_prior(t, offset)) for t in ids]
            tracks = [t for t, prior in priors if prior is not None]
            for b in rows:
                self._gated.setdefault(id(b), {}).update({t: _UNASSIGNED for t, prior in priors if prior is None})
            if not tracks:
                continue
            means = np.array([prior[0] for _, prior in priors if prior is not None])
            covs = np.array([prior[1] for _, prior in priors if prior is not None])
            d2 = bearing_gate_distances(np.array([b.sensor for b in rows]), np.array([b.azel for b in rows]),
                                        np.array([b.R for b in rows]), means, covs)
            d2 = np.where(np.isfinite(d2), d2, _UNASSIGNED).tolist()
            for b, row in zip(rows, d2, strict=True):
                self._gated[id(b)].update(zip(tracks, row, strict=True))

    def _position_prior(self, track_id: int, offset: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The predicted position (mean, 3x3 covariance) of a track ``offset`` steps back (:meth:`_prediction`),
        computed once per update; ``None`` when the state is not observable there."""
        key = (track_id, offset)
        if key not in self._priors:
            try:
                est = self._prediction(self.tracks[track_id], offset)
                self._priors[key] = (est.mean[:3], est.cov[:3, :3])
            except (UninformativeBeliefError, ValueError):
                self._priors[key] = None
        return self._priors[key]

    def _pairs_by_distance(self, bearings: list[Bearing]) -> list[tuple[int, int]]:
        """One detection per track (Hungarian on the gated ``d^2``; for a single detection, the smallest)."""
        if not bearings or not self.tracks:
            return []
        ids, cost = self._distances(bearings)
        gate = self.config.gate
        # Confirmed tracks have the first claim on the detections in their gates: a tentative track started
        # by one of the ~1 % of a target's detections that fall outside its gate is broad (small d^2), so
        # otherwise it takes the target's next detections, gets confirmed and stays a duplicate.
        claim = [0.0 if self.tracks[i].confirmed else gate for i in ids]
        gated = [[c + extra if c <= gate else _UNASSIGNED for c, extra in zip(row, claim, strict=True)]
                 for row in cost]
        if len(bearings) == 1:
            best = min(range(len(ids)), key=gated[0].__getitem__)
            return [(0, ids[best])] if gated[0][best] < _UNASSIGNED else []
        rows, cols = linear_sum_assignment(np.array(gated))
        return [(int(r), ids[c]) for r, c in zip(rows, cols, strict=True) if gated[r][c] < _UNASSIGNED]

    def _pairs_by_label(self, bearings: list[Bearing]) -> list[tuple[int, int]]:
        by_truth = {t.truth_id: t.id for t in self.tracks.values() if t.truth_id is not None}
        return [(i, by_truth[b.truth_id]) for i, b in enumerate(bearings) if b.truth_id in by_truth]

    def _inside_any_gate(self, bearing: Bearing) -> bool:
        _, cost = self._distances([bearing])
        return any(c <= self.config.gate for c in cost[0])

    def _initiate(self, bearing: Bearing) -> Track | None:
        """A new track at the ground point of the ray, with its unscented-transform covariance."""
        located = self._geolocate(bearing)
        if located is None:
            return None
        return self._start_track(located[0], located[1], self._offset(bearing), bearing.truth_id, bearing.t)

    def _start_track(self, position, cov, offset: int, truth_id, last_measured: float) -> Track:
        """A tentative track whose first information is a position measurement ``N(position, cov)``."""
        c = self.config
        if c.motion == "imm":  # the position and a velocity prior, in every mode
            start = np.zeros((STATE_DIM, STATE_DIM))
            start[:3, :3], start[3:, 3:] = cov, self.speed_cov
            belief = ImmWindow.start(self.model, self.epoch - offset, np.concatenate([position, np.zeros(3)]), start,
                                     c.imm.start_probs()).advanced_to(self.epoch)
        else:
            belief = Trajectory.prior(self.model, self.epoch)
            where = PositionMeasurement(STATE_DIM, cov)
            belief = belief.update(where.H, where.R_inv, position, offset)
        if c.motion == "constant_velocity":  # no stationary velocity in the prior: add a local pseudo-prior
            H_v = np.hstack([np.zeros((3, 3)), np.eye(3)])
            belief = belief.update(H_v, np.linalg.inv(self.speed_cov), np.zeros(3), offset)
        track = self._new_track(belief)
        track.truth_id = truth_id
        track.last_measured = last_measured
        return track

    def _new_track(self, belief: Trajectory) -> Track:
        channels = None if self.config.policy == "flood" else ChannelFilter(  # flooding shares no beliefs
            Trajectory.prior(self.model, self.epoch), self.config.policy,
            partial(intersect_on_newest, rule=self.config.intersection), me=self.me,
            check_new_links=False)  # exact on static trees; links that appear between informed agents: use flood
        track = Track(self._next_id, belief, channels, created_epoch=self.epoch)
        self.tracks[track.id] = track
        self._next_id += 1
        return track

    # -- exchange with peers --------------------------------------------------------------------
    def confirmed(self) -> list[Track]:
        return [t for t in self.tracks.values() if t.confirmed]

    def record_sent(self, tracks: list[Track], seq: int) -> None:
        """Record in the channel filters that ``tracks`` went out in message ``seq``."""
        for track in tracks:
            track.channels.on_send(track.belief, seq)

    def prepare_send(self, track: Track) -> dict:
        """Adopt any agreed re-sync baseline into ``track`` before it is sent; its re-sync flags per peer."""
        track.belief, flags = track.channels.prepare_send(track.belief)
        return flags

    def peer_restarted(self, peer: str) -> None:
        """``peer`` started a new life (:mod:`agent.net.incarnation`): its track ids mean nothing any more and
        it holds nothing of ours, so its labels go and every channel to it starts afresh from the common prior
        (:meth:`fusion.channel_filter.ChannelFilter.reset`, the case of a neighbour that restarted)."""
        self.labels = {key: tid for key, tid in self.labels.items() if key[0] != peer}
        for track in self.tracks.values():
            if track.channels is not None and peer in track.channels.neighbours():  # flood keeps no channels
                track.channels.reset(peer)

    def fuse_remote(self, peer: str, remote: list[RemoteTrack], seq: int, edge: Edge = Edge.TREE) -> list[Received]:
        """Fuse a peer's tracks from its message ``seq``."""
        results = []
        claimed = {self.labels[(peer, r.id)] for r in remote if (peer, r.id) in self.labels}
        unclaimed = _Positions([t for t in self.tracks.values() if t.id not in claimed])  # unchanged until claimed
        for r in remote:
            belief = r.belief if r.belief.epoch >= self.epoch else r.belief.advanced_to(self.epoch)
            self.epoch = max(self.epoch, belief.epoch)
            track = self._match_remote(peer, r.id, belief, claimed, unclaimed)
            out = track.channels.on_receive(peer, track.belief, belief, r.ack, seq=seq, tree_edge=edge,
                                            resync=r.resync, fresh=r.fresh)
            track.belief = out.fused
            track.confirmed = True
            track.acks[peer] = seq
            track.last_measured = max(track.last_measured, r.last_measured)
            track.fusions[out.method] = track.fusions.get(out.method, 0) + 1
            results.append(out)
        self.merge_duplicates()
        return results

    def merge_duplicates(self) -> int:
        """Merge confirmed tracks that pass the track-to-track gate (Merino (3.65)); returns how many. Pairs are taken
        in id order, a track absorbing every later one in its gate in turn (its estimate changes with each merge).
        The gate distances from one track to all later ones are computed at once (:class:`_Positions`): a message
        adopting tens of tracks costs milliseconds, not one 3x3 solve in Python (~50 µs) per pair."""
        tracks = sorted((t for t in self.tracks.values() if t.confirmed), key=lambda t: t.id)
        table, alive, merged = _Positions(tracks), np.ones(len(tracks), bool), 0
        for i, keep in enumerate(tracks):
            start = i + 1
            while alive[i] and table.valid[i] and start < len(tracks):
                hit = table.first_in_gate(table.means[i], table.covs[i], np.flatnonzero(alive[start:]) + start,
                                          self.config.track_gate)
                if hit is None:
                    break
                self._merge(keep, tracks[hit])
                alive[hit], start = False, hit + 1
                table.update(i)
                merged += 1
        return merged

    def _merge(self, keep: Track, drop: Track) -> None:
        """``drop`` is ``keep`` seen twice: their intersection stays under ``keep``'s id, with ``drop``'s labels."""
        epoch = max(keep.belief.epoch, drop.belief.epoch)
        keep.belief = intersect_on_newest(
            keep.belief.advanced_to(epoch), drop.belief.advanced_to(epoch), self.config.intersection
        )
        keep.last_measured = max(keep.last_measured, drop.last_measured)
        keep.channels.desynchronize_all()
        self.labels = {k: (keep.id if v == drop.id else v) for k, v in self.labels.items()}
        keep.acks = {}  # after an intersection, no peer holds "our copy" of this track any more
        del self.tracks[drop.id]

    @staticmethod
    def _track_distance(a: Gaussian, b: Gaussian) -> float:
        """``d^2`` of Merino (3.65) over positions: ``(mu_a - mu_b)^T (P_a + P_b)^-1 (mu_a - mu_b)``."""
        return float(gate_distances(a.mean[:3], a.cov[:3, :3], b.mean[None, :3], b.cov[None, :3, :3])[0])

    def _match_remote(self, peer: str, remote_id: int, belief: Trajectory, claimed: set,
                      unclaimed: _Positions) -> Track:
        """The local track of a peer's track: by its label, else the unclaimed track nearest to it inside the gate (the
        first of equals), else a new one. ``unclaimed``: the tracks no track of this message had claimed before it."""
        key = (peer, remote_id)
        if key in self.labels and self.labels[key] in self.tracks:
            return self.tracks[self.labels[key]]
        try:
            theirs = belief.current()
            mean, cov = theirs.mean[:3], theirs.cov[:3, :3]  # cov raises if the peer's track is not fully observable
        except UninformativeBeliefError:
            mean = cov = None
        rows = [i for i, t in enumerate(unclaimed.tracks) if t.id not in claimed]
        nearest = None if mean is None else unclaimed.nearest_in_gate(mean, cov, rows, self.config.track_gate)
        best = self._new_track(Trajectory.prior(self.model, belief.epoch)) if nearest is None \
            else unclaimed.tracks[nearest]
        best.belief = best.belief.advanced_to(belief.epoch)
        self.labels[key] = best.id
        claimed.add(best.id)
        return best

    # -- views ----------------------------------------------------------------------------------
    def estimates(self, confirmed_only: bool = True) -> list[tuple[int, Gaussian]]:
        """The tracks' newest-state estimates, leaving out any whose state is not fully observable (its
        covariance does not exist: e.g. after an intersection with a belief uninformed in some direction)."""
        out = []
        for track in self.tracks.values():
            if track.confirmed or not confirmed_only:
                try:
                    est = track.estimate()
                    est.cov  # noqa: B018 - raises if some direction of the state is unobserved
                except UninformativeBeliefError:
                    continue
                out.append((track.id, est))
        return out


# -- track-to-track gate, vectorised ---------------------------------------------------------------------
def gate_distances(mean: np.ndarray, cov: np.ndarray, means: np.ndarray, covs: np.ndarray) -> np.ndarray:
    """``d^2`` of Merino (3.65) between one position estimate (``mean`` (3,), ``cov`` (3, 3)) and each of ``k``
    others (``means`` (k, 3), ``covs`` (k, 3, 3)): one batched solve of the ``k`` 3x3 systems ``(P + P_j) x = d_j``."""
    d = mean - means
    x = np.linalg.solve(cov + covs, d[..., None])[..., 0]
    return np.einsum("ij,ij->i", d, x)


class _Positions:
    """The position estimates of ``tracks`` stacked for vectorised gate tests: ``means`` (n, 3), ``covs`` (n, 3, 3);
    ``valid[i]`` is False for a track whose position is not fully observable (it cannot be compared)."""

    def __init__(self, tracks: list[Track]):
        self.tracks = tracks
        self.means, self.covs = np.zeros((len(tracks), 3)), np.tile(np.eye(3), (len(tracks), 1, 1))
        self.valid = np.zeros(len(tracks), bool)
        for i in range(len(tracks)):
            self.update(i)

    def update(self, i: int) -> None:
        """Re-read track ``i``'s estimate (after its belief changed)."""
        try:
            estimate = self.tracks[i].estimate()
            self.means[i], self.covs[i] = estimate.mean[:3], estimate.cov[:3, :3]
            self.valid[i] = True
        except UninformativeBeliefError:
            self.valid[i] = False

    def _in_gate(self, mean: np.ndarray, cov: np.ndarray, rows, gate: float) -> tuple[np.ndarray, np.ndarray]:
        """The valid ones among ``rows`` and their ``d^2`` to (``mean``, ``cov``)."""
        rows = np.asarray(rows, int)
        rows = rows[self.valid[rows]]
        return rows, gate_distances(mean, cov, self.means[rows], self.covs[rows]) if rows.size else np.zeros(0)

    def first_in_gate(self, mean: np.ndarray, cov: np.ndarray, rows, gate: float) -> int | None:
        """The first of ``rows`` inside the gate of (``mean``, ``cov``), or ``None``."""
        rows, d2 = self._in_gate(mean, cov, rows, gate)
        inside = np.flatnonzero(d2 < gate)
        return int(rows[inside[0]]) if inside.size else None

    def nearest_in_gate(self, mean: np.ndarray, cov: np.ndarray, rows, gate: float) -> int | None:
        """The one of ``rows`` nearest to (``mean``, ``cov``) inside the gate (the first of equals), or ``None``."""
        rows, d2 = self._in_gate(mean, cov, rows, gate)
        return int(rows[np.argmin(d2)]) if d2.size and d2.min() < gate else None
