"""Bearings on the wire, for the flood policy: one ``(k, 9)`` float64 array per batch of detections.

Row layout: ``[t, sensor_n, sensor_e, sensor_d, azimuth, elevation, R_aa, R_ae, R_ee]`` — the time of the
detection [s], the camera position in NED [m], the bearing in NED [rad] and its 2x2 covariance
[rad^2] (:class:`agent.sensors.bearing.Bearing`; the simulation label never travels). 72 bytes per
detection, against ~4.8 kB for an 8-state trajectory belief.
"""

from __future__ import annotations

import numpy as np

from agent.net.wire import DecodeError
from agent.sensors.bearing import Bearing

COLUMNS = 9
MAX_ROWS = 256  # detections in one batch; a camera frame holds a few (chosen here)


def encode_bearings(bearings: list[Bearing]) -> np.ndarray:
    return np.array([[b.t, *b.sensor, *b.azel, b.R[0, 0], b.R[0, 1], b.R[1, 1]] for b in bearings], float)


def check_bearings(rows) -> list[list[float]]:
    """The rows of a received array as plain floats; ``DecodeError("bad_field")`` naming the fault if it is not a
    ``(k, 9)`` finite float array of at most :data:`MAX_ROWS` rows with positive-definite covariances."""
    if not isinstance(rows, np.ndarray) or rows.dtype != np.float64 or rows.ndim != 2 or rows.shape[1] != COLUMNS:
        raise DecodeError("bad_field", f"bearings must be a (k, {COLUMNS}) float64 array")
    if not 1 <= rows.shape[0] <= MAX_ROWS:
        raise DecodeError("bad_field", f"a batch holds 1 to {MAX_ROWS} bearings, got {rows.shape[0]}")
    if not np.isfinite(rows).all():
        raise DecodeError("bad_field", "bearings must be finite")
    table = rows.tolist()  # a batch holds a few rows and comes with every message: plain floats beat ufuncs here
    if not all(r[6] > 0 and r[6] * r[8] - r[7] * r[7] > 0 for r in table):
        raise DecodeError("bad_field", "a bearing covariance is not positive definite")
    return table


def bearings_from_table(table: list[list[float]]) -> list[Bearing]:
    """:class:`Bearing` objects from rows :func:`check_bearings` accepted (each owns its arrays)."""
    return [Bearing(r[0], np.array(r[1:4]), np.array(r[4:6]), np.array([[r[6], r[7]], [r[7], r[8]]]))
            for r in table]
