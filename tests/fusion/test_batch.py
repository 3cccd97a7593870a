"""GaussianBatch equals the per-track Gaussian / information filter, and rejects bad shapes."""

from __future__ import annotations

import numpy as np
import pytest

from fusion import covariance_intersection, information_filter
from fusion.batch import GaussianBatch
from fusion.gaussian import Gaussian, UninformativeBeliefError
from fusion.measurement import Bearing2D, Bearing3D, PositionMeasurement
from fusion.motion import ConstantVelocity

TOL = 1e-10
SIZES = [1, 37]


def _random_spd(rng, n, scale=1.0):
    A = rng.normal(size=(n, n))
    return scale * (A @ A.T + n * np.eye(n))


def _random_gaussians(rng, N, n, far=False):
    """Random beliefs; with ``far`` the means sit 20-60 m from the origin (bearing sensors live near it)."""
    out = []
    for _ in range(N):
        mean = rng.normal(size=n) * 5.0
        if far:
            direction = rng.normal(size=3)
            mean[:3] = direction / np.linalg.norm(direction) * rng.uniform(20.0, 60.0)
            mean[:2] += 5.0  # keep well away from the vertical through the sensor
        out.append(Gaussian.from_moments(mean, _random_spd(rng, n, 0.5)))
    return out


def _assert_batch_equals(batch: GaussianBatch, beliefs: list[Gaussian]) -> None:
    assert len(batch) == len(beliefs)
    for i, g in enumerate(beliefs):
        scale_y = max(1.0, np.max(np.abs(g.y)))
        scale_Y = max(1.0, np.max(np.abs(g.Y)))
        np.testing.assert_allclose(batch.y[i], g.y, rtol=0, atol=TOL * scale_y)
        np.testing.assert_allclose(batch.Y[i], g.Y, rtol=0, atol=TOL * scale_Y)


@pytest.fixture
def rng():
    return np.random.default_rng(20240607)


# -- conversion ----------------------------------------------------------------------------------
@pytest.mark.parametrize("N", SIZES)
def test_round_trip(rng, N):
    beliefs = _random_gaussians(rng, N, 6)
    batch = GaussianBatch.from_gaussians(beliefs)
    assert len(batch) == N and batch.dim == 6
    back = batch.to_gaussians()
    for a, b in zip(back, beliefs, strict=True):
        assert np.array_equal(a.y, b.y) and np.array_equal(a.Y, b.Y)
    assert np.array_equal(batch[N - 1].Y, beliefs[-1].Y)


@pytest.mark.parametrize("N", SIZES)
def test_means(rng, N):
    beliefs = _random_gaussians(rng, N, 6)
    means = GaussianBatch.from_gaussians(beliefs).means()
    assert means.shape == (N, 6)
    for mu, g in zip(means, beliefs, strict=True):
        np.testing.assert_allclose(mu, g.mean, rtol=0, atol=TOL * max(1.0, np.max(np.abs(g.mean))))


def test_means_of_singular_track_names_it(rng):
    beliefs = _random_gaussians(rng, 5, 4)
    beliefs[3] = Gaussian.zeros(4)
    with pytest.raises(UninformativeBeliefError, match=r"\[3\]"):
        GaussianBatch.from_gaussians(beliefs).means()


# -- prediction and update ------------------------------------------------------------------------
@pytest.mark.parametrize("N", SIZES)
@pytest.mark.parametrize("spatial_dims", [2, 3])
def test_predict_equals_information_filter(rng, N, spatial_dims):
    model = ConstantVelocity(spatial_dims=spatial_dims, q=0.3)
    beliefs = _random_gaussians(rng, N, model.dim)
    dt = 0.7
    F, Q, F_inv = model.transition(dt), model.noise(dt), model.inverse_transition(dt)
    batch = GaussianBatch.from_gaussians(beliefs).predict(F, Q, F_inv)
    _assert_batch_equals(batch, [information_filter.predict(g, model, dt) for g in beliefs])
    # F_inv defaults to inv(F), as in Gaussian.predict
    batch = GaussianBatch.from_gaussians(beliefs).predict(model.transition(dt), model.noise(dt))
    _assert_batch_equals(batch, [g.predict(model.transition(dt), model.noise(dt)) for g in beliefs])


@pytest.mark.parametrize("N", SIZES)
def test_predict_with_per_track_matrices(rng, N):
    model = ConstantVelocity(spatial_dims=3, q=0.2)
    beliefs = _random_gaussians(rng, N, 6)
    dts = rng.uniform(0.05, 2.0, size=N)
    F = np.stack([model.transition(dt) for dt in dts])
    Q = np.stack([model.noise(dt) for dt in dts])
    F_inv = np.stack([model.inverse_transition(dt) for dt in dts])
    batch = GaussianBatch.from_gaussians(beliefs).predict(F, Q, F_inv)
    _assert_batch_equals(batch, [information_filter.predict(g, model, dt) for g, dt in zip(beliefs, dts, strict=True)])


def test_predict_zero_information_and_static_model():
    batch = GaussianBatch.from_gaussians([Gaussian.zeros(4)] * 3)
    model = ConstantVelocity(spatial_dims=2)
    out = batch.predict(model.transition(1.0), model.noise(1.0))
    assert np.all(out.Y == 0) and np.all(out.y == 0)
    g = Gaussian.from_moments(np.arange(4.0), np.eye(4))
    static = GaussianBatch.from_gaussians([g]).predict(np.eye(4), np.zeros((4, 4)))
    _assert_batch_equals(static, [g])


def test_predict_flushes_subnormal_entries(rng):
    """Cross-axis couplings that decay below the smallest normal float become exact zeros (speed)."""
    model = ConstantVelocity(spatial_dims=2, q=0.1)
    g = Gaussian.from_moments(rng.normal(size=4), np.diag([4.0, 9.0, 1.0, 2.0]))
    Y = g.Y.copy()
    Y[0, 1] = Y[1, 0] = 1e-310  # x-y coupling, subnormal
    tiny_coupled = Gaussian(g.y, Y)
    out = GaussianBatch.from_gaussians([tiny_coupled] * 3).predict(model.transition(1.0), model.noise(1.0))
    tiny = np.finfo(float).tiny
    assert not np.any((out.Y != 0) & (np.abs(out.Y) < tiny))
    _assert_batch_equals(out, [tiny_coupled.predict(model.transition(1.0), model.noise(1.0))] * 3)


@pytest.mark.parametrize("N", SIZES)
@pytest.mark.parametrize("spatial_dims", [2, 3])
def test_update_equals_information_filter(rng, N, spatial_dims):
    n = 2 * spatial_dims
    model = PositionMeasurement(n, _random_spd(rng, spatial_dims, 0.1), spatial_dims=spatial_dims)
    beliefs = _random_gaussians(rng, N, n)
    z = rng.normal(size=(N, spatial_dims)) * 10.0
    batch = GaussianBatch.from_gaussians(beliefs).update(model.H, model.R_inv, z)
    _assert_batch_equals(batch, [information_filter.update(g, model, zi) for g, zi in zip(beliefs, z, strict=True)])


@pytest.mark.parametrize("N", SIZES)
def test_update_with_per_track_H_and_R(rng, N):
    beliefs = _random_gaussians(rng, N, 6)
    H = rng.normal(size=(N, 2, 6))
    R_inv = np.stack([_random_spd(rng, 2) for _ in range(N)])
    z = rng.normal(size=(N, 2))
    batch = GaussianBatch.from_gaussians(beliefs).update(H, R_inv, z)
    expected = [g.update(H[i], R_inv[i], z[i]) for i, g in enumerate(beliefs)]
    _assert_batch_equals(batch, expected)


@pytest.mark.parametrize("N", SIZES)
@pytest.mark.parametrize("shared_sensor", [True, False])
@pytest.mark.parametrize("explicit_points", [False, True])
def test_bearing3d_equals_eif(rng, N, shared_sensor, explicit_points):
    beliefs = _random_gaussians(rng, N, 6, far=True)
    sensors = rng.normal(size=(N, 3))
    if shared_sensor:
        sensors[:] = sensors[0]
    R = np.array([[0.02**2, 0.3e-4], [0.3e-4, 0.03**2]])
    # azimuths far from the truth and near +-pi exercise the wrap
    z = np.column_stack([rng.uniform(-np.pi, np.pi, N), rng.uniform(-1.0, 1.0, N)])
    points = np.stack([g.mean for g in beliefs]) + rng.normal(size=(N, 6)) if explicit_points else None
    batch = GaussianBatch.from_gaussians(beliefs).eif_update_bearing3d(
        sensors[0] if shared_sensor else sensors, np.linalg.inv(R), z, points
    )
    expected = [
        information_filter.eif_update(g, Bearing3D(6, sensors[i], R), z[i], None if points is None else points[i])
        for i, g in enumerate(beliefs)
    ]
    _assert_batch_equals(batch, expected)


@pytest.mark.parametrize("N", SIZES)
def test_bearing2d_equals_eif(rng, N):
    beliefs = _random_gaussians(rng, N, 4, far=True)
    sensors = rng.normal(size=(N, 2))
    sigma = 0.02
    z = rng.uniform(-np.pi, np.pi, size=(N, 1))
    batch = GaussianBatch.from_gaussians(beliefs).eif_update_bearing2d(sensors, np.array([[sigma**-2]]), z)
    expected = [
        information_filter.eif_update(g, Bearing2D(4, sensors[i], sigma), z[i]) for i, g in enumerate(beliefs)
    ]
    _assert_batch_equals(batch, expected)


def test_bearing_at_sensor_is_rejected(rng):
    beliefs = _random_gaussians(rng, 3, 6, far=True)
    batch = GaussianBatch.from_gaussians(beliefs)
    sensors = np.zeros((3, 3))
    sensors[1] = batch.means()[1, :3] + np.array([0.0, 0.0, 5.0])  # straight below the target
    with pytest.raises(ValueError, match=r"straight above or below.*\[1\]"):
        batch.eif_update_bearing3d(sensors, np.eye(2), np.zeros((3, 2)))


# -- fusion ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("N", SIZES)
def test_fuse_and_fast_ci_equal_per_track(rng, N):
    a = _random_gaussians(rng, N, 6)
    b = _random_gaussians(rng, N, 6)
    A, B = GaussianBatch.from_gaussians(a), GaussianBatch.from_gaussians(b)
    _assert_batch_equals(A.fuse(B), [x.fuse(y) for x, y in zip(a, b, strict=True)])
    _assert_batch_equals(A.fast_ci(B), [covariance_intersection.fast_ci([x, y]) for x, y in zip(a, b, strict=True)])


def test_fast_ci_gives_zero_weight_to_uninformative_tracks(rng):
    a = _random_gaussians(rng, 4, 4)
    b = _random_gaussians(rng, 4, 4)
    b[2] = Gaussian.zeros(4)
    a[0] = Gaussian(a[0].y, np.diag([1.0, 1.0, 1.0, 0.0]))  # singular: unbounded covariance
    out = GaussianBatch.from_gaussians(a).fast_ci(GaussianBatch.from_gaussians(b))
    _assert_batch_equals(out, [covariance_intersection.fast_ci([x, y]) for x, y in zip(a, b, strict=True)])
    a[2] = Gaussian.zeros(4)
    with pytest.raises(ValueError, match=r"tracks \[2\]"):
        GaussianBatch.from_gaussians(a).fast_ci(GaussianBatch.from_gaussians(b))


# -- shapes ---------------------------------------------------------------------------------------
def test_bad_construction_shapes():
    with pytest.raises(ValueError, match="shape \\(N, n\\)"):
        GaussianBatch(np.zeros(4), np.zeros((4, 4)))
    with pytest.raises(ValueError, match="Y must have shape"):
        GaussianBatch(np.zeros((3, 4)), np.zeros((3, 4, 3)))
    with pytest.raises(ValueError, match="Y must have shape"):
        GaussianBatch(np.zeros((3, 4)), np.zeros((2, 4, 4)))
    with pytest.raises(ValueError, match="empty"):
        GaussianBatch.from_gaussians([])
    with pytest.raises(ValueError, match="one dimension"):
        GaussianBatch.from_gaussians([Gaussian.zeros(4), Gaussian.zeros(6)])


def test_bad_operation_shapes(rng):
    batch = GaussianBatch.from_gaussians(_random_gaussians(rng, 5, 6, far=True))
    F, Q = np.eye(6), np.eye(6)
    with pytest.raises(ValueError, match="transition matrix F"):
        batch.predict(np.eye(4), Q)
    with pytest.raises(ValueError, match="process noise Q"):
        batch.predict(F, np.eye(6)[None].repeat(4, axis=0))
    with pytest.raises(ValueError, match="F_inv"):
        batch.predict(F, Q, np.eye(5))
    H = np.eye(3, 6)
    with pytest.raises(ValueError, match="measurement matrix H"):
        batch.update(np.eye(3, 4), np.eye(3), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="R_inv"):
        batch.update(H, np.eye(2), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="measurements z"):
        batch.update(H, np.eye(3), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="measurements z"):
        batch.update(H, np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match="sensor positions"):
        batch.eif_update_bearing3d(np.zeros((4, 3)), np.eye(2), np.zeros((5, 2)))
    with pytest.raises(ValueError, match="sensor positions"):
        batch.eif_update_bearing3d(np.zeros(2), np.eye(2), np.zeros((5, 2)))
    with pytest.raises(ValueError, match="R_inv"):
        batch.eif_update_bearing3d(np.zeros(3), np.eye(3), np.zeros((5, 2)))
    with pytest.raises(ValueError, match="measurements z"):
        batch.eif_update_bearing3d(np.zeros(3), np.eye(2), np.zeros((5, 1)))
    with pytest.raises(ValueError, match="linearization points"):
        batch.eif_update_bearing3d(np.zeros(3), np.eye(2), np.zeros((5, 2)), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="measurements z"):
        batch.eif_update_bearing2d(np.zeros(2), np.eye(1), np.zeros(5))
    small = GaussianBatch(np.zeros((2, 2)), np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="at least 3 position"):
        small.eif_update_bearing3d(np.zeros(3), np.eye(2), np.zeros((2, 2)))
    other = GaussianBatch.from_gaussians(_random_gaussians(rng, 4, 6))
    with pytest.raises(ValueError, match="batch shape mismatch"):
        batch.fuse(other)
    with pytest.raises(ValueError, match="batch shape mismatch"):
        batch.fast_ci(other)
    with pytest.raises(ValueError, match="expected a GaussianBatch"):
        batch.fuse(other.to_gaussians()[0])


def test_non_finite_inputs_are_rejected(rng):
    batch = GaussianBatch.from_gaussians(_random_gaussians(rng, 3, 6, far=True))
    bad = np.eye(6)
    bad[2, 3] = np.nan
    with pytest.raises(ValueError, match="process noise Q contains non-finite"):
        batch.predict(np.eye(6), bad)
    with pytest.raises(ValueError, match="transition matrix F contains non-finite"):
        batch.predict(bad, np.eye(6))
    z = np.zeros((3, 3))
    z[1, 0] = np.inf
    with pytest.raises(ValueError, match="measurements z contains non-finite"):
        batch.update(np.eye(3, 6), np.eye(3), z)
    with pytest.raises(ValueError, match="measurement matrix H contains non-finite"):
        batch.update(bad[:3], np.eye(3), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="sensor positions contains non-finite"):
        batch.eif_update_bearing3d(np.array([0.0, np.nan, 0.0]), np.eye(2), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="measurements z contains non-finite"):
        batch.eif_update_bearing3d(np.zeros(3), np.eye(2), np.full((3, 2), np.nan))
