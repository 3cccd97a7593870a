"""A synthetic camera that renders only what its detector needs (issue 12 item 5, "a camera that costs what it must").

:func:`perception.render.render_frame` draws every pixel of a 640×480 frame, although the colour-blob detector
only ever finds the few targets in it and the frame-level measures look at it at 320×240. :func:`render_roi`
draws, from the same scene, camera and noise model, a :class:`~perception.roi_frame.RoiFrame`:

* the **preview**: the whole view at scale ``s = min(1, 320/W, 240/H)``, i.e. ``k = 1/s`` frame pixels per
  preview pixel (320×240 for 640×480, k = 2): the image ``I`` of the video quality D(t), thesis 000 §2.4; the
  rows of the banding test, :func:`perception.quality.blind_rows`; the working image of the dark-blob detector,
  §2.2 — each of which is the whole frame downsampled to that size by area averaging (``cv2.INTER_AREA``). So a
  preview pixel is drawn as the mean of k×k frame pixels: the ground samples the frame's mip level averaged over
  the texels those pixels cover (:meth:`perception.ground.FlatGround.layer`), the sensor noise is the frame's
  noise bank averaged over k×k pixels (standard deviation ``σ/k``, the mean of k² independent draws;
  :func:`perception.degradation.add_rgb_noise`), the targets and speckles are drawn at scale ``s``;
* the full-resolution **windows**: around each target and speckle that meets the frame (what a detector may
  respond to: the colour detector to the red targets, the dark detector to dark targets and dark speckles), the
  box of its pixels grown by :data:`WINDOW_MARGIN_PX`, out to whole preview pixels and clipped to the frame,
  overlapping boxes merged (no blob is split between two windows). The renderer projects from the true pose, so
  a window needs no allowance for pose error, only for what the detector adds around a target's pixels. A window
  is the camera with its principal point moved (projection ``A·P``, ``A = [[1, 0, −x0], [0, 1, −y0], [0, 0, 1]]``;
  the preview's is ``A = [[s, 0, (s − 1)/2], [0, s, (s − 1)/2], [0, 0, 1]]``, pixel centres at integers), takes
  the frame's noise bank at its own position, and so holds the whole frame's pixels there (to a gray level of
  rounding, on flat ground; on a terrain the ground is sampled through a coarse grid of rays of its own). The
  preview under a window is then the window averaged k×k: there, it is exactly the whole frame downsampled;
* the **labels**, as render_frame's (:func:`perception.render.target_label`), each counted on a raster of object
  numbers over its own label box.

The degradation is drawn once per frame and applied to every part. A frame with a **banding episode** or a
**failed link** (``snow``, ``black``, ``banding``) is rendered whole by :func:`~perception.render.render_frame`
and returned as its :class:`~perception.scene.RenderedFrame`: bands tear rows sideways across the whole width,
a failed link replaces the whole picture, and the banding and blank-frame checks of the detectors must see it
(at ``banding_prob`` p a camera pays the full price in a fraction p of its frames). So is every frame of a camera
no larger than the preview (``s = 1``): its preview would be the frame itself. The random numbers are drawn as
render_frame draws them (the speckles, the banding decision, one place in the noise banks for all parts), so what
a caller draws from the same generator — the camera sensor's telemetry noise — is the same whichever way its
frames are drawn (up to the first banding episode).

What a ROI frame does not show: whatever a detector would find in the ground texture alone, away from targets
and speckles (over the tiled floor from 80 m the dark-blob detector finds ~4 such blobs a frame in the whole
frame; the colour detector none over the terrain) — so its false alarms are at most the whole frame's.

Scope: RGB, ground, targets and the per-frame degradation, what :class:`agent.sensors.camera.CameraSensor` draws;
fires, smoke, occluders and thermal frames are render_frame's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np

from perception.degradation import Degradation, DegradationInfo
from perception.degrade import (
    Speckle,
    add_rgb_noise,
    banding_episode,
    draw_speckles,
    noise_offset,
    plan_speckles,
)
from perception.ground import GroundLayer, GroundTexture, ground_view
from perception.pinhole import as_view
from perception.render import (
    Projected,
    default_ground,
    ground_rgb,
    painter_order,
    project_object,
    render_frame,
    target_label,
)
from perception.roi_frame import RoiFrame, Window
from perception.scene import RenderedFrame, Target, TargetLabel, parse

__all__ = ["PREVIEW_SIZE", "WINDOW_MARGIN_PX", "preview_scale", "render_roi", "window_boxes"]

#: Largest preview, (width, height): the working size of D(t), the banding rows and the dark-blob detector.
PREVIEW_SIZE = (320, 240)
#: px around a target's outline in its window (chosen here): the colour detector's 3×3 dilation (1 px), the
#: anti-aliased rim (1 px) and the 2 px border rule of the camera sensor need 4; the rest is slack.
WINDOW_MARGIN_PX = 8


@dataclass(frozen=True)
class _Scene:
    """What every part of one frame is drawn on its ground: the projected targets in painter's order
    ``(k, target index, target, projection)`` and the frame's speckles."""

    objects: list[tuple[int, int, Target, Projected]]
    speckles: list[Speckle]

    def paint(self, ground: GroundLayer, box: tuple[int, int, int, int], scale: float, offset) -> np.ndarray:
        """The part ``box = (x0, y0, x1, y1)`` of the frame, an image whose pixel ``p'`` is frame pixel ``p`` at
        ``p' = scale·p − offset``, with its ``ground``: the targets that meet it and the speckles (no sensor noise)."""
        img = ground_rgb(ground)
        for _, _, target, shape in self.objects:
            if _overlap(shape.box, box, slack=1.0):
                shape.draw(img, tuple(int(c) for c in target.rgb), cv2.LINE_AA, scale, offset)
        draw_speckles(img, self.speckles, scale, offset)
        return img

    def labels(self, n_targets: int, width: int, height: int) -> list[TargetLabel]:
        """Labels of targets ``0 … n_targets − 1`` (:func:`perception.render.target_label`), each counted on a
        raster of the object numbers over its label box."""
        drawn = {index: (k, shape) for k, index, _, shape in self.objects}
        out = []
        for i in range(n_targets):
            entry, ids, origin = drawn.get(i), None, (0, 0)
            if entry is not None:
                box = entry[1].label_box(width, height)
                near = [(k, shape) for k, _, _, shape in self.objects if _overlap(shape.box, box, slack=1.0)]
                if len(near) > 1:  # something else is drawn there: who is on top of which pixel
                    ids, origin = np.zeros((box[3] - box[1], box[2] - box[0]), np.uint16), box[:2]
                    for k, shape in near:
                        shape.draw(ids, k, cv2.LINE_8, offset=origin)
            out.append(target_label(i, entry, ids, width, height, origin=origin))
        return out


def _pixel_map(scale: float, offset) -> np.ndarray:
    """``A`` with ``A·(p, 1) = (scale·p − offset, 1)``: frame pixels to the pixels of a window or a preview."""
    return np.array([[scale, 0.0, -offset[0]], [0.0, scale, -offset[1]], [0.0, 0.0, 1.0]])


def _overlap(a, b, slack: float = 0.0) -> bool:
    """Whether boxes ``(x0, y0, x1, y1)`` ``a`` and ``b`` overlap, or come within ``slack`` of each other."""
    return a[0] < b[2] + slack and b[0] < a[2] + slack and a[1] < b[3] + slack and b[1] < a[3] + slack


def preview_scale(width: int, height: int) -> float:
    """Preview pixels per frame pixel: the largest scale ≤ 1 that fits the frame into :data:`PREVIEW_SIZE`."""
    return min(1.0, PREVIEW_SIZE[0] / width, PREVIEW_SIZE[1] / height)


def window_boxes(
    extents: Sequence[tuple], width: int, height: int, margin: int = WINDOW_MARGIN_PX, grid: int = 1
) -> list[tuple[int, int, int, int]]:
    """``(x0, y0, x1, y1)`` windows (``x1``, ``y1`` exclusive) around the ``extents`` (``(x0, y0, x1, y1)``, the
    pixels something covers) that meet the frame: each grown by ``margin`` px, out to multiples of ``grid`` px and
    clipped to the frame, overlapping windows merged into their union."""
    boxes = []
    for bx0, by0, bx1, by1 in extents:
        x0 = max(0, (math.floor(bx0) - margin) // grid * grid)
        y0 = max(0, (math.floor(by0) - margin) // grid * grid)
        x1 = min(width, -(-(math.ceil(bx1) + 1 + margin) // grid) * grid)
        y1 = min(height, -(-(math.ceil(by1) + 1 + margin) // grid) * grid)
        if x0 < x1 and y0 < y1:
            boxes.append((x0, y0, x1, y1))
    merged = True
    while merged:
        merged = False
        for i, a in enumerate(boxes):
            for j in range(i + 1, len(boxes)):
                b = boxes[j]
                if _overlap(a, b):
                    boxes[i] = (min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3]))
                    del boxes[j]
                    merged = True
                    break
            if merged:
                break
    return boxes


def render_roi(
    camera,
    width: int,
    height: int,
    targets: Sequence = (),
    ground: GroundTexture | str | None = None,
    ground_height: float = 0.0,
    terrain=None,
    degradation: Degradation | None = None,
    seed: int | np.random.Generator | None = None,
) -> RoiFrame | RenderedFrame:
    """The frame :func:`~perception.render.render_frame` would draw of ``targets`` (same arguments), as a
    preview and full-resolution windows around the targets and speckles; or the whole RGB frame for a banding
    episode, a failed link or a camera no larger than its preview (see the module docstring)."""
    if width < 8 or height < 8:
        raise ValueError("image must be at least 8×8")
    targets = parse(targets, Target)
    view = as_view(camera, [t.position for t in targets] or [(0.0, 0.0, 0.0)])
    ground = default_ground(ground) if ground is None or isinstance(ground, str) else ground
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    deg = Degradation() if degradation is None else degradation
    s = preview_scale(width, height)

    def drawn_whole(degradation: Degradation) -> RenderedFrame:
        return render_frame(
            view,
            width,
            height,
            targets,
            ground=ground,
            ground_height=ground_height,
            terrain=terrain,
            degradation=degradation,
            seed=rng,
            thermal=False,
        )

    if s == 1.0 or deg.failed is not None:  # no larger than its preview, or a failed link: as render_frame draws it
        return drawn_whole(deg)
    # Random draws in render_frame's order (speckles, banding, noise), so that what a caller draws from the same
    # generator comes out as with whole frames (until a banding episode, which render_frame draws again).
    speckles = plan_speckles(deg, width, height, rng) if deg.speckle_rate > 0 else []
    if banding_episode(deg, rng):
        return drawn_whole(replace(deg, banding_prob=1.0))
    at = noise_offset(rng) if deg.noise_sigma > 0 else (0, 0)  # the frame's place in the noise banks
    objects = [
        (k, index, target, shape)
        for k, (target, index) in enumerate(painter_order(view, targets), start=1)
        if (shape := project_object(view, target)) is not None
    ]
    scene = _Scene(objects, speckles)
    offset = (0.5 - 0.5 * s, 0.5 - 0.5 * s)
    size = (round(width * s), round(height * s))
    step = round(1.0 / s)
    frame_ground = ground_view(ground, view.P, width, height, ground_height, terrain)
    preview = scene.paint(
        frame_ground.layer(_pixel_map(s, offset), size, downsample=step), (0, 0, width, height), s, offset
    )
    if deg.noise_sigma > 0:
        add_rgb_noise(preview, deg.noise_sigma, size, at, average=step)
    aligned = step * s == 1.0 and width % step == 0 and height % step == 0  # windows cover whole preview pixels
    extents = [shape.box for *_, shape in objects] + [speckle.box for speckle in scene.speckles]
    windows = []
    for x0, y0, x1, y1 in window_boxes(extents, width, height, grid=step if aligned else 1):
        image = scene.paint(
            frame_ground.layer(_pixel_map(1.0, (x0, y0)), (x1 - x0, y1 - y0)), (x0, y0, x1, y1), 1.0, (x0, y0)
        )
        if deg.noise_sigma > 0:
            add_rgb_noise(image, deg.noise_sigma, (width, height), (at[0] + y0, at[1] + x0))
        windows.append(Window(x0, y0, image))
        if aligned:  # the preview there is the window downsampled, as the whole frame would be
            cell = ((x1 - x0) // step, (y1 - y0) // step)
            preview[y0 // step : y1 // step, x0 // step : x1 // step] = cv2.resize(
                image, cell, interpolation=cv2.INTER_AREA
            )
    info = DegradationInfo(speckles=len(scene.speckles))
    return RoiFrame(width, height, preview, s, windows, scene.labels(len(targets), width, height), info)
