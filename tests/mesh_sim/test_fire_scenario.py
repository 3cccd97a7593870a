"""The fire scenario end to end: lockstep and live (real agent processes over Zenoh), maps, alarms, Rerun."""

from __future__ import annotations

import io

import numpy as np
import pytest
from rich.console import Console

from mesh_sim import results
from mesh_sim.launcher import Launcher, new_run_dir
from mesh_sim.lockstep import run_lockstep
from mesh_sim.scenario import load
from tests.mesh_sim.test_observer import _read_rrd
from tests.processes import assert_all_gone


@pytest.fixture(scope="module")
def lockstep_run(tmp_path_factory):
    """Two agents on a tree (exact fusion) over ideal links for 40 s: time to map the fires near their start."""
    scenario = load("fire", agents=2, duration=40.0, radio={"topology": "line", "preset": "ideal"})
    run_dir = new_run_dir(tmp_path_factory.mktemp("runs"), scenario.name)
    return run_dir, run_lockstep(scenario, run_dir, rerun="save")


def test_agents_build_share_and_fuse_grids(lockstep_run):
    _, metrics = lockstep_run
    for agent in metrics["agents"]:
        grid = agent["grid"]
        assert grid["frames"] == agent["steps"]
        assert grid["grid_messages"] >= 19 and grid["grid_keyframes"] >= 1
        assert grid["grid_fusions"].get("exact", 0) >= 15  # a line of two is a tree: channel filters
        assert agent["msgs_rejected"] == 0
        assert "grid_evidence" not in agent["bytes_tx_by_kind"]  # simulation data is not radio traffic
        assert agent["sim_bytes_tx_by_kind"]["grid_evidence"] > 0


def test_maps_are_scored_against_the_truth_and_the_centralized_map(lockstep_run):
    run_dir, metrics = lockstep_run
    fleet = metrics["fleet"]["grid"]
    assert fleet["threshold"] == 0.8
    assert fleet["kl_to_central"] is not None and fleet["kl_to_central"] >= 0.0
    grid = metrics["oracle"]["grid"]
    assert set(grid["agents"]) == {"uav0", "uav1"}
    for agent in grid["agents"].values():
        assert [r["threshold"] for r in agent["roc"]] == list(results_thresholds())
        assert len(agent["kl_series"]) >= 15
    # exact fusion end to end: the agent that broadcast last (after fusing the other's last message) holds
    # the centralized map (float32 on the wire), so it decides exactly as the centralized map does
    last = min(grid["agents"].values(), key=lambda agent: agent["kl_final"])
    assert last["kl_final"] < 1e-6
    assert last["roc"] == grid["central"]["roc"]
    maps = np.load(run_dir / "fire_maps.npz")
    assert maps["central"].shape == (60, 60) and maps["agent_uav0"].shape == (60, 60)
    assert np.all((maps["central"] >= 0) & (maps["central"] <= 1))
    assert maps["truth"].dtype == np.int8 and set(np.unique(maps["truth"])) <= {0, 1, 2}
    explored = np.abs(maps["central"] - 0.5) > 0.1
    assert explored.mean() > 0.2  # the entropy planner spread the cameras over a good part of the area
    for plot in ("fire_maps", "map", "traffic", "links"):  # no targets: no error, NEES or RMSE plot
        assert (run_dir / "plots" / f"{plot}.png").stat().st_size > 5000
    assert not (run_dir / "plots" / "errors.png").exists()


def results_thresholds():
    from mesh_sim.fire_scoring import THRESHOLDS

    return THRESHOLDS


def test_alarms_are_located_by_the_hot_spots_tracks_and_fused_exactly_on_the_tree(lockstep_run):
    """The hand-off (Merino Ch. 8): the thermal camera's hot spots in an alarm's gate feed the tracker, and the
    alarms are reported at their tracks. Two agents on a line share one tree edge, so their tracks, fused by
    channel filters, hold the same information: both report every located alarm at the same position."""
    _, metrics = lockstep_run
    located = {}
    for agent in metrics["agents"]:
        assert agent["grid"]["hot_spots"]["bearings"] > 0
        assert agent["fusions"].get("exact", 0) > 0 and agent["fusions"].get("ci", 0) == 0
        located[agent["id"]] = sorted(tuple(a["mean"]) for a in agent["grid"]["located_alarms"]
                                       if a["track"] is not None)
    assert len(located["uav0"]) >= 1
    np.testing.assert_allclose(located["uav0"], located["uav1"], atol=1e-6)
    regions = metrics["oracle"]["grid"]["fire_regions"]
    errors = [min(np.hypot(n - r["centroid"][0], e - r["centroid"][1]) for r in regions) for n, e in located["uav0"]]
    assert min(errors) < 0.5  # a located alarm sits on its fire, well inside the 5 m cell
    scored = metrics["oracle"]["grid"]["located"]
    assert set(scored) == {"uav0", "uav1"} and scored["uav0"]["detected"] >= 1


def test_the_fire_map_table_prints(lockstep_run):
    _, metrics = lockstep_run
    out = io.StringIO()
    Console(file=out, width=200).print(results.grid_table(metrics))
    text = out.getvalue()
    assert "uav0" in text and "central" in text and "decoys ignored" in text


def test_rerun_recording_has_every_map_and_the_true_fire(lockstep_run):
    run_dir, _ = lockstep_run
    rows, _ = _read_rrd(run_dir / "recording.rrd")
    for entity in ("/maps/uav0", "/maps/uav1", "/maps/truth", "/maps/legend"):
        assert rows.get(entity, 0) > 0, (entity, sorted(rows))


@pytest.mark.slow
def test_a_live_fire_run_exchanges_grids_between_processes(tmp_path):
    """Real processes: a Zenoh router, the world, two agents and the observer; grids cross process
    boundaries as deltas and keyframes and are fused."""
    scenario = load("fire", agents=2, duration=12.0)
    outcome = Launcher(scenario, new_run_dir(tmp_path, "fire"), speed=2.0, rerun="save").run()
    assert outcome.status == "completed", outcome.status
    for agent in outcome.metrics["agents"]:
        assert agent["grid"]["grid_messages"] >= 4
        assert sum(agent["grid"]["grid_fusions"].values()) >= 3, agent["grid"]
        assert agent["bytes_rx_by_peer"][{"uav0": "uav1", "uav1": "uav0"}[agent["id"]]]["grid"] > 0
    assert set(outcome.metrics["oracle"]["grid"]["agents"]) == {"uav0", "uav1"}
    rows, _ = _read_rrd(outcome.run_dir / "recording.rrd")
    assert rows.get("/maps/uav0", 0) > 0 and rows.get("/maps/truth", 0) > 0
    assert_all_gone(outcome.pids.values())


@pytest.mark.parametrize("bad, message", [
    ({"fire": {"ignitions": [[0.0, 0.0]], "rate": -1.0}}, "rate"),
    ({"decoys": [[0.0, 0.0, 1.5]]}, "decoys"),  # a probability above one
    ({"grid": {"cell": 0.0}}, "cell"),
])
def test_bad_fire_scenarios_are_clear_errors(bad, message):
    with pytest.raises(ValueError, match=message):
        load("fire", **bad)


def test_a_fire_without_a_grid_is_an_error(tmp_path):
    """[fire] with no [grid]: nobody would map it."""
    text = (load("fire").path).read_text()
    start = text.index("[grid]")
    end = text.index("[tasking]")
    path = tmp_path / "nogrid.toml"
    path.write_text(text[:start] + text[end:].replace('planner = "entropy"', 'planner = "placeholder"'))
    with pytest.raises(ValueError, match="grid"):
        load(str(path))
