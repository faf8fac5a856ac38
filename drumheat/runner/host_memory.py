"""Freed large buffers given back to the system during a run (glibc's mmap threshold).

glibc's ``malloc`` gives a request above its mmap threshold a mapping of its own, which goes
back to the system when it is freed. Its threshold is dynamic, though: when such a block is
freed, the threshold rises to that block's size (up to 32 MiB on 64-bit systems), and from then
on requests of that size come from its heap, whose freed parts it keeps. A run's large buffers
are of that kind: the arrays of the state a set-up builds and drops, the host copies made
between chunks, the neighbour rebuild's scratch, XLA's temporaries of a chunk on the CPU. With
the dynamic threshold the process keeps what it freed, and the resident memory of a run grows
beyond what it holds (docs/performance.md, "Memory").

:func:`return_large_buffers` fixes the threshold at :data:`MMAP_THRESHOLD` (glibc's
``mallopt(M_MMAP_THRESHOLD)``, which also ends the dynamic adjustment), so that every freed
buffer of at least that size goes back to the system at once. :func:`drumheat.run` calls it
before a run. The setting holds for the rest of the process (glibc has no way back to the
dynamic threshold); it changes where large blocks come from, not what a program computes.
Where the user has set glibc's own ``MALLOC_MMAP_THRESHOLD_``, that choice stands and nothing is
changed; on other C libraries and systems nothing is changed either.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import os
import sys

__all__ = ["return_large_buffers", "MMAP_THRESHOLD"]

#: the mmap threshold set, bytes: blocks of at least this size get mappings of their own
MMAP_THRESHOLD = 1 << 20

#: glibc's mallopt parameter number of M_MMAP_THRESHOLD (malloc.h)
_M_MMAP_THRESHOLD = -3

@functools.cache  # once per process: the first call's outcome holds
def return_large_buffers() -> bool:
    """Fix glibc's mmap threshold at :data:`MMAP_THRESHOLD` for this process (idempotent).

    Returns whether the threshold is fixed so now: False where the C library is not glibc,
    where ``mallopt`` refuses, or where ``MALLOC_MMAP_THRESHOLD_`` is set in the environment
    (the user's own setting is kept).
    """
    return _set_threshold()


def _set_threshold() -> bool:
    if not sys.platform.startswith("linux") or "MALLOC_MMAP_THRESHOLD_" in os.environ:
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
        libc.gnu_get_libc_version  # glibc only: other C libraries number mallopt otherwise
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
