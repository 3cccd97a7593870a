"""The camera that draws only what its detector needs (perception.roi_render): its windows are the whole frame where
they are, its preview is the whole frame downsampled, the noise model holds in both, and banding episodes and failed
links are drawn whole."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from perception.camera import Intrinsics
from perception.degradation import Degradation
from perception.pose import CameraPose, Gimbal
from perception.quality import VideoQuality
from perception.render import render_frame
from perception.roi_render import WINDOW_MARGIN_PX, render_roi, window_boxes
from perception.scene import RenderedFrame, Target

INTRINSICS = Intrinsics.from_fov(640, 480, 90.0)
CLEAN = Degradation(noise_sigma=0.0)


def camera(tilt_deg=-90.0, altitude=80.0, north=0.0, east=0.0, yaw=0.4, intrinsics=INTRINSICS):
    pose = CameraPose.from_vehicle([north, east, -altitude], 0.03, -0.02, yaw, Gimbal(0.0, math.radians(tilt_deg)))
    return pose, intrinsics


TARGETS = [Target((12.0, -7.0, 0.0), 1.5, shape="disc"), Target((40.0, 20.0, -1.5), 1.5, shape="sphere"),
           Target((60.0, -30.0, 0.0), 1.5, shape="disc"), Target((-500.0, 0.0, 0.0), 1.5, shape="disc")]


@pytest.mark.parametrize("tilt", [-90.0, -50.0])
def test_windows_are_the_whole_frame_where_they_are_and_the_labels_agree(tilt):
    full = render_frame(camera(tilt), 640, 480, TARGETS, degradation=CLEAN, seed=1, thermal=False)
    roi = render_roi(camera(tilt), 640, 480, TARGETS, degradation=CLEAN, seed=1)
    assert roi.targets == full.targets
    in_frame = [t for t in full.targets if t.in_view]
    assert len(roi.windows) == len(in_frame) >= 2
    for window in roi.windows:
        x0, y0, x1, y1 = map(int, window.box)
        diff = np.abs(full.rgb[y0:y1, x0:x1].astype(int) - window.image.astype(int))
        assert diff.max() <= 1  # the same warp, from a shifted origin: rounding only


def test_windows_hold_every_target_and_speckle_with_its_margin():
    roi = render_roi(camera(), 640, 480, TARGETS, degradation=Degradation(speckle_rate=6.0), seed=3)
    assert roi.info.speckles > 0
    boxes = [w.box for w in roi.windows]
    for label in roi.targets:
        if label.in_view:
            u, v, r = *label.center_px, label.radius_px
            assert any(x0 + WINDOW_MARGIN_PX <= u - r and u + r <= x1 - WINDOW_MARGIN_PX
                       and y0 + WINDOW_MARGIN_PX <= v - r and v + r <= y1 - WINDOW_MARGIN_PX
                       for x0, y0, x1, y1 in boxes), label
    assert len(roi.windows) >= 3  # the speckles have windows of their own (the dark detector responds to them)


def test_window_boxes_are_grown_aligned_clipped_and_merged():
    assert window_boxes([(100.2, 50.0, 110.0, 60.5)], 640, 480, margin=8, grid=2) == [(92, 42, 120, 70)]
    assert window_boxes([(-3.0, 470.0, 5.0, 478.0)], 640, 480, margin=8) == [(0, 462, 14, 480)]
    assert window_boxes([(-40.0, -40.0, -20.0, -20.0), (700.0, 10.0, 720.0, 20.0)], 640, 480) == []
    merged = window_boxes([(100.0, 100.0, 110.0, 110.0), (120.0, 100.0, 130.0, 110.0), (300.0, 300.0, 301.0, 301.0)],
                          640, 480, margin=8)
    assert sorted(merged) == [(92, 92, 139, 119), (292, 292, 310, 310)]


def test_the_preview_is_the_whole_frame_downsampled():
    full = render_frame(camera(), 640, 480, TARGETS, degradation=CLEAN, seed=1, thermal=False)
    roi = render_roi(camera(), 640, 480, TARGETS, degradation=CLEAN, seed=1)
    small = cv2.resize(full.rgb, (320, 240), interpolation=cv2.INTER_AREA).astype(int)
    assert roi.preview.shape == (240, 320, 3) and roi.scale == 0.5
    assert np.abs(small - roi.preview).mean() < 3.0  # the ground sampled box-filtered, not the same texels
    for window in roi.windows:  # where it matters the preview is the frame's pixels averaged
        x0, y0, x1, y1 = (int(c) // 2 for c in window.box)
        assert np.abs(small[y0:y1, x0:x1] - roi.preview[y0:y1, x0:x1]).max() <= 1


def test_noise_is_the_frames_in_the_windows_and_averaged_in_the_preview():
    noisy = render_roi(camera(), 640, 480, TARGETS, degradation=Degradation(noise_sigma=4.0), seed=5)
    clean = render_roi(camera(), 640, 480, TARGETS, degradation=Degradation(noise_sigma=0.0), seed=5)
    window_noise = np.concatenate([(a.image.astype(float) - b.image).ravel()
                                   for a, b in zip(noisy.windows, clean.windows, strict=True)])
    whole = render_frame(camera(), 640, 480, TARGETS, degradation=Degradation(noise_sigma=4.0), seed=5, thermal=False)
    frame_noise = whole.rgb.astype(float) - render_frame(camera(), 640, 480, TARGETS, degradation=CLEAN, seed=5,
                                                         thermal=False).rgb
    assert window_noise.std() == pytest.approx(frame_noise.std(), rel=0.05)
    # a preview pixel is the mean of 2 x 2 frame pixels: the frame's noise standard deviation / 2
    averaged = cv2.resize(frame_noise, (320, 240), interpolation=cv2.INTER_AREA)
    preview_noise = noisy.preview.astype(float) - clean.preview
    assert preview_noise.std() == pytest.approx(averaged.std(), rel=0.1)
    assert preview_noise.std() == pytest.approx(frame_noise.std() / 2, rel=0.15)


@pytest.mark.parametrize("degradation", [Degradation(banding_prob=1.0), Degradation(failed="snow"),
                                         Degradation(failed="black"), Degradation(failed="banding")])
def test_banding_episodes_and_failed_links_are_drawn_whole(degradation):
    frame = render_roi(camera(), 640, 480, TARGETS, degradation=degradation, seed=2)
    assert isinstance(frame, RenderedFrame) and frame.rgb.shape == (480, 640, 3)
    assert frame.info.failed == degradation.failed and frame.info.banding == (degradation.failed is None)
    assert frame.targets == render_frame(camera(), 640, 480, TARGETS, degradation=CLEAN, seed=2, thermal=False).targets


def test_a_camera_no_larger_than_the_preview_is_drawn_whole():
    small = Intrinsics.from_fov(320, 240, 90.0)
    frame = render_roi(camera(intrinsics=small), 320, 240, TARGETS, seed=4)
    whole = render_frame(camera(intrinsics=small), 320, 240, TARGETS, seed=4, thermal=False)
    assert isinstance(frame, RenderedFrame) and np.array_equal(frame.rgb, whole.rgb)


@pytest.mark.parametrize("ground", ["terrain", "tiles"])
def test_the_video_quality_of_the_preview_is_that_of_the_whole_frame(ground):
    """D(t) (thesis 000 §2.4) is defined on the frame downsampled to 320 x 240: the preview is that image, its
    texture box-filtered and its noise sigma / 2, so clean frames measure alike (here within 20 %)."""
    rng = np.random.default_rng(0)
    full, roi = VideoQuality(k=40), VideoQuality(k=40)
    for k in range(20):
        cam = camera(altitude=rng.uniform(50.0, 150.0), north=rng.uniform(-100, 100), east=rng.uniform(-100, 100),
                     yaw=rng.uniform(-3.0, 3.0))
        full.update(render_frame(cam, 640, 480, TARGETS, ground=ground, seed=k, thermal=False).rgb)
        roi.update(render_roi(cam, 640, 480, TARGETS, ground=ground, seed=k).preview)
    assert roi.D == pytest.approx(full.D, rel=0.2)
    assert roi.D < roi.good_level


@pytest.mark.parametrize("degradation", [Degradation(), Degradation(noise_sigma=0.0), Degradation(speckle_rate=3.0)])
def test_a_frame_drawn_in_parts_takes_the_random_draws_of_a_whole_frame(degradation):
    """What else a camera draws from its generator (its telemetry's noise) does not depend on how it draws frames."""
    def whole(rng):
        return render_frame(camera(), 640, 480, TARGETS, degradation=degradation, seed=rng, thermal=False)

    def in_parts(rng):
        return render_roi(camera(), 640, 480, TARGETS, degradation=degradation, seed=rng)

    after = []
    for draw in (whole, in_parts):
        rng = np.random.default_rng(11)
        for _ in range(3):
            draw(rng)
        after.append(rng.random())
    assert after[0] == after[1]
