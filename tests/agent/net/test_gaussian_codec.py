"""agent.net.gaussian_codec: Gaussian and trajectory payload round trips, one test per class of bad
payload (each with its reason), the block-tridiagonal property behind the trajectory codec, and fuzzing
that the decoders raise only DecodeError."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from agent.net.gaussian_codec import decode_gaussian, decode_trajectory, encode_gaussian, encode_trajectory
from agent.net.wire import DecodeError, decode, encode
from fusion.gaussian import Gaussian
from fusion.trajectory import Trajectory
from tests.agent.net.builders import (
    FUZZ,
    MODEL,
    envelope,
    leaves,
    only_decode_errors,
    random_gaussian,
    random_trajectory,
)


def payload_reason(fn, *args) -> str:
    with pytest.raises(DecodeError) as info:
        fn(*args)
    return info.value.reason


# -- round trips -------------------------------------------------------------------------------------
def test_gaussian_payload_round_trip_is_bit_exact():
    g = random_gaussian(np.random.default_rng(2))
    out = decode_gaussian(decode(encode(envelope(encode_gaussian(g)))).payload, dim=6)
    assert np.array_equal(out.y, g.y) and np.array_equal(out.Y, g.Y)


def test_zero_information_gaussian_round_trips():
    out = decode_gaussian(decode(encode(envelope(encode_gaussian(Gaussian.zeros(4))))).payload)
    assert not out.has_information and out.dim == 4


def test_trajectory_payload_round_trip():
    t = random_trajectory(np.random.default_rng(3))
    out = decode_trajectory(decode(encode(envelope(encode_trajectory(t)))).payload, MODEL)
    assert out.epoch == t.epoch and out.model == MODEL
    assert np.array_equal(out.y, t.y)
    np.testing.assert_allclose(out.Y, t.Y, rtol=0, atol=1e-12 * np.max(np.abs(t.Y)))
    assert np.array_equal(out.Y, out.Y.T)


# -- rejected beliefs: Gaussian ----------------------------------------------------------------------
def _gaussian_payload(n: int = 3) -> dict:
    return encode_gaussian(random_gaussian(np.random.default_rng(7), n))


def test_a_gaussian_payload_that_is_not_a_map_is_bad_type():
    assert payload_reason(decode_gaussian, [1, 2]) == "bad_type"


def test_a_gaussian_payload_with_a_missing_or_unknown_key_is_bad_field():
    d = _gaussian_payload()
    assert payload_reason(decode_gaussian, {"y": d["y"]}) == "bad_field"
    assert payload_reason(decode_gaussian, {**d, "extra": 1}) == "bad_field"


def test_gaussian_arrays_that_are_lists_or_integer_arrays_are_bad_type():
    d = _gaussian_payload()
    assert payload_reason(decode_gaussian, {**d, "y": d["y"].tolist()}) == "bad_type"
    assert payload_reason(decode_gaussian, {**d, "Y": d["Y"].astype("<i8")}) == "bad_type"


@pytest.mark.parametrize(
    "y_shape, Y_shape, dim",
    [((3, 1), (3, 3), None), ((3,), (3, 4), None), ((3,), (4, 4), None), ((3,), (9,), None), ((0,), (0, 0), None),
     ((3,), (3, 3), 4)],
    ids=["y-2d", "Y-not-square", "Y-too-big", "Y-flat", "empty", "dim-mismatch"],
)  # fmt: skip
def test_gaussian_arrays_of_the_wrong_shape_are_bad_shape(y_shape, Y_shape, dim):
    d = {"y": np.zeros(y_shape), "Y": np.zeros(Y_shape)}
    assert payload_reason(decode_gaussian, d, dim) == "bad_shape"


@pytest.mark.parametrize("where", ["y", "Y"])
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_nan_or_inf_in_a_gaussian_is_non_finite(where, value):
    d = _gaussian_payload()
    d[where] = d[where].copy()
    d[where].flat[1] = value
    assert payload_reason(decode_gaussian, d) == "non_finite"


def test_a_non_symmetric_information_matrix_is_indefinite():
    d = _gaussian_payload()
    d["Y"] = d["Y"].copy()
    d["Y"][0, 1] += 1e-6 * np.max(np.abs(d["Y"]))
    assert payload_reason(decode_gaussian, d) == "indefinite"


def test_an_asymmetry_within_the_tolerance_is_accepted_and_symmetrised_exactly():
    d = _gaussian_payload()
    d["Y"] = d["Y"].copy()
    d["Y"][0, 1] += 1e-12
    Y = decode_gaussian(d).Y
    assert np.array_equal(Y, Y.T)


def test_a_symmetric_information_matrix_with_a_negative_eigenvalue_is_indefinite():
    d = {"y": np.zeros(3), "Y": np.diag([1.0, 2.0, -1e-3])}
    assert payload_reason(decode_gaussian, d) == "indefinite"


def test_an_information_matrix_near_the_float_limit_is_rejected_quietly():
    """Values whose differences overflow must give a DecodeError, not a warning or an exception."""
    d = {"y": np.zeros(2), "Y": np.array([[1e308, -1.7e308], [1.7e308, 1e308]])}
    with np.errstate(all="raise"):
        assert payload_reason(decode_gaussian, d) == "indefinite"


def test_a_rejected_gaussian_payload_is_left_unchanged():
    d = _gaussian_payload()
    d["Y"] = d["Y"].copy()
    d["Y"][0, 1] += 1.0
    snapshot = {k: v.copy() for k, v in d.items()}
    payload_reason(decode_gaussian, d)
    assert all(np.array_equal(d[k], snapshot[k]) for k in d)


# -- rejected beliefs: trajectory --------------------------------------------------------------------
def _trajectory_payload() -> dict:
    return encode_trajectory(random_trajectory(np.random.default_rng(8)))


def test_a_trajectory_payload_with_a_missing_key_is_bad_field():
    d = _trajectory_payload()
    del d["off"]
    assert payload_reason(decode_trajectory, d, MODEL) == "bad_field"


@pytest.mark.parametrize("key, value", [("epoch", 3.0), ("epoch", True), ("n", "6"), ("L", None)])
def test_trajectory_integers_of_the_wrong_type_are_bad_type(key, value):
    d = _trajectory_payload()
    d[key] = value
    assert payload_reason(decode_trajectory, d, MODEL) == "bad_type"


@pytest.mark.parametrize(
    "key, value",
    [("n", 4), ("L", 10), ("y", np.zeros(47)), ("diag", np.zeros((8, 6, 5))), ("off", np.zeros((8, 6, 6))),
     ("off", np.zeros((7, 36)))],
    ids=["n-not-model", "L-not-model", "y-short", "diag-blocks", "off-count", "off-flat"],
)  # fmt: skip
def test_trajectory_dimensions_that_do_not_match_the_model_are_bad_shape(key, value):
    d = _trajectory_payload()
    d[key] = value
    assert payload_reason(decode_trajectory, d, MODEL) == "bad_shape"


@pytest.mark.parametrize("key", ["y", "diag", "off"])
def test_nan_in_a_trajectory_array_is_non_finite(key):
    d = _trajectory_payload()
    d[key] = d[key].copy()
    d[key].flat[-1] = math.nan
    assert payload_reason(decode_trajectory, d, MODEL) == "non_finite"


@pytest.mark.parametrize("value", [math.inf, -math.inf])
@pytest.mark.parametrize("key", ["y", "diag", "off"])
def test_an_infinity_in_a_trajectory_array_is_non_finite(key, value):
    d = _trajectory_payload()
    d[key] = d[key].copy()
    d[key].flat[0] = value
    assert payload_reason(decode_trajectory, d, MODEL) == "non_finite"


def test_a_trajectory_near_the_float_limit_is_rejected_quietly():
    """A diagonal block holding +-1.7e308 across its diagonal: the asymmetry overflows, and must give a DecodeError,
    not a floating-point warning."""
    d = _trajectory_payload()
    d["diag"] = d["diag"].copy()
    d["diag"][1, 0, 1], d["diag"][1, 1, 0] = 1.7e308, -1.7e308
    with np.errstate(all="raise"):
        assert payload_reason(decode_trajectory, d, MODEL) == "indefinite"


def test_an_asymmetric_diagonal_block_is_indefinite():
    d = _trajectory_payload()
    d["diag"] = d["diag"].copy()
    d["diag"][2, 0, 1] += 1.0
    assert payload_reason(decode_trajectory, d, MODEL) == "indefinite"


def test_off_diagonal_blocks_too_large_for_the_diagonal_are_indefinite():
    d = _trajectory_payload()
    d["off"] = d["off"] * 100.0
    assert payload_reason(decode_trajectory, d, MODEL) == "indefinite"


# -- the block-tridiagonal property ------------------------------------------------------------------
_ops = st.lists(
    st.tuples(st.sampled_from(["advance", "update_a", "update_b", "fuse", "intersect"]), st.integers(0, 7)),
    min_size=1,
    max_size=25,
)


@settings(max_examples=60, deadline=None)
@given(ops=_ops, seed=st.integers(0, 2**32 - 1))
def test_trajectory_information_stays_exactly_block_tridiagonal(ops, seed):
    """After random advances (Schur on the oldest state), updates at any offset, fuse and intersect,
    the dense information matrix equals the one rebuilt from the sent band, to 1e-12."""
    rng = np.random.default_rng(seed)
    a = b = Trajectory.prior(MODEL, epoch=0)
    for op, arg in ops:
        if op == "advance":
            a, b = a.advanced_to(a.epoch + 1 + arg % 3), b.advanced_to(b.epoch + 1 + arg % 3)
        elif op.startswith("update"):
            H = rng.standard_normal((3, 6))
            R_inv = np.diag(rng.uniform(0.1, 100.0, 3))
            t = (a if op == "update_a" else b).update(H, R_inv, rng.standard_normal(3), offset=arg)
            a, b = (t, b) if op == "update_a" else (a, t)
        elif op == "fuse":
            a = a.fuse(b)
        else:
            a = a.intersect(b, arg / 7.0)
    for t in (a, b):
        n, L = MODEL.state_dim, MODEL.window
        band = np.kron(np.abs(np.subtract.outer(np.arange(L), np.arange(L))) <= 1, np.ones((n, n)))
        assert np.all(t.Y[band == 0] == 0.0)  # outside the band: exact zeros
        rebuilt = decode_trajectory(encode_trajectory(t), MODEL)
        assert np.max(np.abs(rebuilt.Y - t.Y)) <= 1e-12 * max(1.0, np.max(np.abs(t.Y)))
        assert np.array_equal(rebuilt.y, t.y)


def test_encode_trajectory_refuses_a_matrix_outside_the_band():
    t = random_trajectory(np.random.default_rng(9))
    Y = t.Y.copy()
    Y[0, -1] = Y[-1, 0] = 1e-3
    with pytest.raises(ValueError, match="block-tridiagonal"):
        encode_trajectory(Trajectory(t.y, Y, t.epoch, MODEL))


_float_arrays = hnp.arrays(
    dtype=st.sampled_from(["<f8", "<f4"]),
    shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=9),
    elements=st.floats(allow_nan=True, allow_infinity=True, width=32),
)


@FUZZ
@given(
    payload=st.dictionaries(
        st.sampled_from(["y", "Y", "epoch", "n", "L", "diag", "off"]),
        _float_arrays | st.integers(-(2**63), 2**64 - 1) | leaves,
        max_size=7,
    ),
)
def test_fuzz_belief_payloads_with_arbitrary_arrays_only_raise_decode_error(payload):
    """The belief codecs, fed directly (as after a valid envelope), reject only with DecodeError."""
    for d in (payload, {**_trajectory_payload(), **payload}, {**_gaussian_payload(), **payload}):
        only_decode_errors(decode_gaussian, d)
        only_decode_errors(decode_gaussian, d, 3)
        only_decode_errors(decode_trajectory, d, MODEL)
