"""The fire camera's configuration (the camera settings of a scenario's ``[grid]`` table).

Apart from :mod:`agent.sensors.fire_camera`, which renders and segments frames (OpenCV), so that reading a
scenario does not load the image code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from perception.camera import Intrinsics


@dataclass(frozen=True)
class FireCameraConfig:
    width: int = 160  # px: a small radiometric thermal core (chosen here)
    height: int = 120  # px
    hfov: float = math.radians(60.0)  # rad (config: hfov_deg); chosen here
    threshold_K: float = 400.0  # segmentation threshold (chosen here: ambient ~290 K, flames 800 K)
    decoy_K: float = 650.0  # temperature of a decoy in the frames where it shows (chosen here)

    def __post_init__(self):
        if not (isinstance(self.width, int) and isinstance(self.height, int) and self.width >= 8 and self.height >= 8):
            raise ValueError(f"fire camera size must be integers >= 8 px, got {self.width}x{self.height}")
        if not (0.0 < self.hfov < math.pi):
            raise ValueError(f"fire camera hfov must be in (0, 180) degrees, got {math.degrees(self.hfov)}")
        if not (np.isfinite(self.threshold_K) and self.threshold_K > 0):
            raise ValueError(f"fire camera threshold_K must be positive, got {self.threshold_K}")

    @property
    def intrinsics(self) -> Intrinsics:
        return Intrinsics.from_fov(self.width, self.height, math.degrees(self.hfov))
