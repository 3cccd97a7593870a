"""Fire truth on the wire: encoding, strict decoding of bad payloads, scene fires and their rendering."""

from __future__ import annotations

import math
import zlib

import numpy as np
import pytest

from agent.net import wire
from agent.net.fire_truth import BURNING, BURNT, MAX_FIRE_CELLS, FireTruth, decode_fire, encode_fire
from perception.degradation import Degradation
from perception.pinhole import PinholeView
from perception.render import render_frame
from perception.terrain import FlatTerrain, HillsTerrain
from tests.agent.net.builders import DELETE, changed


def sample_state(rows=6, cols=8) -> np.ndarray:
    state = np.zeros((rows, cols), np.int8)
    state[2, 3] = BURNING
    state[2, 4] = BURNING
    state[1, 1] = BURNT
    return state


def good_payload() -> dict:
    return encode_fire((100.0, -50.0), 5.0, sample_state(), temperature_K=900.0)


def test_round_trip_through_the_wire_envelope():
    env = wire.Envelope(kind="truth", origin="world", seq=1, stamp=2.0, payload={"fire": good_payload()})
    back = wire.decode(wire.encode(env))
    truth = decode_fire(back.payload["fire"])
    assert truth.origin == (100.0, -50.0) and truth.cell == 5.0 and truth.temperature_K == 900.0
    np.testing.assert_array_equal(truth.state, sample_state())
    assert truth.state.dtype == np.int8 and not truth.state.flags.writeable
    assert truth.burning.sum() == 2 and truth.burnt.sum() == 1


def test_temperature_is_optional_on_the_wire():
    payload = encode_fire((0.0, 0.0), 2.0, sample_state())
    assert "temperature_K" not in payload
    assert decode_fire(payload).temperature_K == 800.0


def test_centres_by_hand():
    truth = decode_fire(good_payload())
    c = truth.centres()
    assert c.shape == (6, 8, 2)
    np.testing.assert_allclose(c[0, 0], [102.5, -47.5])
    np.testing.assert_allclose(c[2, 3], [100.0 + 2.5 * 5.0, -50.0 + 3.5 * 5.0])


def test_scene_fires_one_square_per_burning_cell_with_terrain_heights():
    hills = HillsTerrain(amplitude=10.0, wavelength=80.0, seed=2)
    truth = decode_fire(good_payload(), hills)
    fires = truth.scene_fires()
    assert len(fires) == 2
    for fire, (n, e) in zip(fires, [(112.5, -32.5), (112.5, -27.5)], strict=True):
        np.testing.assert_allclose(fire.region, [n, e, -hills.height(n, e)])
        assert fire.size_m == 5.0 and fire.temperature_K == 900.0
    flat = truth.scene_fires(FlatTerrain(3.0), temperature_K=700.0)  # an explicit terrain wins
    assert [f.region[2] for f in flat] == [-3.0, -3.0] and flat[0].temperature_K == 700.0
    bare = decode_fire(good_payload()).scene_fires()  # no terrain anywhere: the renderer drapes them
    assert [len(f.region) for f in bare] == [2, 2]


def test_scene_fires_render_where_the_fire_is():
    """A small down-looking thermal frame: the fire mask covers the projected burning cells, and
    nothing else (a 4 x 4 block of burning 5 m cells seen from 60 m)."""
    state = np.zeros((20, 20), np.int8)
    state[8:12, 8:12] = BURNING
    state[2:4, 2:4] = BURNT
    truth = decode_fire(encode_fire((0.0, 0.0), 5.0, state), FlatTerrain())
    view = PinholeView.look_at((50.0, 50.0, -60.0), (50.0, 50.0, 0.0), 64, 48, math.radians(60))
    frame = render_frame(view, 64, 48, fires=truth.scene_fires(), rgb=False, thermal=True,
                         degradation=Degradation(noise_sigma=0.0, thermal_noise_K=0.0), seed=0)
    assert frame.fire_mask.any()
    uv, _ = view.project(np.array([[50.0, 50.0, 0.0]]))
    u, v = np.rint(uv[0]).astype(int)
    assert frame.fire_mask[v, u]
    side_px = 20.0 * view.focal / 60.0
    assert frame.fire_mask.sum() == pytest.approx(side_px**2, rel=0.25)
    ys, xs = np.nonzero(frame.fire_mask)
    assert abs(xs.mean() - uv[0, 0]) < 1.5 and abs(ys.mean() - uv[0, 1]) < 1.5
    assert frame.thermal[frame.fire_mask].mean() > 500.0
    elsewhere = decode_fire(encode_fire((500.0, 500.0), 5.0, state)).scene_fires()  # far outside the view
    none = render_frame(view, 64, 48, fires=elsewhere, rgb=False, thermal=True, seed=0)
    assert not none.fire_mask.any()


# ---------------------------------------------------------------------------------- bad payloads


def with_(**changes) -> dict:
    return changed(good_payload(), **changes)


BAD = {
    "not a map": [1, 2, 3],
    "missing state": with_(state=DELETE),
    "missing origin": with_(origin=DELETE),
    "unknown key": {**good_payload(), "seed": 3},
    "origin of 3 numbers": with_(origin=[1.0, 2.0, 3.0]),
    "origin as a string": with_(origin="0,0"),
    "NaN origin": with_(origin=[math.nan, 0.0]),
    "infinite origin": with_(origin=[0.0, math.inf]),
    "bool in origin": with_(origin=[True, 0.0]),
    "negative cell": with_(cell=-5.0),
    "zero cell": with_(cell=0.0),
    "NaN cell": with_(cell=math.nan),
    "cell as a string": with_(cell="5"),
    "shape of one dim": with_(shape=[48]),
    "shape of floats": with_(shape=[6.0, 8.0]),
    "zero rows": with_(shape=[0, 8]),
    "negative cols": with_(shape=[6, -8]),
    "too many cells": with_(shape=[MAX_FIRE_CELLS, 2]),
    "shape not matching the bytes": with_(shape=[6, 7]),
    "shape smaller than the bytes": with_(shape=[2, 2]),
    "state as a list": with_(state=[0] * 48),
    "state not zlib": with_(state=b"\x00" * 48),
    "state truncated": with_(state=zlib.compress(bytes(48))[:-3]),
    "state with trailing bytes": with_(state=zlib.compress(bytes(48)) + b"xx"),
    "state value 3": with_(state=zlib.compress(bytes([3] * 48))),
    "state value -1": with_(state=zlib.compress(np.full(48, -1, np.int8).tobytes())),
    "zip bomb": with_(state=zlib.compress(bytes(10_000_000))),
    "negative temperature": with_(temperature_K=-1.0),
    "NaN temperature": with_(temperature_K=math.nan),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_payload_is_rejected_as_bad_fire(name):
    with pytest.raises(wire.DecodeError) as info:
        decode_fire(BAD[name])
    assert info.value.reason == "bad_fire"


def test_terrain_without_height_is_a_caller_error():
    with pytest.raises(ValueError, match="terrain") as info:
        decode_fire(good_payload(), terrain=object())  # not a terrain
    assert not isinstance(info.value, wire.DecodeError)


@pytest.mark.parametrize(
    "args",
    [
        ((0.0, 0.0), 5.0, np.full((3, 3), 3)),  # state value 3
        ((0.0, 0.0), 5.0, np.zeros(9, int)),  # 1-D state
        ((0.0, 0.0), 5.0, np.zeros((3, 3))),  # float state
        ((0.0, 0.0), 0.0, np.zeros((3, 3), int)),  # zero cell
        ((0.0, math.nan), 5.0, np.zeros((3, 3), int)),  # NaN origin
        ((0.0,), 5.0, np.zeros((3, 3), int)),  # origin of one number
    ],
)
def test_encoding_a_bad_grid_raises(args):
    with pytest.raises(ValueError):
        encode_fire(*args)
    with pytest.raises(ValueError):
        FireTruth(*args)
