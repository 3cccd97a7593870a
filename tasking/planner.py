"""A placeholder planner that is still a real behaviour: search until a target is confirmed, then orbit it.

Behaviour of :class:`PlaceholderPlanner`, called once per agent cycle (DESIGN §4, "plan"):

- **No confirmed track** -> *search*. With ``search="lawnmower"`` agent ``k`` of ``N`` sweeps strip
  ``k`` of the area with a boustrophedon path (:func:`tasking.search.lawnmower_waypoints`), cycling
  forever, so the team covers the area without coordination. With ``search="patrol"`` it makes random
  point-to-point moves inside the whole area (Andreetto et al., spec 004 §2.9), with a generator seeded
  from ``(seed, agent_index)`` so agents differ but a run is reproducible.
- **At least one confirmed track** -> *orbit*. The agent picks a track with
  :func:`tasking.orbit.choose_target` (sort the fused estimates by (north, east), take
  ``agent_index mod M``), and circles its estimated position at ``orbit_radius``. Because the tracks
  are the agent's fused beliefs, this also covers Andreetto et al.'s rendezvous case 1: an agent that never saw
  the target but received a neighbour's estimate goes to the circle. The orbit centre follows the
  estimate every cycle.
- **Tracks disappear** -> back to *search*, resuming the search where it was left (the same lawnmower
  waypoint, or the same patrol point).

Not here yet (full tasking arrives later): equal spacing on the circle (spec 004 §2.8), Bethke's
detection/tracking phases and dwell times (spec 000 §2.10), and the potential-field collision layer
(spec 000 §2.9). Agents sharing a target orbit the same circle in the same direction.

The planner returns a :class:`tasking.orbit.Goal` (plain data); ``agent.vehicles.base.goal_to_setpoint``
turns it into a vehicle setpoint. ``altitude`` is metres above the local origin (positive up).
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Mapping, Sequence

import numpy as np

from fusion.validation import as_vector
from tasking.base import VehicleStateLike
from tasking.orbit import Goal, choose_target, goto_goal, orbit_setpoint
from tasking.search import Area, RandomPatrol, WaypointFollower, check_area, lawnmower_waypoints

__all__ = ["Goal", "PlaceholderPlanner"]

SEARCH_KINDS = ("lawnmower", "patrol")


class PlaceholderPlanner:
    """Search its lane (or patrol) while there is no confirmed track, otherwise orbit a chosen target.

    Parameters (defaults chosen here): ``spacing`` is the lawnmower leg spacing (twice the sensor
    footprint half-width), ``orbit_radius`` the circle radius around a target (15 m is Andreetto et al.'s
    rendezvous value, spec 004 §3), ``acceptance_radius`` the distance at which a search waypoint
    counts as reached (default ``spacing / 2``; a fixed wing needs at least its loiter radius),
    ``speed`` an optional speed limit passed with every goal.

    After each :meth:`plan`, ``mode`` is ``"search"`` or ``"orbit"`` and ``target_id`` the orbited
    track (``None`` while searching).
    """

    def __init__(
        self,
        agent_index: int,
        n_agents: int,
        area: Area,
        altitude: float,
        search: str = "lawnmower",
        spacing: float = 20.0,
        orbit_radius: float = 15.0,
        seed: int = 0,
        *,
        acceptance_radius: float | None = None,
        orbit_direction: int = 1,
        speed: float | None = None,
    ):
        if isinstance(n_agents, bool) or int(n_agents) != n_agents or n_agents < 1:
            raise ValueError(f"n_agents must be a positive integer, got {n_agents}")
        if isinstance(agent_index, bool) or int(agent_index) != agent_index or not 0 <= agent_index < n_agents:
            raise ValueError(f"agent_index must be an integer in [0, {int(n_agents) - 1}], got {agent_index}")
        if search not in SEARCH_KINDS:
            raise ValueError(f"search must be one of {SEARCH_KINDS}, got {search!r}")
        if not math.isfinite(altitude):
            raise ValueError(f"altitude must be finite, got {altitude}")
        if not (math.isfinite(spacing) and spacing > 0):
            raise ValueError(f"spacing must be a positive number of metres, got {spacing}")
        if not (math.isfinite(orbit_radius) and orbit_radius > 0):
            raise ValueError(f"orbit_radius must be a positive number of metres, got {orbit_radius}")
        if acceptance_radius is None:
            acceptance_radius = spacing / 2.0
        if orbit_direction not in (1, -1):
            raise ValueError(f"orbit_direction must be +1 or -1, got {orbit_direction}")
        self.agent_index = int(agent_index)
        self.n_agents = int(n_agents)
        self.area = check_area(area)
        self.altitude = float(altitude)
        self.search = search
        self.orbit_radius = float(orbit_radius)
        self.orbit_direction = orbit_direction
        self.speed = speed
        self.acceptance_radius = float(acceptance_radius)
        if not (math.isfinite(self.acceptance_radius) and self.acceptance_radius > 0):
            raise ValueError(f"acceptance_radius must be a positive number of metres, got {acceptance_radius}")
        self.mode = "search"
        self.target_id: Hashable | None = None
        self._follower: WaypointFollower | None = None
        self._patrol: RandomPatrol | None = None
        self._patrol_point: np.ndarray | None = None
        if search == "lawnmower":
            path = lawnmower_waypoints(self.area, spacing, self.altitude, self.agent_index, self.n_agents)
            self._follower = WaypointFollower(path, self.acceptance_radius)
        else:
            self._patrol = RandomPatrol(self.area, seed=[int(seed), self.agent_index])
            self._patrol_point = self._patrol.next_point()

    def _search_goal(self, position: np.ndarray) -> Goal:
        if self._follower is not None:
            waypoint = self._follower.current(position)
            return goto_goal(waypoint[:2], self.altitude, self.speed)
        assert self._patrol is not None and self._patrol_point is not None
        # Draw a new point when the current one is reached (bounded: a fresh point is almost surely far).
        for _ in range(16):
            if float(np.linalg.norm(position[:2] - self._patrol_point)) > self.acceptance_radius:
                break
            self._patrol_point = self._patrol.next_point()
        return goto_goal(self._patrol_point, self.altitude, self.speed)

    def plan(self, state: VehicleStateLike, views: Mapping[str, object]) -> Goal:
        """The planner seam (:class:`tasking.base.Planner`): orbit or search from the ``"track"`` view."""
        return self.goal_for(state.position, views["track"].positions)

    def goal_for(self, vehicle_position, confirmed_tracks: Sequence[tuple[Hashable, object]]) -> Goal:
        """The goal for this cycle, from the vehicle's NED position and the confirmed ``(track_id, position)``
        pairs (fused estimates, north/east first)."""
        position = as_vector(vehicle_position, "vehicle_position", 3)
        chosen = choose_target(self.agent_index, list(confirmed_tracks))
        if chosen is None:
            self.mode, self.target_id = "search", None
            return self._search_goal(position)
        self.mode, self.target_id = "orbit", chosen[0]
        return orbit_setpoint(chosen[1], self.orbit_radius, self.altitude, self.orbit_direction, self.speed)
