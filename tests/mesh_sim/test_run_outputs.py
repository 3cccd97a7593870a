"""What a tracking run leaves for a reader: every plot kind is a sane PNG after a short lockstep run; the series
say what they claim (the error series pools back to the reported RMSE, the NEES band is scipy's χ² interval, the
traffic sums to ``bytes_tx``, the links follow the agents' neighbour reports); the Rerun recording is compacted
and carries one blueprint made for the fleet and the same series as scalars."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from rerun.chunk import RrdReader
from scipy.stats import chi2

from agent.evaluation import BIN_S, TrackEvaluator
from fusion.gaussian import Gaussian
from mesh_sim.lockstep import run_lockstep
from mesh_sim.observer_geometry import nearest_truth
from mesh_sim.phases import independent_samples
from mesh_sim.plots import fire_maps
from mesh_sim.results import finish
from mesh_sim.run_series import error_series, link_intervals, nees_series, traffic_series
from mesh_sim.scenario import load

PLOTS = ("rmse.png", "errors.png", "nees.png", "map.png", "traffic.png", "links.png")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("run")
    metrics = run_lockstep(load("default", duration=12.0, seed=3), run_dir, rerun="save")
    return run_dir, metrics


def png_size(path) -> tuple[int, int]:
    """Width and height from a PNG's IHDR chunk (``ValueError`` if the file is no PNG)."""
    head = path.read_bytes()[:24]
    if head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise ValueError(f"{path} is not a PNG")
    return struct.unpack(">II", head[16:24])


@pytest.mark.parametrize("name", PLOTS)
def test_every_plot_kind_is_a_sane_png(run, name):
    run_dir, _ = run
    path = run_dir / "plots" / name
    width, height = png_size(path)
    assert 400 <= width <= 2000 and 250 <= height <= 2000
    assert path.stat().st_size > 5000  # something was drawn
    assert not path.with_name(name + ".tmp").exists()  # written atomically


def test_the_error_series_pools_back_to_the_reported_rmse(run):
    _, metrics = run
    scored = [t for a in [*metrics["agents"], metrics["oracle"]] for t in a["targets"] if t["rmse"] is not None]
    assert scored
    for target in scored:
        series = error_series(target)
        n = np.array([b[3] for b in target["bins"] if b[3]], float)
        assert math.isclose(np.sqrt(np.sum(n * series[:, 1] ** 2) / n.sum()), target["rmse"], rel_tol=1e-9)
        assert np.all(series[:, 2] > 0)


def test_sigma_is_the_root_mean_trace_of_the_position_covariance():
    evaluator = TrackEvaluator()
    truth = [{"id": "a", "position": np.zeros(3), "velocity": np.zeros(3)}]
    for t, variance in ((0.1, 1.0), (0.2, 4.0)):
        estimate = Gaussian.from_moments(np.array([0.5, 0, 0, 0, 0, 0]), np.diag([variance] * 3 + [1.0] * 3))
        evaluator.record(t, truth, [(1, estimate)])
    (row,) = error_series(evaluator.summary()[0])
    assert row.tolist() == pytest.approx([BIN_S / 2, 0.5, math.sqrt((3 * 1.0 + 3 * 4.0) / 2)])


def test_the_nees_band_is_scipys_chi2_interval_for_the_bins_independent_samples(run):
    _, metrics = run
    lists = [a["targets"] for a in metrics["agents"]]
    series = nees_series(lists)
    assert len(series) > 3
    for t, anees, lo, hi in series:
        dof = 6 * independent_samples(lists, t - BIN_S / 2, t + BIN_S / 2)
        assert (lo, hi) == pytest.approx((chi2.ppf(0.025, dof) / dof, chi2.ppf(0.975, dof) / dof), rel=1e-12)
        assert lo < 1 < hi and anees > 0
    nees = sum(b[2] for t in lists[0] for b in t["bins"])
    samples = sum(b[3] for t in lists[0] for b in t["bins"])
    weights = np.array([sum(b[3] for t in lists[0] for b in t["bins"] if b[0] + BIN_S / 2 == row[0])
                        for row in nees_series(lists[:1])])
    assert np.sum(weights * nees_series(lists[:1])[:, 1]) / samples == pytest.approx(nees / (6 * samples))


def test_the_traffic_series_sums_to_bytes_tx(run):
    _, metrics = run
    for agent in metrics["agents"]:
        series = traffic_series(agent)
        assert np.sum(series[:, 1]) * BIN_S == agent["bytes_tx"]
        assert np.all(series[:, 2] >= 1)


def test_links_follow_the_neighbour_reports():
    reports = {"a": [[0.0, []], [1.0, ["b"]], [5.0, []]], "b": [[0.0, []], [2.0, ["a"]]]}
    assert link_intervals(reports, 8.0) == {("a", "b"): [(1.0, 2.0, False), (2.0, 5.0, True), (5.0, 8.0, False)]}
    assert link_intervals({}, 8.0) == {}


def test_the_run_records_downsampled_traces(run):
    _, metrics = run
    traces = metrics["oracle"]["traces"]
    assert set(traces["uavs"]) == {a["id"] for a in metrics["agents"]}
    for rows in traces["uavs"].values():  # one row a second of a 12 s run
        assert len(rows) == 13 and np.all(np.diff([r[0] for r in rows]) > 0.5)
    assert {t["target"] for t in metrics["oracle"]["targets"]} == set(traces["truth"])
    assert all(history[-1][1] for history in traces["neighbours"].values())  # a full graph: everyone hears someone


def test_fire_maps_are_a_grid_with_a_colour_bar(tmp_path):
    maps = {f"agent_uav{i}": np.random.default_rng(i).random((20, 20)) for i in range(4)}
    np.savez(tmp_path / "fire_maps.npz", central=np.zeros((20, 20)), extent=[0, 100, 0, 100],
             truth=np.zeros((10, 10)), truth_extent=[0, 100, 0, 100], **maps)
    path = fire_maps.draw(tmp_path / "fire_maps.npz", tmp_path)
    width, height = png_size(path)
    assert width / height < 2.5  # six panels in two rows, not one strip of 1728 x 306
    assert fire_maps.draw(tmp_path / "missing.npz", tmp_path) is None


def blueprint_views(path) -> set[tuple[str, str, str]]:
    """``(view class, name, origin)`` of every view in the recording's only blueprint."""
    reader = RrdReader(path)
    (store,) = reader.blueprints()
    views = set()
    for chunk in reader.stream(store=store):
        batch = chunk.to_record_batch()
        if "ViewBlueprint:class_identifier" in batch.schema.names:
            cells = [batch.column(f"ViewBlueprint:{c}").to_pylist()[-1][0]
                     for c in ("class_identifier", "display_name", "space_origin")]
            views.add(tuple(cells))
    return views


def test_the_recording_carries_a_fleet_blueprint(run):
    run_dir, metrics = run
    views = blueprint_views(run_dir / "recording.rrd")
    agents = [a["id"] for a in metrics["agents"]]
    assert ("3D", "world", "/world") in views
    assert {("3D", a, "/world") for a in agents} <= views  # one tab per agent
    series = {origin for kind, _, origin in views if kind == "TimeSeries"}
    assert {"/metrics/tracks", "/metrics/bytes_seen", "/series/anees", "/series/sent_bytes",
            "/series/sent_messages"} <= series  # one panel per metric, not one per agent
    assert {f"/series/error/{t['target']}" for t in metrics["oracle"]["targets"]} <= series
    assert not any(origin.startswith("/maps") for _, _, origin in views)  # no fire in this scenario


def test_the_recording_holds_the_series_and_is_compacted(run):
    run_dir, metrics = run
    reader = RrdReader(run_dir / "recording.rrd")
    assert len(reader.recordings()) == 1
    chunks = list(reader.stream())
    rows: dict[str, int] = {}
    for chunk in chunks:
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    for a in metrics["agents"]:
        for target in a["targets"]:
            entity = f"/series/error/{target['target']}/{a['id']}"
            assert rows[entity] == rows[f"{entity}/two_sigma"] == len(error_series(target)) + 1  # + its static name
        assert rows[f"/series/sent_bytes/{a['id']}"] == len(traffic_series(a)) + 1
        assert rows[f"/metrics/tracks/{a['id']}"] > 10
    assert rows["/series/anees/fleet"] == rows["/series/anees/band/low"] == len(nees_series(
        [a["targets"] for a in metrics["agents"]])) + 1
    assert len(chunks) < 3 * len(rows)  # the observer's ~2000 small chunks of a 20 s run merged
    labels = {label for chunk in chunks if chunk.entity_path.startswith("/world/agents/")
              and "Ellipsoids3D:labels" in chunk.to_record_batch().schema.names
              for row in chunk.to_record_batch().column("Ellipsoids3D:labels").to_pylist() for label in row or []}
    names = {t["target"] for t in metrics["oracle"]["targets"]}
    assert {label.split("→")[-1] for label in labels if "→" in label} == names  # e.g. "uav1:T1→car"


def test_a_track_is_named_after_the_true_target_within_the_gate():
    ids, positions = ["car", "walker"], np.array([[0.0, 0, 0], [50.0, 0, 0]])
    assert nearest_truth(ids, positions, np.array([48.0, 1, 0]), np.eye(3)) == "walker"
    assert nearest_truth(ids, positions, np.array([25.0, 0, 0]), np.eye(3)) is None  # outside the gate
    assert nearest_truth([], np.zeros((0, 3)), np.zeros(3), np.eye(3)) is None


def test_a_recording_that_cannot_be_read_is_left_as_it_is(run, tmp_path, capsys):
    _, metrics = run
    broken = tmp_path / "recording.rrd"
    broken.write_bytes(b"not an rrd")
    finish(broken, metrics)
    assert broken.read_bytes() == b"not an rrd"
    assert "recording left unfinished" in capsys.readouterr().err
