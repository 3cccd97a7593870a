"""Rotation conventions: Z-Y-X Euler (body FRD -> NED), scalar-last quaternions, hand-checked cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from perception.rotations import (
    as_rotation,
    euler_from_rotation,
    quaternion_from_euler,
    quaternion_from_rotation,
    quaternion_multiply,
    rot_x,
    rot_y,
    rot_z,
    rotation_from_euler,
    rotation_from_quaternion,
)

SETTINGS = settings(max_examples=60, deadline=None)
FORWARD, RIGHT, DOWN = np.eye(3)
NORTH, EAST = np.eye(3)[:2]
UP = -DOWN
H = math.pi / 2

angles = st.floats(-math.pi, math.pi, allow_nan=False)
pitches = st.floats(-1.5, 1.5, allow_nan=False)


# -------------------------------------------------------------------------------- hand-checked cases


def test_elementary_rotations_by_hand():
    # +90° about z turns x into y; about x turns y into z; about y turns z into x (right-handed).
    assert np.allclose(rot_z(H) @ [1, 0, 0], [0, 1, 0])
    assert np.allclose(rot_x(H) @ [0, 1, 0], [0, 0, 1])
    assert np.allclose(rot_y(H) @ [0, 0, 1], [1, 0, 0])
    assert np.allclose(rot_y(H), [[0, 0, 1], [0, 1, 0], [-1, 0, 0]])


def test_yaw_90_maps_body_forward_to_east():
    R = rotation_from_euler(0.0, 0.0, H)
    assert np.allclose(R @ FORWARD, EAST)
    assert np.allclose(R @ RIGHT, -NORTH)  # the right wing points west
    assert np.allclose(R @ DOWN, DOWN)


def test_pitch_up_maps_forward_to_up_and_pitch_down_to_down():
    assert np.allclose(rotation_from_euler(0.0, H, 0.0) @ FORWARD, UP)
    assert np.allclose(rotation_from_euler(0.0, -H, 0.0) @ FORWARD, DOWN)
    # 30° nose down: forward is (cos 30°, 0, +sin 30°) in NED (z down).
    assert np.allclose(rotation_from_euler(0.0, -math.pi / 6, 0.0) @ FORWARD, [math.sqrt(3) / 2, 0, 0.5])


def test_roll_right_maps_right_wing_down():
    R = rotation_from_euler(H, 0.0, 0.0)
    assert np.allclose(R @ RIGHT, DOWN)
    assert np.allclose(R @ DOWN, -EAST)
    assert np.allclose(R @ FORWARD, NORTH)


def test_order_is_yaw_then_pitch_then_roll():
    # yaw 90° then pitch 90° (nose up): forward goes up regardless of yaw; right wing points... west
    # after yaw alone, and stays horizontal after pitch.
    R = rotation_from_euler(0.0, H, H)
    assert np.allclose(R @ FORWARD, UP)
    assert np.allclose(R @ RIGHT, -NORTH)
    assert np.allclose(R, Rotation.from_euler("ZYX", [H, H, 0.0]).as_matrix())


def test_quaternion_by_hand_and_scalar_last():
    s = math.sqrt(0.5)
    q = np.array([0.0, 0.0, s, s])  # 90° about z, (x, y, z, w)
    assert np.allclose(rotation_from_quaternion(q), rot_z(H))
    assert np.allclose(quaternion_from_rotation(rot_z(H)), q)
    assert np.allclose(quaternion_from_rotation(np.eye(3)), [0, 0, 0, 1])
    assert np.allclose(quaternion_from_rotation(rot_x(math.pi)), [1, 0, 0, 0])  # w = 0 case
    assert np.allclose(quaternion_from_euler(0.0, 0.0, H), q)


# --------------------------------------------------------------------------------------- properties


@SETTINGS
@given(angles, pitches, angles)
def test_euler_matches_scipy_and_round_trips(roll, pitch, yaw):
    R = rotation_from_euler(roll, pitch, yaw)
    assert np.allclose(R, Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix(), atol=1e-12)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and math.isclose(np.linalg.det(R), 1.0)
    r2, p2, y2 = euler_from_rotation(R)
    assert np.allclose(rotation_from_euler(r2, p2, y2), R, atol=1e-12)
    assert abs(p2 - pitch) < 1e-9


@SETTINGS
@given(angles, pitches, angles)
def test_quaternion_round_trip_and_scipy(roll, pitch, yaw):
    R = rotation_from_euler(roll, pitch, yaw)
    q = quaternion_from_rotation(R)
    assert q[3] >= 0 and math.isclose(np.linalg.norm(q), 1.0)
    assert np.allclose(rotation_from_quaternion(q), R, atol=1e-12)
    q_scipy = Rotation.from_matrix(R).as_quat()  # scipy is scalar-last too
    assert np.allclose(q, q_scipy * np.sign(q_scipy[3] or 1.0), atol=1e-12)
    q_e = quaternion_from_euler(roll, pitch, yaw)
    assert np.allclose(rotation_from_quaternion(q_e), R, atol=1e-12)


def test_quaternion_product_composes_matrices():
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(2, 4))
    a /= np.linalg.norm(a)
    b /= np.linalg.norm(b)
    assert np.allclose(
        rotation_from_quaternion(quaternion_multiply(a, b)), rotation_from_quaternion(a) @ rotation_from_quaternion(b)
    )


def test_functions_broadcast():
    roll = np.linspace(-1, 1, 5)
    R = rotation_from_euler(roll, 0.2, np.zeros((2, 1)))
    assert R.shape == (2, 5, 3, 3)
    q = quaternion_from_rotation(R)
    assert q.shape == (2, 5, 4)
    assert np.allclose(rotation_from_quaternion(q), R)
    r, p, y = euler_from_rotation(R)
    assert np.allclose(r, np.broadcast_to(roll, (2, 5)))


def test_gimbal_lock_keeps_the_matrix():
    R = rotation_from_euler(0.4, H, 1.0)
    r, p, y = euler_from_rotation(R)
    assert r == 0.0 and math.isclose(p, H)
    assert np.allclose(rotation_from_euler(r, p, y), R, atol=1e-9)


def test_bad_rotations_and_quaternions():
    with pytest.raises(ValueError, match="3x3"):
        as_rotation(np.eye(2))
    with pytest.raises(ValueError, match="orthonormal"):
        as_rotation(2 * np.eye(3))
    with pytest.raises(ValueError, match="reflection"):
        as_rotation(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="non-finite"):
        as_rotation(np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match="non-zero"):
        rotation_from_quaternion([0, 0, 0, 0])
    with pytest.raises(ValueError, match="4 components"):
        rotation_from_quaternion([0, 0, 1])
