"""The spec-003 mission simulation on a short river stretch: a clean run centres the feature and holds the path,
a GPS step is isolated within three GPS epochs, and without isolation the same step ruins navigation and
centring; runs are reproducible; bad configurations raise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mesh_sim.feature_mission import MissionConfig, plan, run_mission

SHORT_RIVER = ((0.0, 0.0), (300.0, 80.0), (600.0, 20.0), (800.0, 150.0))


def config(**kwargs) -> MissionConfig:
    return MissionConfig(feature=SHORT_RIVER, fault_time=20.0, **kwargs)


@pytest.fixture(scope="module")
def flight():
    return plan(config())


@pytest.fixture(scope="module")
def runs(flight):
    return {
        "clean": run_mission(config(fault=None), flight),
        "isolated": run_mission(config(fault="step", fault_size=25.0), flight),
        "not isolated": run_mission(config(fault="step", fault_size=25.0, isolation=False), flight),
    }


def test_clean_run_centres_the_feature_and_holds_the_path(runs, flight):
    clean = runs["clean"]
    assert clean.times[-1] > 0.9 * flight.uav_path.tau_f / flight.speed  # the whole path was flown
    assert np.all(np.isfinite(clean.centring_px))  # the feature was in front of the camera throughout
    # within 2° (about 40 px with f = 1194 px) of the image centre 95 % of the time: half the 15° half-FOV
    assert np.percentile(clean.centring_angle, 95) < math.radians(2.0)
    np.testing.assert_allclose(clean.centring_angle, np.arctan(clean.centring_px / 1194.4), rtol=1e-3)
    assert np.mean(clean.cross_track) < 5.0 and np.max(clean.cross_track) < 15.0
    assert np.sqrt(np.mean(clean.nav_error**2)) < 1.0
    assert clean.isolated_at == {"gps0": None} and math.isnan(clean.detection_delay)


def test_gps_step_is_isolated_and_navigation_survives(runs):
    isolated, blind = runs["isolated"], runs["not isolated"]
    assert 0.0 < isolated.detection_delay <= 0.3 + 1e-9  # by the third faulty fix at 10 Hz
    after, blind_after = isolated.times > 25.0, blind.times > 25.0  # the runs end at slightly different times
    assert np.sqrt(np.mean(isolated.nav_error[after] ** 2)) < 2.0  # dead reckoning after isolation
    assert np.mean(blind.nav_error[blind_after]) > 15.0  # the unchecked filter follows the 25 m bias
    assert np.mean(isolated.centring_px[after]) < 0.5 * np.mean(blind.centring_px[blind_after])


def test_runs_are_reproducible(flight):
    short = dict(feature=SHORT_RIVER[:2], fault=None, seed=3)
    a, b = run_mission(MissionConfig(**short)), run_mission(MissionConfig(**short))
    np.testing.assert_array_equal(a.nav_error, b.nav_error)
    np.testing.assert_array_equal(a.centring_px, b.centring_px)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"fault": "spike"}, "fault must be one of"),  # an unknown fault kind
        ({"gps_rate": 7.0}, "multiple of gps_rate"),  # 20 Hz is not a multiple of 7 Hz
        ({"receivers": 0}, "receivers must be a positive integer"),  # no GPS at all
        ({"altitude": -50.0}, "altitude must be a positive"),  # below the feature
        ({"fault_time": math.nan}, "finite"),  # NaN fault onset
    ],
)
def test_bad_configurations_raise(kwargs, message):
    with pytest.raises(ValueError, match=message):
        MissionConfig(**kwargs)
