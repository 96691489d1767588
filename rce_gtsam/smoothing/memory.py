"""Return freed heap memory to the operating system.

GTSAM builds a window's factor graph and Bayes tree from many small C++ allocations (~0.2 MB per frame
at 20 nodes). When they are freed, glibc keeps the pages in its heap, still counted in the process's
resident memory, and large numpy arrays made afterwards do not reuse them. ``malloc_trim(0)`` hands them
back. A no-op where the C library is not glibc.
"""

from __future__ import annotations

import ctypes
import ctypes.util


def release_freed_memory() -> bool:
    """Call glibc's ``malloc_trim(0)``; True if it ran."""
    name = ctypes.util.find_library("c")
    try:
        trim = ctypes.CDLL(name).malloc_trim
    except (OSError, AttributeError, TypeError):
        return False
    trim(0)
    return True
