"""Video stream quality D(t) (thesis 000 §2.4, Eqs. 2.1–2.4).

A failing analog video link shows rapidly alternating horizontal dark and light bands. Convolving
the image with a horizontal-edge kernel makes them stand out:

    K = [[1, 1, 1], [0, 0, 0], [-1, -1, -1]]          (2.1; row 1 reconstructed, spec 000 §2.4)
    P = I ⊗ K                                          (2.2)
    d(P) = Σ_ij |P_ij|                                 (2.3)
    D(t) = (1/k) Σ_{last k frames} d(P_τ)              (2.4; the last k frames, spec 000 §2.4)

Choices made here (the thesis leaves them open, spec 000 §2.4 and §6 item 9):

* ``I`` is the grayscale frame downsampled to the detector's 320×240 (before equalisation, which
  would amplify the noise of a dark but healthy picture);
* ``d`` is normalised per pixel and by the largest possible response (3·255), so
  ``d ∈ [0, 1]`` whatever the resolution: clean imagery gives ~0.01, analog "snow" ~0.2;
* ``k = 10`` frames (2 s at the 5 Hz agent rate) and the failure threshold ``D > 0.15``
  (measured on the synthetic camera at 640×480 and 320×240: clean ≈ 0.02, banding in half the
  frames ≈ 0.08–0.11 — degraded, weight < 1 — and a failed link: snow ≈ 0.19, bands only ≈ 0.28,
  black = 1);
* a frame that carries no picture (a dark or flat frame: mean < ``blank_mean`` or standard
  deviation < ``blank_std``) and a frame rejected by :func:`~perception.frames.check_frame` count
  as ``d = 1`` (an extension: the thesis measure would call a black frame "clear video");
* ``weight()`` maps D linearly to a measurement weight ``w ∈ [0, 1]`` (1 at ``good_level``, 0 at
  the threshold) for the pseudo-intersection weights of spec 000 §1.3 (not in the thesis).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import cv2
import numpy as np

from perception.frames import FrameError, RejectCounter, check_frame, to_gray

__all__ = ["EDGE_KERNEL", "QualityReport", "VideoQuality", "banding_measure", "noisy_rows", "blind_rows"]

#: Eq. (2.1), row 1 reconstructed as ``[1 1 1]``.
EDGE_KERNEL = np.array([[1, 1, 1], [0, 0, 0], [-1, -1, -1]], dtype=np.float32)
_MAX_RESPONSE = 3.0 * 255.0


def banding_measure(gray: np.ndarray) -> float:
    """Eqs. (2.2)–(2.3) normalised: ``Σ|I ⊗ K| / (n_x n_y · 3 · 255)`` on a uint8 grayscale image.

    ``cv2.filter2D`` computes a correlation; for this kernel a convolution only flips the sign of
    ``P``, which ``|·|`` removes. Borders are replicated (no response from the frame edge)."""
    response = cv2.filter2D(gray, cv2.CV_16S, EDGE_KERNEL, borderType=cv2.BORDER_REPLICATE)
    return float(cv2.norm(response, cv2.NORM_L1)) / (gray.size * _MAX_RESPONSE)


def noisy_rows(gray: np.ndarray, threshold: float = 0.05, window: int = 9) -> np.ndarray:
    """Rows of ``gray`` inside a banding episode: bool array of length ``height``.

    The row-wise version of Eq. (2.3): ``|I ⊗ K|`` averaged along each row (normalised as in
    :func:`banding_measure`), then over ``window`` rows, above ``threshold`` (chosen here: 0.05,
    window 9 rows at 240 lines). A single horizontal edge (a grout line, a target's rim) is one or
    two rows and does not fill the window; alternating bands do. Extension: the thesis measures
    the whole frame only."""
    response = cv2.filter2D(gray, cv2.CV_16S, EDGE_KERNEL, borderType=cv2.BORDER_REPLICATE)
    per_row = cv2.reduce(np.abs(response).astype(np.float32), 1, cv2.REDUCE_AVG)[:, 0] / _MAX_RESPONSE
    smoothed = np.convolve(per_row, np.ones(window, np.float32) / window, mode="same")
    noisy = smoothed > threshold
    # Grow by half a window so that band edges are covered too.
    return np.convolve(noisy.astype(np.float32), np.ones(window, np.float32), mode="same") > 0


def blind_rows(
    gray: np.ndarray, threshold: float = 0.05, work_height: int = 240, frame_height: int | None = None
) -> np.ndarray:
    """:func:`noisy_rows` of a grayscale frame of any size, measured at ``work_height`` lines
    (INTER_AREA) and returned per row of a frame of ``frame_height`` rows (default: the input's, but
    ``gray`` may be the whole frame at a lower resolution)."""
    height, width = gray.shape
    frame_height = height if frame_height is None else frame_height
    small = gray
    if height != work_height:
        size = (max(1, round(width * work_height / height)), work_height)
        small = cv2.resize(gray, size, interpolation=cv2.INTER_AREA)
    rows = noisy_rows(small, threshold)
    if frame_height == work_height:
        return rows
    index = np.clip(
        ((np.arange(frame_height) + 0.5) * work_height / frame_height - 0.5).round().astype(int), 0, work_height - 1
    )
    return rows[index]


@dataclass(frozen=True)
class QualityReport:
    """``d``: this frame's normalised measure; ``D``: the running mean; ``failed``: ``D > threshold``;
    ``error``: the frame rejection reason, if any; ``blank``: the frame carried no picture."""

    d: float
    D: float
    failed: bool
    error: str | None = None
    blank: bool = False


@dataclass
class VideoQuality:
    """Running video-quality estimate D(t) for one camera (thesis 000 §2.4)."""

    k: int = 10  # chosen here: frames in the running mean (2 s at 5 Hz)
    threshold: float = 0.15  # chosen here: D above this flags a failed link / camera
    good_level: float = 0.03  # chosen here: D at or below this gives weight 1
    work_size: tuple[int, int] | None = (320, 240)  # (width, height) of the image I; None = as given
    blank_mean: float = 12.0  # chosen here: a frame darker than this on average carries no picture
    blank_std: float = 1.5  # chosen here: a frame flatter than this carries no picture
    history: deque = field(default_factory=deque, repr=False)
    rejected: RejectCounter = field(default_factory=RejectCounter)

    def __post_init__(self) -> None:
        if self.k < 1:
            raise ValueError("k must be ≥ 1")
        self.history = deque(self.history, maxlen=self.k)

    def frame_measure(self, frame: object) -> tuple[float, str | None, bool]:
        """``(d, error, blank)`` for one frame, without touching the running mean."""
        try:
            image = check_frame(frame, dtypes=(np.uint8,), channels=(1, 3))
        except FrameError as exc:
            return 1.0, self.rejected.record(exc), False
        gray = to_gray(image)
        if self.work_size is not None and gray.shape[::-1] != tuple(self.work_size):
            gray = cv2.resize(gray, tuple(self.work_size), interpolation=cv2.INTER_AREA)
        mean, std = cv2.meanStdDev(gray)
        if float(mean[0, 0]) < self.blank_mean or float(std[0, 0]) < self.blank_std:
            return 1.0, None, True
        return banding_measure(gray), None, False

    def update(self, frame: object) -> QualityReport:
        """Add one frame and return D(t) over the last ``k`` frames (Eq. 2.4)."""
        d, error, blank = self.frame_measure(frame)
        self.history.append(d)
        D = float(np.mean(self.history))
        return QualityReport(d=d, D=D, failed=D > self.threshold, error=error, blank=blank)

    @property
    def D(self) -> float:
        """Current D(t); 0 before any frame (no evidence of a bad link)."""
        return float(np.mean(self.history)) if self.history else 0.0

    @property
    def failed(self) -> bool:
        return self.D > self.threshold

    def weight(self) -> float:
        """Measurement weight in [0, 1]: 1 for ``D ≤ good_level``, 0 for ``D ≥ threshold``."""
        span = self.threshold - self.good_level
        return float(np.clip((self.threshold - self.D) / span, 0.0, 1.0)) if span > 0 else float(not self.failed)
