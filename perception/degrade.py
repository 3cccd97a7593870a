"""Apply a :class:`~perception.degradation.Degradation` to a synthetic frame, in place (OpenCV), whole or in
parts (the ROI camera draws the noise, bands and speckles of a frame window by window).

The effects and their parameters are described in :mod:`perception.degradation`, which holds only the
plain descriptions (no OpenCV), so that configurations can be read without loading OpenCV: an agent with
the geometric bearing sensor never renders a frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from perception.degradation import Degradation, DegradationInfo

__all__ = [
    "Speckle",
    "add_rgb_noise",
    "banding_episode",
    "degrade",
    "draw_speckles",
    "noise_offset",
    "plan_speckles",
]

_PAD = 32


def _frozen(a: np.ndarray) -> np.ndarray:
    """Cached banks are shared by every camera: make them read-only."""
    a.setflags(write=False)
    return a


@lru_cache(maxsize=16)
def _rgb_noise(width: int, height: int, sigma: float, average: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Positive and negative parts of a Gaussian noise bank (uint8, padded for random offsets; each part keeps
    the whole gray levels of its draws). ``average`` > 1: the bank of frames ``average`` times larger, each value
    the rounded mean of ``average``×``average`` of its values, as ``cv2.INTER_AREA`` averages a frame's noise down
    to this size (standard deviation ÷ ``average``)."""
    rng = np.random.default_rng(12345)
    n = rng.normal(0.0, sigma, ((height + _PAD) * average, (width + _PAD) * average, 3))
    if average > 1:
        kept = np.trunc(np.clip(n, -255, 255))
        n = np.round(kept.reshape(height + _PAD, average, width + _PAD, average, 3).mean(axis=(1, 3)))
    return _frozen(np.clip(n, 0, 255).astype(np.uint8)), _frozen(np.clip(-n, 0, 255).astype(np.uint8))


@lru_cache(maxsize=16)
def _unit_noise(width: int, height: int) -> np.ndarray:
    rng = np.random.default_rng(54321)
    return _frozen(rng.standard_normal((height + _PAD, width + _PAD)).astype(np.float32))


def noise_offset(rng: np.random.Generator) -> tuple[int, int]:
    """The random ``(row, column)`` of a frame's top-left pixel in a noise bank (one per frame)."""
    dy, dx = rng.integers(0, _PAD + 1, 2)
    return int(dy), int(dx)


def add_rgb_noise(
    rgb: np.ndarray, sigma: float, frame_size: tuple[int, int], at: tuple[int, int], average: int = 1
) -> None:
    """Add Gaussian noise of ``sigma`` gray levels in place to ``rgb`` (uint8, saturating), from the bank of
    frames of ``frame_size = (width, height)``, starting at bank pixel ``at = (row, column)``: a frame's
    :func:`noise_offset`, plus the position of ``rgb`` in the frame when it is a window of it (so a window gets
    the very noise the whole frame would have there). ``average``: ``rgb`` is a frame ``average`` times larger
    averaged down (its noise too, see :func:`_rgb_noise`)."""
    pos, neg = _rgb_noise(*frame_size, float(sigma), average)
    (y, x), (h, w) = at, rgb.shape[:2]
    cv2.add(rgb, pos[y : y + h, x : x + w], dst=rgb)
    cv2.subtract(rgb, neg[y : y + h, x : x + w], dst=rgb)


def banding_episode(deg: Degradation, rng: np.random.Generator) -> bool:
    """Whether a frame has a banding episode (probability ``banding_prob``)."""
    return deg.banding_prob > 0 and rng.random() < deg.banding_prob


def _window(bank: np.ndarray, width: int, height: int, rng: np.random.Generator) -> np.ndarray:
    dy, dx = noise_offset(rng)
    return bank[dy : dy + height, dx : dx + width]


def _bands(deg: Degradation, width: int, height: int, rng: np.random.Generator, full: bool = False):
    """List of ``(y0, y1, signed amplitude fraction, shift px)`` for one banding episode."""
    lo, hi = (1.0, 1.0) if full else deg.banding_coverage
    cover = max(1, round(rng.uniform(lo, hi) * height))
    top = int(rng.integers(0, height - cover + 1))
    scale = height / 480.0
    rmin, rmax = max(1, round(deg.banding_rows[0] * scale)), max(1, round(deg.banding_rows[1] * scale))
    shift_max = round(deg.banding_shift_px * width / 640.0)
    bands, y, sign = [], top, 1.0 if rng.random() < 0.5 else -1.0
    while y < top + cover:
        t = int(rng.integers(rmin, rmax + 1))
        shift = int(rng.integers(-shift_max, shift_max + 1)) if shift_max and rng.random() < 0.5 else 0
        bands.append((y, min(y + t, top + cover), sign * rng.uniform(0.5, 1.0), shift))
        y += t
        sign = -sign
    return bands


def _band_rgb(img: np.ndarray, bands, amplitude: float) -> None:
    height, width = img.shape[:2]
    y0, y1 = bands[0][0], bands[-1][1]
    offset = np.zeros(y1 - y0, np.float32)
    for a, b, s, shift in bands:
        offset[a - y0 : b - y0] = s * amplitude
        if shift:
            img[a:b] = np.roll(img[a:b], shift, axis=1)
    flat = img[y0:y1].reshape(y1 - y0, -1)  # a view: rows of W·3 bytes
    pos = cv2.resize(
        np.clip(offset, 0, 255).astype(np.uint8)[:, None], (flat.shape[1], y1 - y0), interpolation=cv2.INTER_NEAREST
    )
    neg = cv2.resize(
        np.clip(-offset, 0, 255).astype(np.uint8)[:, None], (flat.shape[1], y1 - y0), interpolation=cv2.INTER_NEAREST
    )
    cv2.add(flat, pos, dst=flat)
    cv2.subtract(flat, neg, dst=flat)


def _band_thermal(th: np.ndarray, bands, amplitude_K: float) -> None:
    for a, b, s, shift in bands:
        if shift:
            th[a:b] = np.roll(th[a:b], shift, axis=1)
        th[a:b] += s * amplitude_K


@dataclass(frozen=True)
class Speckle:
    """One transient blob: an ellipse (centre and semi-axes in frame pixels, angle in degrees), dark or light,
    drawn in RGB at gray level ``gray``."""

    centre: tuple[int, int]
    axes: tuple[int, int]
    angle: float
    dark: bool
    gray: int = 0

    @property
    def box(self) -> tuple[int, int, int, int]:
        """``(x0, y0, x1, y1)``: the pixels the speckle may cover."""
        r = max(self.axes)
        return self.centre[0] - r, self.centre[1] - r, self.centre[0] + r, self.centre[1] + r


def plan_speckles(
    deg: Degradation, width: int, height: int, rng: np.random.Generator, rgb: bool = True
) -> list[Speckle]:
    """The ``Poisson(speckle_rate)`` speckles of one frame, placed uniformly (radius scaled to the frame width);
    ``rgb=False`` leaves out their gray levels (a thermal-only frame)."""
    count = int(rng.poisson(deg.speckle_rate))
    scale = width / 640.0
    speckles = []
    for _ in range(count):
        c = (int(rng.integers(0, width)), int(rng.integers(0, height)))
        r = rng.uniform(*deg.speckle_radius_px) * scale
        axes = (max(1, round(r)), max(1, round(r * rng.uniform(0.6, 1.0))))
        angle = float(rng.uniform(0, 180))
        dark = bool(rng.random() < 0.7)
        gray = (int(rng.integers(0, 45)) if dark else int(rng.integers(210, 256))) if rgb else 0
        speckles.append(Speckle(c, axes, angle, dark, gray))
    return speckles


def draw_speckles(img: np.ndarray, speckles: list[Speckle], scale: float = 1.0, offset=(0.0, 0.0)) -> None:
    """Draw ``speckles`` into the RGB image ``img``, whose pixel ``p'`` is frame pixel ``p`` at
    ``p' = scale·p − offset`` (a window of the frame, or the whole frame at a lower resolution)."""
    for s in speckles:
        c = (round(s.centre[0] * scale - offset[0]), round(s.centre[1] * scale - offset[1]))
        axes = (max(1, round(s.axes[0] * scale)), max(1, round(s.axes[1] * scale)))
        cv2.ellipse(img, c, axes, s.angle, 0, 360, (s.gray, s.gray, s.gray), -1)


def _speckles(
    img: np.ndarray | None, th: np.ndarray | None, deg: Degradation, width: int, height: int, rng: np.random.Generator
) -> int:
    base_K = float(np.median(th[:: max(1, height // 16), :: max(1, width // 16)])) if th is not None else 0.0
    speckles = plan_speckles(deg, width, height, rng, rgb=img is not None)
    if img is not None:
        draw_speckles(img, speckles)
    if th is not None and deg.degrade_thermal:
        for s in speckles:
            cv2.ellipse(th, s.centre, s.axes, s.angle, 0, 360, base_K + (-20.0 if s.dark else 25.0), -1)
    return len(speckles)


def _fail(
    img: np.ndarray | None, th: np.ndarray | None, deg: Degradation, ambient_K: float, rng: np.random.Generator
) -> None:
    height, width = (img if img is not None else th).shape[:2]
    mode = deg.failed
    if mode == "snow":
        snow = np.frombuffer(rng.bytes(width * height), np.uint8).reshape(height, width)
        if img is not None:
            img[:] = snow[..., None]
        if th is not None:
            th[:] = ambient_K + (snow.astype(np.float32) - 128.0) * 0.25
    else:
        if img is not None:
            img[:] = 0 if mode == "black" else 110
        if th is not None:
            th[:] = ambient_K - 20.0
    if mode in ("snow", "banding"):
        bands = _bands(deg, width, height, rng, full=True)
        if img is not None:
            _band_rgb(img, bands, deg.banding_amplitude * (0.6 if mode == "snow" else 1.0))
        if th is not None:
            _band_thermal(th, bands, deg.banding_thermal_K)


def degrade(
    rgb: np.ndarray | None,
    thermal: np.ndarray | None,
    deg: Degradation,
    rng: np.random.Generator,
    ambient_K: float = 295.0,
) -> DegradationInfo:
    """Apply ``deg`` in place to ``rgb`` (H×W×3 uint8) and/or ``thermal`` (H×W float32, Kelvin)."""
    if rgb is None and thermal is None:
        return DegradationInfo()
    height, width = (rgb if rgb is not None else thermal).shape[:2]
    th = thermal if deg.degrade_thermal else None
    speckles, banding = 0, False
    if deg.failed is not None:
        _fail(rgb, thermal, deg, ambient_K, rng)
    else:
        speckles = _speckles(rgb, th, deg, width, height, rng) if deg.speckle_rate > 0 else 0
        if banding_episode(deg, rng):
            banding = True
            bands = _bands(deg, width, height, rng)
            if rgb is not None:
                _band_rgb(rgb, bands, deg.banding_amplitude)
            if th is not None:
                _band_thermal(th, bands, deg.banding_thermal_K)
    if rgb is not None and deg.noise_sigma > 0:
        add_rgb_noise(rgb, deg.noise_sigma, (width, height), noise_offset(rng))
    if thermal is not None and deg.thermal_noise_K > 0:
        cv2.scaleAdd(
            _window(_unit_noise(width, height), width, height, rng), float(deg.thermal_noise_K), thermal, dst=thermal
        )
    return DegradationInfo(banding=banding, speckles=speckles, failed=deg.failed)
