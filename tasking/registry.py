"""``[tasking]``: the planner registry, and a validated section that builds one planner per agent.

``planner = "placeholder"`` (default; :class:`tasking.planner.PlaceholderPlanner`: search its lane, then
orbit a confirmed track) or ``"entropy"`` (:class:`tasking.entropy.EntropyPlanner`: the information-gain
explorer of Merino (4.21)-(4.24) over the agent's fire map) or ``"assignment"``
(:class:`tasking.assignment.AssignmentPlanner`: serve the task the fleet agreed on by consensus, CBBA) or
``"feature"`` (:class:`tasking.feature_planner.FeaturePlanner`: follow an operator's feature polyline with the
camera on it, spec 003). The other keys of the section are that
planner's parameters; unknown keys, wrong types and a planner whose views the agent does not hold are
errors with the key's name, found when the scenario is read.

Adding a planner is one module in ``tasking/`` with a ``plan(state, views)`` method
(:class:`tasking.base.Planner`) plus one :data:`PLANNERS` line.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from numbers import Real

from tasking.assignment import WORDS, AssignmentConfig, AssignmentPlanner
from tasking.base import Planner
from tasking.entropy import EntropyPlanner, EntropyPlannerConfig
from tasking.feature_planner import FeaturePlanner, FeaturePlannerConfig
from tasking.planner import PlaceholderPlanner
from tasking.standoff import LIVE_WAIT, StandoffPilot, vehicle_limits

DEFAULT_PLANNER = "placeholder"


@dataclass(frozen=True)
class PlanningContext:
    """What an agent tells the registry about itself when it builds its planner."""

    index: int  # 0-based index of the agent in the team
    agents: int  # team size
    area: tuple[float, float, float, float]  # north min, max, east min, max [m]
    altitude: float  # flight altitude above the origin [m]
    seed: int
    views: frozenset[str]  # the belief kinds the agent holds (what it can give a planner)
    hints: Mapping[str, object] = field(default_factory=dict)  # from the beliefs, e.g. "detection": (P_D, P_F)
    step: float = 0.2  # s between planner calls (the agent's cycle)
    max_speed: float | None = None  # m/s, the vehicle's top speed (None: not known)
    vehicle: Mapping[str, object] = field(default_factory=dict)  # the [vehicle] section (kind and limits)
    lockstep: bool = False  # stepped by the lockstep harness: no wall-clock deadline, background work is waited for


def _placeholder(options: dict, ctx: PlanningContext) -> Planner:
    options = {"search": "lawnmower", "spacing": 60.0, "orbit_radius": 40.0, **options}
    return PlaceholderPlanner(ctx.index, ctx.agents, ctx.area, ctx.altitude, seed=ctx.seed, **options)


def _assignment(options: dict, ctx: PlanningContext) -> Planner:
    config = AssignmentConfig.from_options(options)
    standoff = None if config.standoff == "circle" else StandoffPilot(
        vehicle_limits(ctx.vehicle, ctx.max_speed), ctx.altitude, config.adopt_after,
        wait=None if ctx.lockstep else LIVE_WAIT)
    return AssignmentPlanner(config, ctx.area, ctx.altitude, ctx.step, ctx.max_speed, standoff)


def _entropy(options: dict, ctx: PlanningContext) -> Planner:
    pd, pf = ctx.hints["detection"]
    return EntropyPlanner(EntropyPlannerConfig(pd=pd, pf=pf, **options), ctx.area, ctx.altitude)


def _feature(options: dict, ctx: PlanningContext) -> Planner:
    return FeaturePlanner(FeaturePlannerConfig.from_options(options), ctx.area, ctx.altitude, ctx.max_speed)


@dataclass(frozen=True)
class PlannerEntry:
    build: Callable[[dict, PlanningContext], Planner]
    needs: str  # the view (belief kind) the planner reads
    options: dict[str, type | tuple[type, ...]]  # allowed keys -> accepted types
    check: Callable[[dict], object] | None = None  # validates the values (ValueError), when the scenario is read


_NUMBER = (Real,)
PLANNERS: dict[str, PlannerEntry] = {
    "placeholder": PlannerEntry(_placeholder, "track", {
        "search": str, "spacing": _NUMBER, "orbit_radius": _NUMBER, "acceptance_radius": _NUMBER,
        "orbit_direction": int, "speed": _NUMBER}),
    "assignment": PlannerEntry(_assignment, "tasks", {
        f.name: (int if f.name in ("capacity", "orbit_slots") else str if f.name in WORDS else _NUMBER)
        for f in fields(AssignmentConfig)},
        AssignmentConfig.from_options),
    "entropy": PlannerEntry(_entropy, "grid", {  # P_D and P_F are the grid sensor's ([grid] pd, pf)
        f.name: {"horizon": int, "explorers": int, "watch": bool}.get(f.name, _NUMBER)
        for f in fields(EntropyPlannerConfig) if f.name not in ("pd", "pf")}),
    "feature": PlannerEntry(_feature, "track", {
        f.name: {"path": list, "look_at": str}.get(f.name, _NUMBER) for f in fields(FeaturePlannerConfig)},
        FeaturePlannerConfig.from_options),
}


def check_tasking(section: dict, views: frozenset[str] | None = None) -> tuple[str, dict]:
    """The planner name and its options from a ``[tasking]`` table; ``ValueError`` naming the bad key, or
    the missing belief when the agent's belief kinds (``views``) are given."""
    if not isinstance(section, dict):
        raise ValueError(f"[tasking] must be a table, got {type(section).__name__}")
    options = dict(section)
    name = options.pop("planner", DEFAULT_PLANNER)
    if name not in PLANNERS:
        raise ValueError(f"tasking.planner must be one of {sorted(PLANNERS)}, got {name!r}")
    entry = PLANNERS[name]
    unknown = sorted(set(options) - set(entry.options))
    if unknown:
        raise ValueError(f"unknown tasking settings for planner {name!r}: {unknown}; known: {sorted(entry.options)}")
    for key, value in options.items():
        if (isinstance(value, bool) and entry.options[key] is not bool) or not isinstance(value, entry.options[key]):
            raise ValueError(f"tasking.{key} has the wrong type: {value!r}")
    if entry.check is not None:
        entry.check(options)
    if views is not None and entry.needs not in views:
        raise ValueError(f"tasking.planner = {name} needs a [{entry.needs}] section (it plans on that belief); "
                         f"the agent holds {sorted(views)}")
    return name, options


def planner_from_config(section: dict, context: PlanningContext) -> Planner:
    """Build the planner a ``[tasking]`` section names for one agent (``ValueError`` on a bad section)."""
    name, options = check_tasking(section, context.views)
    return PLANNERS[name].build(options, context)
