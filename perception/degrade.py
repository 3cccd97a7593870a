"""Apply a :class:`~perception.degradation.Degradation` to a synthetic frame, in place (OpenCV).

The effects and their parameters are described in :mod:`perception.degradation`, which holds only the
plain descriptions (no OpenCV), so that configurations can be read without loading OpenCV: an agent with
the geometric bearing sensor never renders a frame.
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from perception.degradation import Degradation, DegradationInfo

__all__ = ["degrade"]

_PAD = 32


def _frozen(a: np.ndarray) -> np.ndarray:
    """Cached banks are shared by every camera: make them read-only."""
    a.setflags(write=False)
    return a


@lru_cache(maxsize=16)
def _rgb_noise(width: int, height: int, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Positive and negative parts of a Gaussian noise bank (uint8, padded for random offsets)."""
    rng = np.random.default_rng(12345)
    n = rng.normal(0.0, sigma, (height + _PAD, width + _PAD, 3))
    return _frozen(np.clip(n, 0, 255).astype(np.uint8)), _frozen(np.clip(-n, 0, 255).astype(np.uint8))


@lru_cache(maxsize=16)
def _unit_noise(width: int, height: int) -> np.ndarray:
    rng = np.random.default_rng(54321)
    return _frozen(rng.standard_normal((height + _PAD, width + _PAD)).astype(np.float32))


def _window(bank: np.ndarray, width: int, height: int, rng: np.random.Generator) -> np.ndarray:
    dy, dx = rng.integers(0, _PAD + 1, 2)
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


def _speckles(
    img: np.ndarray | None, th: np.ndarray | None, deg: Degradation, width: int, height: int, rng: np.random.Generator
) -> int:
    count = int(rng.poisson(deg.speckle_rate))
    scale = width / 640.0
    base_K = float(np.median(th[:: max(1, height // 16), :: max(1, width // 16)])) if th is not None else 0.0
    for _ in range(count):
        c = (int(rng.integers(0, width)), int(rng.integers(0, height)))
        r = rng.uniform(*deg.speckle_radius_px) * scale
        axes = (max(1, round(r)), max(1, round(r * rng.uniform(0.6, 1.0))))
        angle = float(rng.uniform(0, 180))
        dark = rng.random() < 0.7
        if img is not None:
            g = int(rng.integers(0, 45)) if dark else int(rng.integers(210, 256))
            cv2.ellipse(img, c, axes, angle, 0, 360, (g, g, g), -1)
        if th is not None and deg.degrade_thermal:
            cv2.ellipse(th, c, axes, angle, 0, 360, base_K + (-20.0 if dark else 25.0), -1)
    return count


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
        if deg.banding_prob > 0 and rng.random() < deg.banding_prob:
            banding = True
            bands = _bands(deg, width, height, rng)
            if rgb is not None:
                _band_rgb(rgb, bands, deg.banding_amplitude)
            if th is not None:
                _band_thermal(th, bands, deg.banding_thermal_K)
    if rgb is not None and deg.noise_sigma > 0:
        pos, neg = _rgb_noise(width, height, float(deg.noise_sigma))
        dy, dx = rng.integers(0, _PAD + 1, 2)
        cv2.add(rgb, pos[dy : dy + height, dx : dx + width], dst=rgb)
        cv2.subtract(rgb, neg[dy : dy + height, dx : dx + width], dst=rgb)
    if thermal is not None and deg.thermal_noise_K > 0:
        cv2.scaleAdd(
            _window(_unit_noise(width, height), width, height, rng), float(deg.thermal_noise_K), thermal, dst=thermal
        )
    return DegradationInfo(banding=banding, speckles=speckles, failed=deg.failed)
