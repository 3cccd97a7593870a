"""Two-detection track start-up (agent/beliefs/track_candidates.py): the candidate's gate against the tentative
track's own marginals, the same tracks as one-detection start-up once a target is seen twice, fewer tracks from
clutter, and bad settings refused."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agent.beliefs.tracking import Tracker
from agent.beliefs.tracking_config import TrackerConfig
from agent.sensors.bearing import BearingSensorConfig, GeometricBearingSensor
from tests.agent.beliefs.test_tracking import ALTITUDE, CLUTTER_TARGETS, GROUND, STEP, clean_sensor, orbiting_camera

CAMERA = np.array([-30.0, 0.0, ALTITUDE])


@pytest.mark.parametrize("motion", ["damped", "constant_velocity"])
def test_a_candidates_gate_is_the_tentative_tracks_own_marginal(motion):
    """Oracle: a track started from one bearing (``start_hits = 1``) at grid index 5 and advanced to 9; its
    position marginal at every state of its window, before and after the bearing's, against the candidate's closed
    form ``C + G_|k|``, ``C`` the bearing's ground-point covariance."""
    config = TrackerConfig(motion=motion, start_hits=1)
    tracker = Tracker(config, STEP, GROUND)
    tracker.advance(5)
    (bearing,) = clean_sensor(3).detect(5 * STEP, CAMERA, [{"id": "T", "position": np.array([4.0, -7.0, 0.0])}])
    tracker.update([bearing])
    (track,) = tracker.tracks.values()
    _, C = tracker._geolocate(bearing)
    spread = Tracker(dataclasses.replace(config, start_hits=2), STEP, GROUND).candidates.spread
    tracker.advance(9)
    for offset in range(config.window):
        lag = abs(9 - offset - 5)
        marginal = track.belief.state(offset).cov[:3, :3]
        np.testing.assert_allclose(C + spread[lag], marginal, rtol=1e-6, atol=1e-9)


def _run(start_hits: int, detections) -> Tracker:
    tracker = Tracker(TrackerConfig(start_hits=start_hits), STEP, GROUND)
    for k, scans in detections:
        tracker.advance(k)
        tracker.update_scans(scans)
    return tracker


def test_a_target_seen_twice_has_the_track_one_detection_would_have_started():
    """A clean target seen by two cameras for 4 s: with two-detection start-up the track starts at the second
    detection from the first (as it would have at the first) and takes the second, so from then on the estimates
    equal those of one-detection start-up."""
    sensors = [clean_sensor(11), clean_sensor(12)]
    cameras = [CAMERA, np.array([25.0, 20.0, ALTITUDE])]
    targets = [{"id": "T", "position": np.array([3.0, 5.0, 0.0])}]
    detections = [(k, [s.detect(k * STEP, c, targets) for s, c in zip(sensors, cameras, strict=True)])
                  for k in range(20)]
    one, two = _run(1, detections), _run(2, detections)
    ((_, a),), ((_, b),) = one.estimates(), two.estimates()
    np.testing.assert_allclose(b.mean, a.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(b.cov, a.cov, rtol=1e-9, atol=1e-9)
    assert len(two.candidates) == 0


def test_clutter_seldom_pairs_and_the_targets_stay_tracked():
    """Two orbiting cameras, 0.5 false alarms per frame each, 20 s: one-detection start-up starts a track per
    false alarm; two-detection start-up starts a few, and both end with the two targets confirmed within 3 m."""
    config = BearingSensorConfig(p_detect=0.9, false_alarms=0.5)
    started, tracked = {}, {}
    for start_hits in (1, 2):
        sensors = [GeometricBearingSensor(config, 70 + i) for i in range(2)]
        tracker = Tracker(TrackerConfig(start_hits=start_hits), STEP, GROUND)
        started[start_hits] = 0
        for k in range(100):
            tracker.advance(k)
            truth = [target(k * STEP) for target in CLUTTER_TARGETS]
            for i, sensor in enumerate(sensors):
                started[start_hits] += tracker.update(sensor.detect(k * STEP, orbiting_camera(i, k * STEP),
                                                                    truth))["initiated"]
        tracked[start_hits] = sorted(
            min(float(np.linalg.norm(est.mean[:3] - target(0.0)["position"])) for _, est in tracker.estimates())
            for target in CLUTTER_TARGETS)
    assert started[1] > 60 and started[2] < started[1] / 3
    assert max(tracked[1]) < 3.0 and max(tracked[2]) < 3.0


def test_two_detections_of_one_scan_never_pair_and_candidates_expire():
    """Two detections in one frame are two objects: both are held, no track starts. Nothing pairs with them for
    ``confirm_within`` steps, and they are gone, as an unconfirmed track would be."""
    sensor = GeometricBearingSensor(BearingSensorConfig(p_detect=1.0, false_alarms=0.0, sigma=1e-4), 5)
    near = [{"id": "A", "position": np.array([0.0, 0.0, 0.0])}, {"id": "B", "position": np.array([0.3, 0.0, 0.0])}]
    tracker = Tracker(TrackerConfig(), STEP, GROUND)
    tracker.advance(0)
    assert tracker.update(sensor.detect(0.0, CAMERA, near)) == {"updated": 0, "initiated": 0, "unused": 0,
                                                                 "candidate": 2}
    assert not tracker.tracks
    for k in range(1, tracker.config.confirm_within + 1):
        tracker.advance(k)
        assert len(tracker.candidates) == (2 if k < tracker.config.confirm_within else 0)


@pytest.mark.parametrize("bad", [0, 3, "2"])
def test_start_hits_other_than_one_or_two_is_refused(bad):
    """Bad input: ``[tracking] start_hits`` of 0, 3 or a string."""
    with pytest.raises(ValueError, match="tracking.start_hits must be 1 or 2"):
        TrackerConfig(start_hits=bad)


def test_start_hits_above_confirm_hits_is_refused():
    """Bad input: a track that would need more detections to exist than to be confirmed."""
    with pytest.raises(ValueError, match="at most confirm_hits"):
        TrackerConfig(start_hits=2, confirm_hits=1, confirm_within=1)
