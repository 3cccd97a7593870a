"""Pin-hole intrinsics, OpenCV distortion and its inverse, bad intrinsics."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from perception.camera import MERINO_IR_CAMERA, Intrinsics

SETTINGS = settings(max_examples=40, deadline=None)
DIST = (-0.28, 0.09, 0.0012, -0.0007, -0.012)  # a typical wide-angle lens
LENS = Intrinsics(800.0, 790.0, 321.3, 238.6, 640, 480, DIST)


def test_pinhole_by_hand():
    cam = Intrinsics(100.0, 200.0, 50.0, 40.0, 101, 81)
    # A point 10 m ahead, 1 m right, 2 m down: u = 100 * 0.1 + 50, v = 200 * 0.2 + 40.
    assert np.allclose(cam.project([1.0, 2.0, 10.0]), [60.0, 80.0])
    assert np.allclose(cam.project([0.0, 0.0, 5.0]), [cam.cx, cam.cy])
    d = cam.ray([60.0, 80.0])
    assert np.allclose(d, np.array([0.1, 0.2, 1.0]) / math.sqrt(1.05))
    assert np.allclose(cam.matrix, [[100, 0, 50], [0, 200, 40], [0, 0, 1]])
    assert Intrinsics.from_matrix(cam.matrix, 101, 81) == cam


def test_points_behind_the_camera_project_to_nan():
    uv = LENS.project([[0.0, 0.0, -1.0], [0.1, 0.1, 0.0], [0.1, 0.1, 2.0]])
    assert np.all(np.isnan(uv[:2])) and np.all(np.isfinite(uv[2]))


def test_from_fov_spans_the_image():
    cam = Intrinsics.from_fov(640, 480, 90.0)
    assert math.isclose(cam.fx, 320.0) and cam.fx == cam.fy
    assert (cam.cx, cam.cy) == (319.5, 239.5)
    left, right = cam.ray([[-0.5, cam.cy], [639.5, cam.cy]])
    assert math.isclose(math.degrees(math.acos(left @ right)), 90.0)
    assert cam.contains([0, 0]) and not cam.contains([640, 0])
    assert list(cam.contains([[-0.5, -0.5], [639.5, 479.5], [np.nan, 3]])) == [True, True, False]


def test_projection_matches_opencv():
    rng = np.random.default_rng(0)
    P = np.column_stack([rng.uniform(-1, 1, (200, 2)), rng.uniform(1.5, 4.0, 200)])
    ours = LENS.project(P)
    theirs, _ = cv2.projectPoints(P, np.zeros(3), np.zeros(3), LENS.matrix, np.array(DIST))
    assert np.abs(ours - theirs[:, 0]).max() < 1e-9


def test_undistortion_matches_opencv_and_round_trips():
    rng = np.random.default_rng(1)
    uv = rng.uniform([-0.5, -0.5], [639.5, 479.5], (500, 2))
    ours = LENS.normalized(uv)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)
    theirs = cv2.undistortPoints(uv.reshape(-1, 1, 2), LENS.matrix, np.array(DIST), criteria=criteria)[:, 0]
    assert np.abs(ours - theirs).max() < 1e-9
    default = cv2.undistortPoints(uv.reshape(-1, 1, 2), LENS.matrix, np.array(DIST))[:, 0]
    assert np.abs(ours - default).max() < 1e-4  # OpenCV's default stops after 5 fixed-point steps
    assert np.abs(LENS.project(LENS.ray(uv)) - uv).max() < 1e-9  # pixel -> ray -> pixel


@SETTINGS
@given(st.floats(-0.5, 639.5), st.floats(-0.5, 479.5))
def test_distortion_round_trip_property(u, v):
    ray = LENS.ray([u, v])
    assert math.isclose(np.linalg.norm(ray), 1.0) and ray[2] > 0
    assert np.allclose(LENS.project(3.7 * ray), [u, v], rtol=0, atol=1e-9)


def test_four_coefficients_and_zero_distortion():
    four = Intrinsics(500, 500, 320, 240, 640, 480, (0.05, 0.01, 0.0, 0.0))
    assert four.dist == (0.05, 0.01, 0.0, 0.0, 0.0)
    assert Intrinsics(500, 500, 320, 240, 640, 480, (0, 0, 0, 0, 0)).dist == ()
    assert np.allclose(four.project(four.ray([10.0, 20.0])), [10.0, 20.0], atol=1e-9)


def test_merino_camera():
    assert np.allclose(MERINO_IR_CAMERA.matrix, [[347.881, 0, 119.512], [0, 345.876, 161.781], [0, 0, 1]])
    assert np.allclose(MERINO_IR_CAMERA.ray([119.512, 161.781]), [0, 0, 1])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"fx": 0.0}, "focal"),
        ({"fy": -3.0}, "focal"),
        ({"fx": math.nan}, "fx must be a finite"),
        ({"cx": math.inf}, "cx must be a finite"),
        ({"width": 0}, "width"),
        ({"height": 2.5}, "height"),
        ({"width": True}, "width"),
        ({"dist": (0.1, 0.2, 0.3)}, "dist must have"),
        ({"dist": (0.1, math.nan, 0, 0)}, "finite"),
        ({"dist": (-2.0, 0.0, 0.0, 0.0, 0.0)}, "folds over"),  # barrel so strong it folds in the image
        ({"dist": (0.0, 0.0, 0.0, 0.0, -5.0)}, "folds over"),
    ],
)
def test_invalid_intrinsics(kwargs, match):
    args = {"fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        Intrinsics(**args)


def test_invalid_constructors_and_inputs():
    with pytest.raises(ValueError, match="hfov"):
        Intrinsics.from_fov(640, 480, 180.0)
    with pytest.raises(ValueError, match="3x3"):
        Intrinsics.from_matrix(np.eye(2), 10, 10)
    with pytest.raises(ValueError, match="fx, 0, cx"):
        Intrinsics.from_matrix([[1, 0.1, 0], [0, 1, 0], [0, 0, 1]], 10, 10)
    with pytest.raises(ValueError, match="shape"):
        LENS.project([1.0, 2.0])
    with pytest.raises(ValueError, match="shape"):
        LENS.ray([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="distortion"):
        LENS.ray([1e7, 1e7])  # far outside the calibrated field: the polynomial has no inverse there
