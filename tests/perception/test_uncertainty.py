"""Geolocation uncertainty: UT vs linearisation vs Monte Carlo, Merino §3.7.1 (40 m, viewing angle varied)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from perception.camera import MERINO_IR_CAMERA, Intrinsics
from perception.dem import GridTerrain
from perception.pose import Gimbal
from perception.terrain import FlatTerrain, HillsTerrain
from perception.uncertainty import (
    STUDY_NOISE,
    GeolocationNoise,
    Observation,
    format_study,
    gaussian_kl,
    geolocation_map,
    propagate_linear,
    propagate_monte_carlo,
    propagate_ut,
    viewing_angle_study,
)

ANGLES = (0.0, 20.0, 40.0, 60.0)


@pytest.fixture(scope="module")
def study():
    rows = viewing_angle_study(ANGLES, noise=STUDY_NOISE, n_samples=200_000, seed=0)
    print("\nMerino §3.7.1 study, attitude 3°:\n" + format_study(rows))
    return rows


def test_ut_covariance_within_10_percent_of_monte_carlo(study):
    for row in study:
        assert row.cov_error_ut < 0.10, (row.angle_deg, row.cov_error_ut)
        ratio = np.diag(row.ut.cov) / np.diag(row.mc.cov)
        assert np.all(np.abs(ratio - 1.0) < 0.10), (row.angle_deg, ratio)


def test_ut_is_at_least_as_close_as_linearisation(study):
    for row in study:
        assert row.kl_ut <= row.kl_linear, (row.angle_deg, row.kl_ut, row.kl_linear)
    assert study[-1].kl_linear > 5 * study[-1].kl_ut  # at 60° off nadir the difference is large


def test_the_ground_error_grows_with_the_viewing_angle(study):
    sd_north = [math.sqrt(r.mc.cov[0, 0]) for r in study]
    assert all(a < b for a, b in zip(sd_north, sd_north[1:], strict=False))
    for r in study:  # the nominal hit: 40 m up, tan(angle) ahead
        assert r.linear.mean == pytest.approx([40.0 * math.tan(math.radians(r.angle_deg)), 0.0, 0.0], abs=1e-9)


def test_linearisation_underestimates_at_oblique_views_under_large_attitude_error():
    noise = GeolocationNoise(attitude_sigma=math.radians(5.0))
    (row,) = viewing_angle_study([60.0], noise=noise, n_samples=100_000, seed=1)
    assert row.cov_error_ut < 0.10
    assert row.cov_error_linear > 0.15 and row.linear.cov[0, 0] < row.mc.cov[0, 0]


def test_slant_distance_variant():
    rows = viewing_angle_study([0.0, 45.0], n_samples=50_000, slant=True)
    assert rows[1].linear.mean == pytest.approx([40.0 * math.sqrt(0.5), 0.0, 0.0], abs=1e-9)
    assert all(r.cov_error_ut < 0.10 for r in rows)


def oblique(cam=MERINO_IR_CAMERA, tilt_deg=-50.0):
    return Observation(
        [0.0, 0.0, -60.0], 0.02, -0.03, 0.4, cam, [100.0, 150.0], gimbal=Gimbal(0.1, math.radians(tilt_deg))
    )


class HeightOnly:
    """A flat terrain hidden behind the bare Terrain protocol (forces the generic ray caster)."""

    def __init__(self, level):
        self.level_ = level

    def height(self, north, east):
        return self.level_ + 0.0 * np.asarray(north, float)


def test_closed_form_and_generic_ray_casting_agree():
    obs = oblique()
    rng = np.random.default_rng(3)
    delta = rng.normal(size=(20, 9)) * STUDY_NOISE.sigmas
    fast = geolocation_map(obs, FlatTerrain(2.0))(delta)
    slow = geolocation_map(obs, HeightOnly(2.0))(delta)
    assert np.allclose(fast, slow, atol=1e-5)
    nominal = geolocation_map(obs, FlatTerrain(2.0))(np.zeros(9))
    assert nominal[2] == -2.0
    # the DEM error raises the ground: the hit moves up by δh and back towards the camera
    raised = geolocation_map(obs, FlatTerrain(2.0))(np.eye(9)[8])
    assert raised[2] == pytest.approx(-3.0) and np.hypot(*raised[:2]) < np.hypot(*nominal[:2])


def test_ut_matches_monte_carlo_on_a_dem():
    dem = GridTerrain.sample(HillsTerrain(8.0, 200.0, seed=3), -300.0, -300.0, 10.0, (61, 61))
    cam = Intrinsics.from_fov(320, 240, 60.0)
    obs = Observation([0.0, 0.0, -120.0], 0.0, 0.0, 0.0, cam, [160.0, 120.0], gimbal=Gimbal(0.0, math.radians(-70)))
    noise = GeolocationNoise(attitude_sigma=math.radians(1.5))
    ut = propagate_ut(obs, dem, noise)
    mc = propagate_monte_carlo(obs, dem, noise, n_samples=3000, rng=np.random.default_rng(5))
    assert mc.misses == 0
    assert np.linalg.norm(ut.cov - mc.cov) / np.linalg.norm(mc.cov) < 0.15
    assert np.linalg.norm(ut.mean - mc.mean) < 0.2 * math.sqrt(np.trace(mc.cov))


def test_misses():
    obs = Observation(
        [0.0, 0.0, -50.0],
        0.0,
        0.0,
        0.0,
        MERINO_IR_CAMERA,
        [MERINO_IR_CAMERA.cx, MERINO_IR_CAMERA.cy],
        gimbal=Gimbal(0.0, math.radians(-2.0)),
    )
    noise = GeolocationNoise(attitude_sigma=math.radians(3.0))
    assert propagate_ut(obs, FlatTerrain(0.0), noise) is None  # a sigma point looks above the horizon
    mc = propagate_monte_carlo(obs, FlatTerrain(0.0), noise, n_samples=2000)
    assert 0 < mc.misses < 2000
    up = Observation([0.0, 0.0, -50.0], 0.0, 0.0, 0.0, MERINO_IR_CAMERA, [100.0, 10.0], gimbal=Gimbal(0.0, 0.5))
    assert propagate_linear(up, FlatTerrain(0.0), noise) is None
    with pytest.raises(ValueError, match="hit the terrain"):
        propagate_monte_carlo(up, FlatTerrain(0.0), noise, n_samples=100)


def test_zero_noise_and_kappa():
    obs = oblique()
    zero = GeolocationNoise(0.0, 0.0, 0.0, 0.0)
    ut = propagate_ut(obs, FlatTerrain(0.0), zero)
    assert np.allclose(ut.cov, 0.0) and np.allclose(ut.mean, propagate_linear(obs, FlatTerrain(0.0), zero).mean)
    k0 = propagate_ut(obs, FlatTerrain(0.0), STUDY_NOISE, kappa=0.0)
    assert k0 is not None and np.all(np.linalg.eigvalsh(k0.cov) > 0)


def test_gaussian_kl_by_hand():
    assert gaussian_kl([0.0], [[1.0]], [0.0], [[1.0]]) == 0.0
    # KL(N(0, 1) || N(1, 4)) = ½ (1/4 + 1/4 - 1 + ln 4)
    assert gaussian_kl([0.0], [[1.0]], [1.0], [[4.0]]) == pytest.approx(0.5 * (0.5 - 1 + math.log(4)))
    with pytest.raises(np.linalg.LinAlgError):
        gaussian_kl([0, 0], np.eye(2), [0, 0], np.zeros((2, 2)))


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: GeolocationNoise(position_sigma=-1.0), "position_sigma"),
        (lambda: GeolocationNoise(attitude_sigma=(0.1, 0.1)), "attitude_sigma"),
        (lambda: GeolocationNoise(terrain_sigma=math.nan), "terrain_sigma"),
        (lambda: Observation([0, 0, -10], 0, 0, 0, MERINO_IR_CAMERA, [1.0]), "pixel"),
        (lambda: Observation([0, 0], 0, 0, 0, MERINO_IR_CAMERA, [1.0, 2.0]), "position"),
        (lambda: geolocation_map(oblique(), FlatTerrain(0.0))(np.zeros(8)), "shape"),
        (lambda: propagate_monte_carlo(oblique(), FlatTerrain(0.0), STUDY_NOISE, n_samples=5), "n_samples"),
        (lambda: viewing_angle_study([95.0], n_samples=100), "viewing angle"),
    ],
)
def test_bad_inputs(make, match):
    with pytest.raises(ValueError, match=match):
        make()
