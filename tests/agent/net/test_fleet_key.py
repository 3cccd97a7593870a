"""The fleet key file: made per run with mode 0600, read back exactly, refused when unsafe or empty (the error
names the file, never the key)."""

from __future__ import annotations

import os
import stat

import pytest

from agent.net.fleet_key import KEY_BYTES, new_key_file, read_key_file


def test_a_new_key_is_random_private_and_read_back(tmp_path):
    (tmp_path / "a").mkdir()
    a = new_key_file(tmp_path / "a")
    b = new_key_file(tmp_path)
    assert stat.S_IMODE(a.stat().st_mode) == 0o600
    assert read_key_file(a) == a.read_bytes().strip() and len(read_key_file(a)) == 2 * KEY_BYTES
    assert read_key_file(a) != read_key_file(b)


def test_an_existing_key_is_never_overwritten(tmp_path):
    """Bad environment: a run folder that already holds a key (a second launcher on the same folder)."""
    new_key_file(tmp_path)
    with pytest.raises(FileExistsError):
        new_key_file(tmp_path)


@pytest.mark.parametrize("mode, content, message", [
    (0o644, b"secret", "others may read or write it"),  # world-readable: the key is no secret any more
    (0o620, b"secret", "others may read or write it"),
    (0o600, b"  \n", "is empty"),
])
def test_an_unsafe_or_empty_key_file_is_refused(tmp_path, mode, content, message):
    """Bad input: the key file's mode or content in the parameters."""
    path = tmp_path / "fleet.key"
    path.write_bytes(content)
    os.chmod(path, mode)
    with pytest.raises(ValueError, match=message) as err:
        read_key_file(path)
    assert "secret" not in str(err.value)


def test_a_missing_key_file_names_the_file(tmp_path):
    """Bad input: a path where no file is."""
    with pytest.raises(ValueError, match="no-such.key"):
        read_key_file(tmp_path / "no-such.key")
