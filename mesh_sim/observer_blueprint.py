"""The Rerun layout sent with every recording (``rerun.blueprint``), made for a fleet rather than for one agent.

::

    ┌──────────────────────────────┬──────────────────────┐
    │ world (3D, every agent)      │ tabs: one time-series│
    │                              │ view per metric, one │
    │                              │ line per agent       │
    ├──────────────────────────────┤                      │
    │ tabs: fire maps │ uav0 │ uav1 …  (each agent alone) │
    └──────────────────────────────┴──────────────────────┘

The 3D world takes 3/5 of the width and 3/5 of its column's height. A metric's entities are
``metrics/<metric>/<agent>`` (live, from telemetry) and ``series/<kind>/.../<agent>`` (after the run, from the
metrics: :mod:`mesh_sim.observer_series`), so one :class:`~rerun.blueprint.TimeSeriesView` per metric draws one
line per agent. Views are only made for what the run has (no tracks panel in a fire run without targets).
"""

from __future__ import annotations

import rerun.blueprint as rrb

#: Live metrics (entity ``metrics/<name>/<agent>``) and their panel titles.
LIVE_METRICS = {"tracks": "tracks held", "bytes_seen": "bytes seen by the ground station",
                "bytes_rx": "bytes received", "video_quality": "video quality D(t)"}
MAPS_LEGEND = "maps/legend"
PALETTE = [(31, 119, 180), (148, 103, 189), (23, 190, 207), (188, 189, 34), (227, 119, 194), (140, 86, 75),
           (127, 127, 127), (44, 160, 44), (255, 187, 120), (174, 199, 232)]  # the agents' lines and points, in turn
ORACLE_COLOUR = (0, 0, 0)  # the centralized filter's lines


def fleet_blueprint(agents: list[str], metrics: list[str], maps: bool, series: dict[str, list[str]] | None = None
                    ) -> rrb.Blueprint:
    """The layout for ``agents``: the live ``metrics`` that were logged (keys of :data:`LIVE_METRICS`), fire map
    panels if ``maps``, and the run's series (``{kind: [sub-path, ...]}``, e.g. ``{"error": ["car", "walker"]}``;
    a sub-path's agents are its children) when the run is over."""
    per_agent = [rrb.Spatial3DView(name=agent, origin="/world",
                                   contents=["+ /world/truth/**", f"+ /world/uav/{agent}/**",
                                             f"+ /world/agents/{agent}/**", "+ /world/links/**"])
                 for agent in agents]
    below = [*([_maps(agents)] if maps else []), *per_agent]
    left = rrb.Vertical(rrb.Spatial3DView(name="world", origin="/world"),
                        *([rrb.Tabs(*below, name="per agent")] if below else []),
                        row_shares=[3, 2] if below else None)
    live = [rrb.TimeSeriesView(name=LIVE_METRICS[m], origin=f"/metrics/{m}") for m in metrics]
    after = [rrb.Vertical(*[rrb.TimeSeriesView(name=f"{kind} {sub}".strip(), origin=f"/series/{kind}/{sub}".rstrip("/"))
                            for sub in subs], name=kind)
             for kind, subs in (series or {}).items()]
    right = rrb.Tabs(*after, rrb.Vertical(*live, name="live"), name="metrics") if after else rrb.Vertical(*live)
    return rrb.Blueprint(rrb.Horizontal(left, right, column_shares=[3, 2]), collapse_panels=True)


def _maps(agents: list[str]) -> rrb.Container:
    """The true fire, every agent's map and their legend, in a grid."""
    views = [rrb.Spatial2DView(name="truth", origin="/maps/truth"),
             *[rrb.Spatial2DView(name=agent, origin=f"/maps/{agent}") for agent in agents],
             rrb.TextDocumentView(name="legend", origin=f"/{MAPS_LEGEND}")]
    return rrb.Grid(*views, name="fire maps")
