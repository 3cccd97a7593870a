"""Camera mounting, a two-axis gimbal and the camera pose in the world.

Frames (DESIGN.md §3): world NED, body FRD, camera OpenCV (x right, y down, z optical axis).
The chain is

    R_world_from_cam = R_ned_from_frd(roll, pitch, yaw) · R_body_from_base · R_z(pan) R_y(tilt) · C

* ``R_ned_from_frd`` — vehicle attitude, aerospace Z-Y-X (:func:`perception.rotations.rotation_from_euler`).
* ``R_body_from_base`` — how the gimbal base is bolted to the airframe (:class:`CameraMount`,
  identity by default; the calibrated "q2" of thesis 000 §2.3.2).
* ``R_z(pan) R_y(tilt)`` — the gimbal (:class:`Gimbal`): pan about the base's down axis, positive to
  the right; tilt about the panned right axis, positive up. Zero angles look along body forward;
  ``tilt = -π/2`` looks straight down.
* ``C`` — the fixed re-labelling from FRD axes to camera axes at zero gimbal angles: camera x = right,
  camera y = down, camera z = forward, i.e. ``C = [[0, 0, 1], [1, 0, 0], [0, 1, 0]]``. With the
  camera looking down (tilt -π/2), image up is body forward and image right is body right.

Spec 000 §2.5 composes the bearing as ``R_body->world · R_cam->body · R_pixel->cam · e``; this module
is that composition with explicit matrices (the pixel part lives in :class:`perception.camera.Intrinsics`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from numbers import Real

import numpy as np

from perception.rotations import as_rotation, rot_y, rot_z, rotation_from_euler

__all__ = ["FRD_FROM_CAMERA", "Gimbal", "CameraMount", "CameraPose", "camera_rotation"]

#: Camera axes expressed in FRD at zero gimbal angles (columns: camera x, y, z -> body right, down, forward).
FRD_FROM_CAMERA = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
FRD_FROM_CAMERA.setflags(write=False)

#: Default gimbal travel (chosen here: a typical two-axis UAV gimbal): pan all round, tilt from
#: straight down to 30° above the horizon.
DEFAULT_PAN_LIMITS = (-math.pi, math.pi)
DEFAULT_TILT_LIMITS = (-0.5 * math.pi, math.pi / 6.0)


def _angle(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite angle in radians, got {value!r}")
    return float(value)


def _limits(value, name: str) -> tuple[float, float]:
    try:
        lo, hi = value
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (min, max) in radians, got {value!r}") from None
    lo, hi = _angle(lo, f"{name}[0]"), _angle(hi, f"{name}[1]")
    if lo > hi:
        raise ValueError(f"{name} must have min <= max, got ({lo}, {hi})")
    return lo, hi


@dataclass(frozen=True)
class Gimbal:
    """Two-axis (pan, tilt) gimbal, radians. The commanded angles are clamped to the limits on
    construction (pan is first wrapped to ``[-π, π)`` when its limits span the full circle); the
    clamped values are what :attr:`pan` and :attr:`tilt` hold, and :attr:`saturated` says whether
    clamping changed anything."""

    pan: float = 0.0
    tilt: float = 0.0
    pan_limits: tuple[float, float] = DEFAULT_PAN_LIMITS
    tilt_limits: tuple[float, float] = DEFAULT_TILT_LIMITS
    saturated: bool = field(default=False, init=False, compare=False)

    def __post_init__(self):
        pan, tilt = _angle(self.pan, "gimbal pan"), _angle(self.tilt, "gimbal tilt")
        pan_lo, pan_hi = _limits(self.pan_limits, "gimbal pan_limits")
        tilt_lo, tilt_hi = _limits(self.tilt_limits, "gimbal tilt_limits")
        if not (-0.5 * math.pi <= tilt_lo and tilt_hi <= 0.5 * math.pi):
            raise ValueError(f"gimbal tilt_limits must lie within [-π/2, π/2], got ({tilt_lo}, {tilt_hi})")
        if pan_hi - pan_lo >= 2.0 * math.pi - 1e-12 and not -math.pi <= pan < math.pi:
            pan = (pan + math.pi) % (2.0 * math.pi) - math.pi
        clamped_pan, clamped_tilt = min(max(pan, pan_lo), pan_hi), min(max(tilt, tilt_lo), tilt_hi)
        object.__setattr__(self, "pan_limits", (pan_lo, pan_hi))
        object.__setattr__(self, "tilt_limits", (tilt_lo, tilt_hi))
        object.__setattr__(self, "saturated", clamped_pan != pan or clamped_tilt != tilt)
        object.__setattr__(self, "pan", clamped_pan)
        object.__setattr__(self, "tilt", clamped_tilt)

    @classmethod
    def from_degrees(cls, pan_deg: float = 0.0, tilt_deg: float = 0.0, **limits_deg) -> Gimbal:
        """Config-edge constructor: angles (and ``pan_limits``/``tilt_limits`` pairs) in degrees."""
        limits = {k: tuple(math.radians(float(a)) for a in v) for k, v in limits_deg.items()}
        return cls(math.radians(pan_deg), math.radians(tilt_deg), **limits)

    def command(self, pan: float, tilt: float) -> Gimbal:
        """A new gimbal with the same limits pointed at ``(pan, tilt)`` (clamped)."""
        return Gimbal(pan, tilt, self.pan_limits, self.tilt_limits)

    def look_at(self, direction_base) -> Gimbal:
        """Point the optical axis along ``direction_base`` (in the gimbal-base frame, FRD-like),
        within the limits: ``pan = atan2(d_y, d_x)``, ``tilt = atan2(-d_z, hypot(d_x, d_y))``."""
        d = np.asarray(direction_base, dtype=float)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.any(d):
            raise ValueError(f"look_at needs a finite non-zero 3-vector, got {direction_base!r}")
        horizontal = math.hypot(d[0], d[1])
        pan = math.atan2(d[1], d[0]) if horizontal > 0 else self.pan
        return self.command(pan, math.atan2(-d[2], horizontal))

    @property
    def rotation(self) -> np.ndarray:
        """``R_base_from_cam = R_z(pan) R_y(tilt) C``."""
        return rot_z(self.pan) @ rot_y(self.tilt) @ FRD_FROM_CAMERA


def _store_rigid(obj, rotation: tuple[str, str], vector: tuple[str, str, str]) -> None:
    """Check and store, as read-only copies, a frozen dataclass's rotation field ``(field, name)`` and
    3-vector field ``(field, name, frame and unit)``."""
    (r_field, r_name), (v_field, v_name, unit) = rotation, vector
    R = as_rotation(getattr(obj, r_field), r_name).copy()
    v = np.array(getattr(obj, v_field), dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{v_name} must be a finite 3-vector ({unit}), got {getattr(obj, v_field)!r}")
    R.setflags(write=False)
    v.setflags(write=False)
    object.__setattr__(obj, r_field, R)
    object.__setattr__(obj, v_field, v)


@dataclass(frozen=True)
class CameraMount:
    """Where the gimbal base sits on the airframe: ``R_body_from_base`` (3x3 rotation, default the
    identity) and the lever arm ``offset`` of the optical centre from the vehicle reference point,
    in body FRD metres (default zero; Ross et al. neglect it, spec 002 §2.2)."""

    R_body_from_base: np.ndarray = field(default_factory=lambda: np.eye(3))
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        _store_rigid(self, ("R_body_from_base", "camera mount R_body_from_base"),
                     ("offset", "camera mount offset", "body FRD, m"))


def camera_rotation(roll, pitch, yaw, gimbal: Gimbal | None = None, mount: CameraMount | None = None) -> np.ndarray:
    """``R_world_from_cam`` for the vehicle attitude (broadcasts over array angles -> (..., 3, 3))."""
    gimbal = Gimbal(0.0, 0.0) if gimbal is None else gimbal
    mount = CameraMount() if mount is None else mount
    return rotation_from_euler(roll, pitch, yaw) @ (mount.R_body_from_base @ gimbal.rotation)


@dataclass(frozen=True)
class CameraPose:
    """Rigid pose of the camera in the world: ``R_world_from_cam`` and the optical centre (NED, m).
    A world point ``p`` has camera coordinates ``R^T (p - centre)`` (Merino (3.57) with
    ``R_t = R^T``, ``t_t = R^T centre``)."""

    R_world_from_cam: np.ndarray
    centre: np.ndarray

    def __post_init__(self):
        _store_rigid(self, ("R_world_from_cam", "camera pose rotation"), ("centre", "camera centre", "NED, m"))

    @classmethod
    def from_vehicle(
        cls,
        position_ned,
        roll: float,
        pitch: float,
        yaw: float,
        gimbal: Gimbal | None = None,
        mount: CameraMount | None = None,
    ) -> CameraPose:
        """Camera pose of a vehicle at ``position_ned`` with attitude ``(roll, pitch, yaw)``
        (radians, Z-Y-X), gimbal angles and mount; the centre includes the lever arm."""
        for name, value in (("roll", roll), ("pitch", pitch), ("yaw", yaw)):
            _angle(value, name)
        mount = CameraMount() if mount is None else mount
        R_nb = rotation_from_euler(roll, pitch, yaw)
        p = np.asarray(position_ned, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"vehicle position must be a finite 3-vector (NED, m), got {position_ned!r}")
        return cls(camera_rotation(roll, pitch, yaw, gimbal, mount), p + R_nb @ mount.offset)

    @property
    def optical_axis(self) -> np.ndarray:
        """Unit boresight (camera +z) in the world frame."""
        return self.R_world_from_cam[:, 2].copy()

    def world_to_camera(self, points) -> np.ndarray:
        """World points (..., 3) -> camera-frame coordinates (..., 3)."""
        return (np.asarray(points, dtype=float) - self.centre) @ self.R_world_from_cam

    def camera_to_world(self, points) -> np.ndarray:
        """Camera-frame points (..., 3) -> world points (..., 3)."""
        return np.asarray(points, dtype=float) @ self.R_world_from_cam.T + self.centre
