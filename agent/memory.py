"""An agent process's memory policy: large temporaries go back to the system when they are freed.

glibc's ``malloc`` serves blocks of ``M_MMAP_THRESHOLD`` bytes and more (128 kB at start) with ``mmap``, returned
to the system on ``free``. But by default it raises that threshold to the size of every such block freed (up
to 32 MB), so that after the first few-megabyte temporaries — noise banks, a ground texture's pyramid — blocks
of several megabytes are carved from the heap instead, and freed there, where the heap cannot give back what
lies below a block still in use. A camera agent's heap grew to 76 MB of private memory that way (a 2-agent
live run of the default scenario, ``/proc/PID/smaps`` after 20 s). Setting the threshold explicitly turns the
adjustment off (``mallopt(3)``: "setting this parameter disables the dynamic adjustment"); :data:`MMAP_THRESHOLD`
says where. Same effect as starting the process with ``MALLOC_MMAP_THRESHOLD_=4194304``, but it holds however
the agent is started (``skymesh run``, the test bed, by hand on a companion computer).
"""

from __future__ import annotations

import ctypes
import ctypes.util

M_MMAP_THRESHOLD = -3  # glibc's malloc.h
#: bytes: above a frame and its working images (~1 MB at 640×480: kept in the heap, where the next frame reuses
#: them), below the megabytes-large temporaries (mapped, and unmapped when freed). Measured on a 2-agent live run:
#: private memory 63 MB at 4 MB as at 128 kB (glibc's start), 85 MB without a fixed threshold; CPU per step
#: 8.3-8.9 ms at 4 MB as without, 10.4-11.3 ms at 128 kB (every frame's arrays mapped and zero-filled anew).
MMAP_THRESHOLD = 4 * 1024 * 1024


def fix_mmap_threshold(threshold: int = MMAP_THRESHOLD) -> bool:
    """``mallopt(M_MMAP_THRESHOLD, threshold)``: ``True`` if glibc took it, ``False`` where there is no glibc
    (musl, macOS: their allocators have no such adjustment to turn off)."""
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        mallopt = ctypes.CDLL(name).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return mallopt(M_MMAP_THRESHOLD, threshold) == 1
