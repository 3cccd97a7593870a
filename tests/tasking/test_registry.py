"""tasking.registry: the [tasking] section is validated when a scenario is read, and builds the named
planner; every planner answers the one seam ``plan(state, views)`` as its own ``goal_for`` does."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from agent.beliefs.grid_config import GridConfig
from agent.config import AgentScenario
from tasking.base import MapView, TrackView
from tasking.entropy import EntropyPlanner
from tasking.planner import PlaceholderPlanner
from tasking.registry import PLANNERS, PlanningContext, check_tasking, planner_from_config

AREA = (-100.0, 100.0, -100.0, 100.0)


def context(views=("track",), **hints) -> PlanningContext:
    return PlanningContext(1, 3, AREA, 50.0, 7, frozenset(views), hints)


def test_the_default_is_the_placeholder_planner_with_its_defaults():
    planner = planner_from_config({}, context())
    assert isinstance(planner, PlaceholderPlanner)
    assert planner.orbit_radius == 40.0 and planner.search == "lawnmower"


def test_entropy_takes_the_grid_sensor_model_from_the_hints():
    ctx = context(("track", "grid"), detection=(0.8, 0.1))
    planner = planner_from_config({"planner": "entropy", "step": 10.0}, ctx)
    assert isinstance(planner, EntropyPlanner)
    assert (planner.config.pd, planner.config.pf, planner.config.step) == (0.8, 0.1, 10.0)


@pytest.mark.parametrize("section, words", [
    ({"planner": "astar"}, "tasking.planner must be one of"),  # an unknown planner
    ({"spacing": 20.0, "spacng": 3}, "unknown tasking settings"),  # a typo in a key
    ({"spacing": "wide"}, "tasking.spacing has the wrong type"),  # a string for a number
    ({"orbit_direction": True}, "tasking.orbit_direction has the wrong type"),  # a bool for an int
    ({"planner": "entropy", "pd": 0.9}, "unknown tasking settings"),  # P_D belongs to [grid], not [tasking]
    ({"planner": "entropy", "horizon": 1.5}, "tasking.horizon has the wrong type"),  # a float horizon
])
def test_a_bad_section_is_an_error_naming_the_key(section, words):
    with pytest.raises(ValueError, match=words):
        check_tasking(section)


def test_a_planner_on_a_belief_the_agent_does_not_hold_is_an_error():
    """Bad input: the explorer without a [grid] section, both when building and when reading the scenario."""
    with pytest.raises(ValueError, match=r"needs a \[grid\] section"):
        planner_from_config({"planner": "entropy"}, context())
    with pytest.raises(ValueError, match=r"needs a \[grid\] section"):
        AgentScenario.from_dict({"tasking": {"planner": "entropy"}})
    with pytest.raises(ValueError, match="tasking"):
        AgentScenario.from_dict({"tasking": {"planner": "entropy", "step": "far"}, "grid": {}})
    assert AgentScenario.from_dict({"tasking": {"planner": "entropy"}, "grid": {}}).grid == GridConfig()


def test_the_seam_gives_what_the_planners_own_method_gives():
    state = SimpleNamespace(position=np.array([10.0, -20.0, -50.0]))
    tracks = [(3, np.array([30.0, 40.0])), (5, np.array([-60.0, 10.0]))]
    seam, direct = (planner_from_config({}, context()) for _ in range(2))
    np.testing.assert_array_equal(seam.plan(state, {"track": TrackView(tracks)}).position,
                                  direct.goal_for(state.position, tracks).position)
    rng = np.random.default_rng(0)
    probability = rng.uniform(size=(20, 20))
    centres = np.stack(np.meshgrid(np.linspace(-95, 95, 20), np.linspace(-95, 95, 20), indexing="ij"), axis=-1)
    seam, direct = (planner_from_config({"planner": "entropy"}, context(("grid",), detection=(0.9, 0.05)))
                    for _ in range(2))
    np.testing.assert_array_equal(seam.plan(state, {"grid": MapView(probability, centres)}).position,
                                  direct.goal_for(state.position, probability, centres).position)


def test_every_registered_planner_reads_a_view_and_lists_its_options():
    for name, entry in PLANNERS.items():
        assert entry.needs in ("track", "grid", "tasks"), name
        assert entry.options, name
