"""Pan/tilt pointing (spec 003 §2.9): the pointed camera of perception projects the target onto the principal
point, the angles agree with perception's gimbal, hand-checked cases, limits, rate limits and bad inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from perception.camera import Intrinsics
from perception.pose import DEFAULT_PAN_LIMITS, DEFAULT_TILT_LIMITS, CameraMount, CameraPose, Gimbal
from perception.projection import world_to_pixel
from perception.rotations import rotation_from_euler
from tasking.gimbal import (
    CameraMounting,
    GimbalAngles,
    GimbalLimits,
    VehiclePose,
    line_of_sight,
    off_axis_angle,
    point_at,
    rotation_ned_from_frd,
    slew,
)

CAMERA = Intrinsics.from_fov(640, 480, 30.0)
FULL_TRAVEL = GimbalLimits(tilt=(-0.5 * math.pi, 0.5 * math.pi))
angle = st.floats(-math.pi, math.pi)
attitude = st.floats(math.radians(-40), math.radians(40))


def test_default_travel_is_perceptions():
    limits = GimbalLimits()
    assert limits.pan == DEFAULT_PAN_LIMITS and limits.tilt == DEFAULT_TILT_LIMITS


@settings(max_examples=50, deadline=None)
@given(roll=angle, pitch=st.floats(-1.5, 1.5), yaw=angle)
def test_body_rotation_is_perceptions(roll, pitch, yaw):
    np.testing.assert_allclose(rotation_ned_from_frd(roll, pitch, yaw), rotation_from_euler(roll, pitch, yaw),
                               atol=1e-15)


def random_mount(seed: int) -> tuple[CameraMounting, CameraMount]:
    rng = np.random.default_rng(seed)
    R = rotation_from_euler(*rng.uniform(-0.3, 0.3, 3))
    arm = rng.uniform(-0.5, 0.5, 3)
    return CameraMounting(R, arm), CameraMount(R, arm)


@settings(max_examples=80, deadline=None)
@given(
    roll=attitude,
    pitch=attitude,
    yaw=angle,
    north=st.floats(-500, 500),
    east=st.floats(-500, 500),
    height=st.floats(-200, 400),  # target below or above the aircraft
    seed=st.integers(0, 1000),
)
def test_pointed_camera_images_the_target_at_the_principal_point(roll, pitch, yaw, north, east, height, seed):
    """Closed form: with the angles pointed at it, the target projects (through perception's camera model,
    mounting and gimbal) exactly onto the principal point (cx, cy)."""
    mount, perception_mount = random_mount(seed)
    pose = VehiclePose([10.0, -20.0, -150.0], roll, pitch, yaw)
    target = np.array([north, east, -150.0 - height])
    if np.linalg.norm(target - pose.position) < 5.0:
        return  # the lever arm puts the camera within a metre of the vehicle: skip targets that close
    angles = point_at(pose, target, FULL_TRAVEL, mount)
    camera = CameraPose.from_vehicle(pose.position, roll, pitch, yaw, Gimbal(angles.pan, angles.tilt, tilt_limits=(
        -0.5 * math.pi, 0.5 * math.pi)), perception_mount)
    pixel = world_to_pixel(camera, CAMERA, target)
    assert pixel is not None  # in front of the camera
    np.testing.assert_allclose(pixel, [CAMERA.cx, CAMERA.cy], atol=1e-6)
    assert off_axis_angle(pose, angles, target, mount) < 1e-9
    # perception's own look_at, given the same base-frame direction, picks the same angles
    look = Gimbal(tilt_limits=(-0.5 * math.pi, 0.5 * math.pi)).look_at(line_of_sight(pose, target, mount))
    assert look.tilt == pytest.approx(angles.tilt, abs=1e-12)
    assert math.cos(look.pan - angles.pan) == pytest.approx(1.0, abs=1e-12)


def test_hand_checked_directions():
    level_north = VehiclePose([0.0, 0.0, -100.0], 0.0, 0.0, 0.0)
    below = point_at(level_north, [0.0, 0.0, 0.0], current=GimbalAngles(0.7, 0.0))
    assert below.tilt == pytest.approx(-0.5 * math.pi) and below.pan == 0.7  # nadir keeps the current pan
    ahead = point_at(level_north, [100.0, 0.0, 0.0])
    assert (ahead.pan, ahead.tilt) == pytest.approx((0.0, -0.25 * math.pi))
    right = point_at(level_north, [0.0, 100.0, 0.0])
    assert (right.pan, right.tilt) == pytest.approx((0.5 * math.pi, -0.25 * math.pi))
    # banked 30° right (right wing down) the belly faces 30° left of nadir: a target there is along body down
    banked = VehiclePose([0.0, 0.0, -100.0], math.radians(30.0), 0.0, 0.0)
    along_body_down = point_at(banked, [0.0, -100.0 * math.tan(math.radians(30.0)), 0.0])
    assert along_body_down.tilt == pytest.approx(-0.5 * math.pi)
    # heading east, the same target to the south is on the right
    east = VehiclePose([0.0, 0.0, -100.0], 0.0, 0.0, 0.5 * math.pi)
    assert point_at(east, [-100.0, 0.0, 0.0]).pan == pytest.approx(0.5 * math.pi)


def test_unreachable_targets_raise():
    pose = VehiclePose([0.0, 0.0, -100.0], 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="beyond the tilt limits"):
        point_at(pose, [0.0, 0.0, -300.0])  # straight above the camera: tilt +90° > 30°
    with pytest.raises(ValueError, match="beyond the tilt limits"):
        point_at(pose, [100.0, 0.0, -200.0])  # 45° above the horizon ahead
    with pytest.raises(ValueError, match="beyond the pan limits"):
        point_at(pose, [-100.0, 0.0, 0.0], GimbalLimits(pan=(-0.5 * math.pi, 0.5 * math.pi)))  # behind


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: VehiclePose([0.0, math.nan, -100.0], 0.0, 0.0, 0.0), "non-finite"),  # NaN position
        (lambda: VehiclePose([0.0, 0.0, -100.0], math.nan, 0.0, 0.0), "vehicle roll"),  # NaN roll
        (lambda: VehiclePose([0.0, 0.0, -100.0], 0.0, 0.0, math.inf), "vehicle yaw"),  # infinite yaw
        (lambda: point_at(VehiclePose([0.0, 0.0, -100.0], 0, 0, 0), [0.0, 0.0, -100.0]), "camera centre"),
        (lambda: point_at(VehiclePose([0.0, 0.0, -100.0], 0, 0, 0), [math.nan, 0.0, 0.0]), "non-finite"),
        (lambda: GimbalLimits(tilt=(-2.0, 0.0)), "within \\[-π/2, π/2\\]"),  # tilt below straight down
        (lambda: GimbalLimits(pan_rate=0.0), "positive"),  # a frozen servo
        (lambda: CameraMounting(np.diag([1.0, 1.0, -1.0])), "reflection"),
        (lambda: GimbalAngles(math.nan, 0.0), "gimbal pan"),
    ],
)
def test_bad_inputs_raise(build, message):
    with pytest.raises(ValueError, match=message):
        build()


def test_slew_respects_the_rates_and_wraps_the_shorter_way():
    limits = GimbalLimits(pan_rate=2.0, tilt_rate=1.0)
    moved = slew(GimbalAngles(0.0, 0.0), GimbalAngles(1.0, -1.0), limits, 0.1)
    assert (moved.pan, moved.tilt) == pytest.approx((0.2, -0.1))
    across = slew(GimbalAngles(math.radians(170), 0.0), GimbalAngles(math.radians(-170), 0.0), limits, 1.0)
    assert across.pan == pytest.approx(math.radians(-170))  # +20° through 180°, not -340°
    bounded = GimbalLimits(pan=(-math.pi, 0.99 * math.pi), pan_rate=0.5)  # not continuous: no wrap
    step = slew(GimbalAngles(3.0, 0.0), GimbalAngles(-3.0, 0.0), bounded, 1.0)
    assert step.pan == pytest.approx(2.5)
    state, goal = GimbalAngles(0.0, 0.0), GimbalAngles(-2.0, -1.2)
    for _ in range(30):
        state = slew(state, goal, limits, 0.1)
    assert (state.pan, state.tilt) == pytest.approx((goal.pan, goal.tilt))
    with pytest.raises(ValueError, match="dt"):
        slew(state, goal, limits, -0.1)  # time running backwards


def test_off_axis_angle_of_a_lagging_pan():
    pose = VehiclePose([0.0, 0.0, -100.0], 0.0, 0.0, 0.0)
    target = [0.0, 100.0, -100.0]  # level, 90° right
    assert off_axis_angle(pose, GimbalAngles(math.radians(80), 0.0), target) == pytest.approx(math.radians(10))
