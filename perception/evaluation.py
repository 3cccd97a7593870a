"""Measured detection and false-alarm rates of the detectors on labelled synthetic frames.

* :func:`detection_rates` runs a detector over a sequence of frames and matches its detections to
  the true target pixels (greedy one-to-one, nearest first, within ``match_radius_px``):
  ``P_D = hits / visible targets`` and false alarms per frame = unmatched detections / frames.
* :func:`segmentation_rates` gives per-pixel ``P_D``, ``P_F`` and IoU of a fire segmenter.
* :func:`sequence` renders a labelled flight over targets (and fires) for both; the same scenes
  back the tests in ``tests/perception`` and the table printed by
  ``python -m mesh_sim.bench.detection_rates``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from perception.degradation import Degradation
from perception.pinhole import PinholeView
from perception.render import Fire, RenderedFrame, Smoke, Target, default_ground, render_frame

__all__ = [
    "DetectionRates",
    "SegmentationRates",
    "match",
    "detection_rates",
    "segmentation_rates",
    "sequence",
]


@dataclass(frozen=True)
class DetectionRates:
    """``p_d``: hits / visible targets; ``fa_per_frame``: false alarms / frame; ``p_fa_frame``:
    fraction of frames with at least one false alarm; counts; ``rejected``: frames refused."""

    p_d: float
    fa_per_frame: float
    p_fa_frame: float
    n_truth: int
    n_hits: int
    n_false: int
    n_frames: int
    rejected: int = 0

    def __iter__(self):
        """``p_d, fa_per_frame = detection_rates(...)`` unpacks the two headline numbers."""
        return iter((self.p_d, self.fa_per_frame))


@dataclass(frozen=True)
class SegmentationRates:
    """Per-pixel ``p_d``, ``p_f`` and IoU ``= TP / (TP + FP + FN)``, pooled over frames and over the
    observed pixels (rows the segmenter did not report blind); ``observed``: their fraction."""

    p_d: float
    p_f: float
    iou: float
    n_frames: int
    rejected: int = 0
    observed: float = 1.0


def match(detected: np.ndarray, truth: np.ndarray, radius: float, ignore: np.ndarray | None = None) -> tuple[int, int]:
    """Greedy one-to-one matching, nearest pairs first: ``(hits, false alarms)``.

    ``ignore`` rows ``(u, v, r)``: an unmatched detection within ``radius + r`` of one is not a
    false alarm (a target cut by the frame edge or hidden, see ``RenderedFrame.ignore_regions``)."""
    detected = np.asarray(detected, float).reshape(-1, 2)
    truth = np.asarray(truth, float).reshape(-1, 2)
    hits, used_d, used_t = 0, set(), set()
    if len(detected) and len(truth):
        d = np.linalg.norm(detected[:, None, :] - truth[None, :, :], axis=2)
        for flat in np.argsort(d, axis=None):
            i, j = divmod(int(flat), len(truth))
            if d[i, j] > radius:
                break
            if i in used_d or j in used_t:
                continue
            used_d.add(i)
            used_t.add(j)
            hits += 1
    false = 0
    for i in range(len(detected)):
        if i in used_d:
            continue
        if ignore is not None and len(ignore):
            gap = np.linalg.norm(ignore[:, :2] - detected[i], axis=1) - ignore[:, 2]
            if np.any(gap <= radius):
                continue
        false += 1
    return hits, false


def _truth(label) -> tuple[np.ndarray, np.ndarray | None]:
    if isinstance(label, RenderedFrame):
        return label.visible_centers(), label.ignore_regions()
    return np.asarray(label, float).reshape(-1, 2), None


def detection_rates(
    detector,
    frames: Sequence,
    labels: Sequence,
    match_radius_px: float = 10.0,
    warmup: int = 0,
) -> DetectionRates:
    """Run ``detector.detect`` on every frame, in order; score all frames after ``warmup``.

    ``labels[i]`` is a :class:`~perception.render.RenderedFrame` (its visible targets) or an
    ``(n, 2)`` array of true pixel centres. Detections on targets that are drawn but not visible
    (cut by the frame edge, occluded, in smoke) are ignored. A frame the detector rejects counts as a frame with no
    detections (its targets are missed)."""
    if len(frames) != len(labels):
        raise ValueError("need one label per frame")
    n_truth = n_hits = n_false = frames_with_fa = rejected = 0
    scored = 0
    for k, (frame, label) in enumerate(zip(frames, labels, strict=True)):
        result = detector.detect(frame)
        rejected += result.error is not None
        if k < warmup:
            continue
        truth, ignore = _truth(label)
        hits, false = match(result.centers(), truth, match_radius_px, ignore)
        n_truth += len(truth)
        n_hits += hits
        n_false += false
        frames_with_fa += false > 0
        scored += 1
    return DetectionRates(
        p_d=n_hits / n_truth if n_truth else math.nan,
        fa_per_frame=n_false / scored if scored else math.nan,
        p_fa_frame=frames_with_fa / scored if scored else math.nan,
        n_truth=n_truth,
        n_hits=n_hits,
        n_false=n_false,
        n_frames=scored,
        rejected=rejected,
    )


def segmentation_rates(segmenter, frames: Sequence, masks: Sequence) -> SegmentationRates:
    """Per-pixel rates of ``segmenter.segment`` against true masks (a rejected frame predicts
    nothing; rows the segmenter reports blind are left out)."""
    tp = fp = pos = neg = 0
    rejected, seen, total = 0, 0, 0
    for frame, truth in zip(frames, masks, strict=True):
        truth = np.asarray(truth, bool)
        result = segmenter.segment(frame)
        pred = result.mask if result.mask is not None else np.zeros_like(truth)
        rejected += result.error is not None
        total += truth.size
        blind = getattr(result, "blind_rows", None)
        if blind is not None:
            pred, truth = pred[~blind], truth[~blind]
        seen += truth.size
        tp += int(np.count_nonzero(pred & truth))
        fp += int(np.count_nonzero(pred & ~truth))
        pos += int(np.count_nonzero(truth))
        neg += truth.size - int(np.count_nonzero(truth))
    return SegmentationRates(
        p_d=tp / pos if pos else math.nan,
        p_f=fp / neg if neg else math.nan,
        iou=tp / (pos + fp) if pos + fp else math.nan,
        n_frames=len(masks),
        rejected=rejected,
        observed=seen / total if total else math.nan,
    )


def sequence(
    n_frames: int,
    width: int = 640,
    height: int = 480,
    style: str = "tiles",
    n_targets: int = 3,
    target_rgb: tuple[int, int, int] = (28, 28, 32),
    target_radius_m: float = 0.5,
    n_fires: int = 0,
    altitude_m: float = 30.0,
    speed_m_per_frame: float = 0.4,
    smoke_opacity: float = 0.0,
    degradation: Degradation | None = None,
    seed: int = 0,
    rgb: bool = True,
    thermal: bool = True,
) -> list[RenderedFrame]:
    """A nadir camera (60° HFOV) flying north over ``n_targets`` balls and ``n_fires`` fire cells.

    Targets and fires are placed at random inside the footprint of the middle frame (seeded), so
    they stay in view for most of the flight and slide through the image as the camera moves.
    ``smoke_opacity > 0`` puts a smoke puff over each fire, drifting east with the wind."""
    rng = np.random.default_rng(seed)
    ground = default_ground(style, 0.05 if style == "tiles" else 0.25)
    hfov = math.radians(60.0)
    half_w = altitude_m * math.tan(hfov / 2.0)
    half_h = half_w * height / width
    north0 = -0.5 * speed_m_per_frame * n_frames
    targets = [
        Target(
            (rng.uniform(-0.7, 0.7) * half_h, rng.uniform(-0.8, 0.8) * half_w, -target_radius_m),
            target_radius_m,
            target_rgb,
        )
        for _ in range(n_targets)
    ]
    fires = [
        Fire(
            (rng.uniform(-0.6, 0.6) * half_h, rng.uniform(-0.7, 0.7) * half_w),
            rng.uniform(2.0, 5.0),
            rng.uniform(650.0, 1000.0),
        )
        for _ in range(n_fires)
    ]
    plumes = [(f.region[0], f.region[1], f.size_m) for f in fires]
    frames = []
    for k in range(n_frames):
        smoke = (
            [
                Smoke((n + 0.3 * size, e + size * (0.4 + 0.05 * k % 1.0), -size), 1.2 * size, smoke_opacity)
                for n, e, size in plumes
            ]
            if smoke_opacity > 0
            else []
        )
        eye = (north0 + k * speed_m_per_frame, 0.0, -altitude_m)
        view = PinholeView.look_at(eye, (eye[0], eye[1], 0.0), width, height, hfov)
        frames.append(
            render_frame(
                view,
                width,
                height,
                targets,
                fires,
                smoke,
                ground=ground,
                degradation=degradation,
                seed=int(rng.integers(1 << 31)),
                rgb=rgb,
                thermal=thermal,
            )
        )
    return frames
