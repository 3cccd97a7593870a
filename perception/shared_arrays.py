"""Read-only arrays that every process of a machine builds alike, held once in the page cache.

Every camera agent draws the same procedural ground (:class:`perception.ground.GroundTexture`: the same seed,
the same pyramid of 2×2-tiled mip levels, 21 MB at the default 1024 texels). Built in each process, that is 21 MB
of private memory per agent; written once to a cache file and mapped read-only (``numpy.load(mmap_mode="r")``),
it is one copy in the kernel's page cache that the agents share, each counted ``21/N`` MB in its PSS.

The file name carries a digest of everything that decides the content (the caller's parameters and the source
text of the module that builds it), so a changed generator never reads an old file. Files are written to a
temporary name and renamed (two processes starting together each write a whole file; one wins). Where the
cache folder cannot be written (read-only, full) the process keeps its own copy: the same arrays, only not
shared. The folder is ``$SKYMESH_CACHE``, else ``$XDG_CACHE_HOME/skymesh``, else ``~/.cache/skymesh``.
"""

from __future__ import annotations

import hashlib
import logging
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

log = logging.getLogger("skymesh.perception")


def cache_folder() -> Path:
    if os.environ.get("SKYMESH_CACHE"):
        return Path(os.environ["SKYMESH_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "skymesh"


def digest(*parts) -> str:
    """A short name for ``parts`` (their ``repr``; source texts as bytes)."""
    h = hashlib.sha256()
    for part in parts:
        h.update(part if isinstance(part, bytes) else repr(part).encode())
        h.update(b"\0")
    return h.hexdigest()[:16]


def shared_arrays(name: str, count: int, build: Callable[[], list[np.ndarray]]) -> list[np.ndarray]:
    """The ``count`` arrays ``build()`` returns, mapped read-only from ``<cache>/<name>-<i>.npy`` (built and written
    there first if any is missing or unreadable), or ``build()``'s own arrays, read-only, where the cache cannot be
    written."""
    folder = cache_folder()
    paths = [folder / f"{name}-{i}.npy" for i in range(count)]
    try:
        return [np.load(path, mmap_mode="r") for path in paths]
    except (OSError, ValueError):  # missing, truncated or not an array: build it
        pass
    arrays = build()
    if len(arrays) != count:
        raise ValueError(f"{name}: built {len(arrays)} arrays, expected {count}")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for path, array in zip(paths, arrays, strict=True):
            _write(path, array)
        return [np.load(path, mmap_mode="r") for path in paths]
    except (OSError, ValueError) as err:
        log.debug("cannot cache %s in %s (%s): this process keeps its own copy", name, folder, err)
        for array in arrays:
            array.setflags(write=False)
        return arrays


def _write(path: Path, array: np.ndarray) -> None:
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            np.save(f, array)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
