"""The camera sensor: render (or read) a frame, detect, and turn detections into bearings.

:class:`CameraSensor` plays the role of :class:`agent.sensors.bearing.GeometricBearingSensor` — the agent calls
``detect(t, state, truth)`` (behind the sensor seam of :class:`~agent.sensors.bearing.BearingSource`) and gets
:class:`~agent.sensors.bearing.Bearing` s — but goes through the image:

1. **capture** at ``t``: the frame the vehicle's camera sees, rendered from the *true* pose and the
   world truth (targets drawn as red discs or balls, with the configured
   :class:`~perception.degradation.Degradation`), or the next frame of an external OpenCV source
   (:class:`~agent.sensors.video_source.VideoSource`: a file, a device, a stream) that replaces the
   synthetic camera. With ``render = "roi"`` (the default) the synthetic camera draws only what the
   detector needs (:func:`perception.roi_render.render_roi`): the whole view at 320×240 plus, for the
   colour detector, full-resolution windows around the targets — a few times cheaper than the whole
   640×480 frame, which ``render = "full"`` draws (:func:`perception.render.render_frame`, the reference;
   ``skymesh bench perception`` times both). A frame with a banding episode or a failed link is drawn
   whole either way;
2. **video quality** D(t) of the frame (thesis 000 §2.4, :class:`~perception.quality.VideoQuality`); of a
   frame drawn in parts, D(t) is measured on its 320×240 preview, which is the image ``I`` D(t) is defined
   on (the whole frame downsampled to 320×240; the preview is drawn at that size with the noise the
   downsampling leaves). While D(t) is above its threshold the video source has *failed* (thesis 000: a
   failed link): its frames are still checked (bad frames counted by reason) but give no bearings
   (``video_failed`` among the outcomes), and the first time of failure is in the metrics
   (``video_failed_at``, only when it failed);
3. **detection**: colour blobs by default (Ross et al., :class:`~perception.blobs.ColorBlobDetector`; in
   the windows of a frame drawn in parts) or dark blobs (thesis 000 §2.2; on the preview, its working
   image), optionally through the persistent-object filter; detections are in frame pixels either way;
   blobs touching the image border are dropped (a cut blob's centroid is biased);
4. **pose**: the telemetry the sensor gets is a simulated GPS/attitude stream — the true pose
   delayed by ``gps_latency`` (plus optional attitude noise) — kept in a
   :class:`~perception.pose_buffer.PoseBuffer`. With ``latency_compensation`` the buffer stores each
   report ``gps_latency`` earlier (Ross et al., spec 002 §2.5) and the detections of a frame wait until
   the buffer covers their capture time (delayed pairing, so their bearings come out a few steps later,
   stamped with the capture time; the tracker's trajectory window takes them there);
5. **bearing**: each detection's pixel becomes a world ray (:func:`perception.projection.pixel_to_ray_world`
   with the pose at capture time), i.e. an azimuth/elevation seen from the buffered camera position,
   with a first-order covariance (below). Each bearing is labelled with the id of the rendered target
   whose pixel it matches (simulation only: the centralized oracle associates by it; the agent never
   looks at it).

**Gimbal.** ``gimbal = "fixed"`` (default) keeps the configured pan and tilt. ``gimbal = "steered"`` points the
camera where the planner says (the agent hands every sensor its goal's ``look_at``, :meth:`CameraSensor.point`;
spec 003 §2.9: the GNC computer sends the gimbal its reference): before each capture the reference
``(pan, tilt)`` that puts the point on the optical axis is recomputed from the vehicle's attitude at the
capture time (:func:`tasking.gimbal.point_at`: ``d = R_bbᵀ R_nbᵀ (p_T - c)/‖·‖``, ``pan = atan2(d_y, d_x)``,
``tilt = atan2(-d_z, hypot(d_x, d_y))``, the paper's inertial stabilisation in angle form; the true attitude,
which the gimbal's own sensor head measures) and the servos move toward it for the time since the last
capture at most at ``gimbal_rate`` (:func:`tasking.gimbal.slew`). The frame is rendered, and the pose
telemetry stamped, with the angles reached. The *pointing error* of a frame is the angle between its optical
axis and the line of sight to the commanded point (:func:`tasking.gimbal.off_axis_angle`); with the feature
planner's ``look_at = "feature"`` it is the feature-centring error of spec 003 Eq. 13 (``|e|``).

**Covariance** (first order, chosen here over the UT: one detection costs a few microseconds and the
bearing function is smooth away from the zenith). Inputs ``x = (u, v, roll, pitch, yaw)`` with standard
deviations ``(σ_px, σ_px, σ_att, σ_att, σ_att)``; the line of sight is ``ℓ = R_nb(φ, θ, ψ) M r(u, v)``
(``M`` mount and gimbal, ``r`` the unit camera ray). Its derivatives are exact for the attitude
(``∂ℓ/∂φ = R_z R_y R_x [e_x]× b``, ``∂ℓ/∂θ = R_z R_y [e_y]× R_x b``, ``∂ℓ/∂ψ = [e_z]× ℓ``, ``b = M r``) and a
central difference of ``r`` (±0.5 px) for the pixel. Projected on the local azimuth and elevation
directions, ``d az = e_az·dℓ / cos(el)`` and ``d el = e_el·dℓ`` (``cos(el)`` clamped at 1e-3 as in
:func:`agent.sensors.bearing.bearing_covariance`), so ``R = J diag(σ²) Jᵀ`` with ``J`` (2×5).

Bad input never crashes the agent: an empty, corrupt or wrong-shape frame, a frame the source could not
deliver, a capture older than the pose buffer, or a pose that never arrives is counted by reason in
:attr:`CameraSensor.outcomes` and yields no bearings.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from agent.sensors.bearing import Bearing, BearingSource
from agent.sensors.camera_config import CameraSensorConfig
from fusion.measurement import los_to_azel
from perception.blobs import ColorBlobDetector, DarkBlobDetector
from perception.camera import Intrinsics
from perception.persistence import PersistentDetector, PersistentObjectFilter
from perception.pose import CameraMount, CameraPose, Gimbal
from perception.pose_buffer import PoseBuffer, PoseSample, PoseTooNew, PoseTooOld
from perception.quality import VideoQuality
from perception.render import default_ground, render_frame
from perception.roi_frame import RoiFrame, whole_view
from perception.roi_render import render_roi
from perception.rotations import rot_x, rot_y, rot_z
from perception.scene import Target
from perception.terrain import FlatTerrain
from tasking.gimbal import (
    CameraMounting,
    GimbalAngles,
    GimbalLimits,
    VehiclePose,
    off_axis_angle,
    point_at,
    slew,
)

log = logging.getLogger("skymesh.camera")

__all__ = ["CameraSensor"]

PIXEL_STEP = 0.5  # px, central-difference step of the pixel derivative (chosen here)
POSE_WAIT_MARGIN = 1.0  # s a frame waits for its pose beyond the GPS latency before it is dropped (chosen here)
LABEL_GATE_PX = 3.0  # px added to 1.5 x the apparent radius when matching a detection to a target (chosen here)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


_EX, _EY, _EZ = (_skew(e) for e in np.eye(3))


@dataclass
class _Pending:
    """A captured frame's detections waiting for the pose at their capture time."""

    t: float
    pixels: np.ndarray  # (n, 2)
    labels: list  # truth id or None per detection


@dataclass
class CameraStats:
    frames: int = 0  # frames captured (rendered or read)
    frames_ok: int = 0  # frames the detector accepted
    detections: int = 0  # detections kept (after the border rule)
    bearings: int = 0  # bearings produced
    visible: int = 0  # (frame, target) pairs with the target visible (synthetic camera only)
    detected: int = 0  # of those, how many were detected
    false_detections: int = 0  # detections matching no target (synthetic camera only)
    outcomes: Counter = field(default_factory=Counter)  # reason -> frames or detections lost
    failed_at: float | None = None  # when D(t) first crossed its threshold: the video source failed [s]


class SteeredGimbal:
    """A gimbal that slews toward a commanded point (module docstring, **Gimbal**): its travel is that of
    :class:`perception.pose.Gimbal` and its rates ``rate`` (rad/s)."""

    def __init__(self, gimbal: Gimbal, mount: CameraMount, rate: float):
        self.limits = GimbalLimits(gimbal.pan_limits, gimbal.tilt_limits, rate, rate)
        self.mounting = CameraMounting(mount.R_body_from_base, mount.offset)
        self.look_at: np.ndarray | None = None  # NED, the last command (None: hold)
        self.errors: list[float] = []  # rad, pointing error of each steered frame
        self.out_of_travel = 0  # captures whose command lay beyond the travel (the gimbal held)
        self._t: float | None = None

    def steer(self, t: float, state, gimbal: Gimbal) -> Gimbal:
        """The gimbal at capture time ``t``: moved from ``gimbal`` toward the command for the time since the last
        capture. A bad vehicle state leaves it where it is (the telemetry counts it)."""
        dt, self._t = (0.0 if self._t is None else max(t - self._t, 0.0)), t
        if self.look_at is None:
            return gimbal
        try:
            pose = VehiclePose(state.position, state.roll, state.pitch, state.yaw)
        except ValueError:
            return gimbal
        current = GimbalAngles(gimbal.pan, gimbal.tilt)
        try:
            desired = point_at(pose, self.look_at, self.limits, self.mounting, current)
        except ValueError:  # beyond the tilt travel, or the camera at the point itself
            self.out_of_travel += 1
            return gimbal
        angles = slew(current, desired, self.limits, dt)
        self.errors.append(off_axis_angle(pose, angles, self.look_at, self.mounting))
        return gimbal.command(angles.pan, angles.tilt)

    def metrics(self) -> dict:
        e = np.degrees(self.errors)
        return {"mode": "steered", "out_of_travel": self.out_of_travel, "pointing_error_deg": {
            "mean": float(e.mean()) if e.size else None, "p95": float(np.percentile(e, 95)) if e.size else None,
            "max": float(e.max()) if e.size else None, "samples": int(e.size)}}


class CameraSensor(BearingSource):
    """The camera pipeline behind ``detect(t, state, truth) -> [Bearing]``.

    ``terrain`` is the world's ground (drawn under the targets); ``source`` an optional
    :class:`~agent.sensors.video_source.VideoSource` (or anything with ``read()`` and ``close()``) that
    replaces the renderer."""

    def __init__(self, config: CameraSensorConfig, seed: int, terrain=None, source=None):
        self.config = config
        self.rng = np.random.default_rng(seed)
        self.terrain = terrain if terrain is not None else FlatTerrain()
        self.source = source
        self.intrinsics = config.intrinsics
        if source is not None:
            size = getattr(source, "size", None)
            if size and all(size) and tuple(size) != (config.width, config.height):
                log.info("camera source %s gives %dx%d frames: intrinsics rescaled from %dx%d (same hfov)",
                         getattr(source, "name", "?"), *size, config.width, config.height)
                self.intrinsics = Intrinsics.from_fov(int(size[0]), int(size[1]), math.degrees(config.hfov))
        self.gimbal = Gimbal(config.pan, config.tilt)
        self.mount = CameraMount()
        self._M = self.mount.R_body_from_base @ self.gimbal.rotation  # camera -> body
        self.steering = SteeredGimbal(self.gimbal, self.mount, config.gimbal_rate) if config.gimbal == "steered" \
            else None
        self.degradation = config.degradation
        self.ground = None if source is not None else default_ground(config.ground)
        expected = (self.intrinsics.height, self.intrinsics.width, 3)
        base = ColorBlobDetector(expected_shape=expected) if config.detector == "color" else \
            DarkBlobDetector(expected_shape=expected)
        self.detector = PersistentDetector(base, PersistentObjectFilter(), report_hidden=False) \
            if config.persistence else base
        self.quality = VideoQuality()
        latency = config.gps_latency
        # The true poses the simulated telemetry is drawn from (held long enough to look back by the latency).
        self._truth_poses = PoseBuffer(maxlen=64 + math.ceil(50 * latency), max_extrapolation=0.0)
        # No extrapolation: a frame waits for the sample after it (delayed pairing) rather than guess.
        self.poses = PoseBuffer(maxlen=config.pose_buffer, latency=latency if config.latency_compensation else 0.0,
                                max_extrapolation=0.0)
        self._pending: list[_Pending] = []
        self.stats = CameraStats()
        self.last_quality = None

    # -- the sensor interface ---------------------------------------------------------------------
    def detect(self, t: float, state, truth: list[dict]) -> list[Bearing]:
        """Capture a frame at ``t`` from the vehicle ``state`` (a :class:`agent.vehicles.base.VehicleState`),
        detect, and return the bearings whose pose is known (this frame's, or earlier frames' that waited
        for a late pose). Never raises on bad frames or poses: they are counted in :attr:`outcomes`."""
        if self.steering is not None:
            self.gimbal = self.steering.steer(t, state, self.gimbal)
        self._telemetry(t, state)
        frame, labels = self._capture(t, state, truth)
        self.stats.frames += 1
        self.last_quality = self.quality.update(whole_view(frame))
        if self.last_quality.failed and self.stats.failed_at is None:
            self.stats.failed_at = t
        if frame is not None:
            result = self.detector.detect(frame)
            if result.error is not None:
                self.stats.outcomes[f"frame_{result.error}"] += 1
            elif self.last_quality.failed:  # a frame of a failed source: no bearings from it
                self.stats.outcomes["video_failed"] += 1
                self._label(np.empty((0, 2)), labels)  # its visible targets count as missed
            else:
                self.stats.frames_ok += 1
                pixels = self._kept(result.detections)
                self.stats.detections += len(pixels)
                ids = self._label(pixels, labels)
                if len(pixels):
                    self._pending.append(_Pending(t, pixels, ids))
        return self._pair(t)

    def point(self, look_at) -> None:
        """Point a steered gimbal at ``look_at`` (NED; ``None``: hold) from the next capture on; a fixed one
        ignores it."""
        if self.steering is not None:
            self.steering.look_at = None if look_at is None else np.array(look_at, dtype=float)

    @property
    def outcomes(self) -> Counter:
        return self.stats.outcomes

    @property
    def video_quality(self) -> float:
        """D(t) over the last frames (thesis 000 Eq. 2.4); 0 before the first frame."""
        return self.quality.D

    def metrics(self) -> dict:
        s = self.stats
        return {
            "kind": "camera", "source": getattr(self.source, "name", "synthetic"), "frames": s.frames,
            "frames_ok": s.frames_ok, "detections": s.detections, "bearings": s.bearings,
            "visible_targets": s.visible, "detected_targets": s.detected,
            "detection_rate": s.detected / s.visible if s.visible else None,
            "false_detections": s.false_detections,
            "false_per_frame": s.false_detections / s.frames_ok if s.frames_ok else None,
            "video_quality": self.video_quality, "video_failed": self.quality.failed,
            **({} if s.failed_at is None else {"video_failed_at": s.failed_at}),
            "outcomes": dict(s.outcomes),
            **({} if self.steering is None else {"gimbal": self.steering.metrics()}),
        }

    def telemetry(self) -> dict:
        if self.steering is None:
            return super().telemetry()
        return {**super().telemetry(), "gimbal_pan": self.gimbal.pan, "gimbal_tilt": self.gimbal.tilt}

    def close(self) -> None:
        if self.source is not None:
            self.source.close()

    # -- steps ------------------------------------------------------------------------------------
    def _telemetry(self, t: float, state) -> None:
        """The simulated GPS/attitude report at ``t``: the true pose at ``t - gps_latency``, stamped ``t``."""
        c = self.config
        try:
            self._truth_poses.add(t, state.position, state.roll, state.pitch, state.yaw, self.gimbal.pan,
                                  self.gimbal.tilt)
            true = self._truth_poses.at(t - c.gps_latency) if c.gps_latency > 0 else self._truth_poses.at(t)
        except PoseTooOld:
            return  # the first gps_latency seconds: no report has arrived yet
        except ValueError:
            self.stats.outcomes["bad_vehicle_state"] += 1
            return
        roll, pitch, yaw = true.roll, true.pitch, true.yaw
        if c.attitude_noise > 0:
            roll, pitch, yaw = np.array([roll, pitch, yaw]) + c.attitude_noise * self.rng.standard_normal(3)
        self.poses.add(t, true.position, roll, pitch, yaw, true.pan, true.tilt)

    def _capture(self, t: float, state, truth: list[dict]):
        """The frame at ``t`` (an image, or a :class:`~perception.roi_frame.RoiFrame`) and its target labels
        ``[(truth id, label)]`` (empty for an external source)."""
        if self.source is not None:
            frame = self.source.read()
            if frame is None:
                self.stats.outcomes["read_failed"] += 1
            return frame, []
        try:
            pose = CameraPose.from_vehicle(state.position, state.roll, state.pitch, state.yaw, self.gimbal, self.mount)
        except ValueError:  # already counted as bad_vehicle_state by _telemetry
            return None, []
        c = self.config
        targets, ids = [], []
        for target in truth:
            position = np.asarray(target["position"], float)
            if position.shape != (3,) or not np.all(np.isfinite(position)):
                continue
            if c.target_shape == "sphere":
                position = position - np.array([0.0, 0.0, c.target_radius])  # resting on the ground
            targets.append(Target(tuple(position), c.target_radius, c.target_rgb, shape=c.target_shape))
            ids.append(target["id"])
        level = getattr(self.terrain, "level", None)
        terrain = None if level is not None else self.terrain
        scene = dict(ground=self.ground, ground_height=level or 0.0, terrain=terrain, degradation=self.degradation,
                     seed=self.rng)
        size = (self.intrinsics.width, self.intrinsics.height)
        if c.render == "roi":
            rendered = render_roi((pose, self.intrinsics), *size, targets, **scene)
        else:
            rendered = render_frame((pose, self.intrinsics), *size, targets, thermal=False, **scene)
        frame = rendered if isinstance(rendered, RoiFrame) else rendered.rgb
        return frame, list(zip(ids, rendered.targets, strict=True))

    def _kept(self, detections) -> np.ndarray:
        """Centres of the detections whose box stays clear of the image border."""
        m, w, h = self.config.edge_margin, self.intrinsics.width, self.intrinsics.height
        kept = [d.center for d in detections
                if d.bbox[0] > m and d.bbox[1] > m and d.bbox[0] + d.bbox[2] < w - m and d.bbox[1] + d.bbox[3] < h - m]
        return np.array(kept, float).reshape(-1, 2)

    def _label(self, pixels: np.ndarray, labels: list) -> list:
        """Truth id of the rendered target each detection falls on (nearest within its gate), else ``None``;
        counts visible targets detected and false detections."""
        if not labels:
            return [None] * len(pixels)
        ids = []
        hit = set()
        for p in pixels:
            best, best_d = None, math.inf
            for k, (_, lab) in enumerate(labels):
                if not np.isfinite(lab.depth) or not np.all(np.isfinite(lab.center_px)):
                    continue
                d = math.hypot(p[0] - lab.center_px[0], p[1] - lab.center_px[1])
                if d <= 1.5 * lab.radius_px + LABEL_GATE_PX and d < best_d:
                    best, best_d = k, d
            if best is None:
                self.stats.false_detections += 1
                ids.append(None)
            else:
                hit.add(best)
                ids.append(labels[best][0])
        visible = [k for k, (_, lab) in enumerate(labels) if lab.visible]
        self.stats.visible += len(visible)
        self.stats.detected += sum(k in hit for k in visible)
        return ids

    def _pair(self, t: float) -> list[Bearing]:
        """Bearings of every pending frame whose pose is now known; drops the hopeless ones (counted)."""
        out, waiting = [], []
        wait_limit = self.config.gps_latency + POSE_WAIT_MARGIN
        for pending in self._pending:
            try:
                pose = self.poses.at(pending.t)
            except PoseTooOld:
                self.stats.outcomes["pose_too_old"] += 1
                continue
            except PoseTooNew:
                if t - pending.t > wait_limit:
                    self.stats.outcomes["pose_timeout"] += 1
                else:
                    waiting.append(pending)
                continue
            for pixel, truth_id in zip(pending.pixels, pending.labels, strict=True):
                bearing = self.bearing(pose, pixel, pending.t, truth_id)
                if bearing is not None:
                    out.append(bearing)
        self._pending = waiting
        self.stats.bearings += len(out)
        return out

    # -- geometry ---------------------------------------------------------------------------------
    def bearing(self, pose: PoseSample, pixel, t: float, truth_id=None) -> Bearing | None:
        """The bearing of ``pixel`` seen with camera pose ``pose`` (see the module docstring for ``R``)."""
        c = self.config
        u, v = float(pixel[0]), float(pixel[1])
        h = PIXEL_STEP
        pts = np.array([[u, v], [u + h, v], [u - h, v], [u, v + h], [u, v - h]])
        try:
            rays = self.intrinsics.ray(pts)
        except ValueError:
            self.stats.outcomes["bad_pixel"] += 1
            return None
        Rx, Ry, Rz = rot_x(pose.roll), rot_y(pose.pitch), rot_z(pose.yaw)
        R_nb = Rz @ Ry @ Rx
        if pose.pan != self.config.pan or pose.tilt != self.config.tilt:
            M = self.mount.R_body_from_base @ Gimbal(pose.pan, pose.tilt).rotation
        else:
            M = self._M
        b = M @ rays[0]
        los = R_nb @ b
        J_los = np.empty((3, 5))
        J_los[:, 0] = R_nb @ M @ (rays[1] - rays[2]) / (2 * h)
        J_los[:, 1] = R_nb @ M @ (rays[3] - rays[4]) / (2 * h)
        J_los[:, 2] = Rz @ Ry @ Rx @ (_EX @ b)
        J_los[:, 3] = Rz @ Ry @ (_EY @ (Rx @ b))
        J_los[:, 4] = _EZ @ los
        azel = los_to_azel(los)
        az, el = azel
        cos_el = max(abs(math.cos(el)), 1e-3)
        e_az = np.array([-math.sin(az), math.cos(az), 0.0])
        e_el = np.array([-math.sin(el) * math.cos(az), -math.sin(el) * math.sin(az), -math.cos(el)])
        J = np.vstack([e_az / cos_el, e_el]) @ J_los
        sig = np.array([c.pixel_sigma, c.pixel_sigma, c.attitude_sigma, c.attitude_sigma, c.attitude_sigma])
        R = (J * sig**2) @ J.T
        R = 0.5 * (R + R.T) + 1e-12 * np.eye(2)
        centre = pose.position + R_nb @ self.mount.offset
        return Bearing(t, centre, azel, R, truth_id)
