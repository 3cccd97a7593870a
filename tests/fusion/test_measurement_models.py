"""Measurement models: Jacobians against central finite differences, the NED azimuth/elevation
convention checked by hand (DESIGN.md §3), angle wrapping and degenerate geometry."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.measurement import (
    MIN_RHO2,
    Bearing2D,
    Bearing3D,
    PositionMeasurement,
    azel_to_los,
    bearing3d_information,
    bearing3d_linearization,
    bearing_gate_distances,
    los_to_azel,
    wrap_angle,
)

SETTINGS = settings(max_examples=80, deadline=None)


def central_difference(f, x, step=1e-6):
    """Jacobian of ``f`` at ``x``; differences of angles are wrapped so that ±pi does not break them."""
    x = np.asarray(x, dtype=float)
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = step
        cols.append(wrap_angle(f(x + e) - f(x - e)) / (2 * step))
    return np.stack(cols, axis=1)


def random_geometry(rng, dims):
    """A sensor and a target at least 5 m apart horizontally, at most ~300 m."""
    while True:
        sensor = rng.uniform(-150, 150, size=3)
        target = rng.uniform(-150, 150, size=3)
        if np.hypot(*(target - sensor)[:2]) > 5.0:
            return sensor[:dims], target[:dims]


@pytest.mark.parametrize("seed", range(30))
def test_bearing2d_jacobian_matches_finite_differences(seed):
    rng = np.random.default_rng(seed)
    sensor, target = random_geometry(rng, 2)
    model = Bearing2D(4, sensor, sigma=0.01)
    x = np.concatenate([target, rng.normal(size=2)])  # position then velocity
    J = model.jacobian(x)
    assert J.shape == (1, 4)
    np.testing.assert_allclose(J, central_difference(model.h, x), rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(J[:, 2:], 0.0)


@pytest.mark.parametrize("seed", range(30))
def test_bearing3d_jacobian_matches_finite_differences(seed):
    rng = np.random.default_rng(1000 + seed)
    sensor, target = random_geometry(rng, 3)
    model = Bearing3D(6, sensor, np.diag([1e-4, 1e-4]))
    x = np.concatenate([target, rng.normal(size=3)])
    J = model.jacobian(x)
    assert J.shape == (2, 6)
    np.testing.assert_allclose(J, central_difference(model.h, x), rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(J[:, 3:], 0.0)


def test_bearing3d_jacobian_across_the_azimuth_cut():
    """Target due south-ish (azimuth near ±pi): the wrapped finite difference still agrees."""
    model = Bearing3D(3, [0.0, 0.0, 0.0], np.eye(2) * 1e-4)
    for x in ([-50.0, 1e-7, 10.0], [-50.0, -1e-7, -10.0]):
        np.testing.assert_allclose(model.jacobian(x), central_difference(model.h, x), rtol=1e-6, atol=1e-9)


def test_position_measurement_jacobian_selects_positions():
    m = PositionMeasurement(6, np.eye(3))
    x = np.arange(6.0)
    np.testing.assert_array_equal(m.jacobian(), np.hstack([np.eye(3), np.zeros((3, 3))]))
    np.testing.assert_array_equal(m.h(x), [0.0, 1.0, 2.0])
    np.testing.assert_allclose(m.jacobian(), central_difference(m.h, x), atol=1e-9)


# -- hand-checked NED conventions ------------------------------------------------------------------
def test_azimuth_convention_ned():
    s = np.array([10.0, 20.0, -30.0])
    model = Bearing3D(3, s, np.eye(2) * 1e-4)
    assert model.h(s + [0.0, 5.0, 0.0])[0] == pytest.approx(np.pi / 2)  # due east
    assert model.h(s + [5.0, 0.0, 0.0])[0] == pytest.approx(0.0)  # due north
    assert model.h(s + [0.0, -5.0, 0.0])[0] == pytest.approx(-np.pi / 2)  # due west
    assert abs(model.h(s + [-5.0, 1e-9, 0.0])[0]) == pytest.approx(np.pi)  # due south
    assert model.h(s + [5.0, 5.0, 0.0])[0] == pytest.approx(np.pi / 4)  # north-east


def test_elevation_convention_ned():
    """z points down: a target below the sensor has negative elevation, one above positive."""
    s = np.zeros(3)
    model = Bearing3D(3, s, np.eye(2) * 1e-4)
    below = model.h([10.0, 0.0, 10.0])
    assert below[1] == pytest.approx(-np.pi / 4)
    assert model.h([10.0, 0.0, -10.0])[1] == pytest.approx(np.pi / 4)
    assert model.h([0.0, 10.0, 0.0])[1] == pytest.approx(0.0)
    # the UAV case: sensor 100 m up (z = -100), target on the ground 100 m east
    az, el = Bearing3D(3, [0.0, 0.0, -100.0], np.eye(2) * 1e-4).h([0.0, 100.0, 0.0])
    assert az == pytest.approx(np.pi / 2) and el == pytest.approx(-np.pi / 4)


def test_bearing2d_convention():
    model = Bearing2D(2, [1.0, 1.0], sigma=0.01)
    assert model.h([1.0, 4.0])[0] == pytest.approx(np.pi / 2)  # east
    assert model.h([4.0, 1.0])[0] == pytest.approx(0.0)  # north
    assert model.h([-2.0, -2.0])[0] == pytest.approx(-3 * np.pi / 4)  # south-west
    assert model.R[0, 0] == pytest.approx(1e-4)


def test_los_azel_hand_checked():
    np.testing.assert_allclose(los_to_azel([0.0, 3.0, 0.0]), [np.pi / 2, 0.0])
    np.testing.assert_allclose(los_to_azel([1.0, 0.0, 1.0]), [0.0, -np.pi / 4])
    np.testing.assert_allclose(azel_to_los([np.pi / 2, 0.0]), [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(azel_to_los([0.3, -np.pi / 2]), [0.0, 0.0, 1.0], atol=1e-15)  # straight down
    np.testing.assert_allclose(azel_to_los([0.0, np.pi / 6]), [np.sqrt(3) / 2, 0.0, -0.5], atol=1e-15)


@SETTINGS
@given(st.floats(-np.pi + 1e-6, np.pi - 1e-6), st.floats(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3))
def test_azel_round_trip(az, el):
    los = azel_to_los([az, el])
    assert np.linalg.norm(los) == pytest.approx(1.0, abs=1e-12)
    back = los_to_azel(los)
    assert wrap_angle(back[0] - az) == pytest.approx(0.0, abs=1e-9)
    assert back[1] == pytest.approx(el, abs=1e-9)


@SETTINGS
@given(
    st.lists(st.floats(-100, 100), min_size=3, max_size=3).filter(lambda v: np.hypot(v[0], v[1]) > 1e-3),
    st.floats(0.01, 100),
)
def test_los_round_trip_and_scale_invariance(v, scale):
    v = np.array(v)
    azel = los_to_azel(v)
    np.testing.assert_allclose(los_to_azel(scale * v), azel, atol=1e-9)
    np.testing.assert_allclose(azel_to_los(azel), v / np.linalg.norm(v), atol=1e-9)
    # the measurement model and the free function agree
    np.testing.assert_allclose(Bearing3D(3, np.zeros(3), np.eye(2)).h(v), azel, atol=1e-12)


# -- residuals and wrapping ------------------------------------------------------------------------
def test_bearing2d_residual_wraps_across_pi():
    model = Bearing2D(2, [0.0, 0.0], 0.01)
    np.testing.assert_allclose(model.residual([np.pi - 0.01], np.array([-np.pi + 0.01])), [-0.02], atol=1e-12)
    np.testing.assert_allclose(model.residual([-np.pi + 0.01], np.array([np.pi - 0.01])), [0.02], atol=1e-12)
    np.testing.assert_allclose(model.residual([0.3], np.array([0.1])), [0.2], atol=1e-12)


def test_bearing3d_residual_wraps_azimuth_only():
    model = Bearing3D(3, np.zeros(3), np.eye(2) * 1e-4)
    r = model.residual([np.pi - 0.01, 0.2], np.array([-np.pi + 0.01, -0.1]))
    np.testing.assert_allclose(r, [-0.02, 0.3], atol=1e-12)


@SETTINGS
@given(st.floats(-1e3, 1e3))
def test_wrap_angle_range_and_equivalence(angle):
    w = float(wrap_angle(angle))
    assert -np.pi <= w < np.pi
    assert np.cos(w) == pytest.approx(np.cos(angle), abs=1e-9)
    assert np.sin(w) == pytest.approx(np.sin(angle), abs=1e-9)


# -- degenerate geometry ---------------------------------------------------------------------------
def test_bearing2d_target_at_sensor_raises():
    model = Bearing2D(4, [3.0, 4.0], 0.01)
    with pytest.raises(ValueError, match="target is at the sensor"):
        model.h([3.0, 4.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="target is at the sensor"):
        model.jacobian([3.0, 4.0, 0.0, 0.0])


@pytest.mark.parametrize("offset", [[0.0, 0.0, 0.0], [0.0, 0.0, 25.0], [0.0, 0.0, -25.0]])
def test_bearing3d_target_at_or_straight_below_sensor_raises(offset):
    s = np.array([1.0, 2.0, -50.0])
    model = Bearing3D(6, s, np.eye(2) * 1e-4)
    x = np.concatenate([s + offset, np.zeros(3)])
    with pytest.raises(ValueError, match="azimuth is undefined"):
        model.h(x)
    with pytest.raises(ValueError, match="azimuth is undefined"):
        model.jacobian(x)


def _scalar_gate_distance(sensor, azel, R, mean, cov) -> float:
    """Merino (3.64) written out with the per-bearing model: nu^T (H P H^T + R)^-1 nu."""
    model = Bearing3D(6, sensor, R)
    x = np.concatenate([mean, np.zeros(3)])
    z_hat, H = model.linearize(x)
    nu = model.residual(azel, z_hat)
    P = np.zeros((6, 6))
    P[:3, :3] = cov
    return float(nu @ np.linalg.solve(H @ P @ H.T + R, nu))


@pytest.mark.parametrize("seed", range(10))
def test_vectorised_bearing_geometry_equals_the_per_bearing_model(seed):
    """bearing3d_linearization and bearing_gate_distances against Bearing3D, pair by pair (azimuths across
    the +-pi cut included), and the pairs where a bearing is undefined come out NaN."""
    rng = np.random.default_rng(seed)
    sensors = np.array([random_geometry(rng, 3)[0] for _ in range(4)])
    means = np.array([random_geometry(rng, 3)[1] for _ in range(3)])
    means[0, :2] = sensors[0, :2]  # straight below the first sensor: no azimuth
    azel = np.column_stack([rng.uniform(-np.pi, np.pi, 4), rng.uniform(-1.4, -0.2, 4)])
    R = np.array([np.diag(rng.uniform(1e-5, 1e-3, 2)) for _ in range(4)])
    covs = np.array([(lambda A: A @ A.T + np.eye(3))(rng.normal(size=(3, 3))) for _ in range(3)])
    d2 = bearing_gate_distances(sensors, azel, R, means, covs)
    z_hat, J, rho2 = bearing3d_linearization(means[None], sensors[:, None])
    for i in range(4):
        for j in range(3):
            if i == 0 and j == 0:
                assert np.isnan(d2[i, j]) and rho2[i, j] < MIN_RHO2
                continue
            model = Bearing3D(6, sensors[i], R[i])
            h, H = model.linearize(np.concatenate([means[j], np.zeros(3)]))
            np.testing.assert_allclose(z_hat[i, j], h, rtol=1e-12)
            np.testing.assert_allclose(J[i, j], H[:, :3], rtol=1e-10, atol=1e-15)
            assert d2[i, j] == pytest.approx(_scalar_gate_distance(sensors[i], azel[i], R[i], means[j], covs[j]),
                                             rel=1e-9)


@pytest.mark.parametrize("seed", range(5))
def test_vectorised_bearing_information_equals_the_per_bearing_model(seed):
    """bearing3d_information against Bearing3D one bearing at a time: ``H^T R^-1 H`` and ``H^T R^-1 (nu + H mu)``
    on the position, azimuths across the +-pi cut included."""
    rng = np.random.default_rng(seed)
    geometry = [random_geometry(rng, 3) for _ in range(6)]
    sensors, points = np.array([g[0] for g in geometry]), np.array([g[1] for g in geometry])
    azel = np.column_stack([rng.uniform(-np.pi, np.pi, 6), rng.uniform(-1.4, -0.2, 6)])
    R = np.array([(lambda A: A @ A.T + 1e-5 * np.eye(2))(rng.normal(size=(2, 2)) * 1e-2) for _ in range(6)])
    infos, vectors = bearing3d_information(points, sensors, azel, R)
    for j in range(6):
        model = Bearing3D(6, sensors[j], R[j])
        mu = np.concatenate([points[j], np.zeros(3)])
        h, H = model.linearize(mu)
        HtRi = H.T @ np.linalg.inv(R[j])
        np.testing.assert_allclose(infos[j], (HtRi @ H)[:3, :3], rtol=1e-9)
        np.testing.assert_allclose(vectors[j], (HtRi @ (model.residual(azel[j], h) + H @ mu))[:3], rtol=1e-9)
