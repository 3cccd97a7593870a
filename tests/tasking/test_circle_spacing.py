"""Equal spacing on the orbit and the set-point (spec 004 §2.8, [NOT IN PAPER] minimal law)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tasking.circle_spacing import MAX_SPEED, circle_gaps, spacing_rate, spacing_setpoint


def _positions(phases, radius=15.0):
    return radius * np.stack([np.cos(phases), np.sin(phases)], axis=-1)


@pytest.mark.parametrize("n", [2, 3, 5, 9])
def test_equal_spacing_converges_to_two_pi_over_n(n):
    rng = np.random.default_rng(n)
    phases = np.sort(rng.uniform(0, 2 * np.pi, n))
    centres, heard, dt = np.zeros((n, 2)), np.ones((n, n), bool), 0.1
    for _ in range(3000):
        theta, ahead, behind = circle_gaps(centres, _positions(phases), heard)
        phases = theta + spacing_rate(ahead, behind, 15.0, dt) * dt
    _, ahead, behind = circle_gaps(centres, _positions(phases), heard)
    np.testing.assert_allclose(ahead, 2 * np.pi / n, atol=1e-4)
    np.testing.assert_allclose(behind, 2 * np.pi / n, atol=1e-4)


def test_gaps_are_to_the_nearest_heard_neighbours_and_two_pi_alone():
    phases = np.array([0.0, 1.0, 2.5, 4.0])
    heard = np.ones((4, 4), bool)
    heard[0, 1] = heard[1, 0] = False  # 0 and 1 do not hear each other
    _, ahead, behind = circle_gaps(np.zeros((4, 2)), _positions(phases), heard)
    assert ahead[0] == pytest.approx(2.5) and behind[0] == pytest.approx(2 * np.pi - 4.0)
    assert ahead[2] == pytest.approx(1.5) and behind[2] == pytest.approx(1.5)
    _, ahead, behind = circle_gaps(np.zeros((1, 2)), _positions(np.array([0.3])), np.ones((1, 1), bool))
    assert ahead[0] == behind[0] == pytest.approx(2 * np.pi)


def test_rate_respects_three_measures_per_turn_and_the_speed_cap():
    """Huge gap differences: θ̇ stays in [0, min(2π/(3Δt), (13 - |ṗ̂|)/r)]."""
    rate = spacing_rate(np.array([6.0, 0.1, 3.0]), np.array([0.1, 6.0, 3.0]), 15.0, 1.0, 8.0, k_theta=10.0)
    assert rate.max() == pytest.approx((MAX_SPEED - 8.0) / 15.0) and rate.min() == 0.0
    rate = spacing_rate(6.0, 0.1, 1.0, 0.5, 0.0, k_theta=10.0)  # tiny circle: the 3-per-turn cap binds
    assert float(rate) == pytest.approx(2 * math.pi / 1.5)


def test_setpoint_is_on_the_circle_with_the_feed_forward_velocity():
    centre, velocity = np.array([3.0, 4.0]), np.array([1.0, -2.0])
    sp = spacing_setpoint(centre, velocity, theta=0.5, rate=0.2, radius=15.0)
    assert np.linalg.norm(sp.position - centre) == pytest.approx(15.0)
    np.testing.assert_allclose(sp.velocity, velocity + 15.0 * 0.2 * np.array([-math.sin(0.5), math.cos(0.5)]))
    ahead = spacing_setpoint(centre, velocity, theta=0.5, rate=0.2, radius=15.0, lead=2.0)
    np.testing.assert_allclose(ahead.position, centre + 15.0 * np.array([math.cos(0.9), math.sin(0.9)]))
    fast = spacing_setpoint(centre, np.array([30.0, 0.0]), theta=0.0, rate=0.5, radius=15.0)
    assert np.linalg.norm(fast.velocity) == pytest.approx(MAX_SPEED)


@pytest.mark.parametrize(
    ("call", "named"),
    [
        (lambda: spacing_rate(1.0, 1.0, -15.0, 0.1), "radius"),  # negative radius
        (lambda: spacing_rate(1.0, 1.0, 15.0, 0.0), "dt"),  # zero time step
        (lambda: spacing_rate(1.0, 1.0, 15.0, 0.1, omega_0=0.0), "omega_0"),  # no rotation
        (lambda: spacing_setpoint(np.zeros(2), np.zeros(2), 0.0, 0.1, -1.0), "radius"),  # negative radius
        (lambda: spacing_setpoint(np.zeros(2), np.zeros(2), 0.0, 0.1, 1.0, lead=-1.0), "lead"),  # negative lead
    ],
)
def test_bad_inputs(call, named):
    with pytest.raises(ValueError, match=named):
        call()


def test_spacing_still_acts_when_the_speed_cap_binds():
    """A centre at 11.3 m/s on a 30 m circle leaves θ̇_max = (13 - 11.3) / 30: the nominal rate drops to θ̇_max / 2,
    so a UAV with a wide gap ahead still speeds up and one with a wide gap behind still slows down."""
    cap = (MAX_SPEED - 11.3) / 30.0
    rate = spacing_rate(np.array([3.0, 1.0, 0.1]), np.array([0.1, 1.0, 3.0]), 30.0, 0.05, 11.3, k_theta=0.01)
    np.testing.assert_allclose(rate, [cap / 2 + 0.0145, cap / 2, cap / 2 - 0.0145])
