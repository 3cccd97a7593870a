"""Geodetic <-> NED (agent.vehicles.geodesy) against pymap3d (an independent implementation) and
hand-checked cases."""

import math

import numpy as np
import pymap3d
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.vehicles.geodesy import WGS84_A, ecef_to_geodetic, geodetic_to_ecef, geodetic_to_ned, ned_to_geodetic

ORIGIN = (43.5605, 1.4664, 150.0)

lats = st.floats(-89.9, 89.9)
lons = st.floats(-180.0, 180.0)
heights = st.floats(-500.0, 20000.0)


def test_hand_checked_cases():
    # the origin is NED zero; a point straight above is "up" = negative down
    assert np.allclose(geodetic_to_ned(*ORIGIN, ORIGIN), 0.0, atol=1e-9)
    assert np.allclose(geodetic_to_ned(ORIGIN[0], ORIGIN[1], ORIGIN[2] + 80.0, ORIGIN), [0, 0, -80.0], atol=1e-6)
    # at the equator on the prime meridian, ECEF x is the semi-major axis
    assert np.allclose(geodetic_to_ecef(0.0, 0.0, 0.0), [WGS84_A, 0.0, 0.0])
    # one arc-minute of latitude at 45 degrees is 1852.2 m of meridian arc (M(45 deg) = 6 367 381.8 m)
    north = geodetic_to_ned(45.0 + 1.0 / 60.0, 0.0, 0.0, (45.0, 0.0, 0.0))
    assert north[0] == pytest.approx(6367381.8 * math.radians(1.0 / 60.0), abs=0.05)
    assert abs(north[1]) < 1e-6


@settings(max_examples=200, deadline=None)
@given(lats, lons, heights, st.floats(-5000, 5000), st.floats(-5000, 5000), st.floats(-300, 300))
def test_matches_pymap3d_and_round_trips(lat0, lon0, h0, n, e, d):
    origin = (lat0, lon0, h0)
    lat, lon, h = ned_to_geodetic([n, e, d], origin)
    lat_ref, lon_ref, h_ref = pymap3d.ned2geodetic(n, e, d, *origin)
    assert (lat, h) == (pytest.approx(lat_ref, abs=1e-7), pytest.approx(h_ref, abs=1e-4))
    assert (lon - lon_ref + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-7)  # +-180 is one meridian
    assert np.allclose(geodetic_to_ned(lat, lon, h, origin), [n, e, d], atol=1e-5)
    assert np.allclose(geodetic_to_ned(lat, lon, h, origin), pymap3d.geodetic2ned(lat, lon, h, *origin), atol=1e-5)


@given(lats, lons, heights)
def test_ecef_round_trip(lat, lon, h):
    back = ecef_to_geodetic(geodetic_to_ecef(lat, lon, h))
    assert back[0] == pytest.approx(lat, abs=1e-9)
    assert back[2] == pytest.approx(h, abs=1e-3)


@pytest.mark.parametrize("origin, why", [
    ((95.0, 0.0, 0.0), "latitude beyond the pole"),
    ((float("nan"), 0.0, 0.0), "NaN latitude"),
    ((0.0, 0.0), "two numbers"),
    ("home", "not numbers"),
    ((0.0, 0.0, float("inf")), "infinite height"),
])
def test_bad_origin_is_refused(origin, why):
    with pytest.raises(ValueError):
        geodetic_to_ned(0.0, 0.0, 0.0, origin)


def test_bad_ned_is_refused():
    with pytest.raises(ValueError, match="non-finite"):
        ned_to_geodetic([0.0, float("nan"), 0.0], ORIGIN)
