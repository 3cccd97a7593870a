"""The centre measure of Andreetto et al. 2018 (spec 004 Eqs. (2)-(3)): geometry, Eq. (6), visibility, bad inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tasking.centre_measure import (
    bearing,
    centre_measure,
    centre_measures,
    heading,
    reflected_measures,
    reflected_noise_std,
    rotate,
    saturation_binds,
    visible,
)


def _geometry(centre, phase, distance, target):
    """UAV ``distance`` from ``centre`` at ``phase``, its camera axis at the centre; the true bearing of ``target``."""
    uav = centre + distance * np.array([math.cos(phase), math.sin(phase)])
    axis = float(heading(centre - uav))
    return uav, axis, float(bearing(uav, axis, target))


def _distance_to_line(point, origin, direction):
    d = direction / np.linalg.norm(direction)
    v = point - origin
    return abs(v[0] * d[1] - v[1] * d[0])


@settings(max_examples=200, deadline=None)
@given(
    cx=st.floats(-50, 50),
    cy=st.floats(-50, 50),
    phase=st.floats(0, 2 * math.pi),
    distance=st.floats(1, 60),
    tx=st.floats(-60, 60),
    ty=st.floats(-60, 60),
    kappa=st.floats(0.05, 10),
    Lambda=st.floats(0.05, 1.95),
)
def test_eq6_measure_is_strictly_closer_to_the_target(cx, cy, phase, distance, tx, ty, kappa, Lambda):
    """004 Eq. (6): with the exact geometry, 0 < Λ < 2 and κ > 0, ‖m_i - p‖ < ‖p̂_i - p‖ unless η = 0; and m_i
    sits at |1 - min(κ, Λ)| times the centre's distance from the line of sight (the closed form)."""
    centre, target = np.array([cx, cy]), np.array([tx, ty])
    uav, axis, eta = _geometry(centre, phase, distance, target)
    if np.linalg.norm(target - uav) < 1e-3 or abs(math.sin(eta)) < 1e-3:
        return  # target on the UAV, or on the line UAV-centre: m_i = p̂_i (the proof's first case)
    m = centre_measure(centre, axis, eta, distance, kappa, Lambda, eta_max=math.pi)
    assert np.linalg.norm(m - target) < np.linalg.norm(centre - target)
    line = target - uav
    expected = abs(1 - min(kappa, Lambda)) * _distance_to_line(centre, uav, line)
    assert _distance_to_line(m, uav, line) == pytest.approx(expected, abs=1e-7)


def test_kappa_below_lambda_puts_the_measure_on_the_line_of_sight():
    """κ = 1 <= Λ: the step is r sin η exactly, the foot of the perpendicular (spec 004 §2.2)."""
    centre, target = np.array([0.0, 0.0]), np.array([4.0, 7.0])
    uav, axis, eta = _geometry(centre, 0.3, 20.0, target)
    m = centre_measure(centre, axis, eta, 20.0, kappa=1.0, Lambda=1.5)
    assert _distance_to_line(m, uav, target - uav) == pytest.approx(0.0, abs=1e-9)
    assert not saturation_binds(1.0, 1.5) and saturation_binds(6.0, 1.0)


def test_saturation_makes_kappa_irrelevant_above_lambda():
    centre, target = np.array([1.0, -2.0]), np.array([5.0, 3.0])
    _, axis, eta = _geometry(centre, 2.0, 15.0, target)
    a = centre_measure(centre, axis, eta, 15.0, kappa=6.0, Lambda=0.8)
    b = centre_measure(centre, axis, eta, 15.0, kappa=60.0, Lambda=0.8)
    np.testing.assert_allclose(a, b)


def test_batched_form_matches_one_uav_at_a_time():
    rng = np.random.default_rng(3)
    centres = rng.normal(size=(4, 3, 2))
    headings, etas, radii = rng.uniform(-3, 3, (4, 3)), rng.uniform(-0.5, 0.5, (4, 3)), rng.uniform(5, 30, (4, 3))
    batch = centre_measures(centres, headings, etas, radii, 6.0, 1.0)
    for idx in np.ndindex(4, 3):
        one = centre_measure(centres[idx], headings[idx], etas[idx], radii[idx], 6.0, 1.0)
        np.testing.assert_allclose(batch[idx], one)


def test_bearing_sign_follows_the_rotation_sense():
    """η > 0 when the target is rotated positively (first axis towards the second) from the camera axis."""
    uav, axis = np.zeros(2), 0.0
    assert float(bearing(uav, axis, rotate(np.array([10.0, 0.0]), 0.2))) == pytest.approx(0.2)
    assert float(bearing(uav, axis, rotate(np.array([10.0, 0.0]), -0.2))) == pytest.approx(-0.2)


def test_no_measure_outside_the_fov():
    centre = np.zeros(2)
    assert centre_measure(centre, 0.0, None, 15.0, 6.0, 1.0) is None  # no detection at all
    assert centre_measure(centre, 0.0, math.radians(31), 15.0, 6.0, 1.0) is None  # |η| > η_max = 30°
    assert centre_measure(centre, 0.0, 0.1, 15.0, 6.0, 1.0, target_range=31.0, range_max=30.0) is None  # > R_max
    assert centre_measure(centre, 0.0, math.radians(29), 15.0, 6.0, 1.0, target_range=29.0, range_max=30.0) is not None
    np.testing.assert_array_equal(visible(np.radians([10, 40, 10]), [5, 5, 50], range_max=30.0), [True, False, False])


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        ({"radius": -1.0}, "radius"),  # negative radius
        ({"Lambda": 2.0}, "Lambda"),  # Λ outside (0, 2): the upper end
        ({"Lambda": 0.0}, "Lambda"),  # Λ outside (0, 2): the lower end
        ({"kappa": -1.0}, "kappa"),  # negative gain
        ({"eta": float("nan")}, "eta"),  # NaN bearing
    ],
)
def test_bad_inputs_raise_naming_the_value(kwargs, named):
    args = {"centre": np.zeros(2), "axis_heading": 0.0, "eta": 0.1, "radius": 15.0, "kappa": 6.0, "Lambda": 1.0}
    args.update(kwargs)
    with pytest.raises(ValueError, match=named):
        centre_measure(**args)


def test_batched_nan_bearing_raises():
    with pytest.raises(ValueError, match="eta"):
        centre_measures(np.zeros((2, 2)), [0.0, 0.0], [0.1, np.nan], [15.0, 15.0], 6.0, 1.0)


def test_reflected_measures_are_unbiased_for_equal_spacing_and_have_the_stated_noise():
    """The centroid of Eq. (2) is biased by (1 - β/2) e towards the centre; the reflected measures' centroid is the
    target for n = 5 equally spaced UAVs (oracle: the target), and their per-axis noise is sqrt(2) r σ (Monte Carlo)."""
    radius, kappa, Lambda, n = 30.0, 6.0, 1.0, 5
    target, centre = np.array([0.0, 0.0]), np.array([1.2, -0.7])
    phases = 2 * np.pi * np.arange(n) / n + 0.3
    uavs = centre + radius * np.stack([np.cos(phases), np.sin(phases)], -1)
    axis = np.arctan2(*(centre - uavs).T[::-1])
    eta = bearing(uavs, axis, target)
    m = centre_measures(centre, axis, eta, np.linalg.norm(centre - uavs, axis=-1), kappa, Lambda)
    np.testing.assert_allclose(m.mean(axis=0), target + (1 - Lambda / 2) * (centre - target), atol=2e-2)
    reflected = reflected_measures(centre, m, kappa, Lambda)
    np.testing.assert_allclose(reflected.mean(axis=0), target, atol=2e-2)
    sigma = math.radians(1.0)
    rng = np.random.default_rng(0)
    noisy_eta = eta + sigma * rng.standard_normal((20000, n))
    noisy = reflected_measures(centre, centre_measures(centre, axis, noisy_eta, radius, kappa, Lambda), kappa, Lambda)
    per_axis = np.sqrt(np.mean(np.var(noisy, axis=0)))
    assert per_axis == pytest.approx(reflected_noise_std(radius, sigma), rel=0.05)
    with pytest.raises(ValueError, match="sigma_angle"):
        reflected_noise_std(radius, -1.0)  # negative noise
