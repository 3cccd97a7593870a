"""External video for the camera sensor: an OpenCV source that replaces the synthetic camera."""

from __future__ import annotations

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
            raise ValueError(f"cannot open camera source {self.name!r} (not a readable video file, device or stream)")
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
