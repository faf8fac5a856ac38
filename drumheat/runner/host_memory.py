"""Freed memory given back to the system during a run (glibc's mmap threshold; the heap after
each compilation).

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

Compiling leaves freed memory of the other kind: XLA's compiler (LLVM on the CPU) allocates and
frees many small blocks, below any mmap threshold, and glibc keeps the pages of the heap they
came from, which stay resident for the rest of the run though nothing uses them
(docs/performance.md, "Memory"). :func:`free_heap_after_compiles` (around :func:`drumheat.run` and
:func:`drumheat.run_ensemble`) hands those pages back after every compilation of the run
(:func:`give_back_free_heap`: glibc's ``malloc_trim(0)``, which gives back the unused pages
inside the heap as well as at its top; the blocks in use stay where they are). It is told of
a compilation by JAX's monitoring event :data:`COMPILE_EVENT`, which also marks a program
loaded from the persistent compilation cache.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import functools
import os
import sys
import threading

__all__ = ["return_large_buffers", "MMAP_THRESHOLD", "free_heap_after_compiles",
           "give_back_free_heap", "COMPILE_EVENT"]

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


@functools.cache
def _glibc():
    """The C library if it is glibc (on Linux), else None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.gnu_get_libc_version  # glibc only: other C libraries number mallopt otherwise
    except (OSError, AttributeError):
        return None
    return libc


def _set_threshold() -> bool:
    libc = _glibc()
    if libc is None or "MALLOC_MMAP_THRESHOLD_" in os.environ:
        return False
    mallopt = libc.mallopt
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1


#: JAX's monitoring event at the end of each compilation of a program for a backend (the
#: name of ``jax._src.dispatch.BACKEND_COMPILE_EVENT``; its duration spans
#: ``compile_or_get_cached``, so a program loaded from the persistent cache marks it too)
COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"

_lock = threading.Lock()
_active = 0  # how many free_heap_after_compiles blocks are open in this process


def give_back_free_heap() -> bool:
    """Give the pages of freed heap memory back to the system now (glibc's ``malloc_trim(0)``:
    the unused pages inside every arena's heap as well as at its top).

    Returns whether anything was given back (False where the C library is not glibc). It
    takes a few milliseconds; what is in use is not moved.
    """
    libc = _glibc()
    return bool(libc.malloc_trim(0)) if libc is not None else False


def _after_event(event, duration, *args, **kwargs):
    """JAX's listener of event durations: after a compilation, within an open
    :func:`free_heap_after_compiles`, the freed heap goes back to the system."""
    if event == COMPILE_EVENT and _active:
        give_back_free_heap()


@functools.cache  # once per process; it stays registered (and idle outside the blocks)
def _listen() -> bool:
    if _glibc() is None:
        return False
    import jax.monitoring

    jax.monitoring.register_event_duration_secs_listener(_after_event)
    return True


@contextlib.contextmanager
def free_heap_after_compiles():
    """Within this block (a decorator too), every compilation of a JAX program is followed by
    :func:`give_back_free_heap`, so that the heap XLA's compiler used and freed does not stay
    resident for the rest of the run.

    Yields whether it is in effect (glibc only; elsewhere it does nothing). Blocks may nest
    and may be open in several threads; while one is open, a compilation in any thread is
    followed by the give-back (the heap is the process's), and while none is, JAX's
    compilations are left alone. The listener it registers with ``jax.monitoring`` (once per
    process) stays registered and does nothing while no block is open.
    """
    global _active
    on = _listen()
    with _lock:
        _active += 1
    try:
        yield on
    finally:
        with _lock:
            _active -= 1
