"""A bad environment — an unwritable or full output folder, a port in use, a missing camera, a dead router, an
agent index the scenario has not — is one clear line on stderr and exit code 2, with no traceback and nothing
half-written (issue 16, item 5). Each test names the bad input it gives.

The folder tests mount small tmpfs file systems (read-only, or full): they need root, and are skipped without.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from agent.runtime import atomic_file

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def tmpfs(tmp_path):
    """``tmpfs(name, options)`` mounts a tmpfs at ``tmp_path/name`` and returns it; every mount is unmounted after
    the test (skipped where mounting is not allowed)."""
    mounted: list[Path] = []

    def mount(name: str, options: str) -> Path:
        path = tmp_path / name
        path.mkdir()
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)], capture_output=True,
                              text=True, check=False)
        if done.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here (root needed): {done.stderr.strip()}")
        mounted.append(path)
        return path

    try:
        yield mount
    finally:
        for path in mounted:
            subprocess.run(["umount", str(path)], check=True)


# -- writing results -------------------------------------------------------------------------------------------
def test_atomic_file_leaves_the_old_file_and_no_temporary_when_the_write_fails(tmp_path):
    """Bad input: a write that raises half-way (here a ValueError after some text)."""
    path = tmp_path / "metrics.json"
    path.write_text("old")
    with pytest.raises(ValueError), atomic_file(path) as f:
        f.write("half of the new")
        raise ValueError("the disk went away")
    assert path.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json"]
    with atomic_file(path) as f:
        f.write("new")
    assert path.read_text() == "new" and sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json"]


def test_atomic_file_on_a_full_disk_names_the_file_and_leaves_nothing(tmpfs):
    """Bad input: 64 KiB written to a 16 KiB tmpfs."""
    disk = tmpfs("full", "size=16k")
    with pytest.raises(OSError) as caught, atomic_file(disk / "oracle.json") as f:
        f.write("x" * 65536)
        f.flush()
    assert caught.value.filename == str(disk / "oracle.json") and "No space left" in caught.value.strerror
    assert list(disk.iterdir()) == []
