"""Give the memory a finished command freed back to the operating system.

glibc's malloc keeps the heap a long command (slicing, planning, loading a trajectory) grew, in
the arena of the thread that ran it, and reuses it only for allocations that fit its free
holes: from job to job a node's resident memory then creeps up (the slicer and planner nodes by
tens of MiB per cube job in the 10-minute soak) though nothing leaks. ``malloc_trim(0)`` hands
the free pages back. It briefly holds the allocator's locks, so it runs only after a command
that took long (``TRIM_AFTER_S``), never on a servo loop's beat.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
from typing import Any

TRIM_AFTER_S = 0.5  # s: a command that ran this long is followed by a trim


@functools.cache
def _libc() -> Any:
    name = ctypes.util.find_library("c")
    if not name:
        return None
    try:
        lib = ctypes.CDLL(name)
    except OSError:
        return None
    return lib if hasattr(lib, "malloc_trim") else None


def give_back() -> bool:
    """Return free heap pages to the OS (glibc); False where there is no ``malloc_trim``."""
    lib = _libc()
    if lib is None:
        return False
    lib.malloc_trim(0)
    return True
