"""Frame validation: every image entering a detector is checked here first.

A camera, a capture card or a network hop can hand over an empty buffer, an image of the wrong
size, a frame of the wrong type, or garbage (undecodable bytes, a thermal frame full of NaN).
:func:`check_frame` turns each of these into a :class:`FrameError` with a machine-readable
``reason`` (one of :data:`FRAME_ERROR_REASONS`), so a caller can count rejected frames by reason
(DESIGN.md §5 asks the same of messages) instead of crashing or silently processing garbage.
:class:`RejectCounter` is the small counter the detectors keep.

Colour frames are RGB (not OpenCV's BGR) throughout ``perception``; encoded frames (``bytes``) are
decoded with ``cv2.imdecode`` and converted to RGB.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

__all__ = [
    "FRAME_ERROR_REASONS",
    "FrameError",
    "RejectCounter",
    "check_frame",
    "to_gray",
]

#: Every reason :class:`FrameError` can carry.
FRAME_ERROR_REASONS = ("empty", "wrong_shape", "wrong_dtype", "corrupt")


class FrameError(ValueError):
    """A frame that cannot be processed; ``reason`` is one of :data:`FRAME_ERROR_REASONS`."""

    def __init__(self, reason: str, detail: str = ""):
        if reason not in FRAME_ERROR_REASONS:
            raise ValueError(f"unknown frame error reason {reason!r}")
        self.reason = reason
        self.detail = detail
        super().__init__(f"{reason}: {detail}" if detail else reason)


class RejectCounter:
    """Counts rejected frames by reason (``counter["wrong_shape"]``, ``counter.total``)."""

    def __init__(self) -> None:
        self.counts: Counter[str] = Counter()

    def record(self, error: FrameError) -> str:
        self.counts[error.reason] += 1
        return error.reason

    def __getitem__(self, reason: str) -> int:
        return self.counts[reason]

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def as_dict(self) -> dict[str, int]:
        return {reason: self.counts[reason] for reason in FRAME_ERROR_REASONS}

    def __repr__(self) -> str:
        return f"RejectCounter({self.as_dict()})"


def _decode(buffer: bytes | bytearray | memoryview) -> np.ndarray:
    raw = np.frombuffer(bytes(buffer), dtype=np.uint8)
    if raw.size == 0:
        raise FrameError("empty", "zero-length encoded frame")
    try:
        image = cv2.imdecode(raw, cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:  # pragma: no cover - imdecode normally returns None instead
        raise FrameError("corrupt", f"cannot decode {raw.size} bytes: {exc}") from exc
    if image is None:
        raise FrameError("corrupt", f"cannot decode {raw.size} bytes")
    if image.ndim == 3 and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    elif image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    return image


def check_frame(
    frame: Any,
    expected_shape: Sequence[int | None] | None = None,
    dtypes: Sequence[Any] = (np.uint8,),
    channels: Sequence[int] = (1, 3),
) -> np.ndarray:
    """Return ``frame`` as an image array, or raise :class:`FrameError`.

    * ``empty``: ``None``, a zero-size array or a zero-length buffer;
    * ``wrong_shape``: not 2-D (``H×W``) or 3-D (``H×W×C`` with ``C`` in ``channels``), or not
      matching ``expected_shape`` (``None`` entries are wildcards; a 2-entry shape ``(H, W)``
      checks only the image size);
    * ``wrong_dtype``: not an array, or a dtype not in ``dtypes``;
    * ``corrupt``: bytes that do not decode as an image, or a float frame with a non-finite pixel.
    """
    if frame is None:
        raise FrameError("empty", "frame is None")
    if isinstance(frame, bytes | bytearray | memoryview):
        frame = _decode(frame)
    if not isinstance(frame, np.ndarray):
        raise FrameError("wrong_dtype", f"expected an image array, got {type(frame).__name__}")
    if frame.size == 0:
        raise FrameError("empty", f"zero-size frame of shape {frame.shape}")
    if frame.ndim not in (2, 3) or (frame.ndim == 3 and frame.shape[2] not in channels):
        raise FrameError("wrong_shape", f"shape {frame.shape} is not H×W or H×W×C with C in {tuple(channels)}")
    if expected_shape is not None:
        expected = tuple(expected_shape)
        got = frame.shape[: len(expected)] if len(expected) == 2 else frame.shape
        if len(got) != len(expected) or any(e is not None and e != g for e, g in zip(expected, got, strict=True)):
            raise FrameError("wrong_shape", f"shape {frame.shape}, expected {expected}")
    if not any(frame.dtype == np.dtype(d) for d in dtypes):
        raise FrameError("wrong_dtype", f"dtype {frame.dtype}, expected one of {[np.dtype(d).name for d in dtypes]}")
    if frame.dtype.kind == "f":
        finite = np.isfinite(frame)
        if not finite.all():
            bad = frame.size - int(np.count_nonzero(finite))
            raise FrameError("corrupt", f"{bad} of {frame.size} pixels are not finite")
    return frame


def to_gray(frame: np.ndarray) -> np.ndarray:
    """RGB (or single-channel) uint8 frame -> H×W uint8 grayscale."""
    if frame.ndim == 2:
        return frame
    if frame.shape[2] == 1:
        return frame[:, :, 0]
    return cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)
