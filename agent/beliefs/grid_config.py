"""``[grid]``: the agent's certainty grid — belief type, fusion policy, sensor model, exchange, alarms."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from agent.net.grid_codec import check_tolerance
from agent.sensors.fire_camera_config import FireCameraConfig
from fusion.channel_filter import Policy
from fusion.grid import detection_boundary
from fusion.grid_forgetting import Forgetting
from fusion.grid_geometry import GridGeometry
from fusion.grid_layers import BELIEFS, GridLayers
from perception.grid_sensor_model import DetectionModel, PoseNoise

INTERSECTS = ("chernoff", "max", "half")


@dataclass(frozen=True)
class GridConfig:
    belief: str = "logodds"  # "logodds" (Merino Alg. 4.2/4.3) or "beta" (Alg. 4.4/4.5)
    cell: float = 5.0  # m (chosen here)
    policy: str = "hybrid"  # channel filters: exact, ci (intersection only), hybrid, naive
    intersect: str = "chernoff"  # the conservative rule on loops: chernoff (WEP), max (Merino (4.5)/(4.39)), half
    period: float = 2.0  # s between grid broadcasts (chosen here)
    delta: bool = True  # send deltas against acknowledged messages (False: a keyframe every time)
    keyframe_every: int = 10  # messages between forced keyframes (chosen here)
    delta_tolerance: float = 0.0  # deadband q: a cell travels when |x - b| > q max(1, |b|) (0: every float32 change)
    alarm_threshold: float = 0.8  # cell probability above which cells form alarms (Merino's example value)
    alarm_period: float = 5.0  # s between alarm extractions, T of Merino §4.2.2 (chosen here)
    half_life: float = 0.0  # s: evidence forgetting on the common clock (fusion.grid_forgetting); 0: static grid
    plan_spread: float = 0.0  # planning only: omega of (6.6) per planning step (0: plan on the map as it is)
    plan_steps: int = 4  # planning only: fire-spread steps predicted before the entropy is computed (chosen here)
    handoff: bool = False  # alarms located by the tracker from the thermal camera's hot spots (Merino Ch. 8)
    detection: DetectionModel = field(default_factory=DetectionModel)
    pose_noise: PoseNoise = field(default_factory=PoseNoise)
    camera: FireCameraConfig = field(default_factory=FireCameraConfig)

    def __post_init__(self):
        if self.belief not in BELIEFS:
            raise ValueError(f"grid.belief must be one of {BELIEFS}, got {self.belief!r}")
        if self.intersect not in INTERSECTS:
            raise ValueError(f"grid.intersect must be one of {INTERSECTS}, got {self.intersect!r}")
        Policy(self.policy)  # ValueError names the bad policy
        for name in ("cell", "period", "alarm_period"):
            value = getattr(self, name)
            if isinstance(value, bool) or not (np.isfinite(value) and value > 0):
                raise ValueError(f"grid.{name} must be a positive number, got {value!r}")
        if not 0.0 < self.alarm_threshold < 1.0:
            raise ValueError(f"grid.alarm_threshold must be in (0, 1), got {self.alarm_threshold!r}")
        life = self.half_life
        if isinstance(life, bool) or not isinstance(life, int | float) or not (math.isfinite(life) and life >= 0):
            raise ValueError(f"grid.half_life must be a number of seconds >= 0 (0: no forgetting), got {life!r}")
        if not 0.0 <= self.plan_spread <= 1.0:
            raise ValueError(f"grid.plan_spread must be a probability, got {self.plan_spread!r}")
        if isinstance(self.plan_steps, bool) or not isinstance(self.plan_steps, int) or self.plan_steps < 1:
            raise ValueError(f"grid.plan_steps must be a positive integer, got {self.plan_steps!r}")
        if not isinstance(self.handoff, bool):
            raise ValueError(f"grid.handoff must be true or false, got {self.handoff!r}")
        check_tolerance(self.delta_tolerance, "grid.delta_tolerance")
        if self.belief == "beta" and self.delta_tolerance > 0.0:  # measured: the exact filters fell back on a tree
            raise ValueError("grid.delta_tolerance must be 0 for belief = 'beta': counts held within a deadband make "
                             "the channel filters' subtraction (Merino (4.36)) negative where counts are small")
        if isinstance(self.keyframe_every, bool) or not isinstance(self.keyframe_every, int) or self.keyframe_every < 1:
            raise ValueError(f"grid.keyframe_every must be a positive integer, got {self.keyframe_every!r}")

    @property
    def forgetting(self) -> Forgetting | None:
        """The forgetting of ``half_life`` (``None``: a static grid)."""
        return Forgetting(self.half_life) if self.half_life > 0 else None

    def layers(self, geometry: GridGeometry) -> GridLayers:
        """The grid beliefs of these settings on ``geometry``: the belief type, the forgetting, and for Beta
        the fire boundary of the thermal camera's ``(P_D, P_F)`` (:func:`fusion.grid.detection_boundary`)."""
        boundary = detection_boundary(self.detection.pd, self.detection.pf) if self.belief == "beta" else None
        return GridLayers(self.belief, geometry, self.forgetting, boundary)

    def geometry(self, area: tuple[float, float, float, float], terrain) -> GridGeometry:
        """The grid over the scenario ``area`` (north min, max, east min, max), cell centres on the (flat)
        ground of ``terrain``."""
        level = getattr(terrain, "level", None)
        return GridGeometry.covering(area[:2], area[2:], self.cell, height=-(level or 0.0))

    @classmethod
    def from_dict(cls, d: dict) -> GridConfig:
        """From a scenario's ``[grid]`` table; angles in degrees (``*_deg``); unknown keys are errors."""
        d = dict(d)
        detection = {k: d.pop(k) for k in ("pd", "pf", "d_max", "negative") if k in d}
        noise = {k: d.pop(k) for k in ("position_sigma",) if k in d}
        if "attitude_sigma_deg" in d:
            noise["attitude_sigma"] = math.radians(_number(d.pop("attitude_sigma_deg"), "attitude_sigma_deg"))
        camera = {k: d.pop(k) for k in ("width", "height", "threshold_K", "decoy_K") if k in d}
        if "hfov_deg" in d:
            camera["hfov"] = math.radians(_number(d.pop("hfov_deg"), "hfov_deg"))
        known = {f.name for f in fields(cls)} - {"detection", "pose_noise", "camera"}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown grid settings: {sorted(unknown)}")
        return cls(**d, detection=DetectionModel(**detection), pose_noise=PoseNoise(**noise),
                   camera=FireCameraConfig(**camera))


def _number(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"grid.{name} must be a number, got {value!r}")
    return float(value)
