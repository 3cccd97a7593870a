"""The world's watch over shared orbits (mesh_sim.orbit_watch): closed-form spacing errors, the meeting time."""

import math

import numpy as np
import pytest

from mesh_sim.orbit_watch import SETTLE_S, OrbitWatch, spacing_error


def _on_circle(degrees, radius=30.0, centre=(0.0, 0.0)):
    return {f"uav{i}": [centre[0] + radius * math.cos(math.radians(d)), centre[1] + radius * math.sin(math.radians(d)),
                        -40.0] for i, d in enumerate(degrees)}


def test_spacing_error_closed_forms():
    assert spacing_error(np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])) == pytest.approx(0.0)
    # at 0, 90 and 180 degrees the gaps are 90, 90, 180 against an equal 120: the worst is 60 degrees off
    assert math.degrees(spacing_error(np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]]))) == pytest.approx(60.0)


def test_the_fleet_meets_when_all_are_on_one_targets_circle():
    watch = OrbitWatch(30.0, 3)
    target = [{"id": "t", "position": [0.0, 0.0, 0.0]}]
    watch.observe(0.0, _on_circle([0, 120]), target)  # one UAV not reported yet: nothing to say
    watch.observe(1.0, _on_circle([0, 120, 240], radius=50.0), target)  # all off the circle
    assert watch.summary()["rendezvous_s"] is None
    for k in range(2, 30):
        watch.observe(float(k), _on_circle([0, 120, 240 if k != 5 else 200]), target)
    watch.observe(30.0, _on_circle([0, 120, 240], radius=45.0), target)  # one step off again
    summary = watch.summary()
    assert summary["rendezvous_s"] == 2.0
    assert summary["on_circle_share"] == pytest.approx(28 / 29)
    assert summary["spacing_error_deg"]["median"] == pytest.approx(0.0, abs=1e-9)
    assert summary["spacing_error_deg"]["p95"] > 0  # the step at 5 s with one UAV 40 degrees early
    assert summary["steady_spacing_error_deg"]["p95"] == pytest.approx(0.0, abs=1e-9)  # from 2 + SETTLE_S on
    assert 5.0 < 2.0 + SETTLE_S


def test_a_bad_radius_is_refused():
    with pytest.raises(ValueError, match="radius"):
        OrbitWatch(0.0, 3)


def test_the_run_table_says_how_the_shared_orbit_went():
    from mesh_sim.results import _orbit_caption

    assert _orbit_caption(None) is None  # a scenario without shared orbits
    never = OrbitWatch(30.0, 2).summary()
    assert "never" in _orbit_caption(never)
    watch = OrbitWatch(30.0, 2)
    for k in range(20):
        watch.observe(float(k), _on_circle([0, 180]), [{"id": "t", "position": [0.0, 0.0, 0.0]}])
    assert _orbit_caption(watch.summary()) == ("shared orbit: all on the 30 m circle at 0.0 s, 100% of the time "
                                               "after; spacing error 0° (median, steady)")
