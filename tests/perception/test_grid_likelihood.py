"""Grid sensor likelihoods (Merino §4.2.1, (4.7)-(4.19), (4.31)-(4.33); §6.5): cell projection by the UT,
the expectation over the pixel ellipse, the camera and fire-sensor evidence, and bad input."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from perception.camera import Intrinsics
from perception.cell_projection import mask_expectation
from perception.grid_likelihood import (
    CellEvidence,
    DetectionModel,
    PoseNoise,
    camera_cell_evidence,
    camera_likelihoods,
    fire_sensor_evidence,
    project_cells,
)
from perception.pose import CameraPose, Gimbal
from perception.projection import world_to_pixel
from perception.render import Fire, render_frame
from perception.rotations import rotation_from_euler

INTR = Intrinsics.from_fov(320, 240, 90)
NADIR = CameraPose.from_vehicle([0.0, 0.0, -80.0], 0.0, 0.0, 0.0, Gimbal(0.0, -math.pi / 2))
OBLIQUE = CameraPose.from_vehicle([5.0, -3.0, -60.0], 0.05, -0.03, 0.4, Gimbal(0.2, math.radians(-50.0)))
ZERO = PoseNoise(0.0, 0.0)


def grid(cell: float, north: tuple[float, float], east: tuple[float, float], down: float = 0.0) -> np.ndarray:
    """Row-major cell centres (K, 3) of a grid of side ``cell`` covering [north) x [east)."""
    n, e = np.meshgrid(np.arange(*north, cell) + cell / 2, np.arange(*east, cell) + cell / 2, indexing="ij")
    return np.stack([n.ravel(), e.ravel(), np.full(n.size, down)], axis=-1)


def brute_force(mask: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> float:
    """The defining sum over every pixel with the exact Gaussian weights, renormalised over the image."""
    v, u = np.mgrid[0 : mask.shape[0], 0 : mask.shape[1]]
    d = np.stack([u - mean[0], v - mean[1]], axis=-1)
    w = np.exp(-0.5 * np.einsum("...i,ij,...j->...", d, np.linalg.inv(cov), d))
    return float(np.sum(w * mask) / np.sum(w))


def rotated(l1: float, l2: float, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    R = np.array([[c, -s], [s, c]])
    return R @ np.diag([l1, l2]) @ R.T


# ------------------------------------------------------------------------------------------------ projection
def test_zero_noise_point_cells_project_exactly_like_world_to_pixel():
    cells = grid(7.0, (-150.0, 150.0), (-150.0, 150.0))
    mean, cov, valid = project_cells(cells, 0.0, OBLIQUE, INTR, ZERO)
    expected = world_to_pixel(OBLIQUE, INTR, cells)
    assert np.array_equal(valid, np.all(np.isfinite(expected), axis=1))
    assert valid.sum() > 100 and (~valid).sum() > 100  # both kinds present: the camera looks forward
    np.testing.assert_array_equal(mean[valid], expected[valid])
    np.testing.assert_array_equal(cov[valid], 0.0)


def test_nadir_cell_extent_alone_gives_the_closed_form_covariance():
    """Camera looking straight down at flat ground: pixels are an affine map of (north, east) with gain f/Z,
    so a uniform offset over the cell (variance c²/12) gives Σ = (f c / Z)² / 12 · I and an unbiased mean."""
    cell = 5.0
    cells = grid(cell, (-40.0, 40.0), (-50.0, 50.0))
    mean, cov, valid = project_cells(cells, cell, NADIR, INTR, ZERO)
    assert np.all(valid)
    np.testing.assert_allclose(mean, world_to_pixel(NADIR, INTR, cells), rtol=0, atol=1e-9)
    gain = INTR.fx / 80.0
    np.testing.assert_allclose(cov, np.broadcast_to((gain * cell) ** 2 / 12.0 * np.eye(2), cov.shape), atol=1e-9)


def test_project_cells_matches_monte_carlo_of_the_same_uncertainty():
    """Independent sampling of position (Gaussian), world-side attitude error (Gaussian) and the cell offset
    (uniform over the square), projected sample by sample."""
    cell, noise = 5.0, PoseNoise(2.0, math.radians(2.0))
    cells = np.array([[30, 10, 0], [60, 20, 0], [45, -5, 0], [35, 35, 2.0], [80, 40, 0], [20, -10, -3]], float)
    mean, cov, valid = project_cells(cells, cell, OBLIQUE, INTR, noise)
    assert np.all(valid)
    rng = np.random.default_rng(0)
    n = 40_000
    dp = rng.normal(0.0, noise.position_sigma, (n, 3))
    da = rng.normal(0.0, noise.attitude_sigma, (n, 3))
    offset = np.zeros((n, len(cells), 3))
    offset[..., :2] = rng.uniform(-cell / 2, cell / 2, (n, len(cells), 2))
    R = rotation_from_euler(da[:, 0], da[:, 1], da[:, 2]) @ OBLIQUE.R_world_from_cam
    cam = np.einsum("nkj,nji->nki", cells[None] + offset - (OBLIQUE.centre + dp)[:, None, :], R)
    pixels = INTR.project(cam)
    for k in range(len(cells)):
        mc_mean, mc_cov = pixels[:, k].mean(axis=0), np.cov(pixels[:, k].T)
        assert np.all(np.abs(mean[k] - mc_mean) < 0.05 * np.sqrt(np.diag(mc_cov))), k
        assert np.linalg.norm(cov[k] - mc_cov) < 0.04 * np.linalg.norm(mc_cov), k


def test_cells_behind_or_straddling_the_camera_plane_are_invalid():
    ahead = CameraPose.from_vehicle([0.0, 0.0, -50.0], 0.0, 0.0, 0.0, Gimbal(0.0, 0.0))  # looking north, level
    cells = np.array([[40.0, 0.0, -50.0], [-40.0, 0.0, -50.0], [0.0, 30.0, -50.0], [0.3, 20.0, -50.0]])
    mean, cov, valid = project_cells(cells, 5.0, ahead, INTR, PoseNoise())
    # in front; behind; in the plane of the optical centre; just in front but its cell crosses the plane
    assert valid.tolist() == [True, False, False, False]
    assert np.all(np.isnan(mean[1:])) and np.all(np.isnan(cov[1:]))
    assert np.all(np.isfinite(mean[0])) and np.all(np.linalg.eigvalsh(cov[0]) > 0)


def test_cells_are_projected_independently_of_each_other():
    cells = grid(10.0, (0.0, 100.0), (-60.0, 60.0))
    mean, cov, valid = project_cells(cells, 10.0, OBLIQUE, INTR, PoseNoise())
    for k in (0, 17, len(cells) - 1):
        m1, c1, v1 = project_cells(cells[k : k + 1], 10.0, OBLIQUE, INTR, PoseNoise())
        assert v1[0] == valid[k]
        np.testing.assert_allclose(m1[0], mean[k], rtol=0, atol=1e-9)
        np.testing.assert_allclose(c1[0], cov[k], rtol=0, atol=1e-9)


# ----------------------------------------------------------------------------------------------- expectation
H, W = 72, 96


def _masks(rng: np.random.Generator) -> dict[str, np.ndarray]:
    blobs = cv2.GaussianBlur(rng.standard_normal((H, W)).astype(np.float32), (0, 0), 4.0) > 0.2
    rect = np.zeros((H, W), bool)
    rect[20:50, 30:70] = True
    return {"pixel noise": rng.random((H, W)) < 0.3, "blobs": blobs, "rectangle": rect}


COVARIANCES = [
    np.zeros((2, 2)),
    np.diag([0.1, 0.1]),
    np.diag([1.0, 1.0]),
    rotated(9.0, 4.0, 0.4),
    rotated(30.0, 10.0, 2.0),
    np.array([[25.0, -10.0], [-10.0, 16.0]]),
    rotated(120.0, 50.0, 1.0),
]


@pytest.mark.parametrize("cov", COVARIANCES, ids=lambda c: f"eig{np.round(np.linalg.eigvalsh(c), 1).tolist()}")
def test_gauss_hermite_expectation_matches_brute_force_over_the_pixel_grid(cov):
    rng = np.random.default_rng(11)
    means = np.vstack([rng.uniform([-0.5, -0.5], [W - 0.5, H - 0.5], (30, 2)), [[-0.5, -0.5], [W - 0.5, 3.0]]])
    for name, mask in _masks(rng).items():
        got = mask_expectation(mask, means, np.broadcast_to(cov, (len(means), 2, 2)))
        if not np.any(cov):  # a point: the nearest pixel (the brute-force limit)
            u, v = np.clip(np.rint(means).astype(int), 0, [W - 1, H - 1]).T
            np.testing.assert_array_equal(got, mask[v, u])
            continue
        want = np.array([brute_force(mask, m, cov) for m in means])
        assert np.max(np.abs(got - want)) <= 0.02, (name, np.max(np.abs(got - want)))


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**31),
    log_var=st.floats(math.log(0.05), math.log(150.0)),
    ratio=st.floats(1.0, 3.0),
    angle=st.floats(0.0, math.pi),
    u=st.floats(-0.5, W - 0.5),
    v=st.floats(-0.5, H - 0.5),
)
def test_expectation_property_brute_force_and_complement(seed, log_var, ratio, angle, u, v):
    """Any ellipse with an axis ratio up to 3: within 0.025 of the brute-force sum, in [0, 1], and the fire
    fractions of a mask and of its complement add up to 1 (same renormalisation)."""
    mask = _masks(np.random.default_rng(seed))["blobs" if seed % 2 else "pixel noise"]
    cov = rotated(math.exp(log_var), math.exp(log_var) / ratio, angle)
    p = mask_expectation(mask, [[u, v]], cov[None])[0]
    q = mask_expectation(~mask, [[u, v]], cov[None])[0]
    assert 0.0 <= p <= 1.0
    assert p + q == pytest.approx(1.0, abs=1e-5)
    assert abs(p - brute_force(mask, np.array([u, v]), cov)) <= 0.025


def test_expectation_of_uniform_masks_is_exact_even_at_the_border():
    means = np.array([[-0.5, -0.5], [W - 0.5, H - 0.5], [40.0, 30.0]])
    covs = np.broadcast_to(np.diag([300.0, 200.0]), (3, 2, 2))
    np.testing.assert_allclose(mask_expectation(np.ones((H, W), bool), means, covs), 1.0, atol=1e-6)
    np.testing.assert_array_equal(mask_expectation(np.zeros((H, W), bool), means, covs), 0.0)


# ------------------------------------------------------------------------------------------- camera evidence
def _evidence(mask, model=None, noise=None, cell=5.0):
    model, noise = model or DetectionModel(), noise or PoseNoise()
    cells = grid(cell, (-150.0, 150.0), (-150.0, 150.0))
    return cells, camera_cell_evidence(mask, cells, cell, NADIR, INTR, model, noise)


def test_all_fire_gives_log_pd_over_pf_at_short_range():
    cells, ev = _evidence(np.ones((240, 320), bool), DetectionModel(d_max=1e7))
    assert len(ev) > 500
    np.testing.assert_allclose(ev.p_fire, 1.0, atol=1e-6)
    np.testing.assert_allclose(ev.llr, math.log(0.9 / 0.05), atol=1e-5)
    np.testing.assert_allclose(ev.m, 1.0, atol=1e-6)
    np.testing.assert_allclose(ev.n, 0.0, atol=1e-6)


def test_all_background_is_negative_information():
    model = DetectionModel(d_max=1e7)
    cells, ev = _evidence(np.zeros((240, 320), bool), model)
    assert np.all(ev.p_fire == 0.0)
    np.testing.assert_allclose(ev.llr, math.log(0.1 / 0.95), atol=1e-6)
    assert np.all(ev.llr < 0)
    assert np.all(ev.m == 0.0) and np.all(ev.n == 1.0)


def test_range_dependent_pd_pf_enter_the_llr():
    model = DetectionModel(d_max=200.0)
    for value in (True, False):
        cells, ev = _evidence(np.full((240, 320), value), model)
        pd, pf = model.at_range(np.linalg.norm(cells[ev.index] - NADIR.centre, axis=1))
        want = np.log(pd / pf) if value else np.log((1 - pd) / (1 - pf))
        np.testing.assert_allclose(ev.llr, want, atol=1e-5)


def test_visual_camera_without_negative_information():
    quiet = DetectionModel(negative=False)
    _, ev = _evidence(np.zeros((240, 320), bool), quiet)
    assert len(ev) > 500
    assert np.all(ev.llr == 0.0) and np.all(ev.n == 0.0) and np.all(ev.m == 0.0)
    _, fire = _evidence(np.ones((240, 320), bool), quiet)
    _, fire_ir = _evidence(np.ones((240, 320), bool))
    np.testing.assert_allclose(fire.llr, fire_ir.llr, atol=1e-6)  # detections count the same


def test_range_at_and_beyond_d_max_gives_no_update():
    model = DetectionModel(d_max=250.0)
    pd, pf = model.at_range(np.array([250.0, 251.0, 1e6]))
    assert np.all(pd == 0.5) and np.all(pf == 0.5)
    pd, pf = model.at_range(np.array([0.0, 125.0]))
    np.testing.assert_allclose(pd, [0.9, 0.9 * 0.75 + 0.5 * 0.25])
    np.testing.assert_allclose(pf, [0.05, 0.05 * 0.75 + 0.5 * 0.25])
    # The camera is 80 m up: with d_max = 80 every cell is at or beyond it.
    _, ev = _evidence(np.ones((240, 320), bool), DetectionModel(d_max=80.0))
    assert len(ev) == 0
    cells, ev = _evidence(np.ones((240, 320), bool), DetectionModel(d_max=100.0))
    dist = np.linalg.norm(cells[ev.index] - NADIR.centre, axis=1)
    assert np.all(dist < 100.0) and len(ev) > 0
    assert np.all(ev.llr[dist > 99.0] < 0.05)  # fades to 0 at d_max


@settings(max_examples=60, deadline=None, derandomize=True)
@given(pf=st.floats(0.001, 0.5), gap=st.floats(0.01, 0.99), negative=st.booleans())
def test_llr_is_monotone_in_p_fire(pf, gap, negative):
    pd = pf + gap * (0.999 - pf)
    p = np.linspace(0.0, 1.0, 201)
    fire, clear = camera_likelihoods(p, pd, pf, negative)
    llr = np.log(fire) - np.log(clear)
    assert np.all(np.diff(llr) > 0)
    assert llr[-1] == pytest.approx(math.log(pd / pf))
    assert llr[0] == pytest.approx(math.log((1 - pd) / (1 - pf)) if negative else 0.0, abs=1e-12)


def test_llr_is_the_pixel_sum_of_4_11_over_the_returned_ellipse():
    """(4.11) by brute force: p(z|x) = Σ_q [I(q) P_D + (1 - I(q))(1 - P_D)] w_q with the exact weights."""
    rng = np.random.default_rng(3)
    mask = cv2.GaussianBlur(rng.standard_normal((240, 320)).astype(np.float32), (0, 0), 6.0) > 0.3
    model = DetectionModel(pd=0.8, pf=0.1, d_max=300.0)
    cells, ev = _evidence(mask, model)
    pd, pf = model.at_range(np.linalg.norm(cells[ev.index] - NADIR.centre, axis=1))
    for k in rng.choice(len(ev), 40, replace=False):
        p = brute_force(mask, ev.pixel_mean[k], ev.pixel_cov[k])
        want = math.log(p * pd[k] + (1 - p) * (1 - pd[k])) - math.log(p * pf[k] + (1 - p) * (1 - pf[k]))
        assert ev.llr[k] == pytest.approx(want, abs=0.03)
        assert ev.m[k] + ev.n[k] == pytest.approx(1.0)


def test_only_cells_in_view_and_in_front_are_reported():
    cells, ev = _evidence(np.ones((240, 320), bool))
    mean, _, valid = project_cells(cells, 5.0, NADIR, INTR, PoseNoise())
    expected = np.flatnonzero(valid & INTR.contains(mean))
    np.testing.assert_array_equal(ev.index, expected)
    assert 0 < len(ev) < len(cells)
    np.testing.assert_array_equal(ev.pixel_mean, mean[expected])


def test_end_to_end_with_the_thermal_renderer():
    centre = np.array([12.0, -23.0])
    frame = render_frame((NADIR, INTR), 320, 240, fires=[Fire((*centre, 0.0), 15.0, 800.0)], rgb=False, seed=1)
    mask = frame.thermal > 400.0
    assert 0 < mask.sum() < mask.size // 10
    cell = 5.0
    cells = grid(cell, (-100.0, 100.0), (-120.0, 120.0))
    ev = camera_cell_evidence(mask, cells, cell, NADIR, INTR)
    where = cells[ev.index, :2]
    inside = np.all(np.abs(where - centre) <= 7.5 - cell / 2, axis=1)  # cells entirely in the 15 m fire
    far = np.linalg.norm(where - centre, axis=1) > 25.0
    assert inside.sum() == 4 and far.sum() > 300
    assert np.all(ev.llr[inside] > 0) and np.all(ev.llr[far] < 0)
    positive = ev.llr > 0
    weight = 1.0 / (1.0 + np.exp(-ev.llr[positive]))  # posterior from a 0.5 prior
    centroid = weight @ where[positive] / weight.sum()
    assert np.linalg.norm(centroid - centre) < cell


# ----------------------------------------------------------------------------------------------- fire sensor
def test_fire_sensor_cone_counts_and_closed_forms():
    cells = grid(10.0, (-200.0, 200.0), (-200.0, 200.0))
    position, axis, half = np.array([0.0, 0.0, -100.0]), np.array([0.0, 0.0, 1.0]), math.radians(30.0)
    model = DetectionModel(pd=0.8, pf=0.1, d_max=300.0)
    hit = fire_sensor_evidence(True, cells, position, axis, half, model)
    rel = cells - position
    angle = np.arccos(rel[:, 2] / np.linalg.norm(rel, axis=1))
    np.testing.assert_array_equal(hit.index, np.flatnonzero(angle < half))
    size = len(hit)
    assert size > 50
    np.testing.assert_allclose(hit.m, 1.0 / size)
    assert hit.m.sum() == pytest.approx(1.0) and np.all(hit.n == 0)
    # The cell nearest the axis is at ~100 m: P = P0 g + 0.5 (1 - g), g = (1 - (d/d_max)²)(1 - (α/half)²).
    k = int(np.argmin(angle[hit.index]))
    d, a = np.linalg.norm(rel[hit.index[k]]), angle[hit.index[k]]
    g = (1 - (d / 300.0) ** 2) * (1 - (a / half) ** 2)
    pd, pf = 0.8 * g + 0.5 * (1 - g), 0.1 * g + 0.5 * (1 - g)
    assert hit.llr[k] == pytest.approx(math.log(pd / pf))
    assert np.all(hit.llr > 0) and hit.llr[k] == hit.llr.max()
    miss = fire_sensor_evidence(False, cells, position, axis, half, model)
    np.testing.assert_array_equal(miss.index, hit.index)
    assert miss.llr[k] == pytest.approx(math.log((1 - pd) / (1 - pf)))
    assert np.all(miss.llr < 0) and np.all(miss.n == 1) and np.all(miss.m == 0)
    assert np.all(np.isnan(miss.pixel_mean)) and miss.pixel_cov.shape == (size, 2, 2)
    quiet = fire_sensor_evidence(False, cells, position, axis, half, DetectionModel(negative=False))
    assert np.all(quiet.llr == 0) and np.all(quiet.n == 0)


def test_fire_sensor_evidence_fades_at_the_cone_edge_and_range():
    position, axis, half = np.zeros(3), np.array([1.0, 0.0, 0.0]), 0.5
    model = DetectionModel(d_max=100.0)
    edge = [[50.0 * math.cos(half - 1e-4), 50.0 * math.sin(half - 1e-4), 0.0], [99.99, 0.0, 0.0]]
    out = [[50.0 * math.cos(half + 1e-3), 50.0 * math.sin(half + 1e-3), 0.0], [100.0, 0.0, 0.0], [-10.0, 0, 0]]
    ev = fire_sensor_evidence(True, np.array(edge + out), position, axis, half, model)
    assert ev.index.tolist() == [0, 1]
    assert np.all(np.abs(ev.llr) < 0.01)


# --------------------------------------------------------------------------------------------------- bad input
MASK = np.zeros((240, 320), bool)
CELLS = grid(5.0, (-20.0, 20.0), (-20.0, 20.0))


def test_bad_mask_shape_different_from_the_intrinsics():
    with pytest.raises(ValueError, match="does not match the intrinsics"):
        camera_cell_evidence(np.zeros((320, 240), bool), CELLS, 5.0, NADIR, INTR)


@pytest.mark.parametrize(
    "mask", [np.zeros((240, 320), np.uint8), np.full((240, 320), np.nan), MASK.tolist()], ids=["uint8", "nan", "list"]
)
def test_bad_mask_not_boolean_or_nan(mask):
    with pytest.raises(ValueError, match="boolean"):
        camera_cell_evidence(mask, CELLS, 5.0, NADIR, INTR)


@pytest.mark.parametrize(
    "cells",
    [CELLS[:, :2], CELLS[0], CELLS[None], np.where(np.arange(3) == 1, np.nan, CELLS), np.array([["a", "b", "c"]])],
    ids=["two-columns", "one-point", "3-d", "nan", "strings"],
)
def test_bad_cells_array_of_wrong_shape_or_values(cells):
    with pytest.raises(ValueError, match="cells_ned|could not convert"):
        camera_cell_evidence(MASK, cells, 5.0, NADIR, INTR)
    with pytest.raises(ValueError, match="cells_ned|could not convert"):
        fire_sensor_evidence(True, cells, np.zeros(3), np.array([0, 0, 1.0]), 0.5, DetectionModel())


@pytest.mark.parametrize("size", [-1.0, math.nan, math.inf, True], ids=["negative", "nan", "inf", "bool"])
def test_bad_cell_size(size):
    with pytest.raises(ValueError, match="cell_size"):
        camera_cell_evidence(MASK, CELLS, size, NADIR, INTR)


def test_bad_pose_non_finite():
    with pytest.raises(ValueError, match="finite"):
        CameraPose(np.eye(3), [0.0, math.nan, -80.0])
    corrupted = CameraPose(np.eye(3), [0.0, 0.0, -80.0])
    object.__setattr__(corrupted, "centre", np.array([0.0, math.inf, -80.0]))  # bypassing the constructor
    with pytest.raises(ValueError, match="pose contains non-finite"):
        camera_cell_evidence(MASK, CELLS, 5.0, corrupted, INTR)
    with pytest.raises(ValueError, match="pose contains non-finite"):
        project_cells(CELLS, 5.0, corrupted, INTR, PoseNoise())
    with pytest.raises(ValueError, match="pose must be a CameraPose"):
        project_cells(CELLS, 5.0, (np.eye(3), np.zeros(3)), INTR, PoseNoise())


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"pd": 0.05, "pf": 0.05}, "pd must exceed pf"),
        ({"pd": 0.3, "pf": 0.6}, "pd must exceed pf"),
        ({"pd": 1.0}, "probability"),
        ({"pf": 0.0}, "probability"),
        ({"pd": -0.1}, "probability"),
        ({"pf": math.nan}, "probability"),
        ({"d_max": 0.0}, "d_max"),
        ({"d_max": -5.0}, "d_max"),
        ({"d_max": math.inf}, "d_max"),
        ({"negative": "yes"}, "negative"),
    ],
    ids=["pd==pf", "pd<pf", "pd=1", "pf=0", "pd<0", "pf-nan", "d_max=0", "d_max<0", "d_max-inf", "negative-str"],
)
def test_bad_detection_model(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DetectionModel(**kwargs)


@pytest.mark.parametrize(
    "kwargs", [{"position_sigma": -1.0}, {"attitude_sigma": -0.01}, {"position_sigma": math.nan}], ids=str
)
def test_bad_pose_noise_negative_or_nan_sigma(kwargs):
    with pytest.raises(ValueError, match="sigma"):
        PoseNoise(**kwargs)


@pytest.mark.parametrize("d", [[-1.0], [math.nan], [math.inf]], ids=["negative", "nan", "inf"])
def test_bad_range_for_at_range(d):
    with pytest.raises(ValueError, match="range"):
        DetectionModel().at_range(np.array(d))


def test_bad_model_or_noise_type():
    with pytest.raises(ValueError, match="model must be a DetectionModel"):
        camera_cell_evidence(MASK, CELLS, 5.0, NADIR, INTR, model=(0.9, 0.05))
    with pytest.raises(ValueError, match="noise must be a PoseNoise"):
        camera_cell_evidence(MASK, CELLS, 5.0, NADIR, INTR, noise=1.0)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"detected": 1}, "detected"),
        ({"sensor_position": [0.0, math.nan, 0.0]}, "sensor_position"),
        ({"sensor_position": [0.0, 0.0]}, "sensor_position"),
        ({"axis": [0.0, 0.0, 0.0]}, "axis"),
        ({"axis": [0.0, math.inf, 1.0]}, "axis"),
        ({"half_angle": 0.0}, "half_angle"),
        ({"half_angle": 4.0}, "half_angle"),
        ({"half_angle": math.nan}, "half_angle"),
    ],
    ids=["detected-int", "position-nan", "position-2d", "axis-zero", "axis-inf", "half0", "half>pi", "half-nan"],
)
def test_bad_fire_sensor_input(kwargs, match):
    args = {"detected": True, "cells_ned": CELLS, "sensor_position": np.zeros(3), "axis": [0.0, 0.0, 1.0]}
    args |= {"half_angle": 0.5, "model": DetectionModel()} | kwargs
    with pytest.raises(ValueError, match=match):
        fire_sensor_evidence(**args)


@pytest.mark.parametrize(
    "mean, cov, match",
    [
        ([[-1.0, 5.0]], np.eye(2)[None], "inside the image"),
        ([[5.0, 5.0]], np.array([[[1.0, 0.0], [0.0, -1.0]]]), "positive semi-definite"),
        ([[5.0, math.nan]], np.eye(2)[None], "finite"),
        ([[5.0, 5.0]], np.eye(2), "must be"),
    ],
    ids=["mean-outside", "cov-indefinite", "mean-nan", "cov-shape"],
)
def test_bad_pixel_gaussians_for_mask_expectation(mean, cov, match):
    with pytest.raises(ValueError, match=match):
        mask_expectation(np.zeros((H, W), bool), mean, cov)


def test_bad_cell_evidence_with_mismatched_lengths():
    with pytest.raises(ValueError, match="llr must have shape"):
        CellEvidence(
            np.arange(3), np.zeros(3), np.zeros(2), np.zeros(3), np.zeros(3), np.zeros((3, 2)), np.zeros((3, 2, 2))
        )
