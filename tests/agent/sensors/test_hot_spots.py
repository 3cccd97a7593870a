"""Hot spots (Merino Ch. 8): a thermal frame's fire blobs as bearings, gated by the grid's alarms.

The oracle is geometry in closed form: a down-looking camera 60 m above flat ground sees a hot disc around a
known ground point; the bearing the module makes, cast back onto the ground, must land on that point."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from agent.sensors.hot_spots import GATE, PIXEL_SIGMA, HotSpots, gate_distance, in_gate, inner_blobs
from fusion.grid_alarms import Alarm
from fusion.measurement import azel_to_los
from perception.camera import Intrinsics
from perception.pose import CameraPose, Gimbal
from perception.projection import world_to_pixel

INTRINSICS = Intrinsics.from_fov(160, 120, 60.0)
POSE = CameraPose.from_vehicle(np.array([10.0, -5.0, -60.0]), 0.0, 0.0, 0.3, Gimbal(0.0, -math.pi / 2))
ATTITUDE_SIGMA = math.radians(0.5)


def _frame(*ground_points, radius=3) -> np.ndarray:
    """A segmented frame with a hot disc of ``radius`` px around the pixel of each (north, east) ground point."""
    mask = np.zeros((INTRINSICS.height, INTRINSICS.width), np.uint8)
    for north, east in ground_points:
        u, v = world_to_pixel(POSE, INTRINSICS, np.array([north, east, 0.0]))
        cv2.circle(mask, (round(u), round(v)), radius, 1, -1)
    return mask.astype(bool)


def _alarm(north, east, sigma=2.0) -> Alarm:
    return Alarm(np.array([north, east]), sigma**2 * np.eye(2), 0.9, 1, 0.95)


def _ground(bearing) -> np.ndarray:
    """Where the bearing's ray meets the flat ground z = 0."""
    los = azel_to_los(bearing.azel)
    return bearing.sensor + (-bearing.sensor[2] / los[2]) * los


def test_a_blob_inside_an_alarm_becomes_a_bearing_that_points_at_the_fire():
    spots = HotSpots(INTRINSICS, ATTITUDE_SIGMA, cell=5.0)
    fire = (16.0, 2.0)
    mask = _frame(fire)
    (bearing,) = spots.bearings(3.2, mask, POSE, [_alarm(*fire)])
    assert bearing.t == 3.2 and bearing.truth_id is None
    np.testing.assert_allclose(bearing.sensor, POSE.centre)
    # the disc is drawn at the rounded pixel: the ground point is within half a pixel's footprint (~0.3 m)
    assert np.linalg.norm(_ground(bearing)[:2] - fire) < 0.3
    s2 = ATTITUDE_SIGMA**2 + (PIXEL_SIGMA / INTRINSICS.fx) ** 2
    assert bearing.R[1, 1] == pytest.approx(s2)
    assert bearing.R[0, 0] == pytest.approx(s2 / math.cos(bearing.azel[1]) ** 2)
    assert bearing.R[0, 1] == 0.0
    assert spots.kept == 1 and spots.outside == 0


def test_blobs_outside_every_gate_and_frames_without_alarms_give_nothing():
    spots = HotSpots(INTRINSICS, ATTITUDE_SIGMA, cell=5.0)
    mask = _frame((16.0, 2.0), (0.0, -15.0))  # a fire and a decoy the grid never raised
    assert spots.bearings(0.0, mask, POSE, []) == []  # no alarm yet: nothing is looked for
    (only,) = spots.bearings(0.0, mask, POSE, [_alarm(16.0, 2.0)])
    assert np.linalg.norm(_ground(only)[:2] - (16.0, 2.0)) < 0.3
    assert spots.outside == 1  # the decoy's blob


def test_blobs_cut_by_the_image_border_are_dropped():
    mask = np.zeros((120, 160), bool)
    mask[50:56, 70:76] = True  # inside
    mask[0:4, 20:30] = True  # touches the top edge
    mask[60:70, 155:160] = True  # touches the right edge
    (centre,) = inner_blobs(mask)
    np.testing.assert_allclose(centre, (72.5, 52.5))
    assert inner_blobs(np.ones((120, 160), bool)) == []  # a frame full of fire: no blob has a centre
    assert inner_blobs(np.zeros((120, 160), bool)) == []


def test_the_gate_is_mahalanobis_on_the_alarm_widened_by_one_cell():
    alarm = _alarm(0.0, 0.0, sigma=1.0)
    cell = 5.0
    edge = math.sqrt(GATE * (1.0 + cell**2))  # d^2 = r^2 / (sigma^2 + cell^2) on the edge
    assert gate_distance(np.array([edge, 0.0]), alarm, cell) == pytest.approx(GATE)
    assert in_gate(np.array([0.99 * edge, 0.0]), [alarm], cell)
    assert not in_gate(np.array([1.01 * edge, 0.0]), [alarm], cell)
    assert not in_gate(np.zeros(2), [], cell)
