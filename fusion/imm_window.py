"""An IMM belief that still takes measurements of the last ``window`` grid epochs: late ones by reprocessing.

A tracker on a network receives measurements late (a peer's detections cross hops; a camera's wait for
their pose). :class:`~fusion.trajectory.Trajectory` takes them in information form on a window of states;
an interacting multiple model (:mod:`fusion.imm`, Blom & Bar-Shalom 1988) is a mixture, so it takes them
by *reprocessing*: the window keeps the belief at its oldest epoch (the *anchor*, before that epoch's
measurements) and every measurement from there on, and a measurement older than the newest epoch makes
the newest belief be re-filtered from the anchor, in time order — exactly the recursive IMM that had
received every measurement on time (Bar-Shalom, Li & Kirubarajan, §11.6.6, applied epoch by epoch).
Measurements of one epoch are applied in the order they arrived (extended-Kalman updates do not commute:
each moves the next one's linearization point, by ~1e-5 relative in the tests).

A window is immutable, like a trajectory: ``advanced_to``, ``eif_update`` return new windows. A
measurement at the newest epoch updates the newest belief directly; the others cost one re-filtering of
at most ``window`` epochs, when a marginal is next asked for.

``state(offset)`` is the *filtered* belief at ``epoch - offset`` (the measurements up to that epoch): what
gating a late measurement needs (a trajectory gives the smoothed one; both are the belief the measurement
is compared with, without the measurement itself).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion import validation
from fusion.gaussian import Gaussian
from fusion.imm import ImmBelief, ImmModel
from fusion.trajectory import grid_epoch


@dataclass(frozen=True)
class ImmWindowModel:
    """The switching motion models, the grid (``t_k = k * step``) and how many epochs a window spans."""

    imm: ImmModel
    step: float
    window: int

    def __post_init__(self):
        if not (np.isfinite(self.step) and self.step > 0):
            raise ValueError(f"step must be a positive number of seconds, got {self.step}")
        if int(self.window) != self.window or self.window < 1:
            raise ValueError(f"window must be an integer of at least 1 epoch, got {self.window}")

    @property
    def state_dim(self) -> int:
        return self.imm.dim

    def epoch_of(self, t: float) -> int:
        return grid_epoch(t, self.step)


class ImmWindow:
    """The IMM belief at grid index ``epoch``, able to take measurements at epochs ``oldest .. epoch``."""

    __slots__ = ("model", "epoch", "anchor", "anchor_epoch", "pending", "_timeline", "_states")

    def __init__(self, model: ImmWindowModel, epoch: int, anchor: ImmBelief, anchor_epoch: int, pending: tuple,
                 timeline: list):
        self.model = model
        self.epoch = epoch
        self.anchor = anchor  # the belief at anchor_epoch, before the measurements of that epoch
        self.anchor_epoch = anchor_epoch
        self.pending = pending  # ((epoch, measurement model, z), ...) at epochs >= anchor_epoch, arrival order
        # the filtered beliefs of epochs anchor_epoch, anchor_epoch + 1, ... (each after that epoch's
        # measurements): a valid prefix, completed up to epoch when a marginal is asked for
        self._timeline = timeline
        self._states: dict[int, Gaussian] = {}  # offset -> combined belief, computed once

    @classmethod
    def start(cls, model: ImmWindowModel, epoch: int, mean, cov, probs) -> ImmWindow:
        """A window whose belief at ``epoch`` is ``N(mean, cov)`` in every mode, with mode probabilities
        ``probs`` (:meth:`fusion.imm.ImmBelief.start`)."""
        belief = ImmBelief.start(mean, cov, probs)
        if belief.means.shape[1] != model.state_dim:
            raise ValueError(f"an IMM window of {model.state_dim}-D states cannot start from a "
                             f"{belief.means.shape[1]}-D belief")
        return cls(model, int(epoch), belief, int(epoch), (), [belief])

    @property
    def oldest(self) -> int:
        """The oldest epoch a measurement may still be applied at."""
        return max(self.anchor_epoch, self.epoch - self.model.window + 1)

    # -- time ------------------------------------------------------------------------------------
    def advanced_to(self, epoch: int) -> ImmWindow:
        """The window at grid index ``epoch``: the anchor moved up to the oldest epoch a measurement may still
        reach (the filtered belief of the epoch before it, predicted one step)."""
        if epoch < self.epoch:
            raise ValueError(f"cannot advance an IMM window backwards (from epoch {self.epoch} to {epoch})")
        if epoch == self.epoch:
            return self
        anchor_epoch = max(self.anchor_epoch, epoch - self.model.window + 1)
        if anchor_epoch == self.anchor_epoch:
            return ImmWindow(self.model, int(epoch), self.anchor, anchor_epoch, self.pending, list(self._timeline))
        timeline = self._complete()
        cut = anchor_epoch - self.anchor_epoch
        anchor = (timeline[cut - 1] if cut <= len(timeline) else self._predicted(timeline[-1], cut - len(timeline)))
        anchor = anchor.predict(self.model.imm, self.model.step)
        pending = tuple(p for p in self.pending if p[0] >= anchor_epoch)
        return ImmWindow(self.model, int(epoch), anchor, anchor_epoch, pending, list(timeline[cut:]))

    # -- measurements ----------------------------------------------------------------------------
    def eif_update(self, measurement, z, offset: int = 0) -> ImmWindow:
        """Apply a measurement (a :mod:`fusion.measurement` model with ``R``) of the state ``offset`` epochs
        before the newest, extended-Kalman in every mode (:meth:`fusion.imm.ImmBelief.update`). The filtered
        beliefs before its epoch stay; the later ones are re-filtered when next asked for."""
        z = validation.as_vector(np.atleast_1d(np.asarray(z, dtype=float)), "measurement z", measurement.dim)
        at = self.epoch - int(offset)
        if not self.oldest <= at <= self.epoch:
            raise ValueError(f"a measurement {offset} epochs old is outside the IMM window "
                             f"(epochs {self.oldest}..{self.epoch})")
        index = at - self.anchor_epoch
        timeline = self._timeline[:index]
        if index == len(self._timeline) - 1 and at == self.epoch:  # the newest epoch, filtered: update it
            timeline.append(self._timeline[index].update(measurement, z))
        return ImmWindow(self.model, self.epoch, self.anchor, self.anchor_epoch,
                         (*self.pending, (at, measurement, z)), timeline)

    # -- marginals -------------------------------------------------------------------------------
    def state(self, offset: int = 0) -> Gaussian:
        """The moment-matched belief at ``epoch - offset`` given the measurements up to that epoch."""
        known = self._states.get(offset)
        if known is None:
            known = self._states[offset] = self.belief_at(self.epoch - int(offset)).combined()
        return known

    def current(self) -> Gaussian:
        """The moment-matched belief at the newest epoch."""
        return self.state(0)

    def belief_at(self, at: int) -> ImmBelief:
        """The mixture at epoch ``at`` (``oldest .. epoch``) given the measurements up to it."""
        if not self.oldest <= at <= self.epoch:
            raise ValueError(f"epoch {at} is outside the IMM window (epochs {self.oldest}..{self.epoch})")
        return self._complete()[at - self.anchor_epoch]

    def _complete(self) -> list:
        """The timeline up to ``epoch``: from its last valid belief (or the anchor), predict one epoch and apply
        that epoch's measurements (in arrival order), epoch by epoch."""
        timeline = self._timeline
        first = self.anchor_epoch + len(timeline)
        if first > self.epoch:
            return timeline
        by_epoch: dict[int, list] = {}
        for at, measurement, z in self.pending:
            if at >= first - (not timeline):
                by_epoch.setdefault(at, []).append((measurement, z))
        if not timeline:
            belief = self.anchor
            for measurement, z in by_epoch.get(self.anchor_epoch, ()):
                belief = belief.update(measurement, z)
            timeline.append(belief)
            first += 1
        for k in range(first, self.epoch + 1):
            belief = timeline[-1].predict(self.model.imm, self.model.step)
            for measurement, z in by_epoch.get(k, ()):
                belief = belief.update(measurement, z)
            timeline.append(belief)
        return timeline

    def _predicted(self, belief: ImmBelief, steps: int) -> ImmBelief:
        for _ in range(steps):
            belief = belief.predict(self.model.imm, self.model.step)
        return belief
