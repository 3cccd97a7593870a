"""Fire segmentation into a binary mask (Merino, spec 001b Appendix B, §2.10).

* ``mode="threshold"`` — thermal images: a temperature threshold ("thermal cameras: a
  temperature threshold"). Frames are float Kelvin (or uint8 / uint16 counts). The ANFIS-supervised
  multiresolution histogram thresholding Merino uses for non-radiometric IR is replaced by this
  simpler stand-in, which spec 001b §7 allows. :meth:`FireSegmenter.fit` can pick the threshold
  that minimises the pixel classification error on labelled frames.
* ``mode="histogram"`` — visual RGB images: a trained colour histogram (Alg. B.1). Alg. B.1
  accumulates Gaussians ``N(c, Σ_true)`` at fire-pixel colours and subtracts smaller Gaussians
  ``N(c, Σ_false)`` at background colours, then thresholds the histogram into a binary RGB look-up
  table with the threshold "chosen iteratively to minimise classification error". Adding a
  Gaussian at every sample is a convolution of the count histogram with that Gaussian, so here

      p(c | fire) ∝ G_true * H_fire,   p(c | background) ∝ G_false * H_background
      fire  ⇔  log p(c | fire) − log p(c | background) > τ

  (a likelihood-ratio form of the same rule: Alg. B.1's ``h > th`` is ``N_f p_f − N_b p_b > th``),
  with ``τ`` chosen to minimise the number of misclassified training pixels. ``Σ``, the bin size
  and the training data are not given in the source: 32 bins per channel, ``σ_true = 1`` bin and
  ``σ_false = 0.5`` bin are chosen here.

Both modes end with a binary clean-up (3×3 opening then closing, chosen here; Merino's Ch. 6
pipeline removes spurious pixels and fills holes). :meth:`FireSegmenter.roc` gives the per-pixel
ROC on labelled frames; the measured ``(P_D, P_F)`` feed the likelihoods of (B.5).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

from perception.frames import FrameError, RejectCounter, check_frame
from perception.quality import blind_rows

__all__ = ["FireSegmenter", "SegmentationResult", "pixel_rates"]


@dataclass(frozen=True)
class SegmentationResult:
    """``mask``: bool H×W fire mask (``None`` for a rejected frame); ``error``: rejection reason;
    ``blind_rows``: bool per row where the image could not be read (banding), or ``None`` — no
    fire is reported there, and a fire-map update should treat those pixels as unobserved."""

    mask: np.ndarray | None
    error: str | None = None
    blind_rows: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


def pixel_rates(predicted: np.ndarray, truth: np.ndarray) -> tuple[float, float, float]:
    """Per-pixel ``(P_D, P_F, IoU)`` of a predicted mask against a true mask (both bool H×W)."""
    predicted = np.asarray(predicted, bool)
    truth = np.asarray(truth, bool)
    tp = np.count_nonzero(predicted & truth)
    fp = np.count_nonzero(predicted & ~truth)
    pos = np.count_nonzero(truth)
    neg = truth.size - pos
    union = np.count_nonzero(predicted | truth)
    return (
        tp / pos if pos else float("nan"),
        fp / neg if neg else float("nan"),
        tp / union if union else 1.0,
    )


def _min_error_threshold(scores: np.ndarray, pos: np.ndarray, neg: np.ndarray, prefer: float | None = None) -> float:
    """Threshold τ on ``scores`` minimising ``#pos(score ≤ τ) + #neg(score > τ)``.

    ``pos`` / ``neg`` are the class counts at each score value (weights). The error is constant
    between consecutive distinct scores; among the minimising intervals the threshold is the
    point closest to ``prefer`` (e.g. the Bayes threshold), else the middle of the first."""
    order = np.argsort(scores, kind="stable")
    s, p, n = scores[order], pos[order], neg[order]
    last = np.concatenate([np.flatnonzero(np.diff(s) > 0), [s.size - 1]])  # last index of each value
    values = s[last]
    missed = np.concatenate([[0.0], np.cumsum(p)[last]])  # fire at or below τ, τ in interval i
    false = n.sum() - np.concatenate([[0.0], np.cumsum(n)[last]])
    errors = missed + false
    # Interval i is [values[i-1], values[i]) with values[-1] = -inf and values[len] = +inf.
    lo = np.concatenate([[-np.inf], values])
    hi = np.concatenate([values, [np.inf]])
    best = np.flatnonzero(errors <= errors.min() + 1e-9)
    if prefer is not None:
        candidates = np.clip(prefer, lo[best], np.nextafter(hi[best], -np.inf))
        return float(candidates[np.argmin(np.abs(candidates - prefer))])
    i = best[0]
    if np.isinf(lo[i]):
        return float(hi[i]) - 1.0
    if np.isinf(hi[i]):
        return float(lo[i])
    return float(0.5 * (lo[i] + hi[i]))


@dataclass
class FireSegmenter:
    """Thermal threshold or trained colour-histogram fire segmentation (Merino App. B).

    ``threshold_K`` (thermal mode; chosen here: 420 K, between sun-heated ground ≈ 330 K and flames
    ≥ 600 K) is used until :meth:`fit` replaces it. In histogram mode :meth:`fit` is required.
    ``reject_banding`` (histogram mode; extension, chosen here: on): rows flagged by the row-wise
    banding measure (:func:`perception.quality.blind_rows`) are reported blind and cleared, since
    bright bands turn straw and soil into flame colours. Thermal thresholds are not fooled by
    banding (its amplitude is tens of kelvin against hundreds), so thermal frames are not checked."""

    mode: str = "threshold"
    threshold_K: float = 420.0
    bins: int = 32
    sigma_true: float = 1.0
    sigma_false: float = 0.5
    clean_size: int = 3
    reject_banding: bool = True
    banding_row_threshold: float = 0.05
    expected_shape: tuple[int | None, ...] | None = None
    log_lr: np.ndarray | None = field(default=None, repr=False)  # bins³ table
    tau: float = 0.0
    train_rates: tuple[float, float] | None = None  # (P_D, P_F) per pixel on the training frames
    rejected: RejectCounter = field(default_factory=RejectCounter)

    def __post_init__(self) -> None:
        if self.mode not in ("threshold", "histogram"):
            raise ValueError(f"mode must be 'threshold' or 'histogram', got {self.mode!r}")
        if 256 % self.bins or self.bins > 256:
            raise ValueError("bins must divide 256")
        self._shift = int(np.log2(256 // self.bins))
        self._lut: np.ndarray | None = None

    # -- validation -----------------------------------------------------------------------------
    def _check(self, frame: object) -> np.ndarray:
        if self.mode == "threshold":
            return check_frame(
                frame, self.expected_shape, dtypes=(np.float32, np.float64, np.uint8, np.uint16), channels=(1,)
            )
        return check_frame(frame, self.expected_shape, dtypes=(np.uint8,), channels=(3,))

    # -- histogram classifier -------------------------------------------------------------------
    def _indices(self, image: np.ndarray) -> np.ndarray:
        """Flat histogram-bin index ``(r·B + g)·B + b`` of every pixel."""
        r, g, bl = (np.right_shift(c, self._shift) for c in cv2.split(image))
        if self.bins == 32:  # fast path in uint16 (32³ = 2¹⁵ bins)
            r16, g16, b16 = (c.astype(np.uint16) for c in (r, g, bl))
            return cv2.add(cv2.add(np.left_shift(r16, 10), np.left_shift(g16, 5)), b16)
        return (r.astype(np.int32) * self.bins + g) * self.bins + bl

    def fit(self, images: Sequence[np.ndarray], masks: Sequence[np.ndarray]) -> FireSegmenter:
        """Train on labelled frames (``masks``: bool, True = fire); sets the min-error threshold and
        ``train_rates`` = per-pixel ``(P_D, P_F)`` on the training pixels (before clean-up; measure
        held-out rates with :func:`perception.evaluation.segmentation_rates`)."""
        if len(images) == 0 or len(images) != len(masks):
            raise ValueError("need as many masks as images, and at least one")
        if self.mode == "threshold":
            values = np.concatenate([self._check(im).astype(np.float64).ravel() for im in images])
            labels = np.concatenate([np.asarray(m, bool).ravel() for m in masks])
            uniq, inv = np.unique(np.round(values, 1), return_inverse=True)
            pos = np.bincount(inv, weights=labels, minlength=uniq.size)
            neg = np.bincount(inv, weights=~labels, minlength=uniq.size)
            self.threshold_K = _min_error_threshold(uniq, pos, neg)
            above = uniq > self.threshold_K
            self.train_rates = (pos[above].sum() / max(pos.sum(), 1), neg[above].sum() / max(neg.sum(), 1))
            return self
        nb = self.bins**3
        h_fire = np.zeros(nb)
        h_back = np.zeros(nb)
        for image, mask in zip(images, masks, strict=True):
            idx = self._indices(self._check(image)).ravel()
            m = np.asarray(mask, bool).ravel()
            if m.shape != idx.shape:
                raise ValueError("mask and image sizes differ")
            h_fire += np.bincount(idx[m], minlength=nb)
            h_back += np.bincount(idx[~m], minlength=nb)
        if h_fire.sum() == 0 or h_back.sum() == 0:
            raise ValueError("training data need both fire and background pixels")
        shape = (self.bins,) * 3
        p_fire = gaussian_filter(h_fire.reshape(shape), self.sigma_true, mode="nearest").ravel()
        p_back = gaussian_filter(h_back.reshape(shape), self.sigma_false, mode="nearest").ravel()
        # A small probability floor (chosen here) keeps the ratio finite; a colour seen in neither
        # class gets LR = 1, below the Bayes threshold, i.e. background.
        floor = 1e-9
        p_fire = p_fire / p_fire.sum() + floor
        p_back = p_back / p_back.sum() + floor
        self.log_lr = np.log(p_fire) - np.log(p_back)
        # Ties (perfectly separated training colours) are broken toward the Bayes threshold
        # log(N_background / N_fire).
        self.tau = _min_error_threshold(self.log_lr, h_fire, h_back, prefer=float(np.log(h_back.sum() / h_fire.sum())))
        self.set_tau(self.tau)
        fire = self.log_lr > self.tau
        self.train_rates = (h_fire[fire].sum() / h_fire.sum(), h_back[fire].sum() / h_back.sum())
        return self

    def set_tau(self, tau: float) -> None:
        """Change the log-likelihood-ratio threshold (e.g. to move along the ROC)."""
        if self.log_lr is None:
            raise RuntimeError("fit() the histogram classifier first")
        self.tau = float(tau)
        self._lut = np.where(self.log_lr > self.tau, 255, 0).astype(np.uint8)

    def score(self, frame: np.ndarray) -> np.ndarray:
        """Per-pixel score: temperature (threshold mode) or log-likelihood ratio (histogram mode)."""
        image = self._check(frame)
        if self.mode == "threshold":
            return image.astype(np.float32, copy=False)
        if self.log_lr is None:
            raise RuntimeError("fit() the histogram classifier first")
        return self.log_lr[self._indices(image)]

    # -- segmentation ---------------------------------------------------------------------------
    def _clean(self, binary: np.ndarray) -> np.ndarray:
        if self.clean_size > 1:
            kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (self.clean_size, self.clean_size))
            binary = cv2.morphologyEx(binary, cv2.MORPH_OPEN, kernel)
            binary = cv2.morphologyEx(binary, cv2.MORPH_CLOSE, kernel)
        return binary

    def segment(self, frame: object) -> SegmentationResult:
        """Binary fire mask of one frame; a bad frame gives ``mask=None`` and a counted reason."""
        try:
            image = self._check(frame)
        except FrameError as exc:
            return SegmentationResult(None, self.rejected.record(exc))
        if self.mode == "threshold":
            image = image[:, :, 0] if image.ndim == 3 else image
            binary = (image > self.threshold_K).astype(np.uint8) * 255
        else:
            if self._lut is None:
                raise RuntimeError("fit() the histogram classifier first")
            binary = np.take(self._lut, self._indices(image))
        mask = self._clean(binary) > 0
        rows = None
        if self.mode == "histogram" and self.reject_banding:
            rows = blind_rows(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY), self.banding_row_threshold)
            if rows.any():
                mask[rows] = False
            else:
                rows = None
        return SegmentationResult(mask, blind_rows=rows)

    def roc(self, images: Sequence[np.ndarray], masks: Sequence[np.ndarray], n: int = 21):
        """Per-pixel ROC (no clean-up): ``(thresholds, P_D, P_F)`` at the ``n`` quantiles of the
        fire scores and of the background scores (up to ``2n`` thresholds, increasing)."""
        scores = np.concatenate([self.score(im).ravel() for im in images])
        truth = np.concatenate([np.asarray(m, bool).ravel() for m in masks])
        pos, neg = truth.sum(), (~truth).sum()
        s_fire, s_back = np.sort(scores[truth]), np.sort(scores[~truth])
        q = np.linspace(0.0, 1.0, n)
        parts = [np.quantile(x, q) for x in (s_fire, s_back) if x.size]
        thresholds = np.unique(np.concatenate(parts)) if parts else np.zeros(1)
        p_d = 1.0 - np.searchsorted(s_fire, thresholds, side="right") / max(pos, 1)
        p_f = 1.0 - np.searchsorted(s_back, thresholds, side="right") / max(neg, 1)
        return thresholds, p_d, p_f
