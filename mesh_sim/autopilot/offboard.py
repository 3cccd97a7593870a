"""Offboard setpoints: SET_POSITION_TARGET_LOCAL_NED -> a :class:`agent.vehicles.base.Setpoint` per step.

PX4 (``mavlink_receiver.cpp`` ``handle_message_set_position_target_local_ned``) reads ``type_mask``
(``POSITION_TARGET_TYPEMASK``: bit set = field ignored) per axis: a position the controller tracks, a
velocity it tracks or feeds forward, an acceleration feed-forward. The kinematic models follow a position
setpoint only (DESIGN §4: no new dynamics here), so each axis becomes a reference position:

* position given (with or without velocity): the position, moved along the velocity since the message
  arrived — a position + velocity stream of a moving reference is then tracked without lag, which is what
  PX4's velocity feed-forward achieves;
* velocity only: a carrot ``LOOKAHEAD`` seconds ahead of the vehicle along the velocity, flown at the
  speed ``|v|`` of those axes (far enough ahead that the models' approach law saturates at that speed);
* neither: the vehicle's position when the setpoint arrived (hold that axis).

Accelerations and yaw / yaw rate are accepted and not used: the models turn towards their velocity.
Frames: ``MAV_FRAME_LOCAL_NED``, and ``MAV_FRAME_BODY_NED`` for velocities only (rotated by the yaw).
Anything else, or a non-finite number in a field not ignored, is refused with a reason (and counted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agent.vehicles.base import Setpoint
from agent.vehicles.mavlink_protocol import mavlink

LOOKAHEAD = 5.0  # s; >= 1 / position_gain and >= v / max_accel of the multirotor defaults; chosen here

POSITION_BITS = (
    mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE,
    mavlink.POSITION_TARGET_TYPEMASK_Y_IGNORE,
    mavlink.POSITION_TARGET_TYPEMASK_Z_IGNORE,
)
VELOCITY_BITS = (
    mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE,
    mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE,
    mavlink.POSITION_TARGET_TYPEMASK_VZ_IGNORE,
)


class SetpointRejected(ValueError):
    """A setpoint PX4 would not use; ``reason`` is the counter it is counted under."""

    def __init__(self, reason: str, message: str):
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True)
class OffboardTarget:
    """One SET_POSITION_TARGET_LOCAL_NED, decoded: per NED axis a position and a velocity, NaN where ignored."""

    position: np.ndarray  # (3,)
    velocity: np.ndarray  # (3,)
    received_at: float  # simulator time [s]
    origin: np.ndarray  # vehicle position when it arrived (3,)

    def setpoint(self, position: np.ndarray, now: float) -> Setpoint:
        """The model setpoint at time ``now`` for a vehicle at ``position`` (see the module docstring)."""
        has_p, has_v = ~np.isnan(self.position), ~np.isnan(self.velocity)
        reference = self.origin.copy()
        reference[has_p] = self.position[has_p] + np.where(has_v, self.velocity, 0.0)[has_p] * (now - self.received_at)
        velocity_only = has_v & ~has_p
        reference[velocity_only] = position[velocity_only] + self.velocity[velocity_only] * LOOKAHEAD
        speed = float(np.linalg.norm(self.velocity[velocity_only]))
        return Setpoint(reference, speed=speed if speed > 0 else None)


def decode_target(msg, vehicle_position: np.ndarray, yaw: float, now: float) -> OffboardTarget:
    """The :class:`OffboardTarget` of a SET_POSITION_TARGET_LOCAL_NED message; raises :class:`SetpointRejected`."""
    mask = msg.type_mask
    position = np.array([msg.x, msg.y, msg.z], dtype=float)
    velocity = np.array([msg.vx, msg.vy, msg.vz], dtype=float)
    has_p = np.array([not mask & bit for bit in POSITION_BITS])
    has_v = np.array([not mask & bit for bit in VELOCITY_BITS])
    if not (np.all(np.isfinite(position[has_p])) and np.all(np.isfinite(velocity[has_v]))):
        raise SetpointRejected("non_finite_setpoint", "a setpoint field that is not ignored is not finite")
    if msg.coordinate_frame == mavlink.MAV_FRAME_BODY_NED:
        if has_p.any():
            raise SetpointRejected("unsupported_frame", "MAV_FRAME_BODY_NED positions are not supported")
        if not has_v.all():
            raise SetpointRejected("unsupported_frame", "MAV_FRAME_BODY_NED needs all three velocities")
        c, s = math.cos(yaw), math.sin(yaw)
        velocity = np.array([c * velocity[0] - s * velocity[1], s * velocity[0] + c * velocity[1], velocity[2]])
    elif msg.coordinate_frame != mavlink.MAV_FRAME_LOCAL_NED:
        raise SetpointRejected("unsupported_frame", f"coordinate frame {msg.coordinate_frame} is not supported")
    return OffboardTarget(
        position=np.where(has_p, position, np.nan),
        velocity=np.where(has_v, velocity, np.nan),
        received_at=now,
        origin=np.asarray(vehicle_position, dtype=float).copy(),
    )
