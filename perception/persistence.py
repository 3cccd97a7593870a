"""Persistent Object Filter (thesis 000 §2.3, Figure 2-13), with the pseudo-code defects fixed.

Each frame's instantaneous blobs are matched to a persistent list ``P``; a matched object's frame
count goes up (saturating at ``max_count``), an unmatched one's goes down, an object at count 0 is
dropped, and only objects seen often enough are reported. Noise blobs, uncorrelated from frame to
frame and lasting 1–2 frames, never reach the reporting count; a true object survives a few frames
in which noise hides it, because its count only decays by one per frame.

Deviations from the thesis pseudo-code (spec 000 §2.3 issues (a)–(e)):

(a) A new object is inserted as *found this frame* with count 1, so it is not decremented to 0
    and dropped in the call that created it (as written, nothing could ever persist).
(b) A matched object takes the matched detection's position and area (``update=True``), so a
    moving target does not drift out of the ``C_x`` gate. ``update=False`` keeps the thesis text.
    Extension (``velocity_gain > 0``): each object also keeps an image velocity (px/frame),
    smoothed as ``v ← v + g·(Δx/Δframes − v)`` at every match; the gate is applied around the
    predicted position ``x + v`` and a hidden object is reported where it is predicted to be. On a
    moving camera the whole scene slides through the image, and without this a target hidden for
    two frames is reported a dozen pixels behind where it is.
(c) Reporting uses ``frame_count ≥ min_count`` ("at least", as the thesis comment says), not ``>``.
(d) Association is one-to-one: each persistent object takes at most one detection per frame,
    chosen greedily by increasing pixel distance among the pairs inside both gates (rather than
    "first p that fits"), and objects created in this frame are not candidates for other detections.
(e) Objects are removed by building a new list, never by popping while iterating.

Extension (not observed ≠ absent): where the detector reports that it could not see (rows inside
a banding episode, a blank frame: ``DetectionResult.blind_rows``), an unmatched object keeps its
count instead of losing one, for at most ``max_blind`` consecutive frames; afterwards it decays
as usual, so a camera that stays blind forgets its objects. Without this, with banding in half
the frames a new object's count is a zero-drift random walk and rarely reaches ``min_count``.

Extension: an object that is not found and whose last box touched the image border (within
``edge_margin`` px) is dropped at once — it has most likely left the view, and reporting it where
it was last seen would be a false alarm (the thesis camera hovered; ours flies). This needs the
frame size, which :class:`PersistentDetector` passes.

The area gate ``C_A`` of the thesis is an absolute difference, which cannot suit both a near and a
far target; ``max_area_ratio`` (an extension) gates on the ratio instead. Either may be disabled.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from perception.detection import Detection, DetectionResult

__all__ = ["PersistentObject", "PersistentObjectFilter", "PersistentDetector"]


@dataclass
class PersistentObject:
    """One entry of ``P``: position ``x = (u, v)`` [px], area ``A`` [px²], counts, identity."""

    id: int
    x: tuple[float, float]
    area: float
    bbox: tuple[int, int, int, int]
    frame_count: int = 1
    found_this_frame: bool = True
    frames_missed: int = 0  # consecutive frames without a match (0 when found this frame)
    frames_blind: int = 0  # consecutive unmatched frames spent in a blind region
    velocity: tuple[float, float] = (0.0, 0.0)  # px / frame (extension, see the module docstring)
    matches: int = 1  # detections matched so far (including the one that created it)


@dataclass
class PersistentObjectFilter:
    """Thesis 000 §2.3 with fixes (a)–(e) (see the module docstring).

    Parameters (the thesis gives no numbers; every default is chosen here, for 640×480 input
    coordinates and the agent rate of a few Hz):

    * ``max_distance`` — ``C_x``, pixel gate on ``‖c.x − p.x‖`` (chosen here: 20 px);
    * ``max_area_diff`` — ``C_A``, absolute area gate ``|c.A − p.A|`` in px² (chosen here: off);
    * ``max_area_ratio`` — ratio gate ``max(A)/min(A)`` (extension; chosen here: 3);
    * ``max_count`` — ``maxFrameCount``, saturation of the count (chosen here: 8), which also
      bounds how long a hidden object is kept: ``max_count − min_count`` frames are reported
      after the last sighting, ``max_count`` frames kept in ``P``;
    * ``min_count`` — ``frameCountThreshold``, report objects with ``frame_count ≥ min_count``
      (chosen here: 3, so a blob must be seen in 3 frames; 1–2-frame transients never pass);
    * ``update`` — fix (b), follow the matched detection (chosen here: on);
    * ``velocity_gain`` — gain ``g`` of the image-velocity estimate (extension; chosen here: 0.5;
      0 keeps objects still, as in the thesis; needs ``update``);
    * ``max_blind`` — frames an unmatched object in a blind region keeps its count (extension;
      chosen here: 8);
    * ``edge_margin`` — border band for the "left the view" rule (chosen here: 4 px; ``None`` off).
    """

    max_distance: float = 20.0
    max_area_diff: float | None = None
    max_area_ratio: float | None = 3.0
    max_count: int = 8
    min_count: int = 3
    update: bool = True
    velocity_gain: float = 0.5
    max_blind: int = 8
    edge_margin: float | None = 4.0
    objects: list[PersistentObject] = field(default_factory=list)
    _ids: itertools.count = field(default_factory=itertools.count, repr=False)

    def __post_init__(self) -> None:
        if not 1 <= self.min_count <= self.max_count:
            raise ValueError(f"need 1 ≤ min_count ≤ max_count, got {self.min_count}, {self.max_count}")
        if self.max_distance <= 0:
            raise ValueError("max_distance must be positive")

    @property
    def _predicts(self) -> bool:
        return self.update and self.velocity_gain > 0

    def reset(self) -> None:
        self.objects = []

    def _pairs(self, detections: Sequence[Detection]) -> list[tuple[int, int]]:
        """(detection, object) index pairs inside both gates, nearest first."""
        if not detections or not self.objects:
            return []
        c = np.array([d.center for d in detections], float)
        x = np.array([p.x for p in self.objects], float)
        dist = np.linalg.norm(c[:, None, :] - x[None, :, :], axis=2)
        ok = dist < self.max_distance
        a_c = np.maximum(np.array([d.area for d in detections], float), 1e-9)[:, None]
        a_p = np.maximum(np.array([p.area for p in self.objects], float), 1e-9)[None, :]
        if self.max_area_diff is not None:
            ok &= np.abs(a_c - a_p) < self.max_area_diff
        if self.max_area_ratio is not None:
            ok &= np.maximum(a_c, a_p) <= self.max_area_ratio * np.minimum(a_c, a_p)
        ci, pi = np.nonzero(ok)
        order = np.argsort(dist[ci, pi], kind="stable")
        return [(int(ci[k]), int(pi[k])) for k in order]

    def _at_edge(self, p: PersistentObject, frame_size: tuple[int, int] | None) -> bool:
        if frame_size is None or self.edge_margin is None:
            return False
        width, height = frame_size
        x, y, w, h = p.bbox
        m = self.edge_margin
        return x <= m or y <= m or x + w >= width - m or y + h >= height - m

    def update_frame(
        self,
        detections: Sequence[Detection],
        frame_size: tuple[int, int] | None = None,
        blind: Callable[[float, float], bool] | None = None,
    ) -> list[PersistentObject]:
        """One call of ``persistentObjectFilter`` with this frame's blobs ``C``; returns ``Q``.

        ``frame_size = (width, height)`` enables the border rule; ``blind(u, v)`` says whether the
        detector could see pixel ``(u, v)`` in this frame (see the module docstring)."""
        for p in self.objects:
            p.found_this_frame = False
            if self._predicts:  # predict (extension)
                p.x = (p.x[0] + p.velocity[0], p.x[1] + p.velocity[1])
        # (d): greedy one-to-one association, nearest pairs first, over pre-existing objects only.
        used_c: set[int] = set()
        for ci, pi in self._pairs(detections):
            p = self.objects[pi]
            if ci in used_c or p.found_this_frame:
                continue
            used_c.add(ci)
            c = detections[ci]
            p.found_this_frame = True
            p.frame_count = min(p.frame_count + 1, self.max_count)
            if self._predicts:
                # p.x was advanced by (frames_missed + 1) velocity steps since the last match.
                steps = p.frames_missed + 1
                last = (p.x[0] - steps * p.velocity[0], p.x[1] - steps * p.velocity[1])
                measured = ((c.center[0] - last[0]) / steps, (c.center[1] - last[1]) / steps)
                g = 1.0 if p.matches == 1 else self.velocity_gain
                p.velocity = tuple(v + g * (m - v) for v, m in zip(p.velocity, measured, strict=True))
            p.matches += 1
            p.frames_missed = 0
            if self.update:  # (b)
                p.x, p.area, p.bbox = c.center, c.area, c.bbox
        new = [
            # (a): a new object counts as found in the frame that created it.
            PersistentObject(id=next(self._ids), x=c.center, area=c.area, bbox=c.bbox)
            for ci, c in enumerate(detections)
            if ci not in used_c
        ]
        kept = []
        for p in self.objects:
            if not p.found_this_frame:
                p.frames_missed += 1
                if blind is not None and p.frames_blind < self.max_blind and blind(*p.x):
                    p.frames_blind += 1  # not observed: keep the count
                else:
                    p.frame_count = 0 if self._at_edge(p, frame_size) else p.frame_count - 1
            else:
                p.frames_blind = 0
            if p.frame_count > 0:  # (e): rebuild rather than pop while iterating
                kept.append(p)
        self.objects = kept + new
        return self.confirmed()

    def confirmed(self) -> list[PersistentObject]:
        """``Q = {p ∈ P : p.frame_count ≥ min_count}`` — fix (c)."""
        return [p for p in self.objects if p.frame_count >= self.min_count]


@dataclass
class PersistentDetector:
    """A detector followed by a :class:`PersistentObjectFilter`, with the same ``detect`` interface.

    The detections reported are the confirmed persistent objects (last matched or predicted
    position; score =
    ``frame_count / max_count``). A rejected frame counts as a frame with no blobs, so the objects
    of a camera that keeps sending garbage fade out (after ``max_blind`` frames: a rejected frame
    observed nothing, like a blind row); its ``error`` is passed through.
    ``report_hidden=False`` reports only objects matched in this very frame."""

    detector: object
    filter: PersistentObjectFilter = field(default_factory=PersistentObjectFilter)
    report_hidden: bool = True

    @property
    def rejected(self):
        return self.detector.rejected

    def detect(self, frame: object) -> DetectionResult:
        raw = self.detector.detect(frame)
        if raw.error is not None:
            blind = lambda u, v: True  # noqa: E731 - a rejected frame observed nothing
        else:
            blind = (lambda u, v: raw.is_blind(v)) if raw.blind_rows is not None else None
        confirmed = self.filter.update_frame(raw.detections, raw.frame_size, blind)
        out = [
            Detection(center=p.x, area=p.area, bbox=p.bbox, score=p.frame_count / self.filter.max_count)
            for p in confirmed
            if self.report_hidden or p.found_this_frame
        ]
        return DetectionResult(out, mask=raw.mask, error=raw.error, scale=raw.scale, size=raw.size)
