"""The blob detectors on a frame drawn in parts (perception.roi_frame.RoiFrame): the same blobs as on the whole
frame, in frame pixels; nothing cut by a window edge; banding rows and the persistent-object filter as on whole
frames."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from perception.blobs import ColorBlobDetector, DarkBlobDetector
from perception.camera import Intrinsics
from perception.degradation import Degradation
from perception.persistence import PersistentDetector
from perception.pose import CameraPose, Gimbal
from perception.render import render_frame
from perception.roi_frame import RoiFrame, Window
from perception.roi_render import render_roi
from perception.scene import Target

CLEAN = Degradation(noise_sigma=0.0)


def camera(altitude: float, yaw: float = 0.4, width: int = 640, height: int = 480):
    pose = CameraPose.from_vehicle([0.0, 0.0, -altitude], 0.03, -0.02, yaw, Gimbal(0.0, -math.pi / 2))
    return pose, Intrinsics.from_fov(width, height, 90.0)


def centres(result) -> np.ndarray:
    return np.array(sorted(d.center for d in result.detections), float).reshape(-1, 2)


def test_colour_blobs_in_the_windows_are_those_of_the_whole_frame():
    targets = [Target((12.0, -7.0, 0.0), 1.5, shape="disc"), Target((-30.0, 20.0, 0.0), 1.5, shape="disc"),
               Target((40.0, 30.0, -1.5), 1.5, shape="sphere")]
    full = render_frame(camera(80.0), 640, 480, targets, degradation=CLEAN, seed=1, thermal=False)
    roi = render_roi(camera(80.0), 640, 480, targets, degradation=CLEAN, seed=1)
    detector = ColorBlobDetector(expected_shape=(480, 640, 3))
    whole, parts = detector.detect(full.rgb), detector.detect(roi)
    assert len(parts.detections) == len(whole.detections) == 3
    assert np.abs(centres(parts) - centres(whole)).max() < 0.05  # the same pixels, up to a gray level
    assert parts.frame_size == whole.frame_size == (640, 480)


def test_dark_blobs_in_the_previews_windows_are_those_of_the_whole_frame():
    """Low over the tiled floor (the thesis 000 lab): the preview is the working image, equalised whole."""
    targets = [Target((3.0, -2.0, 0.0), 0.5, (28, 28, 32), shape="disc"),
               Target((-6.0, 8.0, 0.0), 0.5, (28, 28, 32), shape="disc")]
    full = render_frame(camera(25.0), 640, 480, targets, ground="tiles", seed=1, thermal=False)
    roi = render_roi(camera(25.0), 640, 480, targets, ground="tiles", seed=1)
    detector = DarkBlobDetector()
    whole, parts = detector.detect(full.rgb), detector.detect(roi)
    assert len(parts.detections) == len(whole.detections) == 2
    assert np.abs(centres(parts) - centres(whole)).max() < 0.5  # other noise draws, the same working resolution
    assert parts.scale == whole.scale == (2.0, 2.0) and parts.frame_size == (640, 480)


def test_a_blob_cut_by_a_window_edge_inside_the_frame_is_dropped():
    window = np.full((40, 40, 3), 128, np.uint8)
    cv2.circle(window, (20, 20), 6, (220, 10, 10), -1)  # whole: kept
    cv2.circle(window, (37, 8), 6, (220, 10, 10), -1)  # cut by the window's right edge (inside the frame)
    inside = RoiFrame(640, 480, np.zeros((240, 320, 3), np.uint8), 0.5, [Window(100, 100, window)])
    found = ColorBlobDetector().detect(inside).detections
    assert [tuple(round(c) for c in d.center) for d in found] == [(120, 120)]
    # the same window against the frame's right border: the cut is the frame's, for the border rule to judge
    at_border = RoiFrame(140, 480, np.zeros((240, 70, 3), np.uint8), 0.5, [Window(100, 100, window)])
    assert len(ColorBlobDetector().detect(at_border).detections) == 2


def test_banding_rows_are_read_on_the_preview():
    """A preview striped like a banding episode (alternating bright and dark rows) marks those frame rows blind
    and drops the detections there, as the whole frame would."""
    preview = np.full((240, 320, 3), 120, np.uint8)
    for top in range(100, 180, 8):  # bands of 4 rows, dark and light
        preview[top : top + 4] = 20
        preview[top + 4 : top + 8] = 220
    window = np.full((40, 40, 3), 120, np.uint8)
    cv2.circle(window, (20, 20), 6, (220, 10, 10), -1)
    frames = {"in the bands": Window(300, 260, window), "clear": Window(300, 20, window)}
    for where, w in frames.items():
        result = ColorBlobDetector().detect(RoiFrame(640, 480, preview, 0.5, [w]))
        assert result.blind_rows is not None and result.blind_rows.shape == (480,)
        assert result.blind_rows[200:360].all() and not result.blind_rows[:150].any()
        assert len(result.detections) == (where == "clear")


@pytest.mark.parametrize("detector", [ColorBlobDetector, DarkBlobDetector])
def test_the_persistent_object_filter_takes_frames_drawn_in_parts(detector):
    rgb = (200, 20, 20) if detector is ColorBlobDetector else (28, 28, 32)
    target = [Target((2.0, 1.0, 0.0), 0.5, rgb, shape="disc")]
    persistent = PersistentDetector(detector())
    for k in range(4):
        frame = render_roi(camera(25.0), 640, 480, target, ground="tiles", seed=k)
        result = persistent.detect(frame)
    assert result.frame_size == (640, 480) and len(result.detections) == 1
    (p,) = persistent.filter.objects
    assert p.frame_count == 4
