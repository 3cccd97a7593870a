"""The fire benchmark: its quick mode end to end through the command line (per-window rows and JSON), and its
goals judged PASS/MISS from synthetic rows, both ways."""

from __future__ import annotations

import json

import pytest

from mesh_sim import cli
from mesh_sim.bench import fire


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    path = tmp_path_factory.mktemp("bench") / "fire.json"
    assert cli.main(["bench", "fire", "--quick", "--json", str(path)]) == 0
    return json.loads(path.read_text())


@pytest.mark.slow  # benchmark runs
def test_the_quick_mode_writes_per_window_rows_as_json(quick):
    assert quick["benchmark"] == "fire"
    assert quick["settings"]["configs"] == list(fire.QUICK["configs"]) and quick["settings"]["seeds"] == 1
    assert [(r["config"], r["start"], r["end"]) for r in quick["rows"]] == [
        (config, 0.0, pytest.approx(fire.QUICK["duration"])) for config in fire.QUICK["configs"]]
    for row in quick["rows"]:
        assert row["runs"] == 1 and row["maps"] == 4
        assert set(row) >= {"detection_rate", "false_alarm_rejection", "decoy_alarms", "other_false_alarms",
                            "localisation_error_m", "localisation_worst_m", "located_error_m", "located_worst_m",
                            "before_first_detection"}
        assert 0.0 <= row["detection_rate"] <= 1.0 and 0.0 <= row["false_alarm_rejection"] <= 1.0
    assert all(quick["grid_bytes_per_agent_per_s"][c] > 0 for c in fire.QUICK["configs"])
    assert {g["goal"].split(":")[0] for g in quick["goals"]} == set(fire.QUICK["configs"])


def _row(config, window, *, detection=1.0, rejection=1.0, error=0.5, located=0.5, decoy_alarms=0, before=False):
    return {"config": config, "window": window, "before_first_detection": before, "detection_rate": detection,
            "false_alarm_rejection": rejection, "localisation_error_m": error, "located_error_m": located,
            "decoy_alarms": decoy_alarms}


def _verdicts(rows, bytes_per_s=None):
    return {g["goal"]: g["ok"] for g in fire.goals(rows, bytes_per_s or {})}


def test_the_windowed_goals_pass_when_every_window_after_the_first_detection_meets_them():
    # the window that saw the first detection (1) holds time before it: it is not judged
    rows = [_row("hybrid", 0, detection=0.0, error=None, before=True),
            _row("hybrid", 1, detection=0.3, rejection=0.5, error=3.0, located=3.0),
            _row("hybrid", 2), _row("hybrid", 3),
            _row("hybrid-beta", 0, detection=0.2),
            _row("hybrid-beta", 1, detection=0.96, rejection=0.8, error=0.99, located=0.99)]
    verdicts = _verdicts(rows)
    assert len(verdicts) == 8 and all(verdicts.values())


@pytest.mark.parametrize("bad", [{"detection": 0.9}, {"rejection": 0.75}, {"error": 1.0}, {"located": 1.0}])
def test_one_window_after_the_first_detection_missing_a_goal_is_a_miss(bad):
    rows = [_row("hybrid", 0), _row("hybrid", 1), _row("hybrid", 2, **bad), _row("hybrid", 3)]
    verdicts = _verdicts(rows)
    assert sum(not ok for ok in verdicts.values()) == 1


def test_a_mission_that_never_detects_misses_the_detection_goal():
    rows = [_row("hybrid-beta", w, detection=0.0, error=None, located=None, before=True) for w in range(4)]
    goals = {g["goal"].split(" ")[1]: g for g in fire.goals(rows, {})}
    assert goals["detection"]["ok"] is False and goals["detection"]["value"] == 0.0
    assert goals["grid"]["ok"] is None and goals["reported"]["ok"] is None  # no alarm, no figure


def test_naive_must_show_a_decoy_made_false_alarm():
    assert _verdicts([_row("naive", 0), _row("naive", 1, decoy_alarms=1)]) == {
        "naive: decoy-made false alarms across seeds and windows >= 1": True}
    assert _verdicts([_row("naive-beta", 0), _row("naive-beta", 1)]) == {
        "naive-beta: decoy-made false alarms across seeds and windows >= 1": False}


def test_bytes_ratios_are_judged_on_the_mesh_and_the_ring_and_reported_for_the_tree():
    bytes_per_s = {"hybrid": 200.0, "hybrid-keyframes": 1000.0, "ring": 300.0, "ring-keyframes": 1000.0,
                   "tree": 900.0, "tree-keyframes": 1000.0}
    goals = {g["goal"].split(":")[0]: g for g in fire.goals([], bytes_per_s)}
    assert goals["hybrid"]["ok"] is True and goals["hybrid"]["value"] == pytest.approx(0.2)
    assert goals["ring"]["ok"] is False and goals["ring"]["value"] == pytest.approx(0.3)
    assert goals["tree"]["ok"] is None and goals["tree"]["value"] == pytest.approx(0.9)


def test_window_rows_pool_agents_and_seeds():
    def score(detected, error, rejected):
        return {"detection_rate": detected / 3, "false_alarm_rejection": rejected / 3, "decoys": 3,
                "decoys_rejected": rejected, "other_false_alarms": 0, "localisation_error_m": error}

    def window(before, *scores, located=()):
        return {"start": 0.0, "end": 30.0, "before_first_detection": before,
                "agents": {f"uav{i}": s for i, s in enumerate(scores)},
                "located": {f"uav{i}": s for i, s in enumerate(located)}}

    outcomes = [{"windows": [window(False, score(3, 0.5, 3), score(0, None, 2),
                                    located=(score(3, 0.2, 3), score(0, None, 2)))]},
                {"windows": [window(True, score(0, None, 3), score(0, None, 3), located=(score(1, 0.6, 3),))]}]
    (row,) = fire.window_rows("hybrid", outcomes)
    assert row["maps"] == 4 and row["runs"] == 2 and not row["before_first_detection"]
    assert row["detection_rate"] == pytest.approx(0.25) and row["decoy_alarms"] == 1
    assert row["localisation_error_m"] == 0.5 and row["localisation_worst_m"] == 0.5
    assert row["located_error_m"] == pytest.approx(0.4) and row["located_worst_m"] == 0.6


def test_an_unknown_configuration_is_an_error():
    with pytest.raises(ValueError, match=r"unknown fire bench configuration\(s\) \['bogus'\]"):
        fire.run(quick=True, configs=("bogus",))


def test_every_configuration_is_a_valid_fire_scenario():
    """Each configuration's overrides load on the shipped scenario (a Beta grid with the scenario's log-odds
    deadband would be refused: the Beta configurations send exact deltas)."""
    from mesh_sim.bench.fire import CONFIGS
    from mesh_sim.scenario import load

    for name, overrides in CONFIGS.items():
        grid = load("fire", **overrides).agent.grid
        assert grid.belief == ("beta" if "beta" in name else "logodds"), name
