"""Belief exchanges (:class:`agent.plugins.BeliefExchange`), one per wire kind, and their registry.

``EXCHANGES`` maps a wire kind to a builder that returns the exchange when the scenario asks for it
(``None`` otherwise): tracks always, a grid with a ``[grid]`` section, the fleet's task assignment with
``[tasking] planner = "assignment"``, particle candidates with ``[tracking] initiation = "particles"`` (they
live in the track exchange's tracker, which ``_tracks`` leaves in ``ExchangeContext.shared``: the track
builder runs first). Adding a belief kind is one module
in this folder plus one line here.

A builder imports its exchange's module only when the scenario asks for it if that module is heavy: the grid
brings a thermal camera (OpenCV, scipy.ndimage), which an agent without a ``[grid]`` never loads (issue 12).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from agent.beliefs.flood import FloodExchange
from agent.beliefs.tracks import TrackExchange
from agent.net.sending import SendScheduler
from agent.plugins import BeliefExchange, Outbox
from tasking.assignment import AssignmentConfig
from tasking.registry import check_tasking


@dataclass(frozen=True)
class ExchangeContext:
    """What an agent gives the exchanges it hosts."""

    me: str
    scenario: object  # agent.config.AgentScenario
    terrain: object
    seed: int
    sender: SendScheduler  # the link budget and the track-sending trigger
    outbox: Outbox
    unused: Counter  # observations the agent could not use, by reason
    topology: object  # agent.net.topology.Topology: who hears whom, as the agent knows it
    views: object = None  # agent.plugins.Views: the other exchanges' views (filled once all are built)
    vehicle: object = None  # agent.vehicles.base.Vehicle: where this agent is
    incarnation: int = 0  # this life of the agent (agent.net.incarnation): a restarted agent numbers on from it
    shared: dict = field(default_factory=dict)  # what one builder leaves for a later one ("tracker")
    fusions: object = None  # agent.fusion_log.FusionLog: fusions an exchange makes outside receive (settle)


def _tracks(ctx: ExchangeContext) -> TrackExchange:
    sc = ctx.scenario
    args = (ctx.me, sc.tracking, sc.step, ctx.terrain, ctx.seed, ctx.sender, ctx.outbox, ctx.unused)
    if sc.tracking.policy == "flood":
        exchange = FloodExchange(*args, topology=ctx.topology, incarnation=ctx.incarnation)
    else:
        exchange = TrackExchange(*args, topology=ctx.topology, fusions=ctx.fusions)
    ctx.shared["tracker"] = exchange.tracker
    return exchange


def _grid(ctx: ExchangeContext) -> BeliefExchange | None:
    sc = ctx.scenario
    if sc.grid is None:
        return None
    from agent.beliefs.grids import GridExchange  # the thermal camera's image code, only for a [grid]

    return GridExchange(ctx.me, sc.grid, sc.area.as_tuple(), ctx.terrain, ctx.seed + 7919, ctx.outbox,
                        tracker=ctx.shared.get("tracker"), vehicle=ctx.vehicle)


def _tasks(ctx: ExchangeContext) -> BeliefExchange | None:
    sc = ctx.scenario
    name, options = check_tasking(sc.tasking)
    if name != "assignment":
        return None
    from agent.beliefs.assignment import AssignmentExchange

    return AssignmentExchange(ctx.me, AssignmentConfig.from_options(options), sc.area.as_tuple(),
                              ctx.vehicle.state().position, ctx.views, ctx.vehicle, ctx.seed)


def _particles(ctx: ExchangeContext) -> BeliefExchange | None:
    tracking = ctx.scenario.tracking
    if tracking.initiation != "particles":
        return None
    from agent.beliefs.particles import ParticleExchange

    return ParticleExchange(tracking.particle_init, ctx.shared["tracker"], ctx.seed + 15485863)


EXCHANGES: dict[str, Callable[[ExchangeContext], BeliefExchange | None]] = {
    "track": _tracks,
    "grid": _grid,
    "tasks": _tasks,
    "particles": _particles,
}
