"""Bad input is rejected with a ``ValueError`` whose message names the problem, before it touches a belief.

Each test name (and the ``ids``) says what the bad input was."""

from __future__ import annotations

import numpy as np
import pytest

from fusion import information_filter as inf
from fusion.covariance_intersection import ci, fast_ci
from fusion.gaussian import Gaussian
from fusion.measurement import Bearing2D, Bearing3D, PositionMeasurement, azel_to_los, los_to_azel
from fusion.motion import ConstantVelocity, Singer, Static
from fusion.trajectory import Trajectory, TrajectoryModel
from fusion.unscented import sigma_points, unscented_transform

NAN, INF = float("nan"), float("inf")
GOOD_COV = np.array([[2.0, 0.5], [0.5, 1.0]])


def good():
    return Gaussian.from_moments([1.0, 2.0], GOOD_COV)


# -- Gaussian construction -------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("mean", "cov", "match"),
    [
        ([NAN, 0.0], GOOD_COV, "mean contains non-finite"),
        ([INF, 0.0], GOOD_COV, "mean contains non-finite"),
        ([[1.0, 2.0]], GOOD_COV, "mean must be a vector"),
        (1.0, [[1.0]], "mean must be a vector"),
        ([0.0, 0.0], [[NAN, 0.0], [0.0, 1.0]], "covariance contains non-finite"),
        ([0.0, 0.0], [[INF, 0.0], [0.0, 1.0]], "covariance contains non-finite"),
        ([0.0, 0.0], np.eye(3), "covariance must be 2x2"),
        ([0.0, 0.0], np.ones((2, 3)), "covariance must be a square matrix"),
        ([0.0, 0.0], np.ones(2), "covariance must be a square matrix"),
        ([0.0, 0.0], [[1.0, 0.5], [0.2, 1.0]], "covariance is not symmetric"),
        ([0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]], "covariance is not positive definite"),
        ([0.0, 0.0], [[1.0, 1.0], [1.0, 1.0]], "covariance is not positive definite"),
        ([0.0, 0.0], np.zeros((2, 2)), "covariance is not positive definite"),
    ],
    ids=["nan-mean", "inf-mean", "matrix-mean", "scalar-mean", "nan-cov", "inf-cov", "cov-wrong-size",
         "cov-not-square", "cov-vector", "cov-non-symmetric", "cov-indefinite", "cov-singular", "cov-zero"],
)
def test_from_moments_rejects(mean, cov, match):
    with pytest.raises(ValueError, match=match):
        Gaussian.from_moments(mean, cov)


@pytest.mark.parametrize(
    ("y", "Y", "match"),
    [
        ([NAN, 0.0], np.eye(2), "information vector contains non-finite"),
        ([0.0, 0.0], [[1.0, NAN], [NAN, 1.0]], "information matrix contains non-finite"),
        ([0.0, 0.0], np.eye(3), "information matrix must be 2x2"),
        ([0.0, 0.0], [[1.0, 0.3], [0.0, 1.0]], "information matrix is not symmetric"),
        ([0.0, 0.0], [[1.0, 0.0], [0.0, -1e-3]], "information matrix is not positive semi-definite"),
        (np.zeros((2, 1)), np.eye(2), "information vector must be a vector"),
    ],
    ids=["nan-y", "nan-Y", "Y-wrong-size", "Y-non-symmetric", "Y-indefinite", "y-matrix"],
)
def test_from_info_rejects(y, Y, match):
    with pytest.raises(ValueError, match=match):
        Gaussian.from_info(y, Y)


@pytest.mark.parametrize("dim", [0, -2])
def test_zeros_rejects_non_positive_dimension(dim):
    with pytest.raises(ValueError, match="dimension must be positive"):
        Gaussian.zeros(dim)


# -- Gaussian operations ---------------------------------------------------------------------------
def test_fuse_remove_intersect_reject_dimension_mismatch():
    a, b = good(), Gaussian.zeros(3)
    for op in (lambda: a.fuse(b), lambda: a.remove(b), lambda: a.intersect(b, 0.5), lambda: a.kl_divergence(b)):
        with pytest.raises(ValueError, match="dimension mismatch: 2 vs 3"):
            op()


def test_fuse_rejects_non_gaussian():
    with pytest.raises(ValueError, match="expected a Gaussian"):
        good().fuse(np.eye(2))


def test_remove_of_more_information_than_present_raises():
    a = good()
    with pytest.raises(ValueError, match="removing more information than the belief holds"):
        a.remove(a.fuse(a))
    with pytest.raises(ValueError, match="removing more information than the belief holds"):
        Gaussian.zeros(2).remove(a)


@pytest.mark.parametrize("omega", [-0.5, 1.5, NAN], ids=["negative-omega", "omega-above-1", "nan-omega"])
def test_intersect_rejects_bad_omega(omega):
    with pytest.raises(ValueError, match="omega must lie in"):
        good().intersect(good(), omega)


@pytest.mark.parametrize(
    "keep", [[], [0, 0], [2], [-1], [0, 1, 2]], ids=["empty", "duplicate", "out-of-range", "negative", "too-many"]
)
def test_marginal_and_condition_reject_bad_indices(keep):
    with pytest.raises(ValueError, match="not distinct indices of a 2-D state"):
        good().marginal(keep)
    with pytest.raises(ValueError, match="not distinct indices of a 2-D state"):
        good().condition(keep, [0.0])


@pytest.mark.parametrize(("values", "match"), [([1.0, 2.0], "must have length 1"), ([NAN], "non-finite")])
def test_condition_rejects_bad_values(values, match):
    with pytest.raises(ValueError, match=match):
        good().condition([0], values)


@pytest.mark.parametrize(("truth", "match"), [([1.0], "must have length 2"), ([NAN, 0.0], "non-finite")])
def test_nees_rejects_bad_truth(truth, match):
    with pytest.raises(ValueError, match=match):
        good().nees(truth)


@pytest.mark.parametrize(
    ("F", "Q", "match"),
    [
        (np.full((2, 2), NAN), np.eye(2), "non-finite result of the prediction"),
        (np.eye(3), np.eye(2), "transition matrix F must have shape 2x2"),
        (np.eye(2), [[1.0, NAN], [NAN, 1.0]], "non-finite result of the prediction"),
        (np.eye(2), np.eye(3), "process noise Q must have shape 2x2"),
    ],
    ids=["nan-F", "F-wrong-size", "nan-Q", "Q-wrong-size"],
)
def test_predict_rejects_non_finite_or_misshapen_model_matrices(F, Q, match):
    """(Symmetry and definiteness of Q are the motion model's job: see the motion-model tests.)"""
    with pytest.raises(ValueError, match=match):
        good().predict(F, Q)
    with pytest.raises(ValueError, match=match):
        good().predict(F, Q, F_inv=np.eye(2))


def test_predict_rejects_bad_inverse_transition():
    with pytest.raises(ValueError, match="inverse transition must have shape 2x2"):
        good().predict(np.eye(2), np.eye(2), F_inv=np.eye(3))
    with pytest.raises(ValueError, match="non-finite result of the prediction"):
        good().predict(np.eye(2), np.eye(2), F_inv=np.full((2, 2), NAN))


@pytest.mark.parametrize(
    ("z", "match"),
    [([NAN], "non-finite result of the update"), ([1.0, 2.0], "measurement z must have shape 1"),
     ([[1.0]], "measurement z must have shape 1")],
    ids=["nan-z", "z-wrong-length", "z-matrix"],
)
def test_linear_update_rejects_bad_measurement(z, match):
    model = PositionMeasurement(2, [[1.0]], spatial_dims=1)
    with pytest.raises(ValueError, match=match):
        inf.update(good(), model, z)
    with pytest.raises(ValueError, match=match):
        good().update(model.H, model.R_inv, z)


@pytest.mark.parametrize(
    ("z", "match"),
    [([NAN, 0.1], "non-finite result of the update"), ([0.1, 0.2, 0.3], "measurement z must have shape 2"),
     ([0.1], "measurement z must have shape 2")],
    ids=["nan-z", "z-too-long", "z-too-short"],
)
def test_eif_update_rejects_bad_measurement(z, match):
    belief = Gaussian.from_moments([10.0, 5.0, 0.0], np.eye(3))
    model = Bearing3D(3, [0.0, 0.0, -20.0], np.eye(2) * 1e-4)
    with pytest.raises(ValueError, match=match):
        inf.eif_update(belief, model, z)


def test_update_rejects_misshapen_or_non_finite_H_and_R_inv():
    """H with the wrong number of columns for the state, a NaN in H, R^-1 of the wrong size."""
    with pytest.raises(ValueError, match="measurement matrix H must have shape mx2"):
        good().update(np.eye(3), np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match="non-finite result of the update"):
        good().update(np.array([[NAN, 1.0]]), np.eye(1), [0.0])
    with pytest.raises(ValueError, match="inverse measurement noise R\\^-1 must have shape 1x1"):
        good().update(np.array([[1.0, 0.0]]), np.eye(2), [0.0])


def test_eif_update_with_non_finite_linearization_point_raises():
    belief = Gaussian.from_moments([10.0, 5.0, 0.0], np.eye(3))
    model = Bearing3D(3, [0.0, 0.0, -20.0], np.eye(2) * 1e-4)
    with pytest.raises(ValueError, match="non-finite"):
        inf.eif_update(belief, model, [0.1, 0.2], linearization_point=[NAN, 1.0, 0.0])


@pytest.mark.filterwarnings("ignore:invalid value encountered")
def test_prediction_over_negative_or_nan_time_raises():
    g = Gaussian.from_moments(np.zeros(4), np.eye(4))
    for dt in (-1.0, NAN, INF):
        with pytest.raises(ValueError, match="time step must be finite and non-negative"):
            inf.predict(g, ConstantVelocity(2), dt)


# -- motion models ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("factory", "match"),
    [
        (lambda: ConstantVelocity(q=-1.0), "q must be a finite non-negative"),
        (lambda: ConstantVelocity(q=NAN), "q must be a finite non-negative"),
        (lambda: ConstantVelocity(q=INF), "q must be a finite non-negative"),
        (lambda: ConstantVelocity(spatial_dims=0), "spatial_dims must be a positive integer"),
        (lambda: ConstantVelocity(spatial_dims=1.5), "spatial_dims must be a positive integer"),
        (lambda: Static(dim=0), "dim must be a positive integer"),
        (lambda: Singer(alpha=0.0), "alpha must be positive"),
        (lambda: Singer(alpha=-0.1), "alpha must be positive"),
        (lambda: Singer(alpha=NAN), "alpha must be positive"),
        (lambda: Singer(sigma_m=-1.0), "sigma_m must be non-negative"),
        (lambda: Singer(sigma_m=NAN), "sigma_m must be non-negative"),
        (lambda: Singer(spatial_dims=-1), "spatial_dims must be a positive integer"),
    ],
    ids=["cv-negative-q", "cv-nan-q", "cv-inf-q", "cv-zero-dims", "cv-fractional-dims", "static-zero-dim",
         "singer-zero-alpha", "singer-negative-alpha", "singer-nan-alpha", "singer-negative-sigma",
         "singer-nan-sigma", "singer-negative-dims"],
)
def test_motion_model_rejects_bad_parameters(factory, match):
    with pytest.raises(ValueError, match=match):
        factory()


@pytest.mark.parametrize("model", [ConstantVelocity(2), Singer(2)], ids=["cv", "singer"])
@pytest.mark.parametrize("dt", [-0.1, NAN], ids=["negative-dt", "nan-dt"])
def test_motion_noise_rejects_bad_time_step(model, dt):
    with pytest.raises(ValueError, match="time step must be finite and non-negative"):
        model.noise(dt)


# -- measurement models ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("factory", "match"),
    [
        (lambda: PositionMeasurement(6, np.eye(2)), "measurement noise R must be 3x3"),
        (lambda: PositionMeasurement(6, -np.eye(3)), "measurement noise R is not positive definite"),
        (lambda: PositionMeasurement(6, [[1, 2, 0], [0, 1, 0], [0, 0, 1]]), "measurement noise R is not symmetric"),
        (lambda: PositionMeasurement(6, np.full((3, 3), NAN)), "measurement noise R contains non-finite"),
        (lambda: PositionMeasurement(2, np.eye(3)), "state dimension 2 is smaller than the 3 position axes"),
        (lambda: Bearing2D(4, [0.0, 0.0], sigma=0.0), "measurement noise R is not positive definite"),
        (lambda: Bearing2D(4, [0.0, 0.0], sigma=NAN), "measurement noise R contains non-finite"),
        (lambda: Bearing2D(4, [NAN, 0.0], sigma=0.01), "sensor position contains non-finite"),
        (lambda: Bearing2D(4, [1.0], sigma=0.01), "sensor position must have"),
        (lambda: Bearing3D(6, [0.0, 0.0], np.eye(2)), "sensor position must have length 3"),
        (lambda: Bearing3D(6, [0.0, INF, 0.0], np.eye(2)), "sensor position contains non-finite"),
        (lambda: Bearing3D(6, np.zeros(3), np.eye(3)), "measurement noise R must be 2x2"),
        (lambda: Bearing3D(6, np.zeros(3), [[1.0, 2.0], [2.0, 1.0]]), "measurement noise R is not positive definite"),
        (lambda: Bearing3D(2, np.zeros(3), np.eye(2)), "state dimension 2 is smaller than the 3 position axes"),
    ],
    ids=["pos-R-wrong-size", "pos-R-negative", "pos-R-non-symmetric", "pos-R-nan", "pos-state-too-small",
         "b2-zero-sigma", "b2-nan-sigma", "b2-nan-sensor", "b2-short-sensor", "b3-short-sensor", "b3-inf-sensor",
         "b3-R-wrong-size", "b3-R-indefinite", "b3-state-too-small"],
)
def test_measurement_model_rejects_bad_parameters(factory, match):
    with pytest.raises(ValueError, match=match):
        factory()


@pytest.mark.parametrize(
    ("fn", "arg", "match"),
    [
        (los_to_azel, [1.0, 0.0], "line of sight must have length 3"),
        (los_to_azel, [1.0, NAN, 0.0], "line of sight contains non-finite"),
        (azel_to_los, [0.1, 0.2, 0.3], "azimuth/elevation must have length 2"),
        (azel_to_los, [INF, 0.0], "azimuth/elevation contains non-finite"),
    ],
    ids=["los-short", "los-nan", "azel-long", "azel-inf"],
)
def test_angle_conversions_reject_bad_vectors(fn, arg, match):
    with pytest.raises(ValueError, match=match):
        fn(arg)


# -- unscented transform ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("mean", "cov", "kappa", "match"),
    [
        ([NAN, 0.0], np.eye(2), None, "mean contains non-finite"),
        ([0.0, 0.0], np.eye(3), None, "covariance must be 2x2"),
        ([0.0, 0.0], [[1.0, 0.0], [0.0, -1.0]], None, "covariance is not positive semi-definite"),
        ([0.0, 0.0], [[1.0, 0.2], [0.0, 1.0]], None, "covariance is not symmetric"),
        ([0.0, 0.0], np.eye(2), -2.0, "kappa \\+ n must be positive"),
        ([0.0, 0.0], np.eye(2), NAN, "kappa must be finite"),
        ([0.0, 0.0], np.eye(2), INF, "kappa must be finite"),
    ],
    ids=["nan-mean", "cov-wrong-size", "cov-indefinite", "cov-non-symmetric", "kappa-minus-n", "nan-kappa",
         "inf-kappa"],
)
def test_sigma_points_reject(mean, cov, kappa, match):
    with pytest.raises(ValueError, match=match):
        sigma_points(mean, cov, kappa)


def test_unscented_transform_rejects_non_finite_image():
    with pytest.raises(ValueError, match="transformed sigma points contain non-finite"):
        unscented_transform(lambda x: np.where(x > 0, x, np.nan), np.zeros(1), np.eye(1))


# -- covariance intersection -----------------------------------------------------------------------
def test_ci_rejects_bad_inputs():
    a = good()
    with pytest.raises(ValueError, match="needs at least one belief"):
        ci([])
    with pytest.raises(ValueError, match="beliefs of one dimension"):
        ci([a, Gaussian.zeros(3)])
    with pytest.raises(ValueError, match="objective must be 'det', 'trace' or a list of weights"):
        ci([a, a], "entropy")
    with pytest.raises(ValueError, match="expected 2 weights"):
        ci([a, a], [1.0])
    with pytest.raises(ValueError, match="non-negative and sum to 1"):
        ci([a, a], [1.5, -0.5])
    with pytest.raises(ValueError, match="at least one belief with a finite covariance"):
        fast_ci([Gaussian.zeros(2), Gaussian.zeros(2)])


# -- trajectories ----------------------------------------------------------------------------------
def traj_model(**kw):
    args = {"motion": ConstantVelocity(1, q=0.5), "step": 1.0, "window": 3} | kw
    return TrajectoryModel(**args)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"step": 0.0}, "step must be a positive number of seconds"),
        ({"step": -1.0}, "step must be a positive number of seconds"),
        ({"step": NAN}, "step must be a positive number of seconds"),
        ({"window": 1}, "window must be an integer of at least 2"),
        ({"window": 2.5}, "window must be an integer of at least 2"),
        ({"motion": Static(2)}, "positive-definite process noise"),
        ({"motion": ConstantVelocity(1, q=0.0)}, "positive-definite process noise"),
    ],
    ids=["zero-step", "negative-step", "nan-step", "window-1", "fractional-window", "static-motion", "zero-q"],
)
def test_trajectory_model_rejects(kwargs, match):
    with pytest.raises(ValueError, match=match):
        traj_model(**kwargs)


def test_trajectories_at_different_epochs_cannot_be_combined():
    m = traj_model()
    a, b = Trajectory.prior(m, 4), Trajectory.prior(m, 5)
    for op in (lambda: a.fuse(b), lambda: a.remove(b), lambda: a.intersect(b, 0.5)):
        with pytest.raises(ValueError, match="trajectories are not aligned: epoch 4 vs 5"):
            op()


def test_trajectories_with_different_models_cannot_be_combined():
    a = Trajectory.prior(traj_model(), 0)
    b = Trajectory.prior(traj_model(step=2.0), 0)
    with pytest.raises(ValueError, match="must share one TrajectoryModel"):
        a.fuse(b)
    with pytest.raises(ValueError, match="must share one TrajectoryModel"):
        a.fuse(good())


def test_trajectory_advancing_backwards_raises():
    with pytest.raises(ValueError, match="cannot advance a trajectory backwards \\(from epoch 5 to 4\\)"):
        Trajectory.prior(traj_model(), 5).advanced_to(4)


@pytest.mark.parametrize("offset", [-1, 3, 10])
def test_trajectory_offset_outside_window_raises(offset):
    t = Trajectory.prior(traj_model(), 0)
    H, R_inv = np.array([[1.0, 0.0]]), np.eye(1)
    with pytest.raises(ValueError, match=f"state offset {offset} is outside the window of 3 states"):
        t.update(H, R_inv, [0.0], offset=offset)
    with pytest.raises(ValueError, match="outside the window"):
        t.state(offset)


def test_trajectory_remove_of_more_information_raises():
    t = Trajectory.prior(traj_model(), 0)
    more = t.update(np.array([[1.0, 0.0]]), np.eye(1), [1.0])
    with pytest.raises(ValueError, match="removing more information than the trajectory holds"):
        t.remove(more)


def test_trajectory_update_rejects_non_finite_measurement():
    t = Trajectory.prior(traj_model(), 0)
    with pytest.raises(ValueError, match="measurement z contains non-finite"):
        t.update(np.array([[1.0, 0.0]]), np.eye(1), [NAN])
    with pytest.raises(ValueError, match="measurement z must have length 1"):
        t.update(np.array([[1.0, 0.0]]), np.eye(1), [1.0, 2.0])


@pytest.mark.parametrize(
    ("y", "Y", "match"),
    [
        (np.zeros(5), np.eye(6), "trajectory information vector must have length 6"),
        (np.zeros(6), np.eye(5), "trajectory information matrix must be 6x6"),
        (np.full(6, NAN), np.eye(6), "trajectory information vector contains non-finite"),
        (np.zeros(6), -np.eye(6), "trajectory information matrix is not positive semi-definite"),
    ],
    ids=["y-wrong-length", "Y-wrong-size", "nan-y", "Y-indefinite"],
)
def test_trajectory_from_info_rejects(y, Y, match):
    with pytest.raises(ValueError, match=match):
        Trajectory.from_info(y, Y, 0, traj_model())


@pytest.mark.parametrize("omega", [-0.1, 1.1], ids=["negative-omega", "omega-above-1"])
def test_trajectory_intersect_rejects_bad_omega(omega):
    t = Trajectory.prior(traj_model(), 0)
    with pytest.raises(ValueError, match="omega must lie in"):
        t.intersect(t, omega)
