"""Particle initiation: a banana along the first ray, triangulated by later views, handed to a Gaussian track."""

from __future__ import annotations

import numpy as np
import pytest

from agent.beliefs.particle_init import ParticleInitConfig, ParticleInitiator, back_projection, bearing_mahalanobis
from agent.beliefs.tracking import Tracker
from agent.beliefs.tracking_config import TrackerConfig
from agent.sensors.bearing import Bearing
from fusion.measurement import los_to_azel
from perception.terrain import FlatTerrain

TARGET = np.array([30.0, -20.0, -15.0])  # 15 m above the ground: a ray cast on the terrain would miss it
SIGMA = np.deg2rad(0.5)


def _bearing(sensor, t: float, rng, target=TARGET) -> Bearing:
    sensor = np.asarray(sensor, float)
    R = np.diag([SIGMA**2, SIGMA**2])
    azel = los_to_azel(target - sensor) + rng.normal(0.0, SIGMA, 2)
    return Bearing(t, sensor, azel, R, "t1")


def _flight(t: float) -> np.ndarray:
    """A UAV at 80 m flying east at 10 m/s, passing near the target."""
    return np.array([0.0, -80.0 + 10.0 * t, -80.0])


def test_back_projection_lies_on_the_ray_between_the_depth_bounds():
    rng = np.random.default_rng(0)
    bearing = _bearing(_flight(0.0), 0.0, rng)
    particles = back_projection(bearing, 2000, 5.0, 300.0, rng)
    ranges = np.linalg.norm(particles.states - bearing.sensor, axis=1)
    assert ranges.min() >= 5.0 - 1e-9 and ranges.max() <= 300.0 + 1e-9
    d2 = bearing_mahalanobis(particles.states, bearing)
    assert np.mean(d2) == pytest.approx(2.0, rel=0.15)  # directions drawn from N(azel, R): chi-square(2)
    assert not particles.is_unimodal()  # a uniform segment is no Gaussian


def test_views_from_a_moving_camera_triangulate_and_hand_over_a_consistent_gaussian():
    rng = np.random.default_rng(1)
    errors = []
    for seed in range(6):
        initiator = ParticleInitiator(ParticleInitConfig(), seed=seed)
        handed = []
        for k in range(60):
            t = 0.2 * k
            initiator.offer(_bearing(_flight(t), t, rng))
            handed += initiator.ready(t)
            if handed:
                break
        assert len(handed) == 1, initiator.metrics()
        h = handed[0]
        assert h.hits >= 3 and h.truth_id == "t1"
        err = h.position.mean - TARGET
        errors.append(float(err @ np.linalg.solve(h.position.cov, err)))
        assert np.sqrt(np.max(np.linalg.eigvalsh(h.position.cov))) <= ParticleInitConfig().handover_std
    assert np.mean(errors) < 7.8  # NEES of 3-D positions over runs: chi-square(3) mean is 3


def test_a_bearing_outside_every_candidate_starts_another():
    rng = np.random.default_rng(2)
    initiator = ParticleInitiator(ParticleInitConfig(), seed=0)
    initiator.offer(_bearing(_flight(0.0), 0.0, rng))
    initiator.offer(_bearing(_flight(0.2), 0.2, rng, target=np.array([-60.0, 50.0, 0.0])))
    assert initiator.metrics()["started"] == 2 and len(initiator.candidates) == 2
    initiator.offer(_bearing(_flight(0.4), 0.4, rng))
    assert initiator.metrics()["started"] == 2 and initiator.candidates[0].hits == 2


def test_a_candidate_nobody_confirms_expires():
    rng = np.random.default_rng(3)
    initiator = ParticleInitiator(ParticleInitConfig(candidate_lifetime=2.0), seed=0)
    initiator.offer(_bearing(_flight(0.0), 0.0, rng))
    assert initiator.ready(1.0) == [] and len(initiator.candidates) == 1
    assert initiator.ready(2.5) == [] and not initiator.candidates
    assert initiator.metrics()["expired"] == 1


def test_the_tracker_starts_a_track_above_the_ground_from_particles():
    """The ray's ground point is 15 m below this target: the particle hand-over finds its height, and the
    track that follows stays consistent with the truth (NEES of the 3-D position below chi-square(3)
    at 99.9 %)."""
    rng = np.random.default_rng(4)
    tracker = Tracker(TrackerConfig(initiation="particles"), 0.2, FlatTerrain(), seed=1)
    first = None
    for k in range(80):
        tracker.advance(k)
        tracker.update([_bearing(_flight(0.2 * k), 0.2 * k, rng)])
        if first is None and tracker.tracks:
            first = next(iter(tracker.tracks.values())).estimate()
    assert abs(first.mean[2] - TARGET[2]) < 3.0 * np.sqrt(first.cov[2, 2]) < 15.0  # better than the ground point
    [(_, estimate)] = tracker.estimates()
    err = estimate.mean[:3] - TARGET
    assert err @ np.linalg.solve(estimate.cov[:3, :3], err) < 16.27
    assert tracker.initiator.metrics()["handed_over"] == 1


def test_particle_settings_come_from_the_tracking_table():
    config = TrackerConfig(initiation="particles", particle_init={"particles": 200, "depth_max": 150.0})
    assert config.particle_init == ParticleInitConfig(particles=200, depth_max=150.0)


@pytest.mark.parametrize("bad", [
    {"initiation": "guess"},  # an unknown initiation
    {"particle_init": {"particles": 10}},  # too few particles to judge a shape
    {"particle_init": {"depth_min": 50.0, "depth_max": 20.0}},  # reversed depth bounds
    {"particle_init": {"handover_std": 0.0}},
    {"particle_init": {"colour": "red"}},  # an unknown setting
])
def test_bad_particle_settings_are_clear_errors(bad):
    with pytest.raises(ValueError):
        TrackerConfig(**bad)
