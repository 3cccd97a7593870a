"""A time-stamped pose buffer with interpolation and GPS-latency compensation (Ross et al., spec 002 §2.5).

An image is taken at ``t_capture``; the vehicle pose that georeferences it must be the pose *at that
time*. Telemetry arrives as a stream of samples (position NED, roll, pitch, yaw, gimbal pan and tilt);
:meth:`PoseBuffer.at` interpolates between the two samples around the query time:

* position: linear, ``p(t) = p_0 + s (p_1 - p_0)`` with ``s = (t - t_0) / (t_1 - t_0)``;
* attitude: spherical linear interpolation of the Z-Y-X attitude quaternion
  (``q(s) = q_0 (q_0^-1 q_1)^s`` along the shorter arc), converted back to ``(roll, pitch, yaw)``;
* gimbal pan and tilt: linear on the wrapped difference (``a_0 + s wrap(a_1 - a_0)``).

Ross et al. found the autopilot's GPS about 0.43 s late and corrected it, in post-processing, by
"using the GPS position estimate 430 ms into the future": the image taken at ``t`` is paired with the
sample stamped ``t + 0.43``. Here that is the buffer's ``latency``: a sample *reported* at ``t_r``
describes the vehicle at ``t_r - latency`` and is stored there, so ``at(t_capture)`` returns the pose
at the capture time. In real time this is *delayed pairing* (spec 002 §2.5, [NOT IN PAPER]): the pose
for ``t_capture`` exists only once a report stamped ``t_capture + latency`` has arrived, so the caller
keeps the image (or its detections) until :meth:`PoseBuffer.covers` says so. ``latency = 0`` disables
the compensation (a sample is stored at its report time). Ross shifted only the position; here the
whole pose is shifted, because the simulated telemetry delays it whole (spec 002 §6 item 5 leaves it open).

Query times outside the buffer: before the oldest sample :class:`PoseTooOld` (the sample has been
dropped: the buffer is bounded); after the newest by more than ``max_extrapolation`` seconds
:class:`PoseTooNew` (the pose has not arrived yet). Within the allowance the last two samples are
extrapolated (linear position, slerp beyond ``s = 1``). Both are :class:`ValueError` subclasses.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from perception.rotations import euler_from_rotation, quaternion_from_euler, rotation_from_quaternion

__all__ = ["PoseSample", "PoseBuffer", "PoseTooOld", "PoseTooNew", "slerp", "wrap_angle"]

#: Default number of samples kept (chosen here: 64 samples, 12.8 s at 5 Hz, covers any latency we model).
DEFAULT_MAXLEN = 64
#: Default extrapolation allowance past the newest sample [s] (chosen here: a quarter of a 5 Hz step).
DEFAULT_MAX_EXTRAPOLATION = 0.05


class PoseTooOld(ValueError):
    """The query time is older than the oldest sample still in the buffer."""


class PoseTooNew(ValueError):
    """The query time is past the newest sample by more than the extrapolation allowance (or the
    buffer is empty): the pose for that time has not arrived yet."""


def wrap_angle(angle: float) -> float:
    """Wrap to ``[-π, π)``."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def slerp(q0, q1, s: float) -> np.ndarray:
    """Spherical linear interpolation of unit scalar-last quaternions along the shorter arc;
    ``s`` outside ``[0, 1]`` extrapolates along the same great circle."""
    q0 = np.asarray(q0, float)
    q1 = np.asarray(q1, float)
    dot = float(q0 @ q1)
    if dot < 0.0:  # q and -q are the same rotation: take the shorter arc
        q1, dot = -q1, -dot
    dot = min(dot, 1.0)
    theta = math.acos(dot)
    if theta < 1e-9:  # (nearly) the same rotation: linear is exact to rounding
        q = q0 + s * (q1 - q0)
    else:
        q = (math.sin((1.0 - s) * theta) * q0 + math.sin(s * theta) * q1) / math.sin(theta)
    return q / np.linalg.norm(q)


@dataclass(frozen=True)
class PoseSample:
    """Vehicle pose at time ``t``: NED ``position`` [m], attitude ``roll``, ``pitch``, ``yaw`` (Z-Y-X,
    radians, :func:`perception.rotations.rotation_from_euler`) and gimbal ``pan``, ``tilt`` (radians,
    :class:`perception.pose.Gimbal`)."""

    t: float
    position: np.ndarray
    roll: float
    pitch: float
    yaw: float
    pan: float = 0.0
    tilt: float = 0.0

    def __post_init__(self):
        p = np.array(self.position, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"pose position must be a finite 3-vector (NED, m), got {self.position!r}")
        p.setflags(write=False)
        object.__setattr__(self, "position", p)
        for name in ("t", "roll", "pitch", "yaw", "pan", "tilt"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
                raise ValueError(f"pose {name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"pose {name} must be finite, got {value!r}")
            object.__setattr__(self, name, float(value))

    @property
    def quaternion(self) -> np.ndarray:
        return quaternion_from_euler(self.roll, self.pitch, self.yaw)


def interpolate(a: PoseSample, b: PoseSample, t: float) -> PoseSample:
    """The pose at ``t`` between (or, extrapolating, beyond) samples ``a`` and ``b`` (``a.t < b.t``)."""
    s = (t - a.t) / (b.t - a.t)
    position = a.position + s * (b.position - a.position)
    q = slerp(a.quaternion, b.quaternion, s)
    roll, pitch, yaw = euler_from_rotation(rotation_from_quaternion(q))
    pan = wrap_angle(a.pan + s * wrap_angle(b.pan - a.pan))
    tilt = a.tilt + s * (b.tilt - a.tilt)  # tilt lives in [-π/2, π/2]: no wrapping
    return PoseSample(t, position, roll, pitch, yaw, pan, tilt)


class PoseBuffer:
    """Bounded, time-ordered pose samples with interpolation at a query time (see the module docstring).

    ``latency`` [s] is the compensation: a sample added with report time ``t_r`` is stored at
    ``t_r - latency`` (0 disables). ``maxlen`` bounds the number of samples (the oldest are dropped).
    ``max_extrapolation`` [s] is how far past the newest sample :meth:`at` still answers."""

    def __init__(self, maxlen: int = DEFAULT_MAXLEN, latency: float = 0.0,
                 max_extrapolation: float = DEFAULT_MAX_EXTRAPOLATION):
        if isinstance(maxlen, bool) or not isinstance(maxlen, int) or maxlen < 2:
            raise ValueError(f"pose buffer maxlen must be an integer >= 2, got {maxlen!r}")
        for name, value in (("latency", latency), ("max_extrapolation", max_extrapolation)):
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise ValueError(f"pose buffer {name} must be a non-negative number of seconds, got {value!r}")
        self.maxlen = maxlen
        self.latency = float(latency)
        self.max_extrapolation = float(max_extrapolation)
        self._times: list[float] = []
        self._samples: list[PoseSample] = []

    def __len__(self) -> int:
        return len(self._samples)

    @property
    def oldest(self) -> float | None:
        return self._times[0] if self._times else None

    @property
    def newest(self) -> float | None:
        return self._times[-1] if self._times else None

    def add(self, report_time: float, position, roll: float, pitch: float, yaw: float,
            pan: float = 0.0, tilt: float = 0.0) -> PoseSample:
        """Store a telemetry sample reported at ``report_time`` (at ``report_time - latency``); returns
        the stored sample. Samples may arrive out of order; one at an existing time replaces it.
        Non-finite values raise :class:`ValueError` and leave the buffer unchanged."""
        sample = PoseSample(float(report_time) - self.latency, position, roll, pitch, yaw, pan, tilt)
        i = bisect.bisect_left(self._times, sample.t)
        if i < len(self._times) and self._times[i] == sample.t:
            self._samples[i] = sample
            return sample
        self._times.insert(i, sample.t)
        self._samples.insert(i, sample)
        if len(self._samples) > self.maxlen:
            del self._times[0]
            del self._samples[0]
        return sample

    def covers(self, t: float) -> bool:
        """Whether :meth:`at` would answer for ``t`` without :class:`PoseTooNew`."""
        return bool(self._times) and t <= self._times[-1] + self.max_extrapolation

    def at(self, t: float) -> PoseSample:
        """The pose at time ``t``: interpolated between the samples around it, or extrapolated from the
        last two within ``max_extrapolation`` of the newest. Raises :class:`PoseTooOld` or
        :class:`PoseTooNew` outside (see the module docstring)."""
        if isinstance(t, bool) or not isinstance(t, int | float | np.integer | np.floating) or not math.isfinite(t):
            raise ValueError(f"pose query time must be a finite number, got {t!r}")
        t = float(t)
        if not self._times:
            raise PoseTooNew(f"no pose for t={t:.3f} s: the pose buffer is empty")
        if t < self._times[0]:
            raise PoseTooOld(f"no pose for t={t:.3f} s: the oldest pose kept is at {self._times[0]:.3f} s")
        newest = self._times[-1]
        if t > newest + self.max_extrapolation:
            raise PoseTooNew(f"no pose for t={t:.3f} s yet: the newest pose is at {newest:.3f} s "
                             f"(extrapolation allowance {self.max_extrapolation:.3f} s)")
        i = bisect.bisect_left(self._times, t)
        if i < len(self._times) and self._times[i] == t:
            return self._samples[i]
        if len(self._samples) == 1:  # t is within the allowance past the only sample: hold it
            only = self._samples[0]
            return PoseSample(t, only.position, only.roll, only.pitch, only.yaw, only.pan, only.tilt)
        i = min(max(i, 1), len(self._samples) - 1)  # past the newest: extrapolate from the last two
        return interpolate(self._samples[i - 1], self._samples[i], t)
