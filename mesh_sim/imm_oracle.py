"""The centralized oracle's tracker: one interacting-multiple-model filter per true target.

The oracle sees every agent's bearings, associated by their true labels, and must be *consistent* on
every shipped target — a parked car, a walker at constant velocity and a car driving a figure-8 — so that
its ANEES is a reference. No single linear motion model with positive process noise can be: on a target
that truly has no process noise (static or constant velocity), a filter in steady state reports a
covariance of which a fixed share is the process noise it assumes, whatever that noise's size (the
model's time scale adapts to it), so its NEES settles below 1 (about 0.5 measured, for any ``q`` from
1e-4 to 3 m^2/s^3); and a noise small enough never to reach that steady state in a run leaves the
figure-8 (2.6 m/s^2 of acceleration) hopelessly overconfident. Two modes cover the three targets
(:mod:`fusion.imm`, Blom & Bar-Shalom 1988): a *quiet* exact constant-velocity model (no process noise:
static and constant-velocity targets are its special cases) and a *manoeuvring* one with the figure-8's
acceleration. The shipped targets never change how they move, so by default the modes do not switch
(``stay = 1``: the static multiple-model estimator, Bar-Shalom et al. §11.6.4, whose mode probabilities
converge to the model that fits): a switching probability keeps a share of the manoeuvring mode on a
parked car, whose velocity covariance then dominates the mixture's (measured: ANEES 0.45 with
``stay = 0.999``). A scenario with targets that do switch sets ``stay < 1``.

Bearings may arrive late (a camera's bearings wait for their pose) by up to ``window`` grid steps: each
track keeps the belief at the start of its window (the anchor) and the bearings of every later epoch,
and re-filters from the anchor when a bearing lands before the newest epoch (reprocessing, which is exact).

Initiation, confirmation and deletion follow :class:`agent.beliefs.tracking.Tracker`: a track starts at the
ground point of the first bearing's ray (unscented covariance, ``perception.geolocation``) with the
configured speed prior, is confirmed after ``confirm_hits`` bearings, and is deleted when nobody has
measured it for ``stale_after`` seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from agent.beliefs.tracking_config import TrackerConfig
from agent.sensors.bearing import Bearing
from fusion.gaussian import Gaussian
from fusion.imm import ImmBelief, ImmModel
from fusion.measurement import Bearing3D
from fusion.motion import ConstantVelocity
from perception.geolocation import geolocate

STATE_DIM = 6  # (north, east, down, v_north, v_east, v_down)


@dataclass(frozen=True)
class OracleConfig:
    """The oracle's IMM. Every default is chosen here, from the shipped targets (``mesh_sim.targets``)."""

    quiet_q: float = 0.0  # [m^2/s^3] static and constant-velocity targets: no acceleration at all
    manoeuvre_q: float = 3.0  # [m^2/s^3] the figure-8's 2.6 m/s^2 peak acceleration
    vertical_q: float = 0.0  # [m^2/s^3] both modes: ground targets on the shipped (flat) terrain never climb
    stay: float = 1.0  # probability of keeping the same mode from one step to the next (1: no switching)
    quiet_prior: float = 0.5  # probability of the quiet mode when a track starts

    def __post_init__(self):
        for name in ("quiet_q", "manoeuvre_q", "vertical_q"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"oracle.{name} must be a non-negative number, got {getattr(self, name)!r}")
        if not 0.0 < self.stay <= 1.0:
            raise ValueError(f"oracle.stay must be in (0, 1], got {self.stay!r}")
        if not 0.0 < self.quiet_prior < 1.0:
            raise ValueError(f"oracle.quiet_prior must be strictly between 0 and 1, got {self.quiet_prior!r}")

    def model(self) -> ImmModel:
        quiet = ConstantVelocity(3, self.quiet_q, self.vertical_q)
        manoeuvre = ConstantVelocity(3, self.manoeuvre_q, self.vertical_q)
        return ImmModel.two_modes(quiet, manoeuvre, self.stay)


@dataclass(frozen=True)
class Grid:
    """The time grid of the tracker (``t_k = k * step``) and how many epochs late a bearing may be."""

    step: float
    window: int

    def epoch_of(self, t: float) -> int:
        return int(np.floor(t / self.step + 1e-9))


@dataclass
class ImmTrack:
    id: int
    truth_id: str
    anchor: ImmBelief  # the belief at epoch ``anchor_epoch``, every bearing up to that epoch applied
    anchor_epoch: int
    pending: dict = field(default_factory=dict)  # epoch -> bearings after the anchor
    belief: ImmBelief | None = None  # the belief at the tracker's epoch (None: to be re-filtered)
    belief_epoch: int = -1
    hits: int = 1
    last_measured: float = 0.0


class ImmTracker:
    """Label-associated IMM tracks: the same ``advance`` / ``update(by_label=True)`` / ``estimates`` calls as
    :class:`agent.beliefs.tracking.Tracker`, for the oracle of ``mesh_sim.world``."""

    def __init__(self, config: TrackerConfig, step: float, terrain, oracle: OracleConfig | None = None):
        self.config = config
        self.oracle = oracle or OracleConfig()
        self.imm = self.oracle.model()
        self.model = Grid(step, config.window)
        self.terrain = terrain
        self.epoch = 0
        self.tracks: dict[str, ImmTrack] = {}
        self._next_id = 0

    def advance(self, epoch: int) -> None:
        """Move to grid index ``epoch``; delete the tracks nobody has measured for ``stale_after`` seconds."""
        self.epoch = max(self.epoch, epoch)
        now = self.epoch * self.model.step
        for truth_id, track in list(self.tracks.items()):
            if now - track.last_measured > self.config.stale_after:
                del self.tracks[truth_id]
            else:
                self._slide(track)

    def update(self, bearings: list[Bearing], by_label: bool = True) -> dict[str, int]:
        """Apply bearings (each at its own epoch inside the window) to the tracks of their true targets."""
        if not by_label:
            raise ValueError("the IMM oracle associates bearings by their true labels only")
        counts = {"updated": 0, "initiated": 0, "unused": 0}
        for bearing in bearings:
            epoch = self.model.epoch_of(bearing.t)
            if not self.epoch - self.model.window < epoch <= self.epoch:
                raise ValueError(f"bearing at t={bearing.t} is outside the window ending at epoch {self.epoch}")
            if bearing.truth_id is None:
                counts["unused"] += 1
                continue
            track = self.tracks.get(bearing.truth_id)
            if track is None or epoch <= track.anchor_epoch:
                if track is None and self._initiate(bearing, epoch):
                    counts["initiated"] += 1
                else:
                    counts["unused"] += 1
                continue
            track.pending.setdefault(epoch, []).append(bearing)
            if track.belief is not None and epoch == track.belief_epoch:
                track.belief = self._measure(track.belief, bearing)
            elif track.belief is not None and epoch < track.belief_epoch:
                track.belief = None  # late: re-filter from the anchor (a newer epoch is applied on catching up)
            track.hits += 1
            track.last_measured = max(track.last_measured, bearing.t)
            counts["updated"] += 1
        return counts

    def estimates(self, confirmed_only: bool = True) -> list[tuple[int, Gaussian]]:
        """``(track id, moment-matched Gaussian at the tracker's epoch)`` of every (confirmed) track."""
        return [(t.id, self._current(t).combined()) for t in self.tracks.values()
                if t.hits >= self.config.confirm_hits or not confirmed_only]

    # -- internals ------------------------------------------------------------------------------
    def _initiate(self, bearing: Bearing, epoch: int) -> bool:
        located = geolocate(bearing.sensor, bearing.azel, bearing.R, self.terrain,
                            sensor_sigma=self.config.sensor_sigma, terrain_sigma=self.config.terrain_sigma)
        if located is None:
            return False
        c = self.config
        cov = np.zeros((STATE_DIM, STATE_DIM))
        cov[:3, :3] = located[1]
        cov[3:, 3:] = np.diag([c.speed_std**2, c.speed_std**2, c.vertical_speed_std**2])
        mean = np.concatenate([located[0], np.zeros(3)])
        probs = np.array([self.oracle.quiet_prior, 1.0 - self.oracle.quiet_prior])
        start = ImmBelief.start(mean, cov, probs)
        self.tracks[bearing.truth_id] = ImmTrack(self._next_id, bearing.truth_id, start, epoch, belief=start,
                                                 belief_epoch=epoch, last_measured=bearing.t)
        self._next_id += 1
        return True

    def _measure(self, belief: ImmBelief, bearing: Bearing) -> ImmBelief:
        return belief.update(Bearing3D(STATE_DIM, bearing.sensor, bearing.R), bearing.azel)

    def _filter(self, belief: ImmBelief, start: int, stop: int, pending: dict) -> ImmBelief:
        """Predict step by step from epoch ``start`` to ``stop``, applying the bearings of each epoch."""
        for epoch in range(start + 1, stop + 1):
            belief = belief.predict(self.imm, self.model.step)
            for bearing in pending.get(epoch, ()):
                belief = self._measure(belief, bearing)
        return belief

    def _current(self, track: ImmTrack) -> ImmBelief:
        if track.belief is None:
            track.belief = self._filter(track.anchor, track.anchor_epoch, self.epoch, track.pending)
        elif track.belief_epoch < self.epoch:
            track.belief = self._filter(track.belief, track.belief_epoch, self.epoch, track.pending)
        track.belief_epoch = self.epoch
        return track.belief

    def _slide(self, track: ImmTrack) -> None:
        """Move the anchor to just before the oldest epoch a late bearing may still reach (``epoch - window``)."""
        anchor = self.epoch - self.model.window
        if anchor <= track.anchor_epoch:
            return
        track.anchor = self._filter(track.anchor, track.anchor_epoch, anchor, track.pending)
        track.anchor_epoch = anchor
        track.pending = {e: b for e, b in track.pending.items() if e > anchor}
