"""The agent's view of a scenario file (TOML): timing, area, vehicle, sensor, tracking, tasking.

The world's sections (``targets``, later ``radio``) belong to ``mesh_sim.scenario``; the agent reads
only what it needs and rejects what it does not know, so a typo in a scenario is an error, not a
silently ignored setting.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agent.beliefs.grid_config import GridConfig
from agent.beliefs.tracking_config import TrackerConfig
from agent.net.link_plan import LinkPlan
from agent.net.sending import SendConfig
from agent.sensors.bearing import BearingSensorConfig
from agent.sensors.camera_config import CameraSensorConfig
from agent.sensors.registry import sensor_config_from_dict
from tasking.registry import check_tasking

#: Top-level keys that the world reads; the agent accepts and ignores them.
WORLD_KEYS = frozenset({"targets", "radio", "description", "fire", "decoys", "references"})
AGENT_KEYS = frozenset(
    {"name", "duration", "agents", "rate_hz", "altitude", "area", "origin", "terrain", "vehicle",
     "sensor", "tracking", "sending", "tasking", "seed", "radio_plan", "grid"}
)


@dataclass(frozen=True)
class Area:
    north: tuple[float, float]
    east: tuple[float, float]

    def __post_init__(self):
        for name in ("north", "east"):
            lo, hi = getattr(self, name)
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise ValueError(f"area.{name} must be [min, max] with min < max, got {[lo, hi]}")

    def as_tuple(self) -> tuple[float, float, float, float]:
        return (*self.north, *self.east)


@dataclass(frozen=True)
class AgentScenario:
    name: str = "default"
    duration: float = 60.0
    agents: int = 4
    rate_hz: float = 5.0  # DESIGN.md §4 default agent rate
    altitude: float = 80.0  # flight height above the origin [m]; chosen here
    seed: int = 1
    area: Area = field(default_factory=lambda: Area((-150.0, 150.0), (-150.0, 150.0)))
    origin: tuple[float, float, float] = (43.5605, 1.4664, 150.0)  # lat, lon [deg], alt [m]; chosen here
    terrain: dict = field(default_factory=lambda: {"kind": "flat"})
    vehicle: dict = field(default_factory=lambda: {"kind": "multirotor"})
    sensor: BearingSensorConfig | CameraSensorConfig = field(default_factory=BearingSensorConfig)  # [sensor] kind
    tracking: TrackerConfig = field(default_factory=TrackerConfig)
    sending: SendConfig = field(default_factory=SendConfig)
    tasking: dict = field(default_factory=dict)
    radio_plan: LinkPlan | None = None  # compiled by the simulator from the scenario's [radio]; None: ideal links
    grid: GridConfig | None = None  # [grid]: a certainty grid (fire map) built and shared; None: no grid

    def __post_init__(self):
        for name in ("duration", "rate_hz", "altitude"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if isinstance(self.agents, bool) or not isinstance(self.agents, int) or self.agents < 1:
            raise ValueError(f"agents must be a positive integer, got {self.agents!r}")
        check_seed(self.seed)
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"name must be a non-empty string, got {self.name!r}")
        grid = {"grid"} if self.grid is not None else set()
        check_tasking(self.tasking, frozenset({"track", "tasks"} | grid))  # "tasks": built for the assignment

    @property
    def step(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def fleet(self) -> frozenset[str]:
        """The fleet's members, ``uav0`` .. ``uav{agents-1}`` (:func:`member_name`): who may send an agent its beliefs.
        A receiver rejects any other origin before it keeps anything about it (``unknown_origin``), so what it holds
        per peer is bounded by the fleet, not by the names a sender can make up."""
        return frozenset(member_name(i) for i in range(self.agents))

    def fleet_of(self, agent_id: str) -> frozenset[str]:
        """:attr:`fleet`, once ``agent_id`` is known to be in it: a ``ValueError`` otherwise (its peers would reject
        every message it sends as ``unknown_origin``)."""
        if agent_id not in self.fleet:
            raise ValueError(f"agent id {agent_id!r} is not a member of the fleet ({', '.join(sorted(self.fleet))})")
        return self.fleet

    def senders_to(self, agent_id: str) -> tuple[str, ...] | None:
        """The peers whose beliefs can reach ``agent_id`` over the emulated radio, or None for every peer
        (:meth:`agent.net.link_plan.LinkPlan.senders_to`; ideal links: every peer)."""
        return None if self.radio_plan is None else self.radio_plan.senders_to(agent_id)

    def start_position(self, index: int) -> np.ndarray:
        """Agents start spread along the southern edge of the area, at flight altitude."""
        (n0, _), (e0, e1) = self.area.north, self.area.east
        east = e0 + (index + 0.5) * (e1 - e0) / self.agents
        return np.array([n0, east, -self.altitude])

    @classmethod
    def from_dict(cls, d: dict) -> AgentScenario:
        unknown = set(d) - AGENT_KEYS - WORLD_KEYS
        if unknown:
            raise ValueError(f"unknown scenario settings: {sorted(unknown)}")
        kwargs = {k: d[k] for k in ("name", "duration", "agents", "rate_hz", "altitude", "seed") if k in d}
        for number in ("duration", "rate_hz", "altitude"):
            if number in kwargs:
                kwargs[number] = _number(kwargs[number], number)
        for section in ("area", "origin", "terrain", "vehicle", "tasking", "sensor", "tracking", "sending", "grid"):
            if section in d and not isinstance(d[section], dict):
                raise ValueError(f"[{section}] must be a table of settings, got {d[section]!r}")
        if "area" in d:
            kwargs["area"] = Area(tuple(map(float, d["area"]["north"])), tuple(map(float, d["area"]["east"])))
        if "origin" in d:
            o = d["origin"]
            kwargs["origin"] = (float(o["lat"]), float(o["lon"]), float(o.get("alt", 0.0)))
        for section in ("terrain", "vehicle", "tasking"):
            if section in d:
                kwargs[section] = dict(d[section])
        if "sensor" in d:
            kwargs["sensor"] = sensor_config_from_dict(d["sensor"])
        if "tracking" in d:
            kwargs["tracking"] = _dataclass_from_dict(TrackerConfig, d["tracking"], "tracking")
        if "sending" in d:
            kwargs["sending"] = _dataclass_from_dict(SendConfig, d["sending"], "sending")
        if "grid" in d:
            kwargs["grid"] = GridConfig.from_dict(d["grid"])
        if d.get("radio_plan") is not None:
            kwargs["radio_plan"] = LinkPlan.from_dict(d["radio_plan"])
        return cls(**kwargs)


def member_name(index: int) -> str:
    """The name of the fleet's agent of 0-based ``index``, as the launcher and the lockstep harness name them."""
    return f"uav{index}"


def check_seed(seed) -> int:
    """A random seed: an integer in [0, 2**32) (numpy's and the launcher's range). Returns it."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise ValueError(f"seed must be an integer in [0, 2**32), got {seed!r}")
    return seed


def read_scenario_file(path: str | Path) -> dict:
    """Read a scenario: TOML, or the JSON a launcher writes into its run folder. Errors name the file."""
    path = Path(path)
    try:
        if path.suffix == ".json":
            raw = json.loads(path.read_text())
        else:
            with open(path, "rb") as f:
                raw = tomllib.load(f)
    except OSError as err:
        raise ValueError(f"{path}: cannot read: {err.strerror}") from None
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"{path}: not valid {path.suffix.lstrip('.').upper() or 'TOML'}: {err}") from None
    if not isinstance(raw, dict):
        raise ValueError(f"{path}: a scenario must be a table of settings")
    return raw


def _number(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{name} must be a number, got {value!r}")
    return float(value)


def _dataclass_from_dict(cls, d: dict, section: str):
    names = set(cls.__dataclass_fields__)
    unknown = set(d) - names
    if unknown:
        raise ValueError(f"unknown {section} settings: {sorted(unknown)}")
    return cls(**d)
