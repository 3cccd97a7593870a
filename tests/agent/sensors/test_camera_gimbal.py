"""The camera's gimbal: a steered gimbal keeps the commanded point at the image centre over a banked flight (real
rendering and detection, checked in closed form through perception's projection), and a fixed gimbal gives the
bearings it gave before steering existed, whatever it is told to point at."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.sensors.camera import CameraSensor
from agent.sensors.camera_config import CameraSensorConfig
from agent.vehicles.base import Setpoint
from agent.vehicles.fixed_wing import FixedWingModel
from perception.pose import CameraPose
from perception.projection import world_to_pixel

#: Pixel distance from the principal point within which a steered gimbal keeps its point (chosen here: the blob
#: detector's centroid of a 10 px-radius disc drawn with sensor noise is good to well under a pixel).
CENTRE_TOLERANCE_PX = 2.0
STEP = 0.2  # s, the agent's cycle


def banked_flight(steps: int):
    """A fixed wing at 20 m/s turning onto a 120 m circle 80 m above the origin (banked): its states every STEP."""
    wing = FixedWingModel([-120.0, 0.0, -80.0], heading=0.0, airspeed=20.0)
    wing.set_setpoint(Setpoint(np.array([0.0, 0.0, -80.0]), orbit=(np.zeros(2), 120.0, 1)))
    for _ in range(steps):
        yield wing.state()
        wing.step(STEP)


class RecordingDetector:
    """The sensor's detector, keeping the centres it found in each frame."""

    def __init__(self, inner):
        self.inner, self.centres = inner, []

    def detect(self, frame):
        result = self.inner.detect(frame)
        self.centres.append([d.center for d in result.detections])
        return result


def test_a_steered_gimbal_keeps_the_point_at_the_image_centre():
    point = np.array([30.0, 40.0, 0.0])  # a red disc on the ground, off the circle's centre
    sensor = CameraSensor(CameraSensorConfig(hfov=math.radians(60.0), gimbal="steered"), seed=4)
    sensor.detector = RecordingDetector(sensor.detector)
    truth = [{"id": "mark", "position": point}]
    rolls, pans = [], []
    for k, state in enumerate(banked_flight(40)):
        sensor.detect(k * STEP, state, truth)
        sensor.point(point)  # the agent hands it the goal's look_at after planning
        if k < 3:
            continue  # the first frame is taken before any command, the next ones slew from nadir
        pose = CameraPose.from_vehicle(state.position, state.roll, state.pitch, state.yaw, sensor.gimbal)
        pixel = world_to_pixel(pose, sensor.intrinsics, point[None])[0]
        centre = np.array([sensor.intrinsics.cx, sensor.intrinsics.cy])
        assert np.linalg.norm(pixel - centre) < 1e-6, k  # closed form: the point is on the optical axis
        (detected,) = sensor.detector.centres[-1]  # the rendered disc, found by the blob detector
        assert np.linalg.norm(np.asarray(detected) - centre) < CENTRE_TOLERANCE_PX, (k, detected)
        rolls.append(state.roll)
        pans.append(sensor.gimbal.pan)
    assert np.max(np.abs(rolls)) > math.radians(30.0)  # the aircraft banked hard: the gimbal compensated it
    assert np.ptp(pans) > math.radians(30.0)  # and it turned to keep the point while the aircraft circled
    gimbal = sensor.metrics()["gimbal"]
    errors = gimbal["pointing_error_deg"]  # every frame after the first command, the two slewing ones included
    assert errors["samples"] == 39 and errors["p95"] < 1.0 and errors["max"] > 10.0 and gimbal["out_of_travel"] == 0
    assert sensor.telemetry()["gimbal_pan"] == sensor.gimbal.pan


def test_the_gimbal_slews_at_its_rate_limit():
    sensor = CameraSensor(CameraSensorConfig(gimbal="steered", gimbal_rate=math.radians(50.0)), seed=4)
    states = list(banked_flight(2))
    sensor.detect(0.0, states[0], [])
    sensor.point(states[0].position + np.array([0.0, 0.0, 10.0]) + np.array([0.0, 300.0, 0.0]))  # far east
    sensor.detect(STEP, states[1], [])
    assert abs(sensor.gimbal.tilt - (-math.pi / 2)) == pytest.approx(math.radians(50.0) * STEP)


# -- a fixed gimbal: today's behaviour --------------------------------------------------------------------------
TARGETS = [{"id": "a", "position": np.array([60.0, 10.0, 0.0])}, {"id": "b", "position": np.array([120.0, -15.0, 0.0])}]
#: The azimuth and elevation (rad) of the bearings of :func:`fixed_bearings`, computed by the camera sensor before
#: the gimbal could be steered (main at 2f56315).
BEFORE = [
    [0.15585705732, -1.01348855585], [0.16792401197, -1.047494105976], [0.221927931382, -1.088481694806],
    [0.254837390795, -1.112912799193], [0.290518631413, -1.14102070208], [0.314795635215, -1.175329898822],
    [0.327874188598, -1.209991472943], [0.41972994466, -1.249630359281], [0.525682738015, -1.283538717256],
    [0.640486789445, -1.319157429808], [0.74517695828, -1.339982740958], [0.891867988916, -1.36039536682],
    [1.109982506183, -1.366923710478], [1.40662069003, -1.375490720479], [1.625677923188, -1.369696384538],
    [-0.120804115777, -0.948272492474], [1.765093838204, -1.352634936347], [-0.101985573361, -0.97454823197],
    [1.892074615495, -1.321665419031], [-0.114467245423, -1.003319659237], [2.015422990661, -1.303180948774],
    [-0.122742648606, -1.0643277588], [2.238182072287, -1.267599647181], [-0.080774704205, -1.069381575013],
    [2.265910206881, -1.251467601831], [-0.053084850704, -1.110885383437], [2.327400010694, -1.208301427409],
    [-0.042491108314, -1.150016098711], [2.37311028401, -1.171169778419], [2.421650733059, -1.138402364107],
    [-0.015606658092, -1.18601333838], [2.473944849215, -1.094227415188], [0.006605456149, -1.23972906293],
    [2.522924986669, -1.060004841815], [0.063396045116, -1.279457286785], [2.558440700456, -1.047294083606],
    [0.015173989933, -1.313131067855], [2.555822178164, -1.034114241623], [0.064581041806, -1.33038814084],
]


def fixed_bearings(point_at=None) -> list:
    """Bearings of a down-looking camera (the default, fixed gimbal) flown past TARGETS with attitude noise;
    ``point_at`` is handed to the sensor every step."""
    sensor = CameraSensor(CameraSensorConfig(attitude_noise=math.radians(0.5)), seed=11)
    wing = FixedWingModel([0.0, 0.0, -80.0], heading=0.2, airspeed=18.0)
    wing.set_setpoint(Setpoint(np.array([400.0, -100.0, -80.0])))
    out = []
    for k in range(30):
        out += sensor.detect(0.2 * k, wing.state(), TARGETS)
        sensor.point(point_at)
        wing.step(0.2)
    assert "gimbal" not in sensor.metrics() and "gimbal_pan" not in sensor.telemetry()
    return out


def test_a_fixed_gimbal_gives_the_bearings_it_gave_before_and_ignores_pointing():
    bearings = fixed_bearings()
    np.testing.assert_allclose([b.azel for b in bearings], BEFORE, rtol=1e-9, atol=1e-11)
    told = fixed_bearings(point_at=np.array([100.0, 300.0, 0.0]))
    assert len(told) == len(bearings)
    for a, b in zip(told, bearings, strict=True):
        np.testing.assert_array_equal(a.azel, b.azel)
        np.testing.assert_array_equal(a.R, b.R)
