"""Tasks and petal values (thesis 000 (4.1) and the §2.7.4 range test), against hand-computed values."""

import math

import numpy as np
import pytest

from tasking.tasks import Capability, Task, completion_times, operational_range, petal_value, within_reach


def _vehicle(**kw):
    return Capability(**{"position": [0.0, 0.0], "speed": 10.0, "base": [0.0, 0.0], **kw})


def test_completion_times_are_legs_over_speed_plus_dwell():
    tasks = [Task("a", [30.0, 40.0], 1.0, duration=2.0), Task("b", [30.0, 100.0], 1.0)]
    # 50 m at 10 m/s, dwell 2 s -> 7 s; then 60 m -> 13 s
    np.testing.assert_allclose(completion_times(_vehicle(), tasks), [7.0, 13.0])


def test_petal_value_is_the_time_discounted_sum_4_1():
    tasks = [Task("a", [0.0, 50.0], 3.0), Task("b", [0.0, 100.0], 2.0, kind="loiter")]
    value = petal_value(_vehicle(quality=0.5), tasks, 0.9)
    # camera task scaled by q = 0.5, loiter not: 0.5·3·0.9^5 + 2·0.9^10
    assert value == pytest.approx(0.5 * 3 * 0.9**5 + 2 * 0.9**10)
    assert petal_value(_vehicle(), [], 0.9) == 0.0


def test_range_pruning_counts_the_way_home():
    task = [Task("a", [0.0, 100.0], 1.0)]
    assert within_reach(_vehicle(reach=200.0), task)  # 100 out + 100 home
    assert not within_reach(_vehicle(reach=199.0), task)
    assert within_reach(_vehicle(reach=None), task)  # no health model: never pruned
    dwell = [Task("a", [0.0, 100.0], 1.0, duration=1.0)]  # 1 s at 10 m/s costs 10 m of fuel
    assert not within_reach(_vehicle(reach=205.0), dwell)


def test_operational_range_uses_the_current_burn_rate():
    assert operational_range(fuel=60.0, speed=10.0, burn_rate=1.0) == 600.0
    assert operational_range(fuel=60.0, speed=10.0, burn_rate=3.0) == 200.0  # after a failure


@pytest.mark.parametrize("bad, match", [
    (lambda: Task("a", [0.0, math.nan], 1.0), "position"),       # a NaN task position
    (lambda: Task("a", [0.0, 0.0], 0.0), "value"),               # a task worth nothing
    (lambda: Task("a", [0.0, 0.0], 1.0, kind="dance"), "kind"),  # an unknown task kind
    (lambda: Task("a", [0.0, 0.0], 1.0, duration=-1.0), "duration"),
    (lambda: _vehicle(speed=0.0), "speed"),                      # a vehicle that cannot move
    (lambda: _vehicle(quality=1.5), "quality"),                  # camera quality above 1
    (lambda: _vehicle(reach=-1.0), "reach"),
    (lambda: operational_range(1.0, 1.0, 0.0), "burn rate"),     # zero burn rate: infinite range
    (lambda: petal_value(_vehicle(), [], 0.0), "discount"),      # λ = 0
])
def test_bad_input_is_refused(bad, match):
    with pytest.raises(ValueError, match=match):
        bad()
