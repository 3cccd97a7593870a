"""The rendezvous cases and the per-UAV stages (spec 004 §2.7, §2.9)."""

from __future__ import annotations

import numpy as np
import pytest

from tasking.rendezvous import Case, Stage, StageRules, StageState, next_stage, rendezvous_case


def test_three_cases_and_search():
    sees = np.array([False, True, True, False])
    hears = np.array([True, False, True, False])
    np.testing.assert_array_equal(
        rendezvous_case(sees, hears), [Case.FLY_TO_CIRCLE, Case.OWN_ORBIT, Case.CONSENSUS, Case.SEARCH]
    )


def _run(informed_sequence, rules, stage=Stage.SEARCH):
    state = StageState.start((1,), stage)
    stages = []
    for informed in informed_sequence:
        state = next_stage(state, np.array([informed]), rules)
        stages.append(int(state.stage[0]))
    return stages


def test_search_to_approach_to_track():
    rules = StageRules(approach_readings=3, track_patience=2, lost_patience=5)
    assert _run([False, True, True, True, True], rules) == [
        Stage.SEARCH,
        Stage.APPROACH,
        Stage.APPROACH,
        Stage.TRACK,
        Stage.TRACK,
    ]


def test_static_algorithm_never_tracks():
    assert _run([True] * 50, StageRules(approach_readings=None)) == [Stage.APPROACH] * 50


def test_tracking_uav_without_information_returns_to_approach_then_search():
    rules = StageRules(approach_readings=1, track_patience=2, lost_patience=4)
    stages = _run([True, False, False, False, False, False, False], rules)
    assert stages == [Stage.TRACK, Stage.TRACK, Stage.TRACK, Stage.APPROACH, Stage.APPROACH, Stage.SEARCH, Stage.SEARCH]


def test_information_resets_the_missed_count():
    rules = StageRules(approach_readings=None, lost_patience=2)
    assert _run([True, False, False, True, False, False], rules)[-1] == Stage.APPROACH


@pytest.mark.parametrize(
    ("call", "named"),
    [
        (lambda: rendezvous_case(np.array([1, 0]), np.array([True, False])), "sees"),  # integers, not booleans
        (lambda: StageRules(approach_readings=-1), "approach_readings"),  # negative count
        (lambda: StageRules(lost_patience=1.5), "lost_patience"),  # not an integer
        (lambda: next_stage(StageState.start((2,)), np.array([True])), "informed"),  # wrong shape
    ],
)
def test_bad_inputs(call, named):
    with pytest.raises(ValueError, match=named):
        call()
