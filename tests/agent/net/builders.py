"""Shared by the wire-format tests: random beliefs, envelopes around them, a check that decoding raises
only DecodeError, and leaf values for fuzzed msgpack trees."""

from __future__ import annotations

import msgpack
import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from agent.net.wire import REASONS, DecodeError, Envelope
from fusion.gaussian import Gaussian
from fusion.motion import ConstantVelocity
from fusion.trajectory import Trajectory, TrajectoryModel

MODEL = TrajectoryModel(ConstantVelocity(3, q=0.5), step=1.0, window=8)
FUZZ = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def random_gaussian(rng: np.random.Generator, n: int = 6) -> Gaussian:
    A = rng.standard_normal((n, n))
    return Gaussian.from_info(rng.standard_normal(n), A @ A.T + n * np.eye(n))


def random_trajectory(rng: np.random.Generator, steps: int = 5) -> Trajectory:
    t = Trajectory.prior(MODEL, epoch=3)
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    for _ in range(steps):
        t = t.advanced_to(t.epoch + 1).update(H, np.eye(3) * 4.0, rng.standard_normal(3), offset=int(rng.integers(8)))
    return t


def envelope(payload=None, **overrides) -> Envelope:
    fields = dict(kind="clock", origin="uav-01", seq=42, stamp=12.5, acks={"uav-02": 7, "gcs_0": 0})
    fields.update(overrides)
    return Envelope(payload={} if payload is None else payload, **fields)


def only_decode_errors(fn, *args, **kwargs):
    try:
        return fn(*args, **kwargs)
    except DecodeError as exc:
        assert exc.reason in REASONS
        assert not exc.detail.startswith("unexpected"), exc.detail  # the safety net must not be needed
        return None


leaves = (
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=20)
    | st.binary(max_size=20)
    | st.builds(msgpack.ExtType, st.integers(0, 127), st.binary(max_size=40))
    | st.builds(msgpack.Timestamp, st.integers(-(2**40), 2**40), st.integers(0, 999_999_999))
)


DELETE = object()  # in changed(): remove this key


def changed(base: dict, **changes) -> dict:
    """``base`` with keys replaced, or removed where the value is :data:`DELETE` (a bad-input builder)."""
    out = dict(base)
    for key, value in changes.items():
        if value is DELETE:
            del out[key]
        else:
            out[key] = value
    return out
