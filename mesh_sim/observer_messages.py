"""What the ground station accepts: truth and telemetry payloads checked as strictly as an agent checks.

Every check raises :class:`agent.net.wire.DecodeError` with a reason the observer counts; nothing here logs.
"""

from __future__ import annotations

import re

import numpy as np

from agent.net import schemas, wire

SYM_RTOL = 1e-6  # position covariance symmetry tolerance, relative to its largest entry
PSD_RTOL = 1e-9  # smallest eigenvalue allowed, relative to the largest (negatives are clipped to 0)

_AGENT_ID = re.compile(schemas.AGENT_ID_PATTERN)


def _vector(value, n: int | None, name: str) -> np.ndarray:
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "fiu":
            raise wire.DecodeError("bad_type", f"{name} must be numeric")
        arr = value.astype(np.float64)
    elif isinstance(value, list | tuple) and all(
        isinstance(x, int | float) and not isinstance(x, bool) for x in value
    ):
        arr = np.asarray(value, dtype=np.float64)
    else:
        raise wire.DecodeError("bad_type", f"{name} must be a numeric array")
    if n is not None and arr.shape != (n,):
        raise wire.DecodeError("bad_shape", f"{name} has shape {arr.shape}, expected ({n},)")
    if not np.all(np.isfinite(arr)):
        raise wire.DecodeError("non_finite", f"{name} is not finite")
    return arr


def _matrix(value, name: str) -> np.ndarray:
    if not isinstance(value, np.ndarray) or value.dtype.kind != "f":
        raise wire.DecodeError("bad_type", f"{name} must be a float array")
    if not np.all(np.isfinite(value)):
        raise wire.DecodeError("non_finite", f"{name} is not finite")
    return value.astype(np.float64)


def _track_id(value) -> str:
    if isinstance(value, bool) or not isinstance(value, int | str) or (isinstance(value, str) and len(value) > 64):
        raise wire.DecodeError("bad_field", "a track or target id must be an int or a short str")
    return str(value)


def parse_truth(payload: dict) -> tuple[list[str], np.ndarray]:
    targets = payload.get("targets")
    if not isinstance(targets, list):
        raise wire.DecodeError("bad_field", "payload.targets must be a list")
    ids, positions = [], []
    for tg in targets:
        if not isinstance(tg, dict) or "position" not in tg:
            raise wire.DecodeError("bad_field", "each target needs an id and a position")
        ids.append(_track_id(tg.get("id")))
        positions.append(_vector(tg["position"], 3, "target position"))
    return ids, np.asarray(positions, dtype=np.float64).reshape(-1, 3)


def parse_telemetry(payload: dict) -> dict:
    """Checked telemetry: position (3,), bearings (k, 2), neighbours [str], tracks [(id, centre, cov3)]."""
    if "position" not in payload:
        raise wire.DecodeError("bad_field", "telemetry needs a position")
    out = {"position": _vector(payload["position"], 3, "position")}
    bearings = payload.get("bearings")
    if bearings is None:
        out["bearings"] = np.zeros((0, 2))
    else:
        b = _matrix(bearings, "bearings") if isinstance(bearings, np.ndarray) else None
        if b is None or b.ndim != 2 or b.shape[1] != 2:
            raise wire.DecodeError("bad_shape", "bearings must be a (k, 2) float array")
        out["bearings"] = b
    neighbours = payload.get("neighbours", [])
    if not isinstance(neighbours, list) or not all(isinstance(n, str) and _AGENT_ID.fullmatch(n) for n in neighbours):
        raise wire.DecodeError("bad_field", "neighbours must be a list of agent ids")
    out["neighbours"] = set(neighbours)
    tracks = payload.get("tracks", [])
    if not isinstance(tracks, list):
        raise wire.DecodeError("bad_field", "tracks must be a list")
    parsed = []
    for tr in tracks:
        if not isinstance(tr, dict) or "mean" not in tr or "cov" not in tr:
            raise wire.DecodeError("bad_field", "each track needs an id, a mean and a cov")
        tid = _track_id(tr.get("id"))
        mean = _vector(tr["mean"], None, "track mean")
        cov = _matrix(tr["cov"], "track cov")
        if mean.ndim != 1 or mean.size < 3 or cov.shape != (mean.size, mean.size):
            raise wire.DecodeError("bad_shape", f"track mean {mean.shape} and cov {cov.shape} do not match")
        p = cov[:3, :3]
        scale = max(float(np.max(np.abs(p))), 1e-300)
        if np.max(np.abs(p - p.T)) > SYM_RTOL * scale or np.linalg.eigvalsh(0.5 * (p + p.T))[0] < -PSD_RTOL * scale:
            raise wire.DecodeError("indefinite", "track position covariance is not symmetric PSD")
        parsed.append((tid, mean[:3], p))
    out["tracks"] = parsed
    rx = payload.get("bytes_rx")
    numeric = isinstance(rx, int | float) and not isinstance(rx, bool)
    out["bytes_rx"] = float(rx) if numeric and np.isfinite(rx) else None
    particles = payload.get("particles")
    p = _matrix(particles, "particles") if isinstance(particles, np.ndarray) else np.zeros((0, 3))
    if p.ndim != 2 or p.shape[1] != 3:
        raise wire.DecodeError("bad_shape", "particles must be a (k, 3) float array")
    out["particles"] = p
    vq = payload.get("video_quality")
    numeric = isinstance(vq, int | float) and not isinstance(vq, bool)
    out["video_quality"] = float(vq) if numeric and np.isfinite(vq) else None
    return out
