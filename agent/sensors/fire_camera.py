"""The fire camera: a down-looking thermal camera whose frames become per-cell grid evidence.

Each step: render the thermal frame the vehicle's camera sees of the true fire (the burning cells the
world publishes, :mod:`agent.net.fire_truth`; plus transient hot spots, the *decoys*, that flicker into
single frames the way sun glints and hot rocks do), segment it by a temperature threshold (the IR
segmentation of Merino App. B; a threshold stands in for the thesis's ANFIS), and turn the binary mask
into per-cell likelihoods with the pose the telemetry reports (the true pose plus white pose noise of
the size the likelihood model assumes): Merino (4.9)-(4.15) and the Beta pseudo-counts (4.31),
through :func:`perception.grid_likelihood.camera_cell_evidence`. With a hand-off (``[grid] handoff``) the same
mask's blobs in the gates of the grid's alarms also become bearings (:mod:`agent.sensors.hot_spots`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from agent.sensors.fire_camera_config import FireCameraConfig
from agent.sensors.hot_spots import HotSpots
from fusion.grid_alarms import Alarm
from perception.grid_likelihood import CellEvidence, camera_cell_evidence
from perception.grid_sensor_model import DetectionModel, PoseNoise
from perception.pose import CameraPose, Gimbal
from perception.render import render_frame
from perception.scene import Fire

DECOY_SIZE_M = 5.0  # a hot spot the size of a cell: a hot vehicle, a sun glint on a roof (chosen here)


class FireCamera:
    """Render, segment, and turn into cell evidence; ``rng`` drives the pose noise and the decoys."""

    def __init__(self, config: FireCameraConfig, model: DetectionModel, noise: PoseNoise, seed: int):
        self.config = config
        self.model = model
        self.noise = noise
        self.intrinsics = config.intrinsics
        self.gimbal = Gimbal(0.0, -math.pi / 2)
        self.rng = np.random.default_rng(seed)
        self.frames = 0
        self.fire_pixels = 0

    def look(self, state, fires: list[Fire], decoys: list[tuple[float, float, float]],
             terrain=None) -> tuple[np.ndarray, CameraPose]:
        """One frame seen from vehicle ``state``, segmented: its fire mask and the pose the telemetry reports.
        ``decoys`` are (north, east, probability of showing in a frame) of hot spots ``DECOY_SIZE_M`` across."""
        true_pose = CameraPose.from_vehicle(state.position, state.roll, state.pitch, state.yaw, self.gimbal)
        shown = [Fire((n, e), DECOY_SIZE_M, self.config.decoy_K) for n, e, p in decoys if self.rng.random() < p]
        level = getattr(terrain, "level", None)
        frame = render_frame((true_pose, self.intrinsics), self.intrinsics.width, self.intrinsics.height,
                             fires=[*fires, *shown], ground_height=level or 0.0,
                             terrain=None if level is not None or terrain is None else terrain,
                             seed=self.rng, rgb=False, thermal=True)
        mask = frame.thermal > self.config.threshold_K
        self.frames += 1
        self.fire_pixels += int(mask.sum())
        return mask, self._reported_pose(state)

    def cell_evidence(self, mask: np.ndarray, pose: CameraPose, cells_ned: np.ndarray, cell: float) -> CellEvidence:
        """The evidence of a segmented frame on the cells (Merino (4.9)-(4.15), (4.31))."""
        return camera_cell_evidence(mask, cells_ned, cell, pose, self.intrinsics, self.model, self.noise)

    def _reported_pose(self, state) -> CameraPose:
        """The pose the telemetry reports: the truth plus the noise the likelihood model accounts for."""
        n = self.noise
        position = np.asarray(state.position, float) + n.position_sigma * self.rng.standard_normal(3)
        attitude = np.array([state.roll, state.pitch, state.yaw]) + n.attitude_sigma * self.rng.standard_normal(3)
        roll, pitch, yaw = (float(a) for a in attitude)
        return CameraPose.from_vehicle(position, roll, pitch, yaw, self.gimbal)


class ThermalSensor:
    """The fire camera as a sensor of the agent (:class:`agent.plugins.Sensor`): each step, one frame of the
    simulated fire seen from the vehicle, as cell evidence (``"fire_evidence"``) on the grid whose cell
    centres (NED) and side it was built for; with ``hot_spots``, also the frame's fire blobs inside the gates
    of the grid's current ``alarms()`` as ``"bearings"`` (:mod:`agent.sensors.hot_spots`, Merino Ch. 8)."""

    def __init__(self, camera: FireCamera, cells_ned: np.ndarray, cell: float, terrain,
                 hot_spots: HotSpots | None = None, alarms: Callable[[], list[Alarm]] = list):
        self.camera = camera
        self.cells_ned = cells_ned
        self.cell = cell
        self.terrain = terrain
        self.hot_spots = hot_spots
        self.alarms = alarms
        self._fires: list[Fire] = []
        self._decoys: list[tuple[float, float, float]] = []

    def on_truth(self, truth) -> None:
        self._fires, self._decoys = truth.fires, truth.decoys

    def measure(self, t: float, state) -> dict:
        mask, pose = self.camera.look(state, self._fires, self._decoys, self.terrain)
        out = {"fire_evidence": self.camera.cell_evidence(mask, pose, self.cells_ned, self.cell)}
        if self.hot_spots is not None:
            out["bearings"] = self.hot_spots.bearings(t, mask, pose, self.alarms())
        return out

    def telemetry(self) -> dict:
        return {}

    def point(self, look_at) -> None:
        """A planner's gimbal command: ignored (the thermal camera keeps its configured pointing)."""

    def metrics(self) -> dict:
        out = {"frames": self.camera.frames}
        if self.hot_spots is not None:
            out["hot_spots"] = {"bearings": self.hot_spots.kept, "outside_alarms": self.hot_spots.outside}
        return out

    def close(self) -> None:
        pass
