"""External video for the camera sensor: an OpenCV source that replaces the synthetic camera."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


class VideoSource:
    """An OpenCV video source (``cv2.VideoCapture``): a file path, a device index (``"0"``) or a stream
    URL. Opening a source that does not open is a :class:`ValueError`; :meth:`read` returns the next
    frame as RGB uint8, or ``None`` when no frame could be read or decoded (counted by the sensor)."""

    def __init__(self, source: str | int):
        self.name = str(source)
        spec = int(source) if isinstance(source, str) and source.strip().isdigit() else source
        self.capture = cv2.VideoCapture(spec)
        if not self.capture.isOpened():
            self.capture.release()
            raise ValueError(f"cannot open camera source {self.name!r} ({_why_not(self.name)})")
        self.size = (int(self.capture.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self.capture.get(cv2.CAP_PROP_FRAME_HEIGHT)))

    def read(self) -> np.ndarray | None:
        try:
            ok, frame = self.capture.read()
        except cv2.error:
            return None
        if not ok or frame is None:
            return None
        if frame.ndim == 3 and frame.shape[2] == 3:
            return cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
        return frame

    def close(self) -> None:
        self.capture.release()


def _why_not(source: str) -> str:
    """Why a source did not open, as far as the file system tells: a missing file, a folder, or a file that is
    no video OpenCV can read (a device index or a stream URL: OpenCV does not say)."""
    path = Path(source)
    if source.strip().isdigit() or "://" in source:
        return "not a video device or stream that could be opened"
    if not path.exists():
        return "no such file"
    if path.is_dir():
        return "a folder, not a video file"
    return "not a video file OpenCV can read"
