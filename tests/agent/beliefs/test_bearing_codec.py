"""Bearings on the wire under ``flood`` (agent.beliefs.bearing_codec): round trip, and every malformed batch
refused with the wire's ``bad_field`` and the fault named."""

from __future__ import annotations

import numpy as np
import pytest

from agent.beliefs.bearing_codec import MAX_ROWS, bearings_from_table, check_bearings, encode_bearings
from agent.net.wire import DecodeError
from agent.sensors.bearing import Bearing


def _batch(k=3) -> list[Bearing]:
    rng = np.random.default_rng(k)
    out = []
    for i in range(k):
        A = rng.normal(size=(2, 2)) * 1e-2
        out.append(Bearing(0.2 * i, rng.normal(size=3) * 50, rng.uniform(-1, 1, 2), A @ A.T + 1e-6 * np.eye(2)))
    return out


def test_a_batch_comes_back_as_it_was_sent_and_owns_its_arrays():
    bearings = _batch()
    rows = encode_bearings(bearings)
    back = bearings_from_table(check_bearings(rows))
    for b, c in zip(bearings, back, strict=True):
        assert c.t == b.t and type(c.t) is float
        assert np.array_equal(c.sensor, b.sensor) and np.array_equal(c.azel, b.azel) and np.array_equal(c.R, b.R)
        assert c.truth_id is None  # the simulation label never travels
    rows[:] = 0.0  # the received buffer is reused: the bearings must not change with it
    assert np.array_equal(back[0].sensor, bearings[0].sensor) and np.array_equal(back[-1].R, bearings[-1].R)


def _with(row: int, column: int, value: float) -> np.ndarray:
    rows = encode_bearings(_batch())
    rows[row, column] = value
    return rows


@pytest.mark.parametrize(
    "rows, match",
    [
        ([[0.0] * 9], "float64 array"),  # a list, not an array
        (encode_bearings(_batch()).astype(np.float32), "float64 array"),  # single precision
        (np.zeros((3, 8)), "float64 array"),  # a column missing
        (np.zeros(9), "float64 array"),  # one row, not a table
        (np.zeros((0, 9)), "1 to 256"),  # an empty batch
        (np.tile(encode_bearings(_batch(1)), (MAX_ROWS + 1, 1)), "1 to 256"),  # too many rows
        (_with(1, 4, np.nan), "finite"),  # a NaN azimuth
        (_with(2, 1, np.inf), "finite"),  # an infinite sensor position
        (_with(0, 6, 0.0), "positive definite"),  # a zero azimuth variance
        (_with(1, 8, -1e-4), "positive definite"),  # a negative elevation variance
        (_with(2, 7, 1.0), "positive definite"),  # a correlation beyond 1
    ],
)
def test_a_malformed_batch_is_refused_with_the_fault_named(rows, match):
    with pytest.raises(DecodeError, match=match) as err:
        check_bearings(rows)
    assert err.value.reason == "bad_field"
