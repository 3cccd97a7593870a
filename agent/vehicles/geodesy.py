"""Geodetic (WGS-84 latitude, longitude, height) <-> local NED: the one place that converts (DESIGN §3).

A scenario's ``origin`` (lat0, lon0, h0) is the NED origin. The conversion goes through Earth-centred,
Earth-fixed (ECEF) coordinates, so it is exact (to floating point) at any distance, not a flat-Earth
approximation. Latitudes and longitudes are in degrees at this edge (MAVLink's GLOBAL_POSITION_INT and
HOME_POSITION carry degE7), heights in metres above the ellipsoid; NED in metres.

Equations (Groves, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation Systems*,
2nd ed., 2013, §2.4.2 and §2.4.3):

* transverse radius of curvature  R_E(L) = a / sqrt(1 - e² sin² L)                         (2.106)
* geodetic -> ECEF  x = (R_E + h) cos L cos λ,  y = (R_E + h) cos L sin λ,
  z = ((1 - e²) R_E + h) sin L                                                              (2.112)
* ECEF -> geodetic by Bowring's closed form with one refinement (2.113 ff.), below 1 mm everywhere
  between the Earth's centre region and 1000 km altitude;
* ECEF -> NED: the rotation C_e^n(L, λ) with rows north, east, down                        (2.150)
"""

from __future__ import annotations

import math

import numpy as np

from fusion.validation import as_vector

WGS84_A = 6378137.0  # semi-major axis [m]
WGS84_F = 1.0 / 298.257223563  # flattening
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared
WGS84_B = WGS84_A * (1.0 - WGS84_F)  # semi-minor axis [m]
_EP2 = WGS84_E2 / (1.0 - WGS84_E2)  # second eccentricity squared


def _check_origin(origin) -> tuple[float, float, float]:
    try:
        lat, lon, h = (float(v) for v in origin)
    except (TypeError, ValueError):
        raise ValueError(f"origin must be (lat [deg], lon [deg], height [m]), got {origin!r}") from None
    _check_lat_lon(lat, lon, h)
    return lat, lon, h


def _check_lat_lon(lat: float, lon: float, h: float) -> None:
    if not (math.isfinite(lat) and -90.0 <= lat <= 90.0):
        raise ValueError(f"latitude must be within [-90, 90] degrees, got {lat!r}")
    if not (math.isfinite(lon) and -180.0 <= lon <= 360.0):
        raise ValueError(f"longitude must be within [-180, 360] degrees, got {lon!r}")
    if not math.isfinite(h):
        raise ValueError(f"height must be finite, got {h!r}")


def geodetic_to_ecef(lat_deg: float, lon_deg: float, h: float) -> np.ndarray:
    """ECEF (3,) [m] of a geodetic point, Groves (2.106), (2.112)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    s, c = math.sin(lat), math.cos(lat)
    r_e = WGS84_A / math.sqrt(1.0 - WGS84_E2 * s * s)  # (2.106)
    return np.array([(r_e + h) * c * math.cos(lon), (r_e + h) * c * math.sin(lon), ((1.0 - WGS84_E2) * r_e + h) * s])


def ecef_to_geodetic(ecef) -> tuple[float, float, float]:
    """(lat [deg], lon [deg], h [m]) of an ECEF point: Bowring's parametric-latitude form, then one
    fixed-point refinement of the latitude with h recomputed (Groves §2.4.2)."""
    x, y, z = (float(v) for v in as_vector(ecef, "ecef", 3))
    p = math.hypot(x, y)
    lon = math.atan2(y, x)
    beta = math.atan2(z * WGS84_A, p * WGS84_B)  # parametric latitude, first guess
    lat = math.atan2(z + _EP2 * WGS84_B * math.sin(beta) ** 3, p - WGS84_E2 * WGS84_A * math.cos(beta) ** 3)
    beta = math.atan2((1.0 - WGS84_F) * math.sin(lat), math.cos(lat))  # refinement
    lat = math.atan2(z + _EP2 * WGS84_B * math.sin(beta) ** 3, p - WGS84_E2 * WGS84_A * math.cos(beta) ** 3)
    s, c = math.sin(lat), math.cos(lat)
    r_e = WGS84_A / math.sqrt(1.0 - WGS84_E2 * s * s)
    # h from whichever of p, z is better conditioned at this latitude
    h = p / c - r_e if abs(c) > 1e-3 else z / s - (1.0 - WGS84_E2) * r_e
    return math.degrees(lat), math.degrees(lon), h


def ecef_to_ned_rotation(lat_deg: float, lon_deg: float) -> np.ndarray:
    """C_e^n (3, 3): rows are the north, east and down unit vectors in ECEF, Groves (2.150)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])


def geodetic_to_ned(lat_deg: float, lon_deg: float, h: float, origin) -> np.ndarray:
    """NED (3,) [m] of a geodetic point relative to ``origin = (lat0, lon0, h0)``."""
    lat0, lon0, h0 = _check_origin(origin)
    _check_lat_lon(float(lat_deg), float(lon_deg), float(h))
    delta = geodetic_to_ecef(lat_deg, lon_deg, h) - geodetic_to_ecef(lat0, lon0, h0)
    return ecef_to_ned_rotation(lat0, lon0) @ delta


def ned_to_geodetic(ned, origin) -> tuple[float, float, float]:
    """(lat [deg], lon [deg], h [m]) of a NED point relative to ``origin = (lat0, lon0, h0)``."""
    lat0, lon0, h0 = _check_origin(origin)
    ned = as_vector(ned, "ned", 3)
    return ecef_to_geodetic(geodetic_to_ecef(lat0, lon0, h0) + ecef_to_ned_rotation(lat0, lon0).T @ ned)
