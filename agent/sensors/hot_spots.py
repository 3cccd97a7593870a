"""Hot spots: the fire blobs of a thermal frame as bearings to the alarms the grid raised (Merino Ch. 8).

Merino's alarm state (8.1) is ``x = (P, theta)``: the position ``P`` of an alarm is estimated by the
decentralized information filter of Ch. 3, its class ``theta`` by the grid's probability. Marvin's grid
raises alarms (4.20); Heliv segments its infrared images, and "if a segmented object is associated with an
alarm, it updates the position (IF)" (spec 001b §2.8). Here every agent's thermal camera plays Heliv's part
for the alarms of its own fused grid:

* **blobs**: the 8-connected regions of the frame's segmentation mask
  (:func:`perception.detection.blobs_from_mask`, no shape test), without those that touch the image border: a
  fire cut by the border has a centroid that is not the fire's (Merino §7.4 discards such blobs too);
* **bearing**: the line of sight through the blob's centroid from the pose the telemetry reports, with
  isotropic angular noise about it, ``s^2 = sigma_att^2 + (sigma_px / f)^2``, so that ``R = diag(s^2 /
  cos^2(el), s^2)`` in azimuth/elevation (the azimuth term grows near nadir, where the azimuth moves the ground
  point little; ``cos(el)`` is floored at :data:`MIN_COS_EL`);
* **gate**: a blob becomes a bearing only if its ground point ``g`` lies inside an alarm's gate,
  ``(g - mu)^T (Sigma + c^2 I)^-1 (g - mu) <= 9`` (Merino (3.64)'s threshold; ``mu, Sigma`` from (4.20),
  ``c`` one grid cell for the front that spread since the alarm was extracted). A flickering decoy that the
  grid rejects never reaches the filter; the fire's blobs do, at every look.

The bearings go to the agent's tracker like any other (``"bearings"``): with ``[tracking] measurement =
"position"`` they are geolocated there ((3.60)-(3.61)) and fused across agents by channel filters like target
tracks, so the alarms' positions converge at the resolution of the camera rather than of the grid.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from agent.sensors.bearing import Bearing
from fusion.grid_alarms import Alarm
from fusion.measurement import los_to_azel
from perception.camera import Intrinsics
from perception.detection import ShapeFilter, blobs_from_mask
from perception.pose import CameraPose
from perception.projection import cast_ray, pixel_to_ray_world
from perception.terrain import FlatTerrain

GATE = 9.0  # Merino (3.64)'s d^2 threshold
PIXEL_SIGMA = 1.0  # px: a blob centroid's noise (chosen here)
MIN_AREA = 2.0  # px: smaller blobs are noise (chosen here)
MIN_COS_EL = 1e-3  # floor of cos(el) in the azimuth variance (as the target camera's bearings)
_BLOBS = ShapeFilter(min_area=MIN_AREA, max_aspect=None, min_fill=None)


def inner_blobs(mask: np.ndarray) -> list[tuple[float, float]]:
    """Centroids ``(u, v)`` of the blobs of a boolean ``mask`` that do not touch its border."""
    height, width = mask.shape
    out = []
    for blob in blobs_from_mask(mask.astype(np.uint8), _BLOBS):
        x, y, w, h = blob.bbox
        if x > 0 and y > 0 and x + w < width and y + h < height:
            out.append(blob.center)
    return out


def gate_distance(point: np.ndarray, alarm: Alarm, cell: float) -> float:
    """``d^2`` of the ground point ``point`` (north, east) from ``alarm``, its covariance widened by one cell."""
    d = np.asarray(point, float) - alarm.mean
    return float(d @ np.linalg.solve(alarm.cov + cell**2 * np.eye(2), d))


def in_gate(point: np.ndarray, alarms: Sequence[Alarm], cell: float) -> bool:
    """Whether the ground point ``point`` (north, east) lies inside any alarm's gate (module docstring)."""
    return any(gate_distance(point, alarm, cell) <= GATE for alarm in alarms)


class HotSpots:
    """Bearings to the gated blobs of one frame (module docstring); counts what it kept and dropped."""

    def __init__(self, intrinsics: Intrinsics, attitude_sigma: float, cell: float, terrain=None):
        f = float(intrinsics.fx)
        self.intrinsics = intrinsics
        self.angle_var = attitude_sigma**2 + (PIXEL_SIGMA / f) ** 2
        self.cell = cell
        self.terrain = terrain if terrain is not None else FlatTerrain()
        self.kept = 0
        self.outside = 0  # blobs outside every alarm's gate

    def bearings(self, t: float, mask: np.ndarray, pose: CameraPose, alarms: Sequence[Alarm]) -> list[Bearing]:
        if not alarms:
            return []
        out = []
        for pixel in inner_blobs(mask):
            ray = pixel_to_ray_world(pose, self.intrinsics, np.asarray(pixel, float))
            ground = cast_ray(self.terrain, pose.centre, ray)
            if ground is None or not in_gate(ground[:2], alarms, self.cell):
                self.outside += 1
                continue
            azel = los_to_azel(ray)
            cos_el = max(abs(math.cos(azel[1])), MIN_COS_EL)
            R = np.diag([self.angle_var / cos_el**2, self.angle_var])
            out.append(Bearing(t, pose.centre.copy(), azel, R))
        self.kept += len(out)
        return out
