"""A vehicle's sortie (thesis 000 §2.7.4-2.7.5): home on low fuel or a failed camera, land, refuel, fly again;
lost when the tank runs dry in the air; the assignment's capability uses the current burn rate."""

import numpy as np
import pytest

from tasking.health import HealthModel, VehicleHealth
from tasking.sortie import Sortie

BASE = np.zeros(2)
MODEL = HealthModel(capacity=1.0, burn=1 / 100, burn_failed=2 / 100, failure_rate=0.0, refuel_time=10.0)


def _sortie(fuel=1.0, model=MODEL, reserve=5.0):
    return Sortie(VehicleHealth(model, np.random.default_rng(0), fuel=fuel), speed=10.0, reserve=reserve,
                  landing_radius=5.0)


def test_low_fuel_sends_the_vehicle_home_then_it_lands_refuels_and_flies_again():
    sortie = _sortie(fuel=0.3)  # 30 s of flight left
    assert sortie.update(0.0, [150.0, 0.0], BASE) == "flying"  # home is 15 s away, + 5 s reserve < 30 s
    t = 0.0
    while sortie.state == "flying":
        t += 1.0
        sortie.update(t, [150.0, 0.0], BASE)
    assert sortie.state == "home" and sortie.returns == 1
    assert sortie.health.flight_time() == pytest.approx(20.0, abs=1.0)  # 15 s home + 5 s reserve
    assert sortie.update(t + 1.0, [3.0, 0.0], BASE) == "refuelling"  # within the landing radius
    fuel = sortie.health.fuel
    assert sortie.update(t + 5.0, [3.0, 0.0], BASE) == "refuelling" and sortie.health.fuel == fuel  # no burn
    assert sortie.update(t + 12.0, [3.0, 0.0], BASE) == "flying" and sortie.health.fuel == 1.0


def test_a_vehicle_that_runs_dry_in_the_air_is_lost():
    sortie = _sortie(fuel=0.05, reserve=0.0)
    sortie.update(0.0, [1000.0, 0.0], BASE)  # already too far: home, but 5 s of fuel for 100 s of flight
    sortie.update(10.0, [990.0, 0.0], BASE)
    assert sortie.state == "lost" and sortie.lost_at == 10.0
    assert sortie.update(20.0, [0.0, 0.0], BASE) == "lost"  # stays lost


def test_a_failed_camera_sends_the_vehicle_home():
    sortie = _sortie()
    assert sortie.update(0.0, [50.0, 0.0], BASE, video_quality=0.01) == "flying"
    assert sortie.capability([50.0, 0.0], BASE).quality == 1.0
    assert sortie.update(1.0, [50.0, 0.0], BASE, video_quality=0.5) == "home"  # D(t) above the failure level


def test_the_capability_reach_uses_the_current_burn_rate():
    sortie = _sortie(fuel=0.5)
    assert sortie.capability([0.0, 0.0], BASE).reach == pytest.approx(10.0 * 0.5 / (1 / 100))
    sortie.health.failed = True  # a failure doubles the burn
    assert sortie.capability([0.0, 0.0], BASE).reach == pytest.approx(10.0 * 0.5 / (2 / 100))


@pytest.mark.parametrize("kwargs, match", [
    ({"speed": 0.0}, "speed"),                # a vehicle that cannot fly home
    ({"reserve": -1.0}, "reserve"),           # a negative reserve
    ({"landing_radius": 0.0}, "landing_radius"),
])
def test_bad_sortie_settings_are_refused(kwargs, match):
    args = {"speed": 10.0, "reserve": 5.0, "landing_radius": 5.0, **kwargs}
    with pytest.raises(ValueError, match=match):
        Sortie(VehicleHealth(MODEL, np.random.default_rng(0)), **args)
