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
from mesh_sim import cli

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


def _one_line(err: str) -> str:
    """The single line of ``err``, asserting it is one and no traceback."""
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err.strip()


def _run(capsys, out: Path, *args: str) -> tuple[int, str]:
    """``skymesh run --lockstep --rerun off --duration 2 --out OUT ARGS``: its exit code and its one stderr line."""
    code = cli.main(["run", "--lockstep", "--rerun", "off", "--duration", "2", "--out", str(out), *args])
    return code, _one_line(capsys.readouterr().err)


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


# -- the output folder -----------------------------------------------------------------------------------------
def test_a_read_only_output_folder_is_one_line_naming_it(tmpfs, capsys):
    """Bad input: ``--out`` inside a read-only tmpfs."""
    out = tmpfs("ro", "ro,size=64k") / "runs"
    code, line = _run(capsys, out)
    assert code == 2
    assert line == f"skymesh run: {out}: cannot create a run folder here: Read-only file system"


def test_an_output_folder_under_a_regular_file_is_one_line_naming_it(tmp_path, capsys):
    """Bad input: ``--out FILE/runs`` where FILE is a regular file."""
    (tmp_path / "a-file").write_text("")
    out = tmp_path / "a-file" / "runs"
    code, line = _run(capsys, out)
    assert code == 2 and line == f"skymesh run: {out}: cannot create a run folder here: Not a directory"


@pytest.mark.slow  # a lockstep run of 2 s
def test_a_full_disk_is_one_line_and_leaves_no_half_written_run(tmpfs, capsys):
    """Bad input: ``--out`` on a 32 KiB tmpfs: the agents' and the world's JSON fit, metrics.json does not.
    The line names the file; the run folder is removed, with no partial metrics.json or temporary file."""
    out = tmpfs("full", "size=32k")
    code, line = _run(capsys, out)
    assert code == 2
    assert line.startswith(f"skymesh run: {out}/default-") and line.endswith("/metrics.json: No space left on device")
    assert list(out.iterdir()) == []
