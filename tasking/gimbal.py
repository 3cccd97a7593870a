"""Pan/tilt gimbal pointing: the angles that put a NED point on the optical axis, with travel and rate limits.

Lee, Kaminer, Dobrokhodov and Jones (NPS, 2010), spec 003 §2.9: a 2-axis (pan, tilt) gimbal keeps the feature
at the image centre; the paper gives the reference only in the roll plane (Eq. 12) and no loop equations, so
the full 3-D pointing below is [NOT IN PAPER].

Frames (DESIGN.md §3) and mounting are exactly those of :mod:`perception.pose` (tasking may not import
perception; the tests check the two agree):

    R_ned_from_cam = R_z(ψ) R_y(θ) R_x(φ) · R_body_from_base · R_z(pan) R_y(tilt) · C

with the vehicle attitude ``(roll φ, pitch θ, yaw ψ)`` Z-Y-X, body FRD, pan about the gimbal base's down axis
(positive right), tilt about the panned right axis (positive up, ``-π/2`` straight down) and ``C`` the fixed
FRD -> camera (x right, y down, z optical axis) relabelling. The optical axis in the base frame is therefore
``d = (cos pan cos tilt, sin pan cos tilt, -sin tilt)``, and for a target at ``p_T`` seen from the camera
centre ``c = p + R_ned_from_frd · lever_arm``:

    d = R_body_from_baseᵀ R_ned_from_frdᵀ (p_T - c) / ‖p_T - c‖
    pan = atan2(d_y, d_x),   tilt = atan2(-d_z, hypot(d_x, d_y))

At the base's zenith or nadir the pan is undefined and the current pan is kept. The reference is recomputed
from the current attitude at every step, which is the paper's inertial stabilisation ("subtraction of the
UAV Euler angular rates from the gimbal reference commands") in angle rather than rate form; the servos then
move toward it at most at the rate limits (:func:`slew`). Default travel: that of :mod:`perception.pose`
(pan all round, tilt from straight down to 30° up); default rates 120°/s (chosen here: "high-speed digital
servos", spec 003 §1.2, no figure given).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fusion.validation import as_vector

#: Gimbal travel of :mod:`perception.pose` (pan all round; tilt straight down to 30° above the horizon).
DEFAULT_PAN_LIMITS = (-math.pi, math.pi)
DEFAULT_TILT_LIMITS = (-0.5 * math.pi, math.pi / 6.0)
#: Servo rate limits (rad/s), chosen here.
DEFAULT_RATE = math.radians(120.0)


def _finite(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def _wrap(angle: float) -> float:
    """To ``[-π, π)``."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def rotation_ned_from_frd(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """``R_z(ψ) R_y(θ) R_x(φ)``: body FRD -> NED (aerospace Z-Y-X, as
    :func:`perception.rotations.rotation_from_euler`)."""
    cr, sr, cp, sp, cy, sy = (f(a) for a in (roll, pitch, yaw) for f in (math.cos, math.sin))
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


@dataclass(frozen=True)
class GimbalLimits:
    """Travel ``(min, max)`` of pan and tilt and their rate limits (rad, rad/s). Pan limits spanning 2π mean a
    continuous pan (it wraps); tilt must stay within ``[-π/2, π/2]``."""

    pan: tuple[float, float] = DEFAULT_PAN_LIMITS
    tilt: tuple[float, float] = DEFAULT_TILT_LIMITS
    pan_rate: float = DEFAULT_RATE
    tilt_rate: float = DEFAULT_RATE

    def __post_init__(self):
        for name in ("pan", "tilt"):
            lo, hi = (_finite(a, f"gimbal {name} limit") for a in getattr(self, name))
            if lo > hi:
                raise ValueError(f"gimbal {name} limits must be (min, max) with min <= max, got ({lo}, {hi})")
            object.__setattr__(self, name, (lo, hi))
        if not (-0.5 * math.pi <= self.tilt[0] and self.tilt[1] <= 0.5 * math.pi):
            raise ValueError(f"gimbal tilt limits must lie within [-π/2, π/2], got {self.tilt}")
        for name in ("pan_rate", "tilt_rate"):
            if _finite(getattr(self, name), f"gimbal {name}") <= 0:
                raise ValueError(f"gimbal {name} must be positive, got {getattr(self, name)}")

    @property
    def continuous_pan(self) -> bool:
        return self.pan[1] - self.pan[0] >= 2.0 * math.pi - 1e-12


@dataclass(frozen=True)
class GimbalAngles:
    """Pan and tilt (rad)."""

    pan: float
    tilt: float

    def __post_init__(self):
        object.__setattr__(self, "pan", _finite(self.pan, "gimbal pan"))
        object.__setattr__(self, "tilt", _finite(self.tilt, "gimbal tilt"))


@dataclass(frozen=True)
class VehiclePose:
    """NED position (m) and Z-Y-X attitude (rad) of the vehicle; NaN or inf anywhere raises ``ValueError``."""

    position: np.ndarray
    roll: float
    pitch: float
    yaw: float

    def __post_init__(self):
        object.__setattr__(self, "position", as_vector(self.position, "vehicle position (NED)", 3))
        for name in ("roll", "pitch", "yaw"):
            object.__setattr__(self, name, _finite(getattr(self, name), f"vehicle {name}"))

    @property
    def rotation(self) -> np.ndarray:
        """``R_ned_from_frd``."""
        return rotation_ned_from_frd(self.roll, self.pitch, self.yaw)


@dataclass(frozen=True)
class CameraMounting:
    """``R_body_from_base`` (how the gimbal base is bolted on) and the lever arm of the optical centre in body
    FRD (m): the two fields of :class:`perception.pose.CameraMount`, defaults identity and zero."""

    R_body_from_base: np.ndarray = field(default_factory=lambda: np.eye(3))
    lever_arm: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        R = np.asarray(self.R_body_from_base, dtype=float)
        if R.shape != (3, 3) or not np.all(np.isfinite(R)) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9):
            raise ValueError(f"R_body_from_base must be a 3x3 rotation matrix, got {self.R_body_from_base!r}")
        if np.linalg.det(R) < 0:
            raise ValueError("R_body_from_base is a reflection, not a rotation")
        object.__setattr__(self, "R_body_from_base", R)
        object.__setattr__(self, "lever_arm", as_vector(self.lever_arm, "camera lever arm (body FRD)", 3))


_DEFAULT_MOUNT = CameraMounting()


def camera_centre(pose: VehiclePose, mount: CameraMounting = _DEFAULT_MOUNT) -> np.ndarray:
    """``c = p + R_ned_from_frd · lever_arm`` (NED)."""
    return pose.position + pose.rotation @ mount.lever_arm


def line_of_sight(pose: VehiclePose, target, mount: CameraMounting = _DEFAULT_MOUNT) -> np.ndarray:
    """Unit direction from the camera centre to ``target`` (NED) in the gimbal-base frame."""
    target = as_vector(target, "gimbal target (NED)", 3)
    los = target - camera_centre(pose, mount)
    norm = float(np.linalg.norm(los))
    if norm == 0.0:
        raise ValueError(f"gimbal target {target.tolist()} is at the camera centre: no direction to point along")
    return mount.R_body_from_base.T @ (pose.rotation.T @ los) / norm  # d = R_bbᵀ R_nbᵀ (p_T - c) / ‖·‖


def look_angles(direction_base, pan_if_vertical: float = 0.0) -> GimbalAngles:
    """``pan = atan2(d_y, d_x)``, ``tilt = atan2(-d_z, hypot(d_x, d_y))``, without limits; along the base's vertical
    the pan is undefined and ``pan_if_vertical`` is kept."""
    d = as_vector(direction_base, "gimbal direction", 3)
    horizontal = math.hypot(d[0], d[1])
    if horizontal == 0.0 and d[2] == 0.0:
        raise ValueError("gimbal direction is the zero vector")
    pan = _wrap(math.atan2(d[1], d[0])) if horizontal > 1e-12 * abs(d[2]) else float(pan_if_vertical)
    return GimbalAngles(pan, math.atan2(-d[2], horizontal))


def point_at(
    pose: VehiclePose,
    target,
    limits: GimbalLimits | None = None,
    mount: CameraMounting = _DEFAULT_MOUNT,
    current: GimbalAngles | None = None,
) -> GimbalAngles:
    """The pan and tilt that put ``target`` (NED) on the optical axis. Raises ``ValueError`` when they lie outside
    the travel (e.g. a target above the camera beyond the tilt limit); ``current`` supplies the pan to keep when
    the target is straight below or above the base."""
    limits = GimbalLimits() if limits is None else limits
    angles = look_angles(line_of_sight(pose, target, mount), 0.0 if current is None else current.pan)
    lo, hi = limits.tilt
    if not lo - 1e-12 <= angles.tilt <= hi + 1e-12:
        raise ValueError(
            f"gimbal target needs tilt {math.degrees(angles.tilt):.1f}°, beyond the tilt limits "
            f"[{math.degrees(lo):.1f}°, {math.degrees(hi):.1f}°]"
        )
    if not limits.continuous_pan and not limits.pan[0] - 1e-12 <= angles.pan <= limits.pan[1] + 1e-12:
        raise ValueError(
            f"gimbal target needs pan {math.degrees(angles.pan):.1f}°, beyond the pan limits "
            f"[{math.degrees(limits.pan[0]):.1f}°, {math.degrees(limits.pan[1]):.1f}°]"
        )
    return GimbalAngles(min(max(angles.pan, limits.pan[0]), limits.pan[1]), min(max(angles.tilt, lo), hi))


def slew(current: GimbalAngles, desired: GimbalAngles, limits: GimbalLimits, dt: float) -> GimbalAngles:
    """Move from ``current`` toward ``desired`` for ``dt`` seconds at most at the rate limits (a continuous pan
    turns the shorter way round), staying within the travel."""
    if _finite(dt, "dt") < 0:
        raise ValueError(f"dt must be non-negative, got {dt}")
    pan_step = desired.pan - current.pan
    if limits.continuous_pan:
        pan_step = _wrap(pan_step)
    pan_step = min(max(pan_step, -limits.pan_rate * dt), limits.pan_rate * dt)
    tilt_step = min(max(desired.tilt - current.tilt, -limits.tilt_rate * dt), limits.tilt_rate * dt)
    pan = _wrap(current.pan + pan_step) if limits.continuous_pan else current.pan + pan_step
    tilt = current.tilt + tilt_step
    return GimbalAngles(min(max(pan, limits.pan[0]), limits.pan[1]), min(max(tilt, limits.tilt[0]), limits.tilt[1]))


def optical_axis(pose: VehiclePose, angles: GimbalAngles, mount: CameraMounting = _DEFAULT_MOUNT) -> np.ndarray:
    """The unit optical axis in NED: ``R_ned_from_frd R_body_from_base (cos pan cos tilt, sin pan cos tilt,
    -sin tilt)``."""
    cp, sp, ct, st = math.cos(angles.pan), math.sin(angles.pan), math.cos(angles.tilt), math.sin(angles.tilt)
    return pose.rotation @ (mount.R_body_from_base @ np.array([cp * ct, sp * ct, -st]))


def off_axis_angle(pose: VehiclePose, angles: GimbalAngles, target, mount: CameraMounting = _DEFAULT_MOUNT) -> float:
    """Angle (rad) between the optical axis and the line of sight to ``target`` (NED)."""
    los_base = line_of_sight(pose, target, mount)
    axis_base = mount.R_body_from_base.T @ (pose.rotation.T @ optical_axis(pose, angles, mount))
    # atan2(|a x b|, a·b): accurate near zero, where acos loses half the digits
    return math.atan2(float(np.linalg.norm(np.cross(axis_base, los_base))), float(axis_base @ los_base))
