"""A frame rendered in parts, and how the pixels of its parts map to the frame's.

:func:`perception.roi_render.render_roi` draws only what the detectors need of a frame: a *preview* (the whole
view at a lower resolution, what the frame-level measures work on) and, around everything drawn on the ground
that a detector could respond to, full-resolution *windows*. :class:`RoiFrame` holds them; the detectors
(:mod:`perception.blobs`) take it in place of an image — the colour-blob detector looks in the windows, the
dark-blob detector, which works at the preview's resolution, in the windows cut from the preview
(:meth:`RoiFrame.crops`) — and report in frame pixels.

Pixel maps (pixel centres at integers, DESIGN.md §3): a full-resolution window's pixel ``p'`` is frame pixel
``p' + (x0, y0)``; a pixel ``i`` of an image of the whole view at ``1/step`` of the frame's resolution covers
frame pixels ``[i·step, (i + 1)·step)``, centre ``(i + ½)·step − ½`` (what ``cv2.INTER_AREA`` averages, and how
:func:`perception.detection.blobs_from_mask` scales a blob found on a downsampled image back to the frame).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from perception.degradation import DegradationInfo
from perception.detection import Detection
from perception.scene import TargetLabel

__all__ = ["Window", "RoiFrame", "whole_view"]


@dataclass(frozen=True)
class Window:
    """Part of a frame: ``image`` pixel ``(i, j)`` covers frame pixels from ``(x0 + i·sx, y0 + j·sy)`` over
    ``step = (sx, sy)`` (``(1, 1)``: full resolution)."""

    x0: float
    y0: float
    image: np.ndarray
    step: tuple[float, float] = (1.0, 1.0)

    @property
    def box(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` in frame pixels (``x1``, ``y1`` exclusive)."""
        h, w = self.image.shape[:2]
        return self.x0, self.y0, self.x0 + w * self.step[0], self.y0 + h * self.step[1]


@dataclass(frozen=True)
class RoiFrame:
    """One ``width``×``height`` frame as a ``preview`` of the whole view at ``scale`` (preview pixels per frame
    pixel, ≤ 1), the regions of interest ``boxes`` (``(x0, y0, x1, y1)`` frame pixels, ``x1``, ``y1``
    exclusive) and their full-resolution ``windows`` (one per box, or none when they were not rendered);
    ``targets`` are the labels in frame pixels (as :attr:`perception.scene.RenderedFrame.targets`), ``info``
    what degraded the frame."""

    width: int
    height: int
    preview: np.ndarray
    scale: float
    windows: list[Window] = field(default_factory=list)
    targets: list[TargetLabel] = field(default_factory=list)
    info: DegradationInfo = field(default_factory=DegradationInfo)

    @property
    def size(self) -> tuple[int, int]:
        return self.width, self.height

    def crops(self, image: np.ndarray) -> list[Window]:
        """The windows cut from ``image``, an image of the whole view (the preview, or one made from it at any
        size), each grown to whole pixels of it."""
        h, w = image.shape[:2]
        sx, sy = self.width / w, self.height / h
        out = []
        for x0, y0, x1, y1 in (window.box for window in self.windows):
            i0, j0 = math.floor(x0 / sx), math.floor(y0 / sy)
            i1, j1 = min(w, math.ceil(x1 / sx)), min(h, math.ceil(y1 / sy))
            out.append(Window(i0 * sx, j0 * sy, image[j0:j1, i0:i1], (sx, sy)))
        return out

    def detections(self, windows: Sequence[Window], find: Callable[[Window], list[Detection]]) -> list[Detection]:
        """``find(window)`` — detections in frame pixels relative to the window's origin — in each window,
        moved to frame pixels.

        A blob whose box touches an edge of its window that lies inside the frame is dropped: it may be cut
        there (a region's margin keeps the targets clear of its edges; what touches them is a piece of
        something outside). Edges on the frame's border are left to the detector's border rule, as on a whole
        frame."""
        out = []
        for window in windows:
            x0, y0, x1, y1 = window.box
            w, h = x1 - x0, y1 - y0
            for d in find(window):
                bx, by, bw, bh = d.bbox
                cut = (
                    (bx <= 0 < x0)
                    or (by <= 0 < y0)
                    or (bx + bw >= w and x1 < self.width)
                    or (by + bh >= h and y1 < self.height)
                )
                if not cut:
                    center = (d.center[0] + x0, d.center[1] + y0)
                    out.append(Detection(center, d.area, (round(bx + x0), round(by + y0), bw, bh), d.score))
        return out


def whole_view(frame: np.ndarray | RoiFrame) -> np.ndarray:
    """The whole view a frame shows: an image itself, or a :class:`RoiFrame`'s preview (what the frame-level
    measures such as D(t) take, :mod:`perception.quality`)."""
    return frame.preview if isinstance(frame, RoiFrame) else frame
