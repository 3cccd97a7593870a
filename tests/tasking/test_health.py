"""Vehicle health (thesis 000 §2.7.4-§2.7.5): fuel burn, Poisson failures, loss, refuel, camera quality."""

import math

import numpy as np
import pytest

from perception.quality import VideoQuality
from tasking.health import HealthModel, VehicleHealth, camera_quality
from tasking.tasks import operational_range

NO_FAILURES = HealthModel(failure_rate=0.0)


def _fly(health: VehicleHealth, seconds: float, dt: float = 1.0) -> None:
    for _ in range(round(seconds / dt)):
        health.step(dt, flying=True)


def test_fuel_burns_at_k_fuel_in_flight_only():
    health = VehicleHealth(NO_FAILURES, np.random.default_rng(0))
    _fly(health, 60.0)
    assert health.fuel == pytest.approx(1.0 - 60.0 * NO_FAILURES.burn)  # f = f0 - k t
    for _ in range(30):
        health.step(1.0, flying=False)  # parked: no burn
    assert health.fuel == pytest.approx(1.0 - 60.0 * NO_FAILURES.burn)


def test_a_failure_switches_to_the_failure_burn_at_the_failure_time():
    model = HealthModel(failure_rate=1 / 50.0)
    # The vehicle's generator draws its first failure time first: the same draw from the same seed.
    failure_time = np.random.default_rng(3).exponential(50.0)
    assert failure_time < 50.0
    health = VehicleHealth(model, np.random.default_rng(3))
    dt = 0.7 + 1e-3  # a step that does not divide the failure time
    _fly(health, 50.0, dt)
    flown = round(50.0 / dt) * dt
    assert health.failed and health.failures == 1
    expected = 1.0 - model.burn * failure_time - model.burn_failed * (flown - failure_time)
    assert health.fuel == pytest.approx(expected, abs=1e-12)  # exact split within the step


def test_failure_times_do_not_depend_on_the_step():
    coarse, fine = (VehicleHealth(HealthModel(failure_rate=1 / 40.0), np.random.default_rng(7)) for _ in range(2))
    _fly(coarse, 50.0, dt=5.0)
    _fly(fine, 50.0, dt=0.1)
    assert coarse.failed == fine.failed and coarse.fuel == pytest.approx(fine.fuel, abs=1e-9)


def test_monte_carlo_failure_rate_matches_p_f():
    """Fraction of vehicles failed after T seconds of flight is 1 - exp(-p_f T) (Poisson process), within
    three binomial standard deviations."""
    p_f, flight, n = 1 / 1000.0, 100.0, 2000
    model = HealthModel(failure_rate=p_f)
    rng = np.random.default_rng(11)
    failed = 0
    for _ in range(n):
        health = VehicleHealth(model, rng)
        _fly(health, flight, dt=10.0)
        failed += health.failed
    p = 1.0 - math.exp(-p_f * flight)
    assert abs(failed - n * p) < 3.0 * math.sqrt(n * p * (1 - p))


def test_failures_after_repairs_count_as_a_poisson_process():
    """Repaired at once after each failure, a vehicle fails N ~ Poisson(p_f T) times in T seconds of flight."""
    p_f, flight = 1 / 20.0, 4000.0
    model = HealthModel(failure_rate=p_f, refuel_time=0.0, capacity=1.0, burn=1e-6, burn_failed=2e-6)
    health = VehicleHealth(model, np.random.default_rng(5))
    for _ in range(round(flight)):
        health.step(1.0, flying=True)
        if health.failed:
            health.start_refuel()  # refuel time 0: repaired at once
    mean = p_f * flight
    assert abs(health.failures - mean) < 3.0 * math.sqrt(mean)


def test_fuel_exhausted_in_the_air_is_lost_and_stays_lost():
    health = VehicleHealth(NO_FAILURES, np.random.default_rng(0), fuel=0.01)
    _fly(health, 0.01 / NO_FAILURES.burn + 1.0)
    assert health.lost and health.fuel == 0.0
    health.step(10.0, flying=True)
    assert health.lost and health.fuel == 0.0
    with pytest.raises(ValueError, match="lost"):
        health.start_refuel()


def test_an_empty_tank_on_the_ground_is_not_a_loss():
    health = VehicleHealth(NO_FAILURES, np.random.default_rng(0), fuel=0.0)
    health.step(10.0, flying=False)
    assert not health.lost


def test_refuel_takes_refuel_time_then_restores_fuel_and_repairs():
    model = HealthModel(failure_rate=1.0, refuel_time=20.0)  # fails within seconds
    health = VehicleHealth(model, np.random.default_rng(1))
    _fly(health, 10.0)
    assert health.failed
    health.start_refuel()
    for _ in range(19):
        health.step(1.0, flying=False)
        assert health.refuelling and health.fuel < model.capacity
    with pytest.raises(ValueError, match="refuelling"):
        health.step(1.0, flying=True)
    health.step(1.0, flying=False)
    assert not health.refuelling and health.fuel == model.capacity and not health.failed


def test_reach_uses_the_current_burn_when_health_aware_and_the_nominal_burn_otherwise():
    model = HealthModel(failure_rate=1.0)
    health = VehicleHealth(model, np.random.default_rng(2))
    assert health.reach(5.0) == operational_range(1.0, 5.0, model.burn)
    _fly(health, 10.0)
    assert health.failed
    assert health.reach(5.0) == pytest.approx(5.0 * health.fuel / model.burn_failed)  # r = v f / k_failure
    assert health.reach(5.0, health_aware=False) == pytest.approx(5.0 * health.fuel / model.burn)


def test_camera_quality_is_the_video_quality_weight_ramp():
    model = HealthModel()
    quality = VideoQuality()
    for D in (0.0, 0.03, 0.06, 0.09, 0.12, 0.15, 0.4):
        quality.history.clear()
        quality.history.append(D)
        assert camera_quality(D, model) == pytest.approx(quality.weight())  # the perception ramp is the oracle
    assert camera_quality(0.09, model) == pytest.approx(0.5)  # half way between D_good and D_fail


def test_return_to_base_on_low_flight_time_or_failed_camera():
    model = HealthModel(failure_rate=0.0, burn=1 / 100.0, burn_failed=2 / 100.0)
    health = VehicleHealth(model, np.random.default_rng(0), fuel=0.5)  # 50 s of flight left
    assert not health.must_return(distance_home=200.0, speed=5.0)  # 40 s home
    assert health.must_return(distance_home=200.0, speed=5.0, reserve=10.0)  # 40 s + 10 s reserve
    assert health.must_return(distance_home=250.0, speed=5.0)
    health.observe_camera(0.05)
    assert not health.camera_failed and not health.must_return(0.0, 5.0)
    health.observe_camera(0.05, failed=True)  # the agent's flag
    assert health.camera_failed and health.quality < 1 and health.must_return(0.0, 5.0)
    health.observe_camera(0.2)  # D above the failure level
    assert health.camera_failed and health.quality == 0.0


@pytest.mark.parametrize("bad, match", [
    (lambda: VehicleHealth(HealthModel(), np.random.default_rng(0), fuel=-0.1), "fuel"),  # negative fuel
    (lambda: VehicleHealth(HealthModel(), np.random.default_rng(0), fuel=2.0), "fuel"),   # above capacity
    (lambda: HealthModel(failure_rate=-1e-3), "p_f"),                 # negative failure intensity
    (lambda: HealthModel(capacity=0.0), "capacity"),                  # an empty tank model
    (lambda: HealthModel(burn=0.0), "k_fuel"),                        # no burn: infinite range
    (lambda: HealthModel(burn_failed=1 / 600.0), "k_fuel,failure"),   # a failure that lowers the burn
    (lambda: HealthModel(refuel_time=-1.0), "refuel"),
    (lambda: HealthModel(camera_fail=0.01), "D_fail"),                # failure level below the good level
    (lambda: camera_quality(-0.1, HealthModel()), "D\\(t\\)"),        # negative video-quality measure
    (lambda: VehicleHealth(HealthModel(), np.random.default_rng(0)).step(-1.0, True), "dt"),
])
def test_bad_input_is_refused(bad, match):
    with pytest.raises(ValueError, match=match):
        bad()
