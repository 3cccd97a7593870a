"""Search patterns: boustrophedon (lawnmower) lanes, random patrol, and a cycling waypoint follower.

Neither source specifies a search pattern: Bethke (spec 000 §2.8) only says a quad-rotor flies "a
search pattern through the space", and Andreetto et al. (spec 004 §2.9) use random point-to-point moves
inside a 200 x 200 m area. Both are offered here; the lawnmower geometry and its parameters are chosen
here.

Conventions (DESIGN §3): positions are local NED metres. An ``area`` is the horizontal rectangle
``(north_min, north_max, east_min, east_max)``. ``altitude`` is the height above the local origin
(positive up), so a waypoint's third coordinate is ``z = -altitude``.
"""

from __future__ import annotations

import math

import numpy as np

from fusion.validation import as_vector

Area = tuple[float, float, float, float]


def check_area(area, name: str = "area") -> tuple[float, float, float, float]:
    """Return ``area`` as ``(north_min, north_max, east_min, east_max)`` floats; ValueError if it is empty."""
    values = as_vector(area, name, 4)
    north_min, north_max, east_min, east_max = (float(v) for v in values)
    if not (north_min < north_max and east_min < east_max):
        raise ValueError(f"{name} must be (north_min, north_max, east_min, east_max) with min < max, got {tuple(area)}")
    return north_min, north_max, east_min, east_max


def _check_lanes(lane_index: int, lanes: int) -> None:
    if isinstance(lanes, bool) or int(lanes) != lanes or lanes < 1:
        raise ValueError(f"lanes must be a positive integer, got {lanes}")
    if isinstance(lane_index, bool) or int(lane_index) != lane_index or not 0 <= lane_index < lanes:
        raise ValueError(f"lane_index must be an integer in [0, {int(lanes) - 1}], got {lane_index}")


def lane_area(area: Area, lane_index: int = 0, lanes: int = 1) -> tuple[float, float, float, float]:
    """The strip of ``area`` that lane ``lane_index`` of ``lanes`` covers.

    The area is cut along east into ``lanes`` strips of equal width, each spanning the full north
    extent; strip ``k`` is ``[east_min + k w / L, east_min + (k + 1) w / L]``. The strips partition the
    area (they share only their boundaries).
    """
    north_min, north_max, east_min, east_max = check_area(area)
    _check_lanes(lane_index, lanes)
    width = (east_max - east_min) / lanes
    lo = east_min + lane_index * width
    hi = east_max if lane_index == lanes - 1 else east_min + (lane_index + 1) * width
    return north_min, north_max, lo, hi


def lawnmower_waypoints(area: Area, spacing: float, altitude: float, lane_index: int = 0, lanes: int = 1) -> np.ndarray:
    """Boustrophedon path over lane ``lane_index`` of ``area``, as an ``(K, 3)`` array of NED waypoints.

    Legs run north-south over the full north extent of the lane's strip (:func:`lane_area`), alternating
    direction, starting at the strip's south-west corner and going north. A strip of width ``w`` gets
    ``n = ceil(w / spacing)`` legs at east offsets ``(i + 1/2) w / n``: consecutive legs are at most
    ``spacing`` apart and the outer legs at most ``spacing / 2`` from the strip edges, so every point
    of the strip lies within ``spacing / 2`` of the path — a sensor footprint of half-width
    ``spacing / 2`` sweeps the whole strip. With ``lanes = N`` agents, agent ``k`` flying lane ``k``
    gives a partition of the area without any coordination.
    """
    north_min, north_max, east_min, east_max = lane_area(area, lane_index, lanes)
    if not (math.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing must be a positive number of metres, got {spacing}")
    if not math.isfinite(altitude):
        raise ValueError(f"altitude must be finite, got {altitude}")
    width = east_max - east_min
    n_legs = max(1, math.ceil(width / spacing - 1e-9))
    z = -float(altitude)
    points = []
    for i in range(n_legs):
        east = east_min + (i + 0.5) * width / n_legs
        south_first = i % 2 == 0
        first, second = (north_min, north_max) if south_first else (north_max, north_min)
        points.append((first, east, z))
        points.append((second, east, z))
    return np.array(points, dtype=float)


class RandomPatrol:
    """Random point-to-point patrol (Andreetto et al., spec 004 §2.9): uniform points inside ``area``.

    ``next_point()`` returns a new ``(north, east)`` point drawn uniformly in the area from a
    ``numpy`` generator seeded with ``seed`` (an int or a sequence of ints), so a run is reproducible.
    """

    def __init__(self, area: Area, seed=0):
        self.area = check_area(area)
        self._rng = np.random.default_rng(seed)

    def next_point(self) -> np.ndarray:
        north_min, north_max, east_min, east_max = self.area
        return np.array([self._rng.uniform(north_min, north_max), self._rng.uniform(east_min, east_max)])


class WaypointFollower:
    """Cycle through ``waypoints``: the current waypoint is accepted when the vehicle comes within
    ``acceptance_radius`` of it, and the follower moves on to the next one, wrapping to the first after
    the last.

    Acceptance is checked horizontally (north, east) by default, because a search flies at one
    altitude and a vehicle still climbing should not stall the pattern; ``horizontal=False`` uses the
    3-D distance (waypoints must then be 3-D).
    """

    def __init__(self, waypoints, acceptance_radius: float, horizontal: bool = True):
        points = np.asarray(waypoints, dtype=float)
        if points.ndim != 2 or points.shape[0] < 1 or points.shape[1] not in (2, 3):
            raise ValueError(f"waypoints must be a non-empty (K, 2) or (K, 3) array, got shape {points.shape}")
        if not np.all(np.isfinite(points)):
            raise ValueError("waypoints contain non-finite values (NaN or inf)")
        if not (math.isfinite(acceptance_radius) and acceptance_radius > 0):
            raise ValueError(f"acceptance_radius must be a positive number of metres, got {acceptance_radius}")
        if not horizontal and points.shape[1] != 3:
            raise ValueError("3-D acceptance (horizontal=False) needs (K, 3) waypoints")
        self._waypoints = points
        self.acceptance_radius = float(acceptance_radius)
        self.horizontal = horizontal
        self.index = 0
        self.laps = 0  # completed cycles through the list

    @property
    def waypoints(self) -> np.ndarray:
        return self._waypoints.copy()

    def advance(self) -> None:
        self.index += 1
        if self.index == len(self._waypoints):
            self.index = 0
            self.laps += 1

    def _reached(self, position: np.ndarray) -> bool:
        target = self._waypoints[self.index]
        dims = 2 if self.horizontal else 3
        return float(np.linalg.norm(position[:dims] - target[:dims])) <= self.acceptance_radius

    def current(self, position) -> np.ndarray:
        """The waypoint to fly to from ``position`` (NED, length 2 or 3), advancing past reached ones.

        At most one full cycle is skipped per call, so a radius that covers every waypoint cannot loop.
        """
        position = np.asarray(position, dtype=float)
        for _ in range(len(self._waypoints)):
            if not self._reached(position):
                break
            self.advance()
        return self._waypoints[self.index].copy()
