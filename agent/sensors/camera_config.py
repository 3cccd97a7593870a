"""The camera sensor's configuration: the ``[sensor] kind = "camera"`` table of a scenario.

Angles are radians here and degrees in the scenario file (``*_deg`` keys, DESIGN §3); every value is
checked when the config is built, so a bad scenario fails when it is read, naming the setting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from perception.camera import Intrinsics
from perception.degradation import FAILURE_MODES, Degradation
from perception.pose import Gimbal
from tasking.gimbal import DEFAULT_RATE

DETECTORS = ("color", "dark")
RENDERS = ("roi", "full")
TARGET_SHAPES = ("disc", "sphere")
GIMBALS = ("fixed", "steered")


@dataclass(frozen=True)
class CameraSensorConfig:
    """``[sensor] kind = "camera"``. Every default is chosen here unless noted."""

    kind = "camera"  # class attribute (not a field): what sensor_config_from_dict dispatched on
    width: int = 640  # px
    height: int = 480  # px
    hfov: float = math.radians(90.0)  # horizontal field of view [rad] (config: hfov_deg)
    pan: float = 0.0  # gimbal pan [rad] (config: pan_deg)
    tilt: float = -math.pi / 2  # gimbal tilt [rad]; -90 deg looks straight down (config: tilt_deg)
    gimbal: str = "fixed"  # "fixed": pan/tilt stay as configured; "steered": slews to the planner's look_at
    gimbal_rate: float = DEFAULT_RATE  # rad/s, a steered gimbal's servo rate limit (config: gimbal_rate_deg)
    detector: str = "color"  # "color" (Ross et al. HSV blobs) or "dark" (thesis 000 dark blobs)
    render: str = "roi"  # "roi": only what the detector needs (perception.roi_render); "full": the whole frame
    persistence: bool = False  # run detections through the persistent-object filter (thesis 000 §2.3)
    edge_margin: float = 2.0  # px: blobs whose box comes this close to the border are dropped
    noise: float = 2.0  # sensor noise [gray levels] (Degradation.noise_sigma)
    banding_prob: float = 0.0  # probability of a banding episode per frame (thesis 000 §2.2)
    speckle_rate: float = 0.0  # mean transient blobs per frame
    failed: str | None = None  # None, "snow", "black" or "banding": a failed video link
    gps_latency: float = 0.0  # s by which the telemetry pose the sensor gets is late (Ross: 0.43)
    latency_compensation: bool = False  # store reports gps_latency earlier and pair frames late (Ross §VI.C)
    pixel_sigma: float = 1.0  # px: detection noise in the bearing covariance
    attitude_sigma: float = math.radians(0.5)  # rad: attitude noise in the covariance (config: attitude_sigma_deg)
    attitude_noise: float = 0.0  # rad: white attitude noise injected into the telemetry (config: attitude_noise_deg)
    target_radius: float = 1.5  # m: targets are drawn this size (a car-sized disc)
    target_shape: str = "disc"  # "disc" lying on the ground (its centre is the truth point) or "sphere"
    target_rgb: tuple[int, int, int] = (200, 20, 20)  # red, for the colour detector
    ground: str = "terrain"  # procedural ground texture: "terrain" or "tiles"
    pose_buffer: int = 64  # samples kept in the pose buffer

    def __post_init__(self):
        if self.detector not in DETECTORS:
            raise ValueError(f"sensor.detector must be one of {DETECTORS}, got {self.detector!r}")
        if self.render not in RENDERS:
            raise ValueError(f"sensor.render must be one of {RENDERS}, got {self.render!r}")
        if self.target_shape not in TARGET_SHAPES:
            raise ValueError(f"sensor.target_shape must be one of {TARGET_SHAPES}, got {self.target_shape!r}")
        if self.gimbal not in GIMBALS:
            raise ValueError(f"sensor.gimbal must be one of {GIMBALS}, got {self.gimbal!r}")
        if self.failed is not None and self.failed not in FAILURE_MODES:
            raise ValueError(f"sensor.failed must be none or one of {FAILURE_MODES}, got {self.failed!r}")
        if self.ground not in ("terrain", "tiles"):
            raise ValueError(f"sensor.ground must be terrain or tiles, got {self.ground!r}")
        for name in ("width", "height", "pose_buffer"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < (8 if name != "pose_buffer" else 2):
                raise ValueError(f"sensor.{name} must be an integer (>= 8 px, >= 2 samples), got {value!r}")
        checks = {
            "hfov": 0 < self.hfov < math.pi, "edge_margin": self.edge_margin >= 0, "noise": self.noise >= 0,
            "banding_prob": 0 <= self.banding_prob <= 1, "speckle_rate": self.speckle_rate >= 0,
            "gps_latency": self.gps_latency >= 0, "pixel_sigma": self.pixel_sigma > 0,
            "attitude_sigma": self.attitude_sigma >= 0, "attitude_noise": self.attitude_noise >= 0,
            "target_radius": self.target_radius > 0, "pan": True, "tilt": True, "gimbal_rate": self.gimbal_rate > 0,
        }
        for name, ok in checks.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not (ok and math.isfinite(value)):
                raise ValueError(f"sensor.{name} = {value!r} is out of range")
        if len(self.target_rgb) != 3 or not all(0 <= int(c) <= 255 for c in self.target_rgb):
            raise ValueError(f"sensor.target_rgb must be three values in 0..255, got {self.target_rgb!r}")
        Gimbal(self.pan, self.tilt)  # the gimbal accepts the angles (it clamps to its travel)

    @property
    def intrinsics(self) -> Intrinsics:
        return Intrinsics.from_fov(self.width, self.height, math.degrees(self.hfov))

    @property
    def degradation(self) -> Degradation:
        return Degradation(noise_sigma=self.noise, banding_prob=self.banding_prob, speckle_rate=self.speckle_rate,
                           failed=self.failed)

    @classmethod
    def from_dict(cls, d: dict) -> CameraSensorConfig:
        """From a scenario's ``[sensor]`` table (angles in degrees, named ``*_deg``)."""
        degrees = {"hfov_deg": "hfov", "pan_deg": "pan", "tilt_deg": "tilt", "attitude_sigma_deg": "attitude_sigma",
                   "attitude_noise_deg": "attitude_noise", "gimbal_rate_deg": "gimbal_rate"}
        plain = {"width", "height", "detector", "render", "persistence", "edge_margin", "noise", "banding_prob",
                 "speckle_rate", "failed", "gps_latency", "latency_compensation", "pixel_sigma", "target_radius",
                 "target_shape", "target_rgb", "ground", "pose_buffer", "gimbal"}
        unknown = set(d) - set(degrees) - plain - {"kind"}
        if unknown:
            raise ValueError(f"unknown camera sensor settings: {sorted(unknown)}")
        kwargs = {}
        for key, value in d.items():
            if key in degrees:
                kwargs[degrees[key]] = math.radians(_number(value, key))
            elif key in ("width", "height", "pose_buffer"):
                if isinstance(value, bool) or not isinstance(value, int):
                    raise ValueError(f"sensor.{key} must be an integer, got {value!r}")
                kwargs[key] = value
            elif key in ("persistence", "latency_compensation"):
                if not isinstance(value, bool):
                    raise ValueError(f"sensor.{key} must be true or false, got {value!r}")
                kwargs[key] = value
            elif key == "failed":
                kwargs[key] = None if value in (None, "none", "") else value
            elif key == "target_rgb":
                kwargs[key] = tuple(int(c) for c in value)
            elif key in ("detector", "render", "target_shape", "ground", "gimbal"):
                kwargs[key] = value
            elif key in plain:
                kwargs[key] = _number(value, key)
        return cls(**kwargs)


def _number(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"sensor.{name} must be a number, got {value!r}")
    return float(value)
