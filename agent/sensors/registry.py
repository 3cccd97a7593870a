"""Sensors (DESIGN §4): a scenario's ``[sensor]`` table -> a sensor config -> the agent's sensor.

``[sensor] kind`` names an entry of :data:`SENSORS`: ``"bearing"`` (the default: the geometric bearing
sensor of :mod:`agent.sensors.bearing`) or ``"camera"`` (the camera pipeline of :mod:`agent.sensors.camera`,
configured by :mod:`agent.sensors.camera_config`).

To add a sensor, write a module with a frozen config dataclass whose ``from_dict(d)`` reads the
``[sensor]`` table (rejecting unknown keys and bad values with the setting's name) and a sensor class,
and add a :class:`SensorKind` line to :data:`SENSORS`. The config modules are imported here (every scenario
is read with them); a sensor module that loads heavy libraries is imported by its factory, when an agent
builds that sensor: the camera pipeline's OpenCV is never loaded by an agent with the geometric sensor.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from agent.sensors.bearing import BearingSensorConfig, GeometricBearingSensor
from agent.sensors.camera_config import CameraSensorConfig


class SensorKind(NamedTuple):
    config_class: type  # a frozen dataclass with from_dict(d) for the [sensor] table
    factory: Callable  # factory(config, seed, terrain, source) -> the sensor


def _geometric_bearing_sensor(config: BearingSensorConfig, seed: int, terrain=None, source=None):
    """The geometric sensor draws its bearings from the truth: it needs neither the terrain nor a video."""
    return GeometricBearingSensor(config, seed)


def _camera_sensor(config: CameraSensorConfig, seed: int, terrain=None, source=None):
    """The camera pipeline (render or read, detect, bearings): OpenCV is loaded here, with the camera."""
    from agent.sensors.camera import CameraSensor

    return CameraSensor(config, seed, terrain, source)


SENSORS: dict[str, SensorKind] = {
    "bearing": SensorKind(BearingSensorConfig, _geometric_bearing_sensor),
    "camera": SensorKind(CameraSensorConfig, _camera_sensor),
}
DEFAULT_SENSOR = "bearing"


def sensor_from_config(config, seed: int, terrain=None, source=None):
    """The agent's sensor for its scenario's ``[sensor]`` config (an instance of a :data:`SENSORS` config
    class): the camera pipeline for a :class:`CameraSensorConfig` or an external ``source`` (a
    :class:`~agent.sensors.video_source.VideoSource`), else the geometric bearing sensor."""
    kind = getattr(config, "kind", None)
    if kind not in SENSORS or not isinstance(config, SENSORS[kind].config_class):
        raise TypeError(f"unknown sensor config {type(config).__name__}")
    if source is not None and kind != "camera":
        config = CameraSensorConfig()  # an external camera with the default intrinsics and pose
    return SENSORS[config.kind].factory(config, seed, terrain, source)


def sensor_config_from_dict(d: dict):
    """``[sensor]``: ``kind = "bearing"`` (default, :class:`BearingSensorConfig`) or ``"camera"``."""
    kind = d.get("kind", DEFAULT_SENSOR)
    if not (isinstance(kind, str) and kind in SENSORS):
        raise ValueError(f"sensor.kind must be {' or '.join(SENSORS)}, got {kind!r}")
    return SENSORS[kind].config_class.from_dict(d)
