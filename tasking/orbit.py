"""Goals, orbit goals and a talk-free target choice.

:class:`Goal` is what tasking hands to the agent: plain data that the agent turns into its vehicle's
setpoint (``agent.vehicles.base.goal_to_setpoint``). Tasking never imports ``agent`` (DESIGN §1).

Orbiting the target is how Andreetto et al. observe it (spec 004 §2.8): bearing-only sensors on a circle
centred at the estimated target. The equal spacing of agents on the circle and the rendezvous logic
(spec 004 §2.9) belong to the full tasking; here every agent simply circles its chosen target.

Conventions (DESIGN §3): local NED metres; ``altitude`` is the height above the local origin
(positive up), so a goal's ``position[2] == -altitude``. An orbit ``direction`` of ``+1`` is
clockwise seen from above (north -> east -> south, a right turn, positive yaw rate), ``-1``
anticlockwise.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import numpy as np

from fusion.validation import as_vector


@dataclass(frozen=True)
class Goal:
    """Where tasking wants the vehicle.

    ``position`` (3,) NED is the point to fly to. If ``orbit_center`` (north, east) is given the goal
    is to circle it at ``orbit_radius`` in ``orbit_direction`` (+1 clockwise from above, -1
    anticlockwise), at the depth ``position[2]``; ``position[:2]`` is then the centre. ``speed`` is an
    optional speed limit in m/s (``None``: the vehicle's own cruise/max speed). ``velocity`` (2,) (north, east)
    [m/s] is an optional feed-forward: the velocity of the point or of the orbit's centre, which the vehicle adds
    to its own guidance (a moving circle is then flown in the centre's frame). ``look_at`` (3,) NED is an
    optional gimbal command, "point the camera here" (``None``: the sensors keep their own pointing; spec 003
    §2.9: the GNC computer sends the gimbal its reference).
    """

    position: np.ndarray
    orbit_center: np.ndarray | None = None
    orbit_radius: float | None = None
    orbit_direction: int = 1
    speed: float | None = None
    look_at: np.ndarray | None = None
    velocity: np.ndarray | None = None

    def __post_init__(self):
        object.__setattr__(self, "position", as_vector(self.position, "goal position", 3))
        if self.orbit_center is None:
            if self.orbit_radius is not None:
                raise ValueError("orbit_radius given without orbit_center")
        else:
            object.__setattr__(self, "orbit_center", as_vector(self.orbit_center, "orbit_center", 2))
            radius = self.orbit_radius
            if radius is None or not (math.isfinite(radius) and radius > 0):
                raise ValueError(f"orbit_radius must be a positive number of metres, got {radius}")
            object.__setattr__(self, "orbit_radius", float(radius))
        if self.orbit_direction not in (1, -1):
            raise ValueError(f"orbit_direction must be +1 or -1, got {self.orbit_direction}")
        if self.speed is not None and not (math.isfinite(self.speed) and self.speed > 0):
            raise ValueError(f"speed must be a positive number of m/s or None, got {self.speed}")
        if self.look_at is not None:
            object.__setattr__(self, "look_at", as_vector(self.look_at, "goal look_at (NED)", 3))
        if self.velocity is not None:
            object.__setattr__(self, "velocity", as_vector(self.velocity, "goal velocity (north, east)", 2))

    @property
    def is_orbit(self) -> bool:
        return self.orbit_center is not None


def goto_goal(position_ne, altitude: float, speed: float | None = None) -> Goal:
    """Fly to ``position_ne`` (north, east) at ``altitude`` (metres above the origin, positive up)."""
    ne = as_vector(position_ne, "position_ne", 2)
    return Goal(position=np.array([ne[0], ne[1], -float(altitude)]), speed=speed)


def orbit_setpoint(center_ne, radius: float, altitude: float, direction: int = 1, speed: float | None = None,
                   velocity=None) -> Goal:
    """Circle ``center_ne`` (north, east) at ``radius`` and ``altitude`` (positive up) in ``direction``, the centre
    moving at ``velocity`` (north, east) if given."""
    center = as_vector(center_ne, "center_ne", 2)
    return Goal(
        position=np.array([center[0], center[1], -float(altitude)]),
        orbit_center=center,
        orbit_radius=radius,
        orbit_direction=direction,
        speed=speed,
        velocity=velocity,
    )


def choose_target(agent_index: int, tracks: Sequence[tuple[Hashable, object]]) -> tuple[Hashable, np.ndarray] | None:
    """Pick the track agent ``agent_index`` should orbit, without talking to the others.

    ``tracks`` are ``(track_id, position)`` pairs with the *fused* estimated position (north, east, ...;
    only the first two coordinates are used). The tracks are sorted by (north, east) and the agent
    takes entry ``agent_index mod len(tracks)``. Every agent that sorts the same fused estimates gets the
    same order, so agents ``0..N-1`` spread over the ``M`` targets round-robin: each target gets
    ``floor(N/M)`` or ``ceil(N/M)`` agents, with no negotiation.

    Caveat: agents whose fused estimates differ (before their beliefs have converged, or across a
    partition) may order two targets of nearly equal north differently and briefly double up on one.
    Ties in (north, east) are broken by ``str(track_id)`` so that the order is total.
    Returns ``None`` if there is no track.
    """
    if isinstance(agent_index, bool) or int(agent_index) != agent_index or agent_index < 0:
        raise ValueError(f"agent_index must be a non-negative integer, got {agent_index}")
    if not tracks:
        return None
    entries = []
    for track_id, position in tracks:
        pos = np.asarray(position, dtype=float).ravel()
        if pos.size < 2 or not np.all(np.isfinite(pos[:2])):
            raise ValueError(f"track {track_id!r} needs a finite (north, east) position, got {position!r}")
        entries.append((float(pos[0]), float(pos[1]), str(track_id), track_id, pos[:2].copy()))
    entries.sort(key=lambda e: (e[0], e[1], e[2]))
    chosen = entries[int(agent_index) % len(entries)]
    return chosen[3], chosen[4]
