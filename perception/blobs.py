"""Blob detectors: colour blobs in HSV (Ross et al.) and dark blobs (thesis 000 §2.2).

* :class:`ColorBlobDetector` — Ross et al., spec 002 §2.1: RGB -> HSV, keep pixels with
  ``H_min ≤ H ≤ H_max`` and ``S ≥ S_min`` (and ``V ≥ V_min``), dilate, label connected regions,
  keep blobs that pass size / aspect / fill / solidity / circularity filters. Red straddles hue 0
  (OpenCV hue runs 0..179, i.e. degrees / 2), so a hue band with ``h_min > h_max`` is split into
  two intervals ``[h_min, 179] ∪ [0, h_max]`` — the wrap-around the paper does not mention.
  :func:`pair_detections` is step 6 (two balls of similar size at a given separation).
* :class:`DarkBlobDetector` — thesis 000 §2.2 ``processRawFrame``: grayscale, downsample
  640×480 -> 320×240, histogram equalisation, binary threshold (targets darker than the floor),
  8-connected blobs with number, area and location.

Both validate each frame (:func:`perception.frames.check_frame`); a rejected frame gives an empty
:class:`~perception.detection.DetectionResult` with ``error`` set and is counted in ``rejected``.
Frames are RGB uint8 (grayscale accepted by the dark-blob detector).

Both also take a frame drawn in parts (:class:`~perception.roi_frame.RoiFrame`, from
:func:`perception.roi_render.render_roi`) and run the same steps where it was drawn: the colour detector in its
full-resolution windows, the dark detector in its preview — the whole view at the working size, checked for
contrast and equalised whole as a downsampled frame is — cut to the windows; the banding rows are read on the
preview. Detections are in frame pixels either way.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from perception.detection import Detection, DetectionResult, ShapeFilter, blobs_from_mask
from perception.frames import FrameError, RejectCounter, check_frame, to_gray
from perception.quality import blind_rows
from perception.roi_frame import RoiFrame

__all__ = [
    "HsvRange",
    "red_range",
    "ColorBlobDetector",
    "DarkBlobDetector",
    "pair_detections",
]

_HUE_MAX = 179  # OpenCV 8-bit hue: 0..179 (degrees / 2)


def _drop_blind(result: DetectionResult, gray: np.ndarray, threshold: float, frame_height: int | None = None) -> None:
    """Mark the rows of ``gray`` (the frame, or its preview for a frame of ``frame_height`` rows) inside a
    banding episode blind and drop the detections there."""
    rows = blind_rows(gray, threshold, frame_height=frame_height)
    result.blind_rows = rows if rows.any() else None
    result.drop_blind()


@dataclass(frozen=True)
class HsvRange:
    """A hue band ``[h_min, h_max]`` (OpenCV units, 0..179) with saturation / value bounds.

    ``h_min > h_max`` means the band wraps through 0 (red): see :meth:`intervals`."""

    h_min: int
    h_max: int
    s_min: int = 100  # chosen here: saturated colours only (Ross gives no value)
    v_min: int = 50  # chosen here: ignore near-black pixels, whose hue is meaningless
    s_max: int = 255
    v_max: int = 255

    def __post_init__(self) -> None:
        for name in ("h_min", "h_max"):
            if not 0 <= getattr(self, name) <= _HUE_MAX:
                raise ValueError(f"{name} must be in 0..{_HUE_MAX} (OpenCV hue), got {getattr(self, name)}")

    @property
    def wraps(self) -> bool:
        return self.h_min > self.h_max

    def intervals(self, wrap: bool = True) -> list[tuple[np.ndarray, np.ndarray]]:
        """``(lower, upper)`` bounds for ``cv2.inRange``: two intervals for a wrapping band.

        With ``wrap=False`` a wrapping band is passed to ``inRange`` as one interval with
        ``lower > upper``, which matches nothing — the bug the two-interval logic avoids."""
        lo = (self.s_min, self.v_min)
        hi = (self.s_max, self.v_max)
        if self.wraps and wrap:
            return [
                (np.array([self.h_min, *lo], np.uint8), np.array([_HUE_MAX, *hi], np.uint8)),
                (np.array([0, *lo], np.uint8), np.array([self.h_max, *hi], np.uint8)),
            ]
        return [(np.array([self.h_min, *lo], np.uint8), np.array([self.h_max, *hi], np.uint8))]


def red_range(half_width: int = 8, s_min: int = 100, v_min: int = 50) -> HsvRange:
    """The red band ``[180 - half_width, half_width]`` (wraps through hue 0)."""
    return HsvRange((_HUE_MAX + 1 - half_width) % (_HUE_MAX + 1), half_width, s_min=s_min, v_min=v_min)


@dataclass
class ColorBlobDetector:
    """Colour filtering and blob shape tests (Ross et al., spec 002 §2.1).

    ``ranges`` is one :class:`HsvRange` or several (OR-ed). ``wrap=False`` reproduces the naive
    single-interval test for a band that crosses hue 0 (for comparison only). ``dilate`` is the
    number of 3×3 dilations (step 3, ``cvDilate``; chosen here: 1). ``shape`` holds the blob tests
    (areas in input pixels, since this detector works at full resolution). ``reject_banding`` is
    as for :class:`DarkBlobDetector` (extension): banding tears balls into pieces that pass for
    small balls."""

    ranges: HsvRange | Sequence[HsvRange] = field(default_factory=red_range)
    wrap: bool = True
    dilate: int = 1
    shape: ShapeFilter = field(
        default_factory=lambda: ShapeFilter(
            min_area=12.0, max_area=20000.0, max_aspect=2.0, min_fill=0.5, min_solidity=0.8
        )  # chosen here: ball-like blobs (a disc: aspect 1, fill 0.785, solidity ≈ 1)
    )
    expected_shape: tuple[int | None, ...] | None = None
    reject_banding: bool = True
    banding_row_threshold: float = 0.05
    rejected: RejectCounter = field(default_factory=RejectCounter)

    def _range_list(self) -> list[HsvRange]:
        return [self.ranges] if isinstance(self.ranges, HsvRange) else list(self.ranges)

    def mask(self, frame: np.ndarray) -> np.ndarray:
        """Steps 1-3: HSV threshold (two intervals for a wrapping band) and dilation."""
        hsv = cv2.cvtColor(frame, cv2.COLOR_RGB2HSV)
        out: np.ndarray | None = None
        for band in self._range_list():
            for lower, upper in band.intervals(self.wrap):
                m = cv2.inRange(hsv, lower, upper)
                out = m if out is None else cv2.bitwise_or(out, m)
        assert out is not None
        if self.dilate > 0:
            out = cv2.dilate(out, np.ones((3, 3), np.uint8), iterations=self.dilate)
        return out

    def blobs(self, image: np.ndarray) -> list[Detection]:
        """Steps 1-5 on an RGB image: the blobs of :meth:`mask` that pass the shape tests."""
        return blobs_from_mask(self.mask(image), self.shape)

    def detect(self, frame: object) -> DetectionResult:
        """Blobs of an RGB frame, or of the windows of a :class:`~perception.roi_frame.RoiFrame` (its banding
        rows from its preview)."""
        if isinstance(frame, RoiFrame):
            result = DetectionResult(frame.detections(frame.windows, lambda w: self.blobs(w.image)), size=frame.size)
            gray, height = to_gray(frame.preview), frame.height
        else:
            try:
                image = check_frame(frame, self.expected_shape, dtypes=(np.uint8,), channels=(3,))
            except FrameError as exc:
                return DetectionResult(error=self.rejected.record(exc))
            mask = self.mask(image)
            result = DetectionResult(blobs_from_mask(mask, self.shape), mask=mask)
            gray, height = to_gray(image), None
        if self.reject_banding:
            _drop_blind(result, gray, self.banding_row_threshold, height)
        return result


def pair_detections(
    detections: Sequence[Detection],
    separation_px: tuple[float, float],
    max_size_ratio: float = 1.5,
) -> list[tuple[int, int]]:
    """Ross et al. step 6: index pairs of blobs of similar size at a separation in ``separation_px``.

    Similar size means ``max(A_i, A_j) / min(A_i, A_j) ≤ max_size_ratio`` (chosen here: 1.5).
    Pairs are returned best first (closest size ratio)."""
    lo, hi = separation_px
    pairs: list[tuple[float, int, int]] = []
    for i, a in enumerate(detections):
        for j in range(i + 1, len(detections)):
            b = detections[j]
            ratio = max(a.area, b.area) / max(min(a.area, b.area), 1e-9)
            dist = float(np.hypot(a.center[0] - b.center[0], a.center[1] - b.center[1]))
            if lo <= dist <= hi and ratio <= max_size_ratio:
                pairs.append((ratio, i, j))
    return [(i, j) for _, i, j in sorted(pairs)]


@dataclass
class DarkBlobDetector:
    """Thesis 000 §2.2 ``processRawFrame`` (Figure 2-7).

    grayscale -> ``cv2.resize(work_size, INTER_AREA)`` (the downsampling method is not specified;
    area averaging chosen here) -> ``cv2.equalizeHist`` -> pixels ``≤ threshold`` are foreground
    (targets are darker than the floor) -> optional 3×3 opening (chosen here; removes the
    single-pixel specks that equalisation makes of sensor noise) -> 8-connected blobs.

    ``threshold`` is on the equalised image, so it is roughly the fraction of darkest pixels
    (× 255) that may become foreground (chosen here: 10, i.e. the darkest ~4 %). ``shape`` areas are
    in working pixels (320×240 by default; ``min_area`` 12 rejects the 3×3 dots that tile-grout
    crossings become inside dark bands). The thesis gives no blob filters at all; the aspect
    (≤ 2) and fill (≥ 0.5) tests are Ross-style additions, chosen here, that reject pieces of
    bands. Detections are in input-frame pixels.

    ``min_contrast`` (chosen here: 4 gray levels) guards the equalisation: on a frame whose
    working image has a smaller standard deviation (a black or flat frame) equalisation would turn
    sensor noise into "dark" blobs everywhere, so such a frame yields no detections.

    ``reject_banding`` (extension, chosen here: on) drops blobs that touch rows flagged by the
    row-wise banding measure :func:`perception.quality.noisy_rows` (threshold
    ``banding_row_threshold``): inside a banding episode a dark blob is more likely a piece of a
    band than a target, and a target hidden there is bridged by the persistent-object filter."""

    work_size: tuple[int, int] | None = (320, 240)  # (width, height); None = no downsampling
    threshold: int = 10
    open_size: int = 3
    shape: ShapeFilter = field(
        default_factory=lambda: ShapeFilter(min_area=12.0, max_area=2500.0, max_aspect=2.0, min_fill=0.5)
    )
    min_contrast: float = 4.0
    reject_banding: bool = True
    banding_row_threshold: float = 0.05
    expected_shape: tuple[int | None, ...] | None = None
    rejected: RejectCounter = field(default_factory=RejectCounter)

    def preprocess(self, frame: np.ndarray) -> tuple[np.ndarray, tuple[float, float]]:
        """Grayscale and downsample; returns the small gray image and input px per working px."""
        gray = to_gray(frame)
        h, w = gray.shape
        if self.work_size is None or (w, h) == tuple(self.work_size):
            return gray, (1.0, 1.0)
        ww, wh = self.work_size
        small = cv2.resize(gray, (ww, wh), interpolation=cv2.INTER_AREA)
        return small, (w / ww, h / wh)

    def binarise(self, small_gray: np.ndarray) -> np.ndarray:
        """Equalise and threshold (dark = 255)."""
        return self.foreground(cv2.equalizeHist(small_gray))

    def foreground(self, equalised: np.ndarray) -> np.ndarray:
        """Threshold an equalised image (dark = 255) and open it."""
        _, binary = cv2.threshold(equalised, self.threshold, 255, cv2.THRESH_BINARY_INV)
        if self.open_size > 1:
            kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (self.open_size, self.open_size))
            binary = cv2.morphologyEx(binary, cv2.MORPH_OPEN, kernel)
        return binary

    def detect(self, frame: object) -> DetectionResult:
        """Blobs of an RGB or gray frame, or of a :class:`~perception.roi_frame.RoiFrame`: its preview (the whole
        view at about the working size) is the working image — checked for contrast and equalised whole, as a
        downsampled frame is — and blobs are sought in its regions of interest."""
        if isinstance(frame, RoiFrame):
            image, height = frame.preview, frame.height
            small, _ = self.preprocess(image)
            scale = (frame.width / small.shape[1], frame.height / small.shape[0])
        else:
            try:
                image = check_frame(frame, self.expected_shape, dtypes=(np.uint8,), channels=(1, 3))
            except FrameError as exc:
                return DetectionResult(error=self.rejected.record(exc))
            height = image.shape[0]
            small, scale = self.preprocess(image)
        if float(cv2.meanStdDev(small)[1][0, 0]) < self.min_contrast:
            blind = np.ones(height, bool)  # no picture: nothing was observed
            return DetectionResult([], mask=np.zeros_like(small), scale=scale, blind_rows=blind)
        equalised = cv2.equalizeHist(small)
        if isinstance(frame, RoiFrame):
            found = frame.detections(
                frame.crops(equalised), lambda w: blobs_from_mask(self.foreground(w.image), self.shape, w.step)
            )
            result = DetectionResult(found, scale=scale, size=frame.size)
        else:
            binary = self.foreground(equalised)
            result = DetectionResult(blobs_from_mask(binary, self.shape, scale), binary, scale=scale)
        if self.reject_banding:
            _drop_blind(result, to_gray(image), self.banding_row_threshold, height)
        return result
