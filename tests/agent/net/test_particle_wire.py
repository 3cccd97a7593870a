"""Particle beliefs on the wire: the thesis's message size (≈ 6400 bytes for 200 particles x 4 doubles, Merino
§5.4.1), exact round trips, the compressed form, and strict validation of received payloads."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.net import particle_wire as pw
from agent.net import wire
from agent.net.wire import DecodeError
from fusion.mixture import GaussianMixture
from fusion.particles import ParticleSet

KINDS = wire.KINDS | {pw.KIND}


def weighted_set(n=200, d=3, seed=1) -> ParticleSet:
    rng = np.random.default_rng(seed)
    return ParticleSet.from_unnormalised(rng.normal(size=(n, d)) * 10.0 + 100.0, rng.random(n))


def envelope_bytes(payload: dict) -> bytes:
    env = wire.Envelope(kind=pw.KIND, origin="uav-2", seq=41, stamp=12.5, acks={"uav-1": 7}, payload=payload)
    return wire.encode(env, kinds=KINDS)


# -- size -------------------------------------------------------------------------------------------------
def test_200_particles_of_4_doubles_are_about_6400_bytes():
    ps = weighted_set(200, 3)
    payload = pw.encode_particles(ps)
    assert len(payload["x"]) + len(payload["w"]) == 200 * 4 * 8 == 6400
    assert 6400 <= pw.payload_bytes(payload) <= 6700
    assert 6400 <= len(envelope_bytes(payload)) <= 6700  # the whole message, envelope included


@pytest.mark.parametrize(("n", "d"), [(1, 1), (200, 2), (500, 3), (2000, 3), (300, 6)])
def test_full_set_size_is_n_times_d_plus_one_doubles_plus_a_small_constant(n, d):
    payload = pw.encode_particles(weighted_set(n, d))
    overhead = pw.payload_bytes(payload) - 8 * n * (d + 1)
    assert 0 < overhead <= 32


def test_compressed_form_is_much_smaller_and_keeps_the_moments():
    ps = weighted_set(200, 3)
    payload = pw.encode_compressed(ps, 8, np.random.default_rng(2))
    size = pw.payload_bytes(payload)
    assert size == pytest.approx(pw.mixture_bytes(payload["k"], 3), abs=40) and payload["k"] == 8
    assert size < 6400 / 8
    gm = pw.decode_particle_belief(payload, dim=3)
    assert isinstance(gm, GaussianMixture)
    np.testing.assert_allclose(gm.mean(), ps.mean(), rtol=1e-10)
    np.testing.assert_allclose(gm.cov(), ps.cov(), rtol=1e-8)


# -- round trips ---------------------------------------------------------------------------------------------
def test_full_set_round_trip_through_the_envelope_is_exact():
    ps = weighted_set(200, 3)
    env = wire.decode(envelope_bytes(pw.encode_particles(ps)), kinds=KINDS, expected_origin="uav-2")
    out = pw.decode_particle_belief(env.payload, dim=3)
    assert isinstance(out, ParticleSet)
    np.testing.assert_array_equal(out.states, ps.states)
    np.testing.assert_array_equal(out.weights, ps.weights)


def test_mixture_round_trip_is_exact():
    rng = np.random.default_rng(3)
    gm = GaussianMixture.from_particles(weighted_set(300, 4), 5, rng)
    env = wire.decode(envelope_bytes(pw.encode_mixture(gm)), kinds=KINDS)
    out = pw.decode_mixture(env.payload, dim=4)
    np.testing.assert_array_equal(out.weights, gm.weights)
    np.testing.assert_array_equal(out.means, gm.means)
    np.testing.assert_array_equal(out.covs, gm.covs)


def test_byte_budget_picks_the_full_set_or_the_largest_mixture_that_fits():
    rng = np.random.default_rng(4)
    ps = weighted_set(200, 3)
    assert pw.encode_for_budget(ps, 7000, rng)["f"] == "set"
    small = pw.encode_for_budget(ps, 1000, rng)
    assert small["f"] == "gmm" and pw.payload_bytes(small) <= 1000
    assert pw.payload_bytes(pw.encode_compressed(ps, small["k"] + 1, rng)) > 1000  # the largest that fits
    with pytest.raises(ValueError, match="not hold even one"):
        pw.encode_for_budget(ps, 60, rng)  # budget below one component
    with pytest.raises(ValueError, match="positive integer"):
        pw.encode_for_budget(ps, 0, rng)  # zero budget


def test_encoders_reject_wrong_types():
    with pytest.raises(ValueError, match="ParticleSet"):
        pw.encode_particles(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="GaussianMixture"):
        pw.encode_mixture(weighted_set())


# -- validation of received payloads -------------------------------------------------------------------------
def good_set() -> dict:
    return pw.encode_particles(ParticleSet.from_states(np.arange(6.0).reshape(3, 2)))


def good_gmm() -> dict:
    return pw.encode_mixture(GaussianMixture(np.array([0.5, 0.5]), np.zeros((2, 2)), np.stack([np.eye(2)] * 2)))


def with_(payload: dict, **changes) -> dict:
    out = dict(payload)
    for key, value in changes.items():
        if value is None:
            out.pop(key)
        else:
            out[key] = value
    return out


def doubles(*values) -> bytes:
    return struct.pack(f"<{len(values)}d", *values)


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        ([1, 2], "bad_type"),
        (with_(good_set(), w=None), "bad_field"),
        (with_(good_set(), extra=1), "bad_field"),
        (with_(good_set(), f="cloud"), "bad_field"),
        (with_(good_set(), n="3"), "bad_type"),
        (with_(good_set(), n=True), "bad_type"),
        (with_(good_set(), n=0), "bad_field"),
        (with_(good_set(), d=-2), "bad_field"),
        (with_(good_set(), n=pw.MAX_PARTICLES + 1), "oversize"),
        (with_(good_set(), d=pw.MAX_DIM + 1), "oversize"),
        (with_(good_set(), n=4), "bad_shape"),
        (with_(good_set(), x=doubles(0, 1, 2, 3, 4)), "bad_shape"),
        (with_(good_set(), x=[0.0] * 6), "bad_type"),
        (with_(good_set(), x=doubles(0, 1, float("nan"), 3, 4, 5)), "non_finite"),
        (with_(good_set(), w=doubles(0.5, 0.5, float("inf"))), "non_finite"),
        (with_(good_set(), w=doubles(0.6, 0.6, -0.2)), "bad_field"),
        (with_(good_set(), w=doubles(0.5, 0.5, 0.5)), "bad_field"),
        (with_(good_set(), w=doubles(0.0, 0.0, 0.0)), "bad_field"),
        (with_(good_gmm(), c=doubles(1, 0, 1, 1, 2, 1)), "indefinite"),
        (with_(good_gmm(), m=doubles(0, 0, float("nan"), 0)), "non_finite"),
        (with_(good_gmm(), a=doubles(0.7, 0.7)), "bad_field"),
        (with_(good_gmm(), k=pw.MAX_COMPONENTS + 1), "oversize"),
        (with_(good_gmm(), c=doubles(1, 0, 1)), "bad_shape"),
    ],
    ids=["payload-not-a-map", "missing-weights", "unknown-field", "unknown-form", "count-as-string", "count-as-bool",
         "zero-particles", "negative-dimension", "too-many-particles", "dimension-too-large",
         "count-does-not-match-bytes", "states-short-by-one-double", "states-as-list", "nan-state", "inf-weight",
         "negative-weight", "weights-sum-1.5", "all-zero-weights", "gmm-indefinite-covariance", "gmm-nan-mean",
         "gmm-weights-sum-1.4", "gmm-too-many-components", "gmm-covariances-short"],
)
def test_decode_rejects(payload, reason):
    with pytest.raises(DecodeError) as info:
        pw.decode_particle_belief(payload)
    assert info.value.reason == reason


def test_decode_rejects_a_dimension_other_than_expected():
    with pytest.raises(DecodeError) as info:
        pw.decode_particles(good_set(), dim=3)  # a 2-D set where 3-D is expected
    assert info.value.reason == "bad_shape"
    with pytest.raises(DecodeError) as info:
        pw.decode_mixture(good_set())  # a full set given to the mixture decoder
    assert info.value.reason == "bad_field"


@settings(max_examples=150, deadline=None)
@given(
    st.sampled_from(["set", "gmm"]),
    st.sampled_from(["f", "n", "k", "d", "x", "w", "a", "m", "c"]),
    st.one_of(st.none(), st.integers(-5, 10**6), st.binary(max_size=64), st.text(max_size=8), st.floats(),
              st.lists(st.integers(), max_size=3)),
)
def test_decode_raises_only_decode_errors_whatever_a_field_holds(form, key, value):
    payload = dict(good_set() if form == "set" else good_gmm())
    payload[key] = value
    try:
        out = pw.decode_particle_belief(payload)
    except DecodeError as err:
        assert err.reason in wire.REASONS
    else:
        assert isinstance(out, ParticleSet | GaussianMixture)


# -- candidate messages (agent.beliefs.particles) ----------------------------------------------------------
def candidate_payload() -> dict:
    rng = np.random.default_rng(5)
    return pw.encode_candidates({3: GaussianMixture.from_particles(weighted_set(200, 3, 1), 6, rng),
                                 11: GaussianMixture.from_particles(weighted_set(200, 3, 2), 2, rng)})


def test_candidate_message_round_trip_through_the_envelope_is_exact():
    payload = candidate_payload()
    env = wire.decode(envelope_bytes(payload), kinds=KINDS, expected_origin="uav-2")
    out = pw.decode_candidates(env.payload, 3)
    assert sorted(out) == [3, 11] and out[3].k == 6 and out[11].k == 2
    for entry in payload["candidates"]:
        sent = pw.decode_mixture(entry["b"], 3)
        np.testing.assert_array_equal(out[entry["id"]].means, sent.means)
        np.testing.assert_array_equal(out[entry["id"]].covs, sent.covs)
        np.testing.assert_array_equal(out[entry["id"]].weights, sent.weights)


def test_a_candidate_of_six_components_costs_480_bytes_of_numbers():
    payload = candidate_payload()
    assert pw.mixture_bytes(6, 3) == 480
    assert pw.payload_bytes(payload) < 480 + 160 + 2 * 60  # two candidates: numbers plus keys and headers


def _with(payload: dict, **change) -> dict:
    entries = [dict(e) for e in payload["candidates"]]
    entries[0].update(change)
    return {"candidates": entries}


@pytest.mark.parametrize("mutate, reason", [
    (lambda p: [], "bad_field"),  # not a map
    (lambda p: {**p, "extra": 1}, "bad_field"),  # an unknown field
    (lambda p: {"candidates": "x"}, "bad_type"),  # candidates not a list
    (lambda p: {"candidates": p["candidates"] * 40}, "oversize"),  # more than MAX_SHARED
    (lambda p: _with(p, id=-1), "bad_field"),  # negative id
    (lambda p: _with(p, id=True), "bad_field"),  # a bool is no id
    (lambda p: _with(p, id=11), "bad_field"),  # the same id twice
    (lambda p: {"candidates": [{"id": 1}]}, "bad_field"),  # no belief
    (lambda p: _with(p, b={**p["candidates"][0]["b"], "d": 2}), "bad_shape"),  # a 2-D belief for a 3-D state
    (lambda p: _with(p, b={**p["candidates"][0]["b"], "m": b"\x00" * 7}), "bad_shape"),  # truncated means
])
def test_decode_candidates_rejects_bad_input_with_a_reason(mutate, reason):
    with pytest.raises(DecodeError) as err:
        pw.decode_candidates(mutate(candidate_payload()), 3)
    assert err.value.reason == reason and err.value.reason in wire.REASONS


def test_encode_candidates_refuses_more_than_the_wire_holds():
    mixture = GaussianMixture(np.ones(1), np.zeros((1, 3)), np.eye(3)[None])
    with pytest.raises(ValueError, match="exceed"):
        pw.encode_candidates(dict.fromkeys(range(pw.MAX_SHARED + 1), mixture))
