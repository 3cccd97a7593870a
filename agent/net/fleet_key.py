"""The fleet key: the shared secret every process of a fleet signs and checks its messages with.

Every envelope carries an HMAC-SHA256 over its bytes made with this key (:mod:`agent.net.wire`), so a process
on the network without the key can neither inject a message nor alter one: an unsigned or wrongly signed
message is rejected (``bad_mac``) and counted. It does not hide the traffic (Zenoh's TLS does that: see the
README's threat model).

``skymesh run`` makes a new key per run (:func:`new_key_file`): 32 random bytes, hex-encoded, in a file only
its owner may read (mode 0600) in the run folder, whose path it gives to the agents, the world and the
observer (``--fleet-key-file``). The key itself is never logged, nor written to the metrics or the recording.
"""

from __future__ import annotations

import os
import secrets
import stat
from pathlib import Path

KEY_FILE = "fleet.key"  # its name in a run folder
KEY_BYTES = 32  # random bytes of a new key: the HMAC-SHA256 block's worth of entropy (chosen here)


def new_key_file(folder: Path) -> Path:
    """Create ``folder/fleet.key`` with a new random key, readable by its owner only (created 0600: never
    visible to anyone else, not even for a moment). Raises ``OSError`` if it cannot be written."""
    path = Path(folder) / KEY_FILE
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(secrets.token_hex(KEY_BYTES))
    return path


def read_key_file(path: str | Path) -> bytes:
    """The key in ``path``. Raises ``ValueError`` (naming the file, never its content) for a missing,
    unreadable or empty file, or one that others may read or write."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
        key = path.read_bytes().strip()
    except OSError as err:
        raise ValueError(f"fleet key file {path}: {err.strerror}") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise ValueError(f"fleet key file {path}: others may read or write it (mode {stat.filemode(mode)}); "
                         "chmod 600 it")
    if not key:
        raise ValueError(f"fleet key file {path} is empty")
    return key
