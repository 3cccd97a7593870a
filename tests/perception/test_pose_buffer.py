"""The pose buffer: interpolation at a query time, bounds, and Ross et al.'s GPS-latency compensation.

Every case is checked by hand (the expected numbers are worked out in the comments)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from perception.pose_buffer import PoseBuffer, PoseSample, PoseTooNew, PoseTooOld, slerp
from perception.rotations import quaternion_from_euler, rotation_from_euler

D = math.radians


def test_position_is_linear_between_samples():
    buf = PoseBuffer()
    buf.add(0.0, [0.0, 0.0, -80.0], 0.0, 0.0, 0.0)
    buf.add(1.0, [10.0, 20.0, -70.0], 0.0, 0.0, 0.0)
    # a quarter of the way: (0, 0, -80) + 0.25 (10, 20, 10)
    assert np.allclose(buf.at(0.25).position, [2.5, 5.0, -77.5])
    assert buf.at(0.25).t == 0.25
    # exactly on a sample: that sample
    assert np.allclose(buf.at(1.0).position, [10.0, 20.0, -70.0])


def test_single_axis_attitude_interpolates_the_angle():
    buf = PoseBuffer()
    buf.add(0.0, [0, 0, 0], 0.0, 0.0, 0.0)
    buf.add(2.0, [0, 0, 0], D(20.0), 0.0, 0.0)
    # slerp about one fixed axis is linear in the angle: roll 5 deg at t = 0.5
    pose = buf.at(0.5)
    assert pose.roll == pytest.approx(D(5.0), abs=1e-12)
    assert pose.pitch == pytest.approx(0.0, abs=1e-12) and pose.yaw == pytest.approx(0.0, abs=1e-12)


def test_yaw_interpolates_through_plus_minus_180_not_through_zero():
    buf = PoseBuffer()
    buf.add(0.0, [0, 0, 0], 0.0, 0.0, D(170.0))
    buf.add(1.0, [0, 0, 0], 0.0, 0.0, D(-170.0))
    # the short way from 170 to -170 (= 190) passes 180; the naive average would be 0
    assert abs(abs(buf.at(0.5).yaw) - math.pi) < 1e-9
    assert buf.at(0.25).yaw == pytest.approx(D(175.0), abs=1e-9)


def test_pan_interpolates_on_the_wrapped_difference():
    buf = PoseBuffer()
    buf.add(0.0, [0, 0, 0], 0, 0, 0, pan=D(179.0), tilt=D(-90.0))
    buf.add(1.0, [0, 0, 0], 0, 0, 0, pan=D(-179.0), tilt=D(-60.0))
    pose = buf.at(0.5)
    assert abs(abs(pose.pan) - math.pi) < 1e-9  # 179 -> 181 (= -179): midpoint 180
    assert pose.tilt == pytest.approx(D(-75.0))


def test_general_attitude_matches_scipy_slerp():
    a = (D(10.0), D(-5.0), D(30.0))
    b = (D(-20.0), D(15.0), D(100.0))
    buf = PoseBuffer()
    buf.add(0.0, [0, 0, 0], *a)
    buf.add(1.0, [0, 0, 0], *b)
    ref = Slerp([0.0, 1.0], Rotation.from_matrix([rotation_from_euler(*a), rotation_from_euler(*b)]))
    for s in (0.1, 0.37, 0.5, 0.9):
        pose = buf.at(s)
        assert np.allclose(rotation_from_euler(pose.roll, pose.pitch, pose.yaw), ref(s).as_matrix(), atol=1e-12)


def test_slerp_takes_the_shorter_arc_for_opposite_sign_quaternions():
    q0 = quaternion_from_euler(0.0, 0.0, 0.0)
    q1 = -quaternion_from_euler(0.0, 0.0, D(40.0))  # the same rotation with the sign flipped
    q = slerp(q0, q1, 0.5)
    assert np.allclose(np.abs(q), np.abs(quaternion_from_euler(0.0, 0.0, D(20.0))))


def test_too_old_and_too_new_are_clear_value_errors():
    buf = PoseBuffer(max_extrapolation=0.05)
    with pytest.raises(PoseTooNew, match="empty"):
        buf.at(0.0)
    buf.add(1.0, [0, 0, 0], 0, 0, 0)
    buf.add(2.0, [10, 0, 0], 0, 0, 0)
    with pytest.raises(PoseTooOld, match="oldest pose kept is at 1.000"):
        buf.at(0.99)
    with pytest.raises(PoseTooNew, match="newest pose is at 2.000"):
        buf.at(2.06)
    assert issubclass(PoseTooOld, ValueError) and issubclass(PoseTooNew, ValueError)
    # within the allowance: extrapolated from the last two samples (10 m/s): 2.04 s -> 10.4 m
    assert np.allclose(buf.at(2.04).position, [10.4, 0, 0])
    assert buf.covers(2.05) and not buf.covers(2.051)
    with pytest.raises(ValueError, match="finite"):
        buf.at(float("nan"))


def test_the_buffer_is_bounded_and_drops_the_oldest():
    buf = PoseBuffer(maxlen=3)
    for k in range(5):
        buf.add(float(k), [k, 0, 0], 0, 0, 0)
    assert len(buf) == 3 and buf.oldest == 2.0 and buf.newest == 4.0
    with pytest.raises(PoseTooOld):
        buf.at(1.5)


def test_out_of_order_samples_are_sorted_and_a_repeated_time_replaces():
    buf = PoseBuffer()
    buf.add(2.0, [20, 0, 0], 0, 0, 0)
    buf.add(0.0, [0, 0, 0], 0, 0, 0)
    buf.add(1.0, [99, 0, 0], 0, 0, 0)
    buf.add(1.0, [10, 0, 0], 0, 0, 0)  # replaces the bad sample at t = 1
    assert len(buf) == 3
    assert np.allclose(buf.at(0.5).position, [5, 0, 0])
    assert np.allclose(buf.at(1.5).position, [15, 0, 0])


def test_bad_samples_are_rejected_and_leave_the_buffer_unchanged():
    buf = PoseBuffer()
    buf.add(0.0, [0, 0, 0], 0, 0, 0)
    for bad in ([np.nan, 0, 0], [0, 0], "abc"):
        with pytest.raises(ValueError):
            buf.add(1.0, bad, 0, 0, 0)
    with pytest.raises(ValueError):
        buf.add(1.0, [0, 0, 0], float("inf"), 0, 0)
    assert len(buf) == 1
    with pytest.raises(ValueError):
        PoseBuffer(maxlen=1)
    with pytest.raises(ValueError):
        PoseBuffer(latency=-0.1)
    with pytest.raises(ValueError):
        PoseSample(0.0, [0, 0, 0], True, 0, 0)


def _late_telemetry(buf: PoseBuffer, speed: float, latency: float, until: float, rate: float = 5.0) -> None:
    """A vehicle flying north at ``speed``; at every report time t_r the telemetry gives its position at
    t_r - latency (the GPS is late) and stamps it t_r."""
    for k in range(int(until * rate) + 1):
        t_r = k / rate
        buf.add(t_r, [speed * (t_r - latency), 0.0, -80.0], 0.0, 0.0, 0.0)


def test_ross_latency_without_compensation_puts_the_camera_behind():
    # 10 m/s north, 0.43 s late: the pose paired with an image taken at t = 2 s is the one of 1.57 s,
    # 4.3 m behind the true 20 m (Ross: "the target will always appear to be behind").
    buf = PoseBuffer(latency=0.0)
    _late_telemetry(buf, 10.0, 0.43, until=3.0)
    assert buf.at(2.0).position[0] == pytest.approx(15.7)


def test_ross_latency_compensation_stores_reports_earlier_and_recovers_the_true_pose():
    buf = PoseBuffer(latency=0.43)
    _late_telemetry(buf, 10.0, 0.43, until=3.0)
    # the report stamped 3.0 s is stored at 2.57 s ...
    assert buf.newest == pytest.approx(2.57)
    # ... and the image taken at 2 s is paired with the true 20 m
    assert buf.at(2.0).position[0] == pytest.approx(20.0)
    # an image taken now (3 s) must wait: its pose has not arrived yet (delayed pairing)
    assert not buf.covers(3.0)
    with pytest.raises(PoseTooNew):
        buf.at(3.0)
