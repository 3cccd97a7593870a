"""``[tracking] intersection``: the rule the tracker uses where common information is unknown — in its channel
filters (policy ``ci``, loops, lost history) and when it merges duplicate tracks — is the configured one."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agent.beliefs.tracking import Tracker
from agent.beliefs.tracking_config import TrackerConfig
from fusion.trajectory import intersect_on_newest
from tests.agent.beliefs.test_tracking import (
    ALTITUDE,
    CAMERA_A,
    GROUND,
    SHARED,
    STEP,
    broadcast,
    clean_sensor,
    received,
)

RULES = ("ci", "fast_ci", "ici")


def test_an_unknown_rule_is_a_clear_error():
    with pytest.raises(ValueError, match="tracking.intersection must be one of ci, fast_ci, ici, got 'cu'"):
        TrackerConfig(intersection="cu")


def two_tracks_of_one_target(config: TrackerConfig) -> Tracker:
    """A tracker holding two confirmed tracks of ``SHARED`` (label-driven updates from two cameras)."""
    tracker = Tracker(config, STEP, GROUND)
    sensors = clean_sensor(32), clean_sensor(33)
    cameras = (np.array([40.0, 20.0, ALTITUDE]), np.array([10.0, 50.0, ALTITUDE]))
    for k in range(10):
        t = k * STEP
        tracker.advance(k)
        (x,) = sensors[0].detect(t, cameras[0], [SHARED(t)])
        (y,) = sensors[1].detect(t, cameras[1], [SHARED(t)])
        tracker.update([dataclasses.replace(x, truth_id="X"), dataclasses.replace(y, truth_id="Y")], by_label=True)
    assert len(tracker.estimates()) == 2
    return tracker


@pytest.mark.parametrize("rule", RULES)
def test_duplicates_merge_with_the_configured_rule(rule):
    tracker = two_tracks_of_one_target(TrackerConfig(intersection=rule))
    keep, drop = (tracker.tracks[i] for i in sorted(tracker.tracks))
    expected = intersect_on_newest(keep.belief, drop.belief, rule)
    assert tracker.merge_duplicates() == 1
    assert keep.belief.allclose(expected, rtol=1e-12)


@pytest.mark.parametrize("rule", RULES)
def test_channel_filters_intersect_with_the_configured_rule(rule):
    config = TrackerConfig(policy="ci", intersection=rule)
    a, b = Tracker(config, STEP, GROUND), two_tracks_of_one_target(config)
    sensor = clean_sensor(31)
    for k in range(10):
        a.advance(k)
        a.update(sensor.detect(k * STEP, CAMERA_A, [SHARED(k * STEP)]))
    (track,) = a.tracks.values()
    local = track.belief
    message = received(broadcast(b, 1), "A")[:1]
    (result,) = a.fuse_remote("B", message, 1)
    assert result.method == "ci"
    assert track.belief.allclose(intersect_on_newest(local, message[0].belief, rule), rtol=1e-12)
