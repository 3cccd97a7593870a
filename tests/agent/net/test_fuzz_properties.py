"""Property tests of the receive path on mutated envelopes of every kind (the small-budget side of ``skymesh bench
fuzz``): whatever the mutation, ``wire.decode`` raises nothing but ``DecodeError`` and ``Agent.receive`` raises
nothing at all. Hypothesis picks the kind, the mutation family, its random stream and extra byte edits."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from agent.net import wire
from agent.net.keys import Incoming
from mesh_sim.bench import fuzz
from mesh_sim.bench.fuzz_mutate import FAMILIES, Input, Mutator
from mesh_sim.bench.fuzz_seeds import CASES, cases
from tests.agent.net.builders import only_decode_errors


@pytest.fixture(scope="module")
def receivers():
    """Per kind, a case without and one with a fleet key."""
    return cases(CASES, (None, fuzz.FLEET_KEY))


edits = st.lists(st.tuples(st.integers(0, 1 << 20), st.integers(0, 255)), max_size=4)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(which=st.integers(0, 2 * len(CASES) - 1), family=st.sampled_from(FAMILIES), seed=st.integers(0, 2**32),
       byte_edits=edits)
def test_mutated_envelopes_raise_only_decode_errors_and_never_crash_the_agent(receivers, which, family, seed,
                                                                              byte_edits):
    case = receivers[which]
    inp = Mutator(case, np.random.default_rng(seed)).make(family)
    data = bytearray(inp.data)
    for where, value in byte_edits if data else ():
        data[where % len(data)] = value
    inp = Input(inp.family, inp.key, bytes(data), inp.invalid)
    origin = None if case.spec.kind == "truth" else inp.key.rsplit("/", 1)[-1]
    only_decode_errors(wire.decode, inp.data, expected_origin=origin, key=case.fleet_key, kinds=case.agent.kinds)
    rejected = case.agent.rejected.total()
    case.agent.receive(Incoming(inp.key, inp.data, 0.0), case.now)  # must not raise
    if family == "truncated" or case.fleet_key and family in ("random", "bitflip") and not byte_edits:
        assert case.agent.rejected.total() == rejected + 1, (case.spec.name, family)  # cut short, or a bad MAC
