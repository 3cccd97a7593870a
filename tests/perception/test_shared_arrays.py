"""Arrays every process builds alike, mapped from one cache file (perception.shared_arrays) — and built in memory
where the cache cannot be used."""

from __future__ import annotations

import numpy as np
import pytest

from perception.ground import GroundTexture
from perception.shared_arrays import digest, shared_arrays


def _builder(calls: list):
    def build():
        calls.append(1)
        return [np.arange(12, dtype=np.uint8).reshape(3, 4), np.full((2, 2, 4), 7, np.uint8)]
    return build


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("SKYMESH_CACHE", str(folder))
    return folder


def test_the_second_process_maps_the_first_ones_file_instead_of_building(cache):
    calls = []
    first = shared_arrays("demo-1", 2, _builder(calls))
    second = shared_arrays("demo-1", 2, _builder(calls))
    assert calls == [1]  # built once
    assert all(isinstance(a, np.memmap) and not a.flags.writeable for a in second)
    assert [a.tolist() for a in first] == [a.tolist() for a in second] == [a.tolist() for a in _builder([])()]
    assert sorted(p.name for p in cache.iterdir()) == ["demo-1-0.npy", "demo-1-1.npy"]  # no temporary left


def test_an_unwritable_cache_leaves_the_process_its_own_read_only_copy(cache):
    """Bad environment: the cache folder's path is taken by a file (as a read-only or full disk, the folder
    cannot be written)."""
    cache.parent.mkdir(exist_ok=True)
    cache.write_text("not a folder")
    calls = []
    arrays = shared_arrays("demo-2", 2, _builder(calls))
    assert calls == [1]
    assert not any(isinstance(a, np.memmap) for a in arrays) and not any(a.flags.writeable for a in arrays)
    assert arrays[0].tolist() == np.arange(12).reshape(3, 4).tolist()


def test_a_truncated_cache_file_is_rebuilt(cache):
    """Bad input: a cache file cut short (a crash of another process cannot leave one — files are renamed into
    place once whole — but a disk can)."""
    shared_arrays("demo-3", 2, _builder([]))
    path = cache / "demo-3-0.npy"
    path.write_bytes(path.read_bytes()[:-5])
    calls = []
    arrays = shared_arrays("demo-3", 2, _builder(calls))
    assert calls == [1] and arrays[0].tolist() == np.arange(12).reshape(3, 4).tolist()


def test_a_builder_that_returns_the_wrong_number_of_arrays_is_an_error(cache):
    with pytest.raises(ValueError, match="built 2 arrays, expected 3"):
        shared_arrays("demo-4", 3, _builder([]))


def test_the_name_changes_with_every_part():
    assert digest("terrain", 1024, b"source") != digest("terrain", 1024, b"source!") != digest("tiles", 1024, b"source")
    assert digest("terrain", 1024) == digest("terrain", 1024)


def test_ground_textures_built_in_two_processes_share_one_pyramid(cache):
    """The ground is the same from the cache file as built (every level, texel for texel), and a second texture
    of the same parameters maps it rather than building it; another seed has its own."""
    built = GroundTexture(size_px=128)
    mapped = GroundTexture(size_px=128)
    assert [level.shape for level in built.levels] == [(256, 256, 4), (128, 128, 4)]
    assert all(isinstance(level, np.memmap) for level in mapped.levels)
    assert all(np.array_equal(a, b) for a, b in zip(built.levels, mapped.levels, strict=True))
    other = GroundTexture(size_px=128, seed=1)
    assert not np.array_equal(other.levels[0], built.levels[0])
    assert len(list(cache.glob("ground-*-0.npy"))) == 2
