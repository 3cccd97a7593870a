"""Gimbal, mount and camera pose conventions; pixel <-> world ray <-> ground round trips; footprints."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from perception.camera import Intrinsics
from perception.dem import GridTerrain
from perception.pose import FRD_FROM_CAMERA, CameraMount, CameraPose, Gimbal
from perception.projection import cast_ray, footprint, pixel_to_ground, pixel_to_ray_world, world_to_pixel
from perception.rotations import rot_z
from perception.terrain import FlatTerrain, HillsTerrain

H = math.pi / 2
NORTH, EAST, DOWN = np.eye(3)
PLAIN = Intrinsics.from_fov(640, 480, 90.0)
LENS = Intrinsics(800.0, 790.0, 321.3, 238.6, 640, 480, (-0.28, 0.09, 0.0012, -0.0007, -0.012))
SETTINGS = settings(max_examples=80, deadline=None)


# ------------------------------------------------------------------------------ hand-checked frames


def test_camera_axes_at_zero_gimbal_look_forward():
    pose = CameraPose.from_vehicle([0, 0, 0], 0.0, 0.0, 0.0)
    R = pose.R_world_from_cam
    assert np.allclose(R @ [0, 0, 1], NORTH)  # optical axis = body forward
    assert np.allclose(R @ [1, 0, 0], EAST)  # image right = body right
    assert np.allclose(R @ [0, 1, 0], DOWN)  # image down = body down
    assert np.allclose(FRD_FROM_CAMERA, [[0, 0, 1], [1, 0, 0], [0, 1, 0]])


def test_tilt_minus_90_looks_down_with_image_up_forward():
    pose = CameraPose.from_vehicle([0, 0, -50], 0.0, 0.0, 0.0, Gimbal(0.0, -H))
    assert np.allclose(pose.optical_axis, DOWN)
    assert np.allclose(pose.R_world_from_cam @ [0, -1, 0], NORTH)  # image up = forward
    assert np.allclose(pose.R_world_from_cam @ [1, 0, 0], EAST)


def test_pan_right_and_vehicle_yaw():
    assert np.allclose(CameraPose.from_vehicle([0, 0, 0], 0, 0, 0, Gimbal(H, 0.0)).optical_axis, EAST)
    # heading east, camera 45° down: the axis points east and down
    pose = CameraPose.from_vehicle([0, 0, 0], 0.0, 0.0, H, Gimbal(0.0, -math.pi / 4))
    assert np.allclose(pose.optical_axis, [0, math.sqrt(0.5), math.sqrt(0.5)])
    # nose 10° down plus tilt -80° is straight down
    pose = CameraPose.from_vehicle([0, 0, 0], 0.0, -math.radians(10), 0.0, Gimbal(0.0, -math.radians(80)))
    assert np.allclose(pose.optical_axis, DOWN)


def test_mount_rotation_and_lever_arm():
    backwards = CameraMount(R_body_from_base=rot_z(math.pi), offset=[1.0, 0.0, 0.5])
    pose = CameraPose.from_vehicle([10.0, 20.0, -30.0], 0.0, 0.0, H, mount=backwards)
    assert np.allclose(pose.optical_axis, -EAST)  # vehicle heads east, the camera faces aft
    assert np.allclose(pose.centre, [10.0, 21.0, -29.5])  # lever arm 1 m forward (east), 0.5 m down


def test_gimbal_limits_clamp_and_wrap():
    g = Gimbal(0.0, -2.0)
    assert g.tilt == -H and g.saturated
    assert Gimbal(0.0, 1.0).tilt == pytest.approx(math.pi / 6)
    assert Gimbal(3 * H, 0.0).pan == pytest.approx(-H) and not Gimbal(3 * H, 0.0).saturated  # full circle wraps
    limited = Gimbal(2.0, 0.0, pan_limits=(-1.0, 1.0))
    assert limited.pan == 1.0 and limited.saturated
    assert limited.command(-5.0, -0.1).pan == -1.0
    d = Gimbal.from_degrees(30.0, -45.0, tilt_limits=(-90.0, 0.0))
    assert d.pan == pytest.approx(math.radians(30)) and d.tilt_limits == pytest.approx((-H, 0.0))
    looking = Gimbal().look_at([1.0, 1.0, math.sqrt(2.0)])  # right-forward, 45° down
    assert looking.pan == pytest.approx(math.pi / 4) and looking.tilt == pytest.approx(-math.pi / 4)
    assert Gimbal(0.7, 0.0).look_at([0, 0, 1]).pan == 0.7 and Gimbal().look_at([0, 0, 1]).tilt == -H


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: Gimbal(math.nan, 0.0), "pan"),
        (lambda: Gimbal(0.0, 0.0, tilt_limits=(0.5, -0.5)), "min <= max"),
        (lambda: Gimbal(0.0, 0.0, tilt_limits=(-2.0, 0.0)), "within"),
        (lambda: Gimbal(0.0, 0.0, pan_limits=3.0), "pair"),
        (lambda: Gimbal().look_at([0, 0, 0]), "non-zero"),
        (lambda: CameraMount(R_body_from_base=2 * np.eye(3)), "orthonormal"),
        (lambda: CameraMount(offset=[0, 0]), "offset"),
        (lambda: CameraPose(np.eye(3), [0, 0, math.inf]), "centre"),
        (lambda: CameraPose(np.diag([1.0, -1.0, 1.0]), [0, 0, 0]), "reflection"),
        (lambda: CameraPose.from_vehicle([0, 0, 0], math.nan, 0, 0), "roll"),
        (lambda: CameraPose.from_vehicle([0, 0], 0, 0, 0), "position"),
    ],
)
def test_bad_pose_inputs(make, match):
    with pytest.raises(ValueError, match=match):
        make()


# ------------------------------------------------------------------------------ pixels and rays


def test_centre_pixel_gives_the_boresight():
    pose = CameraPose.from_vehicle([0, 0, -100], 0.1, -0.2, 0.3, Gimbal(0.4, -0.9))
    assert np.allclose(pixel_to_ray_world(pose, LENS, [LENS.cx, LENS.cy]), pose.optical_axis)


def test_points_behind_the_camera():
    pose = CameraPose.from_vehicle([0, 0, -100], 0.0, 0.0, 0.0, Gimbal(0.0, -H))
    assert world_to_pixel(pose, PLAIN, [0.0, 0.0, -200.0]) is None  # straight above
    assert world_to_pixel(pose, PLAIN, [5.0, 0.0, -100.001]) is None  # just behind the optical centre
    uv = world_to_pixel(pose, PLAIN, [[0.0, 0.0, -200.0], [0.0, 0.0, 0.0]])
    assert np.all(np.isnan(uv[0])) and np.allclose(uv[1], [PLAIN.cx, PLAIN.cy])
    with pytest.raises(ValueError, match="shape"):
        world_to_pixel(pose, PLAIN, [1.0, 2.0])


def test_nadir_footprint_by_hand():
    h = 100.0
    pose = CameraPose.from_vehicle([5.0, -7.0, -h], 0.0, 0.0, 0.0, Gimbal(0.0, -H))
    corners = footprint(pose, PLAIN, FlatTerrain(0.0))
    # 90° HFOV: half-width h east-west, 0.75 h north-south; image top = north.
    expected = [[0.75 * h, -h], [0.75 * h, h], [-0.75 * h, h], [-0.75 * h, -h]]
    for got, (n, e) in zip(corners, expected, strict=True):
        assert np.allclose(got, [5.0 + n, -7.0 + e, 0.0])


def test_footprint_corners_above_the_horizon_are_none():
    pose = CameraPose.from_vehicle([0, 0, -50], 0.0, 0.0, 0.0, Gimbal(0.0, 0.0))  # looking at the horizon
    tl, tr, br, bl = footprint(pose, PLAIN, FlatTerrain(0.0))
    assert tl is None and tr is None
    assert br is not None and bl is not None and br[1] > 0 > bl[1]
    assert pixel_to_ground(pose, PLAIN, FlatTerrain(0.0), [PLAIN.cx, 10.0]) is None
    assert footprint(pose, PLAIN, FlatTerrain(0.0), max_range=60.0) == [None] * 4


def test_cast_ray_misses_and_bad_input():
    flat = FlatTerrain(10.0)
    assert cast_ray(flat, [0, 0, -5], DOWN) is None  # starts below the ground (altitude 5 < 10)
    assert np.allclose(cast_ray(flat, [0, 0, -10], DOWN), [0, 0, -10])  # on the ground
    assert cast_ray(flat, [0, 0, -100], NORTH) is None  # level
    assert cast_ray(flat, [0, 0, -100], [1, 0, 0.001], max_range=1000.0) is None  # beyond range
    with pytest.raises(ValueError, match="non-zero"):
        cast_ray(flat, [0, 0, -100], [0, 0, 0])
    with pytest.raises(ValueError, match="finite"):
        cast_ray(flat, [0, 0, math.nan], DOWN)
    with pytest.raises(ValueError, match="pixel"):
        pixel_to_ground(CameraPose(np.eye(3), [0, 0, -1]), PLAIN, flat, [1.0])


# ------------------------------------------------------------------------------ round trips


def poses(draw_angle_tilt=(-H, -0.35)):
    """(north, east, altitude, roll, pitch, yaw, pan, tilt)."""
    return st.tuples(
        st.floats(-500, 500),
        st.floats(-500, 500),
        st.floats(20, 800),
        st.floats(-0.5, 0.5),
        st.floats(-0.5, 0.5),
        st.floats(-math.pi, math.pi),
        st.floats(-math.pi, math.pi),
        st.floats(*draw_angle_tilt),
    )


def make_pose(p):
    n, e, alt, roll, pitch, yaw, pan, tilt = p
    return CameraPose.from_vehicle(
        [n, e, -alt], roll, pitch, yaw, Gimbal(pan, tilt), CameraMount(offset=[0.3, -0.1, 0.2])
    )


fractions = st.tuples(st.floats(0, 1), st.floats(0, 1))


@SETTINGS
@given(poses(), fractions, st.sampled_from([PLAIN, LENS]), st.floats(-50, 50))
def test_round_trip_pixel_ground_pixel_on_flat_terrain(p, frac, cam, level):
    pose, ground = make_pose(p), FlatTerrain(level)
    pixel = np.array([-0.5 + frac[0] * cam.width, -0.5 + frac[1] * cam.height])
    hit = pixel_to_ground(pose, cam, ground, pixel, max_range=2e4)
    assume(hit is not None)
    uv = world_to_pixel(pose, cam, hit)  # world -> pixel
    assert np.allclose(uv, pixel, rtol=0, atol=1e-9)
    again = pixel_to_ground(pose, cam, ground, uv, max_range=2e4)  # pixel -> ray -> ground
    assert np.allclose(again, hit, rtol=0, atol=1e-9)
    assert again[2] == -level


@SETTINGS
@given(poses((-H, -0.6)), st.floats(-1, 1), st.floats(-1, 1), st.sampled_from([PLAIN, LENS]))
def test_round_trip_world_pixel_ground_on_flat_terrain(p, a, b, cam):
    pose, ground = make_pose(p), FlatTerrain(0.0)
    aim = cast_ray(ground, pose.centre, pose.optical_axis, max_range=2e4)
    assume(aim is not None)
    # a ground point (world first) somewhere around where the camera looks
    reach = 0.8 * float(np.linalg.norm(aim - pose.centre))
    point = np.array([aim[0] + a * reach, aim[1] + b * reach, 0.0])
    uv = world_to_pixel(pose, cam, point)
    assume(uv is not None and cam.contains(uv))
    back = pixel_to_ground(pose, cam, ground, uv, max_range=2e4)
    assert back is not None and np.allclose(back, point, rtol=0, atol=1e-9)


HILLS = HillsTerrain(amplitude=12.0, wavelength=300.0, seed=2)
GRIDS = {k: GridTerrain.sample(HILLS, -1500.0, -1500.0, 25.0, (121, 121), k) for k in ("bilinear", "triangles")}


@SETTINGS
@given(poses((-H, -0.9)), fractions, st.sampled_from(sorted(GRIDS)), st.sampled_from([PLAIN, LENS]))
def test_round_trip_on_a_terrain_grid(p, frac, kind, cam):
    grid = GRIDS[kind]
    pose = make_pose(p)
    pixel = np.array([-0.5 + frac[0] * cam.width, -0.5 + frac[1] * cam.height])
    d = pixel_to_ray_world(pose, cam, pixel)
    assume(d[2] > 1.5 * grid.max_slope * math.hypot(d[0], d[1]))  # steeper than any slope: one crossing
    hit = pixel_to_ground(pose, cam, grid, pixel)
    assume(hit is not None)
    assert abs(-hit[2] - grid.height(hit[0], hit[1])) < 1e-9  # on the surface
    uv = world_to_pixel(pose, cam, hit)
    assert np.allclose(uv, pixel, rtol=0, atol=1e-9)
    assert np.allclose(pixel_to_ground(pose, cam, grid, uv), hit, rtol=0, atol=1e-9)


def test_hills_ground_point_lies_on_the_ray_and_surface():
    pose = CameraPose.from_vehicle([0, 0, -300], 0.05, -0.1, 0.7, Gimbal(0.2, -0.8))
    hit = pixel_to_ground(pose, LENS, HILLS, [100.0, 400.0])
    assert abs(-hit[2] - HILLS.height(hit[0], hit[1])) < 1e-6
    assert np.allclose(world_to_pixel(pose, LENS, hit), [100.0, 400.0], atol=1e-6)
