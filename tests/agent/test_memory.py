"""An agent's memory policy (agent.memory): after a large temporary, arrays of several megabytes are still
mapped on their own, not carved from a heap that keeps them."""

from __future__ import annotations

import subprocess
import sys

import pytest

from agent.memory import MMAP_THRESHOLD

PROBE = """
import sys
import numpy as np
from agent.memory import fix_mmap_threshold
if sys.argv[1] == "fixed":
    assert fix_mmap_threshold()
big = np.ones(2 * 8 * 2**20 // 8)  # a 16 MB temporary (a noise bank, a ground pyramid) ...
del big  # ... freed: glibc's dynamic threshold rises to 16 MB
kept = [np.ones(6 * 2**20 // 8) for _ in range(10)]  # ten 6 MB arrays alive
heap = 0
with open("/proc/self/smaps") as f:
    inside = False
    for line in f:
        if "-" in line.split()[0] and ":" not in line.split()[0]:
            inside = line.rstrip().endswith("[heap]")
        elif inside and line.startswith("Rss:"):
            heap += int(line.split()[1])
print(heap // 1024)
"""


def _heap_mb(mode: str) -> int:
    out = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True, check=True, timeout=60)
    return int(out.stdout.strip())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc and /proc/self/smaps are Linux's")
def test_with_the_threshold_fixed_large_arrays_stay_out_of_the_heap():
    """Bad input for glibc's default: a 16 MB temporary freed raises its mmap threshold, and the next 60 MB of
    6 MB arrays land in the heap (which cannot return them while a later block is in use)."""
    assert MMAP_THRESHOLD < 6 * 2**20
    assert _heap_mb("default") >= 55
    assert _heap_mb("fixed") < 20

