"""Ground-target truth models (spec 004 §4): closed forms, velocity = d(position)/dt, Singer
statistics, terrain following, plain-data snapshots and config errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from mesh_sim.target_set import targets_from_config, truth_snapshot
from mesh_sim.targets import (
    ConstantVelocityTarget,
    DampedVelocityTarget,
    Figure8Target,
    SingerTarget,
    StaticTarget,
    Target,
)
from perception.terrain import FlatTerrain, HillsTerrain

HILLS = HillsTerrain(amplitude=15.0, wavelength=120.0, seed=1)


def all_kinds(terrain):
    return [
        StaticTarget((30.0, -20.0), id="s", terrain=terrain),
        ConstantVelocityTarget((-50.0, 10.0), (3.0, -4.0), id="cv", terrain=terrain),
        Figure8Target((10.0, 5.0), heading=0.4, id="f8", terrain=terrain),
        SingerTarget(
            (0.0, 0.0), (2.0, 1.0), alpha=0.3, sigma=1.0, seed=11, acceleration=(1.0, 1.0), id="sg", terrain=terrain
        ),
    ]


# ------------------------------------------------------------------------------------ figure-8


def test_figure8_closed_form_by_hand():
    f = Figure8Target((100.0, -40.0))
    p, v = f.state(0.0)
    np.testing.assert_allclose(p, [100.0, -40.0, 0.0], atol=1e-12)  # through the centre at t = 0
    w = 2 * math.pi * 0.0285
    np.testing.assert_allclose(v, [2 * w * 20.0, w * 20.0, 0.0], rtol=1e-12)  # (7.16, 3.58) m/s
    np.testing.assert_allclose(v[:2], [7.16, 3.58], atol=5e-3)
    T = 1 / 0.0285
    np.testing.assert_allclose(f.state(T / 2)[0], [100.0, -40.0, 0.0], atol=1e-9)  # the crossing point
    np.testing.assert_allclose(
        f.state(T / 8)[0], [100.0 + 20.0, -40.0 + 20.0 * math.sin(math.pi / 4), 0.0], atol=1e-9
    )  # sin(4πω T/8) = 1


def test_figure8_peak_speed_and_period():
    f = Figure8Target((0.0, 0.0), d=20.0, omega=0.0285)
    T = 1 / 0.0285
    assert f.period == pytest.approx(T) and T == pytest.approx(35.09, abs=0.01)
    ts = np.linspace(0.0, T, 20001)
    speeds = np.array([np.linalg.norm(f.state(t)[1]) for t in ts])
    assert speeds.max() == pytest.approx(8.0, abs=0.01)  # 2πωd√5 = 8.008 m/s
    assert speeds.max() == pytest.approx(f.peak_speed, rel=1e-9)
    for t in (0.3, 7.0, 21.4):
        for a, b in zip(f.state(t), f.state(t + T), strict=True):
            np.testing.assert_allclose(a, b, atol=1e-9)
        # not periodic over half a period (the figure has two lobes)
        assert np.linalg.norm(f.state(t)[0] - f.state(t + T / 2)[0]) > 1.0


def test_figure8_heading_turns_the_long_axis():
    T = 1 / 0.0285
    east = Figure8Target((0.0, 0.0), heading=math.pi / 2)
    np.testing.assert_allclose(east.state(T / 8)[0][:2], [-20.0 * math.sin(math.pi / 4), 20.0], atol=1e-9)


# ------------------------------------------------------------------------------------ every kind


@pytest.mark.parametrize("terrain", [FlatTerrain(3.0), HILLS], ids=["flat", "hills"])
@pytest.mark.parametrize("kind", range(4))
def test_velocity_is_the_derivative_of_position(terrain, kind):
    target = all_kinds(terrain)[kind]
    h = 1e-4
    for t in (0.5, 3.02, 17.7, 61.03, 130.0):
        p, v = target.state(t)
        numeric = (target.state(t + h)[0] - target.state(t - h)[0]) / (2 * h)
        np.testing.assert_allclose(v, numeric, atol=2e-5 * (1 + np.linalg.norm(v)))


@pytest.mark.parametrize("kind", range(4))
def test_targets_ride_on_the_terrain(kind):
    target = all_kinds(HILLS)[kind]
    assert isinstance(target, Target)
    for t in np.linspace(0.0, 200.0, 41):
        p, v = target.state(float(t))
        assert p.shape == (3,) and v.shape == (3,)
        assert p[2] == pytest.approx(-HILLS.height(p[0], p[1]), abs=1e-12)  # NED z down = -height
    if kind == 0:
        np.testing.assert_array_equal(target.state(5.0)[1], 0.0)


def test_constant_velocity_by_hand():
    target = ConstantVelocityTarget((1.0, 2.0), (3.0, -4.0), terrain=FlatTerrain(10.0))
    p, v = target.state(2.0)
    np.testing.assert_allclose(p, [7.0, -6.0, -10.0])
    np.testing.assert_allclose(v, [3.0, -4.0, 0.0])


# ------------------------------------------------------------------------------------ Singer


def make_singer(seed, **kw):
    kw = {"alpha": 0.2, "sigma": 0.8, **kw}
    return SingerTarget((5.0, -5.0), (1.0, 0.0), seed=seed, **kw)


def test_singer_is_deterministic_per_seed_and_independent_of_query_order():
    times = [0.0, 0.05, 12.345, 59.99, 60.0, 60.01, 250.0, 400.7]
    a, b = make_singer(3), make_singer(3)
    forward = [a.state(t) for t in times]
    backward = [b.state(t) for t in reversed(times)][::-1]
    for (pa, va), (pb, vb) in zip(forward, backward, strict=True):
        np.testing.assert_array_equal(pa, pb)
        np.testing.assert_array_equal(va, vb)
    np.testing.assert_allclose(a.state(0.0)[0][:2], [5.0, -5.0])
    np.testing.assert_allclose(a.state(0.0)[1][:2], [1.0, 0.0])
    assert a == b
    other = make_singer(4)
    assert np.linalg.norm(other.state(100.0)[0] - a.state(100.0)[0]) > 1.0
    assert other != a


def test_singer_state_is_continuous_across_grid_points_and_chunks():
    s = make_singer(5)
    for knot in (0.05 * 7, 60.0, 120.0):
        for left, right in zip(s.state(knot - 1e-9), s.state(knot + 1e-9), strict=True):
            np.testing.assert_allclose(left, right, atol=1e-6)
    times, pos, vel, acc = s.grid(130.0)
    assert times.shape == (2601,) and pos.shape == vel.shape == acc.shape == (2601, 2)
    np.testing.assert_allclose(s.state(times[1234])[0][:2], pos[1234], atol=1e-9)
    np.testing.assert_allclose(s.state(times[1234])[1][:2], vel[1234], atol=1e-9)


def test_singer_speed_is_clipped():
    s = make_singer(7, sigma=3.0, alpha=0.05, max_speed=6.0)
    _, _, vel, _ = s.grid(600.0)
    speeds = np.hypot(vel[:, 0], vel[:, 1])
    assert speeds.max() <= 6.0 + 1e-9
    assert np.mean(speeds > 5.999) > 0.1  # the clip is really engaged with these parameters
    for t in np.linspace(0.0, 600.0, 97):
        assert np.hypot(*s.state(float(t))[1][:2]) <= 6.0 + 1e-9
    default = make_singer(7, sigma=3.0, alpha=0.05)
    assert default.max_speed == 8.0
    assert np.hypot(*default.grid(300.0)[2].T).max() <= 8.0 + 1e-9


def autocorrelation(x, lag):
    x = x - x.mean(axis=0)
    return float(np.sum(x[:-lag] * x[lag:]) / np.sum(x * x)) if lag else 1.0


@pytest.mark.parametrize("seed", [1, 2])
def test_singer_acceleration_autocorrelation_decays_like_exp_minus_alpha_tau(seed):
    alpha, sigma, dt = 0.5, 1.0, 0.05
    s = SingerTarget((0.0, 0.0), (0.0, 0.0), alpha=alpha, sigma=sigma, seed=seed, dt=dt, max_speed=math.inf)
    _, _, vel, acc = s.grid(2000.0)
    realised = np.diff(vel, axis=0) / dt  # what the target actually does (no clipping here)
    for series in (acc, realised):
        assert np.var(series) == pytest.approx(sigma**2, rel=0.2)
        for tau in (0.5, 1.0, 2.0, 4.0):
            lag = round(tau / dt)
            assert autocorrelation(series, lag) == pytest.approx(math.exp(-alpha * tau), abs=0.1)


def test_singer_time_limits():
    s = make_singer(1, max_horizon=100.0)
    s.state(100.0)
    for t in (-0.1, 100.5, math.nan, math.inf):
        with pytest.raises(ValueError):
            s.state(t)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"alpha": 0.0}, "alpha"),
        ({"sigma": -1.0}, "sigma"),
        ({"dt": 0.0}, "dt"),
        ({"max_speed": 0.5}, "max_speed"),  # below the initial speed of 1 m/s
        ({"max_speed": math.nan}, "max_speed"),
        ({"seed": -1}, "seed"),
        ({"acceleration": (1.0, 2.0, 3.0)}, "acceleration"),
    ],
)
def test_singer_rejects_bad_parameters(kwargs, match):
    base = {"alpha": 0.2, "sigma": 0.8, "seed": 1}
    with pytest.raises(ValueError, match=match):
        SingerTarget((0.0, 0.0), (1.0, 0.0), **{**base, **kwargs})


# ------------------------------------------------------------------------------------ damped velocity


def test_damped_velocity_target_moves_as_the_trackers_model_says():
    """Monte Carlo over 600 targets against the closed forms of the integrated Ornstein-Uhlenbeck velocity
    (stationary std ``sigma``, correlation time ``tau``): ``Var v = sigma²`` at every time (the start drawn from the
    stationary law), ``Cov(v(t), v(t + h)) = sigma² e^{-h/tau}``, and the displacement over ``h``,
    ``Var(p(h) - p(0)) = 2 sigma² tau² (h/tau - 1 + e^{-h/tau})`` (Uhlenbeck & Ornstein, Phys. Rev. 36, 1930) —
    and the filters' own discretisation (:class:`fusion.motion.DampedVelocity`, Van Loan) predicts the same."""
    from fusion.motion import DampedVelocity

    sigma, tau, h = 1.5, 10.0, 7.0
    runs = [DampedVelocityTarget((0.0, 0.0), sigma, tau, seed) for seed in range(600)]
    start = np.array([r.state(0.0) for r in runs])[:, :, :2]  # (runs, position|velocity, north/east)
    later = np.array([r.state(h) for r in runs])[:, :, :2]
    assert np.var(start[:, 1]) == pytest.approx(sigma**2, rel=0.1)
    assert np.var(later[:, 1]) == pytest.approx(sigma**2, rel=0.1)
    assert np.mean(start[:, 1] * later[:, 1]) == pytest.approx(sigma**2 * math.exp(-h / tau), rel=0.15)
    displacement = 2 * sigma**2 * tau**2 * (h / tau - 1 + math.exp(-h / tau))
    assert np.var(later[:, 0] - start[:, 0]) == pytest.approx(displacement, rel=0.12)
    model = DampedVelocity(spatial_dims=1, speed_std=sigma, tau=tau)
    F, Q = model.transition(h), model.noise(h)
    stationary = np.diag([0.0, sigma**2])
    predicted = F @ stationary @ F.T + Q  # of (p(h) - p(0), v(h)) from p(0) = 0 and a stationary v(0)
    assert predicted[0, 0] == pytest.approx(displacement, rel=1e-9)
    assert predicted[1, 1] == pytest.approx(sigma**2, rel=1e-9)


def test_damped_velocity_target_is_continuous_deterministic_and_takes_a_given_start_velocity():
    a, b = DampedVelocityTarget((3.0, 4.0), 1.0, 10.0, 5), DampedVelocityTarget((3.0, 4.0), 1.0, 10.0, 5)
    for t in (130.0, 0.35, 60.0):  # queried in another order than a's
        for left, right in zip(a.state(t), b.state(t), strict=True):
            np.testing.assert_array_equal(left, right)
    for knot in (0.05 * 7, 60.0, 120.0):
        for left, right in zip(a.state(knot - 1e-9), a.state(knot + 1e-9), strict=True):
            np.testing.assert_allclose(left, right, atol=1e-6)
    given = DampedVelocityTarget((0.0, 0.0), 1.0, 10.0, 5, velocity=(0.5, -0.25))
    np.testing.assert_allclose(given.state(0.0)[1][:2], [0.5, -0.25])


@pytest.mark.parametrize("kwargs, match", [
    ({"speed_std": 0.0}, "speed_std"),
    ({"tau": -1.0}, "tau"),
    ({"tau": math.inf}, "tau"),
    ({"seed": -3}, "seed"),
    ({"seed": 1.5}, "seed"),
    ({"velocity": (1.0, math.nan)}, "velocity"),
])
def test_damped_velocity_target_rejects_bad_parameters(kwargs, match):
    """Bad input: a zero speed spread, a negative or infinite correlation time, a negative or fractional seed, a
    NaN start velocity."""
    base = {"speed_std": 1.0, "tau": 10.0, "seed": 1}
    with pytest.raises(ValueError, match=match):
        DampedVelocityTarget((0.0, 0.0), **{**base, **kwargs})


# ------------------------------------------------------------------------------------ snapshot / config


def test_truth_snapshot_is_plain_data():
    targets = all_kinds(HILLS)
    snap = truth_snapshot(targets, 12.5)
    assert [s["id"] for s in snap] == ["s", "cv", "f8", "sg"]
    assert json.loads(json.dumps(snap)) == snap
    for target, s in zip(targets, snap, strict=True):
        assert set(s) == {"id", "position", "velocity"}
        assert all(type(x) is float for x in s["position"] + s["velocity"])
        p, v = target.state(12.5)
        assert s["position"] == p.tolist() and s["velocity"] == v.tolist()


def test_targets_from_config():
    configs = [
        {"id": "t0", "kind": "figure8", "center": [0, 0], "d": 20, "omega": 0.0285},
        {"kind": "static", "position": [10, -5]},
        {"id": "walker", "kind": "constant_velocity", "position": [0, 0], "velocity": [1, 1]},
        {"kind": "singer", "position": [1, 2], "velocity": [0.5, 0], "alpha": 0.1, "sigma": 0.5, "seed": 3},
        {"kind": "figure8", "center": [5, 5], "heading_deg": 90},
        {"kind": "damped_velocity", "position": [3, 4], "speed_std": 1.0, "tau": 10, "seed": 2},
    ]
    targets = targets_from_config(configs, HILLS)
    assert [t.id for t in targets] == ["t0", "t1", "walker", "t3", "t4", "t5"]
    assert targets[5] == DampedVelocityTarget((3, 4), 1.0, 10.0, 2, id="t5", terrain=HILLS)
    assert targets[0] == Figure8Target((0.0, 0.0), 20.0, 0.0285, id="t0", terrain=HILLS)
    assert targets[1] == StaticTarget((10.0, -5.0), id="t1", terrain=HILLS)
    assert targets[3] == SingerTarget((1, 2), (0.5, 0), alpha=0.1, sigma=0.5, seed=3, id="t3", terrain=HILLS)
    assert targets[4].heading == pytest.approx(math.pi / 2)
    assert all(t.terrain is HILLS for t in targets)
    assert targets_from_config([{"kind": "static", "position": [0, 0]}])[0].terrain == FlatTerrain(0.0)


@pytest.mark.parametrize(
    "config, match",
    [
        ({"id": "a", "kind": "zigzag", "position": [0, 0]}, r"'a'.*kind"),
        ({"id": "a", "position": [0, 0]}, r"'a'.*kind"),
        ({"id": "b", "kind": "static"}, r"'b'.*position"),
        ({"id": "c", "kind": "static", "position": [1, 2, 3]}, r"'c'.*position.*2 entries"),
        ({"id": "c", "kind": "static", "position": 5.0}, r"'c'.*position"),
        ({"id": "c", "kind": "static", "position": "ab"}, r"'c'.*position"),
        ({"id": "d", "kind": "constant_velocity", "position": [0, 0]}, r"'d'.*velocity"),
        ({"id": "d", "kind": "constant_velocity", "position": [0, 0], "velocity": [1, math.inf]}, r"'d'.*velocity"),
        ({"id": "e", "kind": "figure8", "center": [0, math.nan]}, r"'e'.*center"),
        ({"id": "e", "kind": "figure8", "center": [0, 0], "omega": -0.1}, r"'e'.*omega"),
        ({"id": "e", "kind": "figure8", "center": [0, 0], "d": "20"}, r"'e'.*'d'"),
        ({"id": "e", "kind": "figure8", "center": [0, 0], "heading": 1.0}, r"'e'.*heading"),
        (
            {"id": "f", "kind": "singer", "position": [0, 0], "velocity": [0, 0], "alpha": 0.1, "sigma": 0.5},
            r"'f'.*seed",
        ),
        (
            {
                "id": "f",
                "kind": "singer",
                "position": [0, 0],
                "velocity": [0, 0],
                "alpha": 0.1,
                "sigma": 0.5,
                "seed": 1.5,
            },
            r"'f'.*seed",
        ),
        (
            {
                "id": "f",
                "kind": "singer",
                "position": [0, 0],
                "velocity": [0, 0],
                "alpha": math.inf,
                "sigma": 0.5,
                "seed": 1,
            },
            r"'f'.*alpha",
        ),
        (
            {
                "id": "f",
                "kind": "singer",
                "position": [0, 0],
                "velocity": [9, 0],
                "alpha": 0.1,
                "sigma": 0.5,
                "seed": 1,
            },
            r"'f'.*max_speed",
        ),
        ({"id": "", "kind": "static", "position": [0, 0]}, r"id"),
        ({"id": 7, "kind": "static", "position": [0, 0]}, r"id"),
    ],
)
def test_target_config_errors_name_target_and_field(config, match):
    with pytest.raises(ValueError, match=match):
        targets_from_config([config])


def test_target_config_structural_errors():
    with pytest.raises(ValueError, match="duplicate"):
        targets_from_config([{"id": "x", "kind": "static", "position": [0, 0]}] * 2)
    with pytest.raises(ValueError, match="list"):
        targets_from_config({"kind": "static", "position": [0, 0]})
    with pytest.raises(ValueError, match="#1"):
        targets_from_config([{"kind": "static", "position": [0, 0]}, "static"])
