"""Synthetic camera: geometry, labels, layers, degradations and speed."""

from __future__ import annotations

import math
import time
from types import SimpleNamespace

import numpy as np
import pytest

from perception.degradation import Degradation
from perception.ground import GroundTexture
from perception.pinhole import PinholeView, as_view
from perception.render import (
    SKY_RGB,
    Fire,
    Occluder,
    Smoke,
    Target,
    default_ground,
    render_frame,
    render_rgb,
    render_thermal,
)

W, H = 320, 240
QUIET = Degradation(noise_sigma=0.0, thermal_noise_K=0.0)


def nadir(north=0.0, east=0.0, altitude=30.0, width=W, height=H, hfov_deg=60.0):
    return PinholeView.look_at((north, east, -altitude), (north, east, 0.0), width, height, math.radians(hfov_deg))


# -- camera conventions ---------------------------------------------------------------------------


def test_look_at_nadir_hand_checked():
    # 90° HFOV on 100 px: f = 50, principal point 49.5. Image up = north, image right = east.
    view = PinholeView.look_at((0, 0, -10), (0, 0, 0), 100, 100, math.radians(90))
    uv, depth = view.project(np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 0]]))
    np.testing.assert_allclose(uv, [[49.5, 44.5], [54.5, 49.5], [49.5, 49.5]], atol=1e-9)
    np.testing.assert_allclose(depth, 10.0)
    np.testing.assert_allclose(view.R[2], [0, 0, 1])  # optical axis = NED down


def test_look_at_forward_hand_checked():
    # Looking north, level: right = east, down = NED down.
    view = PinholeView.look_at((0, 0, -10), (10, 0, -10), 100, 100, math.radians(90))
    np.testing.assert_allclose(view.R, [[0, 1, 0], [0, 0, 1], [1, 0, 0]], atol=1e-12)
    uv, _ = view.project(np.array([[10.0, 1.0, -10.0], [10.0, 0.0, -9.0]]))
    np.testing.assert_allclose(uv, [[54.5, 49.5], [49.5, 54.5]], atol=1e-9)


def test_camera_descriptions_agree():
    view = PinholeView.look_at((3, -2, -25), (10, 4, 0), W, H, math.radians(70))
    pts = np.array([[10.0, 4.0, 0.0], [0.0, 0.0, 0.0], [20.0, -5.0, -3.0]])
    pose = SimpleNamespace(R_world_from_cam=view.R.T, centre=view.center)
    intr = SimpleNamespace(fx=view.K[0, 0], fy=view.K[1, 1], cx=view.K[0, 2], cy=view.K[1, 2], dist=())

    def pixels_only(points):  # NaN behind the camera, like perception.projection.world_to_pixel
        return view.project(points)[0]

    for camera in (view.P * -3.0, (view.K, view.R, view.t), (pose, intr), view.project, pixels_only):
        other = as_view(camera)
        np.testing.assert_allclose(other.project(pts)[0], view.project(pts)[0], atol=1e-6)
        np.testing.assert_allclose(other.project(pts)[1], view.project(pts)[1], atol=1e-6)


def test_non_pinhole_callable_and_distortion_are_refused():
    view = nadir()

    def fisheye(points):
        uv, depth = view.project(points)
        r = uv - [W / 2, H / 2]
        return uv + 1e-3 * r * (r**2).sum(axis=1, keepdims=True) ** 0.5, depth

    with pytest.raises(ValueError, match="not a pinhole"):
        as_view(fisheye)
    pose = SimpleNamespace(R_world_from_cam=view.R.T, centre=view.center)
    intr = SimpleNamespace(fx=300.0, fy=300.0, cx=160.0, cy=120.0, dist=(0.1, 0.0))
    with pytest.raises(ValueError, match="distortion"):
        as_view((pose, intr))
    with pytest.raises(TypeError):
        as_view("camera")


# -- layers and labels ----------------------------------------------------------------------------


def test_target_label_matches_projection_and_apparent_size():
    view = nadir(altitude=20.0)
    target = Target((2.0, -1.5, -0.5), 0.5, (200, 20, 20))
    frame = render_rgb(view, W, H, [target], degradation=QUIET, seed=0)
    label = frame.targets[0]
    uv, depth = view.project(np.array([target.position]))
    np.testing.assert_allclose(label.center_px, uv[0], atol=1e-9)
    dist = np.linalg.norm(np.array(target.position) - view.center)
    assert label.radius_px == pytest.approx(view.focal * math.tan(math.asin(0.5 / dist)))
    assert label.visible and label.in_view and label.visible_fraction == 1.0
    u, v = (round(c) for c in label.center_px)
    assert frame.rgb[v, u].tolist() == [200, 20, 20]
    # The drawn disc has the apparent area.
    red = (frame.rgb[..., 0] > 150) & (frame.rgb[..., 1] < 60)
    assert red.sum() == pytest.approx(math.pi * label.radius_px**2, rel=0.15)
    assert frame.thermal is None


def test_targets_out_of_view_and_behind_are_labelled():
    view = nadir()
    frame = render_rgb(view, W, H, [Target((200.0, 0.0, 0.0), 0.5), Target((0.0, 0.0, -40.0), 0.5)], seed=0)
    outside, behind = frame.targets
    assert not outside.in_view and not outside.visible
    assert not behind.in_view and math.isnan(behind.depth)
    assert frame.visible_centers().shape == (0, 2)


def test_ground_texture_is_fixed_in_the_world():
    ground = default_ground()
    a = render_rgb(nadir(0.0, 0.0), W, H, ground=ground, degradation=QUIET)
    b = render_rgb(nadir(2.0, 1.0), W, H, ground=ground, degradation=QUIET)
    # World points seen by both cameras have the same colour in both images.
    pts = np.column_stack([np.linspace(-4, 5, 40), np.linspace(3, -3, 40), np.zeros(40)])
    ua, _ = nadir(0.0, 0.0).project(pts)
    ub, _ = nadir(2.0, 1.0).project(pts)
    ca = a.rgb[np.round(ua[:, 1]).astype(int), np.round(ua[:, 0]).astype(int)].astype(float)
    cb = b.rgb[np.round(ub[:, 1]).astype(int), np.round(ub[:, 0]).astype(int)].astype(float)
    assert np.abs(ca - cb).mean() < 6.0
    # ... and a different place looks different.
    c = render_rgb(nadir(37.0, -11.0), W, H, ground=ground, degradation=QUIET)
    assert np.abs(c.rgb.astype(float) - a.rgb).mean() > 10.0


def test_terrain_path_matches_the_homography_on_a_raised_plane():
    view = nadir(altitude=40.0)
    flat = render_rgb(view, W, H, ground_height=5.0, degradation=QUIET)
    raised = render_rgb(view, W, H, terrain=lambda n, e: np.full(np.shape(n), 5.0), degradation=QUIET)
    assert np.abs(flat.rgb.astype(float) - raised.rgb).mean() < 3.0


def test_sky_above_the_horizon():
    view = PinholeView.look_at((0, 0, -20), (100, 0, -20), W, H, math.radians(60))
    frame = render_frame(view, W, H, degradation=QUIET, seed=0)
    assert frame.rgb[:20].reshape(-1, 3).tolist() == [list(SKY_RGB)] * (20 * W)
    assert np.all(frame.thermal[:20] < 260.0)
    assert not np.all(frame.rgb[-20:] == SKY_RGB)


def test_fire_is_hot_and_flame_coloured_with_the_projected_area():
    view = nadir(altitude=30.0)
    fire = Fire((0.0, 0.0), 4.0, 800.0)
    frame = render_frame(view, W, H, fires=[fire], degradation=QUIET, seed=1)
    side_px = 4.0 * view.focal / 30.0
    assert frame.fire_mask.sum() == pytest.approx(side_px**2, rel=0.1)
    hot = frame.thermal[frame.fire_mask]
    assert hot.min() > 500.0 and np.median(hot) > 650.0
    assert frame.thermal[~frame.fire_mask].max() < 420.0
    r, g, b = (frame.rgb[frame.fire_mask][:, c].astype(int) for c in range(3))
    assert np.mean((r >= g) & (g >= b)) > 0.95  # red / orange / yellow
    # A polygon given in 2-D and the same cell given by its centre draw the same mask.
    square = Fire([(-2.0, -2.0), (-2.0, 2.0), (2.0, 2.0), (2.0, -2.0)], temperature_K=800.0)
    other = render_frame(view, W, H, fires=[square], degradation=QUIET, seed=1)
    assert np.array_equal(other.fire_mask, frame.fire_mask)


def test_occluder_and_smoke_hide_targets():
    view = nadir(altitude=30.0)
    target = Target((0.0, 0.0, -0.5), 0.5, (30, 30, 30))
    canopy = Occluder((0.0, 0.0, -4.0), 1.5)
    hidden = render_frame(view, W, H, [target], occluders=[canopy], degradation=QUIET)
    assert hidden.targets[0].in_view and not hidden.targets[0].visible
    assert hidden.targets[0].visible_fraction < 0.5
    assert len(hidden.ignore_regions()) == 1
    smoky = render_frame(view, W, H, [target], smoke=[Smoke((0.0, 0.0, -8.0), 3.0, 0.9)], degradation=QUIET)
    assert not smoky.targets[0].visible
    u, v = (round(c) for c in smoky.targets[0].center_px)
    assert smoky.rgb[v, u].min() > 100  # grey smoke over a dark target
    assert smoky.thermal[v, u] > smoky.thermal.mean()  # the warm target still shows in IR
    clear = render_frame(view, W, H, [target], degradation=QUIET)
    assert clear.targets[0].visible


def test_thermal_only_render():
    frame = render_thermal(nadir(), W, H, [Target((0.0, 0.0, -0.5), 0.5, temperature_K=330.0)], seed=0)
    assert frame.rgb is None and frame.thermal.dtype == np.float32
    u, v = (round(c) for c in frame.targets[0].center_px)
    assert frame.thermal[v, u] == pytest.approx(330.0, abs=2.0)


# -- degradations ---------------------------------------------------------------------------------


def test_same_seed_same_frame():
    targets = [Target((1.0, 1.0, -0.5), 0.5)]
    deg = Degradation(banding_prob=0.5, speckle_rate=2.0)
    a = render_frame(nadir(), W, H, targets, degradation=deg, seed=7)
    b = render_frame(nadir(), W, H, targets, degradation=deg, seed=7)
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.thermal, b.thermal)


def test_banding_is_horizontal():
    clean = render_rgb(nadir(), W, H, degradation=QUIET, seed=3)
    banded = render_rgb(
        nadir(),
        W,
        H,
        degradation=Degradation(noise_sigma=0, banding_prob=1.0, banding_coverage=(1.0, 1.0), banding_shift_px=0),
        seed=3,
    )
    assert banded.info.banding and not clean.info.banding
    diff = banded.rgb.astype(float).mean(axis=2) - clean.rgb.astype(float).mean(axis=2)
    row_means = diff.mean(axis=1)
    # Whole rows move together (up to clipping), alternating in sign.
    assert np.mean(np.abs(diff - row_means[:, None]) < 12) > 0.9
    assert (row_means > 20).sum() > 40 and (row_means < -20).sum() > 40


def test_speckles_are_transient_blobs():
    deg = Degradation(noise_sigma=0, speckle_rate=6.0)
    frames = [render_rgb(nadir(), W, H, degradation=deg, seed=s) for s in range(4)]
    assert all(f.info.speckles > 0 for f in frames)
    dark = [(f.rgb.mean(axis=2) < 50) for f in frames]
    assert all(d.sum() > 20 for d in dark)
    assert (dark[0] & dark[1]).sum() < 0.5 * min(dark[0].sum(), dark[1].sum())  # not in the same place


@pytest.mark.parametrize("mode", ["snow", "black", "banding"])
def test_failed_camera_shows_no_scene(mode):
    target = Target((0.0, 0.0, -0.5), 0.5, (210, 25, 30))
    frame = render_frame(
        nadir(), W, H, [target], fires=[Fire((3.0, 3.0), 4.0)], degradation=Degradation(failed=mode), seed=2
    )
    assert frame.failed == mode
    red = (frame.rgb[..., 0] > 150) & (frame.rgb[..., 1] < 60) & (frame.rgb[..., 2] < 60)
    assert red.sum() == 0
    assert frame.thermal.max() < 400.0
    gray = frame.rgb.mean(axis=2)
    if mode == "black":
        assert gray.mean() < 3.0
    else:
        assert gray.std() > 30.0


def test_invalid_degradation_is_refused():
    with pytest.raises(ValueError):
        Degradation(failed="melted")
    with pytest.raises(ValueError):
        Degradation(banding_prob=1.5)
    with pytest.raises(ValueError):
        GroundTexture(style="lava")


# -- speed ----------------------------------------------------------------------------------------


@pytest.mark.parametrize(("width", "height", "budget_ms"), [(320, 240, 10.0), (640, 480, 25.0)])
def test_render_speed(width, height, budget_ms):
    # Typical on 2 cores: ~1.3 ms (320×240) and ~3–5 ms (640×480) for RGB + thermal; the budget
    # is loose so that a loaded machine does not fail the suite, yet a per-pixel Python loop would.
    view = nadir(width=width, height=height)
    targets = [Target((1.0, 2.0, -0.5), 0.5), Target((-3.0, 1.0, -0.5), 0.5, (30, 30, 30))]
    fires = [Fire((4.0, -3.0), 4.0, 800.0)]
    render_frame(view, width, height, targets, fires)
    times = []
    for seed in range(15):
        t0 = time.perf_counter()
        render_frame(view, width, height, targets, fires, seed=seed)
        times.append(time.perf_counter() - t0)
    assert np.median(times) * 1e3 < budget_ms
