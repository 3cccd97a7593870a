"""The sensor registry (agent.sensors.registry): ``[sensor]`` tables of each kind, their errors, scenario
overrides that switch the kind, and the sensor each config builds."""

from __future__ import annotations

import math

import pytest

from agent.config import AgentScenario
from agent.sensors.bearing import BearingSensorConfig, GeometricBearingSensor
from agent.sensors.camera import CameraSensor
from agent.sensors.camera_config import CameraSensorConfig
from agent.sensors.registry import SENSORS, sensor_config_from_dict, sensor_from_config
from mesh_sim.scenario import load

D = math.radians


def test_sensor_config_kinds():
    assert isinstance(sensor_config_from_dict({}), BearingSensorConfig)
    assert isinstance(sensor_config_from_dict({"kind": "bearing", "sigma_deg": 2.0}), BearingSensorConfig)
    cam = sensor_config_from_dict({"kind": "camera", "hfov_deg": 60.0, "tilt_deg": -80.0, "gps_latency": 0.43,
                                   "latency_compensation": True, "failed": "none", "detector": "dark"})
    assert isinstance(cam, CameraSensorConfig)
    assert cam.hfov == pytest.approx(D(60.0)) and cam.tilt == pytest.approx(D(-80.0)) and cam.failed is None
    assert cam.gps_latency == 0.43 and cam.latency_compensation and cam.detector == "dark"
    for bad, match in (({"kind": "lidar"}, "bearing or camera"), ({"kind": "camera", "hfov": 60}, "hfov"),
                       ({"kind": "camera", "detector": "yolo"}, "detector"),
                       ({"kind": "camera", "gps_latency": -1.0}, "gps_latency"),
                       ({"kind": "camera", "latency_compensation": 1}, "true or false"),
                       ({"kind": "camera", "failed": "smoke"}, "failed")):
        with pytest.raises(ValueError, match=match):
            sensor_config_from_dict(bad)
    scenario = AgentScenario.from_dict({"sensor": {"kind": "camera", "width": 320, "height": 240}})
    assert isinstance(scenario.sensor, CameraSensorConfig) and scenario.sensor.width == 320


def test_a_sensor_override_of_another_kind_replaces_the_section():
    # default.toml has camera settings; switching the kind must not carry them over
    bearing = load("default", sensor={"kind": "bearing", "range": 123.0}).agent.sensor
    assert isinstance(bearing, BearingSensorConfig) and bearing.range == 123.0
    camera = load("default", sensor={"width": 320, "height": 240}).agent.sensor  # same kind: merged
    assert isinstance(camera, CameraSensorConfig) and (camera.width, camera.height) == (320, 240)
    assert camera.hfov == pytest.approx(math.radians(90.0))  # the rest of the section is kept
    assert isinstance(load("default", sensor={"kind": "bearing"}).agent.sensor, BearingSensorConfig)
    assert load("default", sensor={"gps_latency": 0.43}).agent.sensor.width == 640


class _Source:
    size = (320, 240)
    name = "scripted"

    def read(self):
        return None

    def close(self):
        pass


def test_each_config_builds_its_sensor_and_a_video_source_makes_a_camera():
    assert set(SENSORS) == {"bearing", "camera"}
    assert isinstance(sensor_from_config(BearingSensorConfig(), 0), GeometricBearingSensor)
    camera = sensor_from_config(CameraSensorConfig(width=320, height=240), 0)
    assert isinstance(camera, CameraSensor) and camera.intrinsics.width == 320
    external = sensor_from_config(BearingSensorConfig(), 0, source=_Source())
    assert isinstance(external, CameraSensor) and external.config == CameraSensorConfig()
    assert external.source.name == "scripted" and external.intrinsics.width == 320  # rescaled to the source
    with pytest.raises(TypeError, match="unknown sensor config dict"):
        sensor_from_config({"kind": "bearing"}, 0)
    with pytest.raises(ValueError, match="bearing or camera"):
        sensor_config_from_dict({"kind": ["camera"]})
