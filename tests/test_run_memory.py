"""What a run keeps in memory (docs/performance.md, "Memory").

A chunk advanced in place keeps nothing of the state it started from, its cleared accumulators
included; the switch to the cyclic replay frees the coupled DEM's mechanics before it assembles
the replay, keeping the temperatures, the heat account and the thermal parameters; and a run
fixes glibc's mmap threshold, so that freed large buffers go back to the system, and gives the
heap's freed pages back after each compilation.
"""

import ctypes
import ctypes.util
import sys

import jax
import numpy as np
import pytest

from drumheat.motion import make_motion
from drumheat.runner import host_memory
from drumheat.runner.spill import copy_leaves

from test_resume import dem_scene

#: a short coupled DEM run that records its contacts and switches to the replay at 0.1 s
RECORDING = {"dem.record_interval": 0.05, "dem.replay_after": 0.1, "dem.replay_cycle": 0.05}


def _own(state):
    """``state`` in buffers of its own (as the run loop's chunks get it from the spill)."""
    leaves, treedef = jax.tree_util.tree_flatten(state)
    return jax.tree_util.tree_unflatten(treedef, copy_leaves(leaves))


def test_a_chunk_in_place_keeps_nothing_of_its_start():
    """The chunk's start (the recording's and the output interval's accumulators cleared) is
    made in the buffers of the given state too, so that no array of it outlives the chunk; the
    numbers are those of the chunk that keeps its start."""
    motion = make_motion(dem_scene(**RECORDING))
    start = _own(motion.initial_state())
    leaves = jax.tree_util.tree_leaves(start)
    assert start.extra.pair.rec_time is not None  # the accumulators the start clears
    end = motion.advance_in_place(start, 0.0, 0.05)
    alive = [x.shape for x in leaves if x.ndim > 0 and not x.is_deleted()]
    assert alive == []
    ref = motion.advance(motion.initial_state(), 0.0, 0.05)
    for a, b in zip(jax.tree_util.tree_leaves(end), jax.tree_util.tree_leaves(ref)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_the_switch_to_the_replay_frees_the_mechanics():
    motion = make_motion(dem_scene(**RECORDING))
    state = motion.initial_state()
    log = motion.start_log(state)
    for t0, t1 in ((0.0, 0.05), (0.05, 0.1)):
        state = motion.advance(state, t0, t1)
        seen = jax.device_get(state.position)  # a host copy made before the switch
        T = np.asarray(state.extra.T).copy()
        dem, (state, log) = state, motion.between(state, log, t1)
    assert isinstance(state, dict)  # the replay's state
    np.testing.assert_array_equal(np.asarray(state["T"]), T)
    assert not any(x.is_deleted() for x in jax.tree_util.tree_leaves(state["model"]))
    for x in (dem.position, dem.velocity, dem.pair_spring, dem.nbrs.idx, dem.extra.pair.time):
        assert x.is_deleted()
    assert np.all(np.isfinite(seen))  # host copies stay valid
    end = motion.advance(state, 0.1, 0.15)  # the replay runs on
    assert np.all(np.isfinite(np.asarray(end["T"])))


def _glibc(*names) -> bool:
    """Whether the C library is glibc (with the functions ``names``)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        for name in ("gnu_get_libc_version",) + names:
            getattr(libc, name)
    except (OSError, AttributeError):
        return False
    return True


def test_the_mmap_threshold_is_fixed_where_glibc_is(monkeypatch):
    monkeypatch.delenv("MALLOC_MMAP_THRESHOLD_", raising=False)
    assert host_memory._set_threshold() == (sys.platform.startswith("linux") and _glibc())


def test_a_users_own_mmap_threshold_is_kept(monkeypatch):
    monkeypatch.setenv("MALLOC_MMAP_THRESHOLD_", "65536")
    assert host_memory._set_threshold() is False


def _mapped_mib(fix: bool) -> float:
    """MiB that glibc serves with mappings of their own (``mallinfo2().hblkhd``, the blocks it
    gives back to the system when freed) for a 2 MiB array in a fresh process, after a 16 MiB
    array was freed (which raises glibc's dynamic threshold to 16 MiB); ``fix``: with
    :func:`~drumheat.runner.host_memory.return_large_buffers` called before the 2 MiB array."""
    import os
    import subprocess

    code = (
        "import ctypes\n"
        "import numpy as np\n"
        "from drumheat.runner.host_memory import return_large_buffers\n"
        "class Info(ctypes.Structure):\n"
        "    _fields_ = [(k, ctypes.c_size_t) for k in ('arena', 'ordblks', 'smblks', 'hblks',"
        " 'hblkhd', 'usmblks', 'fsmblks', 'uordblks', 'fordblks', 'keepcost')]\n"
        "libc = ctypes.CDLL('libc.so.6')\n"
        "libc.mallinfo2.restype = Info\n"
        "a = np.ones(2 << 20); del a\n"
        f"assert return_large_buffers() if {fix} else True\n"
        "before = libc.mallinfo2().hblkhd\n"
        "b = np.ones(1 << 18)\n"
        "print((libc.mallinfo2().hblkhd - before) / 2**20)\n")
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_MMAP_THRESHOLD_"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         check=True)
    return float(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not (sys.platform.startswith("linux") and _glibc("mallinfo2")),
                    reason="glibc 2.33 or later only")
def test_freed_large_buffers_go_back_to_the_system():
    assert _mapped_mib(fix=False) == 0  # from the heap, which keeps it when it is freed
    assert _mapped_mib(fix=True) >= 2  # a mapping of its own, unmapped when it is freed


#: glibc's malloc_trim gives the freed heap back; elsewhere the block does nothing
glibc_only = pytest.mark.skipif(not (sys.platform.startswith("linux") and _glibc("malloc_trim")),
                                reason="glibc only")


@glibc_only
def test_the_heap_goes_back_after_each_compilation_within_a_run(monkeypatch):
    """JAX tells of each compilation by the event the block listens to (a renamed event would
    leave the heap unreturned silently): inside the block a new program is followed by a
    :func:`give_back_free_heap`, outside it none is, and blocks nest."""
    calls = []
    monkeypatch.setattr(host_memory, "give_back_free_heap", lambda: calls.append(1) or True)
    x = np.arange(3.0)
    with host_memory.free_heap_after_compiles() as on:
        assert on
        with host_memory.free_heap_after_compiles():
            jax.jit(lambda v: v * 3.0 + 1.0)(x)  # a new function: compiled (or loaded)
        inner = len(calls)
        jax.jit(lambda v: v * 5.0 - 2.0)(x)
        assert inner >= 1 and len(calls) > inner
    done = len(calls)
    jax.jit(lambda v: v * 7.0 + 4.0)(x)
    assert len(calls) == done


def _anon_given_back_mib() -> float:
    """MiB of anonymous resident memory that :func:`give_back_free_heap` gives back in a fresh
    process after 64 MiB of 64 KiB blocks (below the mmap threshold: from the heap) of which
    every other one was freed: holes inside the heap, which glibc keeps resident by itself."""
    import subprocess

    code = (
        "import ctypes\n"
        "from drumheat.runner.host_memory import give_back_free_heap, return_large_buffers\n"
        "def anon():\n"
        "    for line in open('/proc/self/status'):\n"
        "        if line.startswith('RssAnon:'):\n"
        "            return int(line.split()[1]) / 1024\n"
        "return_large_buffers()\n"
        "libc = ctypes.CDLL('libc.so.6')\n"
        "libc.malloc.restype = ctypes.c_void_p\n"
        "libc.memset.argtypes = (ctypes.c_void_p, ctypes.c_int, ctypes.c_size_t)\n"
        "libc.free.argtypes = (ctypes.c_void_p,)\n"
        "blocks = [libc.malloc(1 << 16) for _ in range(1024)]\n"
        "for b in blocks:\n"
        "    libc.memset(b, 1, 1 << 16)\n"
        "for b in blocks[::2]:\n"
        "    libc.free(b)\n"
        "before = anon()\n"
        "assert give_back_free_heap()\n"
        "print(before - anon())\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    return float(out.stdout.strip().splitlines()[-1])


@glibc_only
def test_the_freed_heap_goes_back_to_the_system():
    assert _anon_given_back_mib() > 24  # of the 32 MiB freed inside the heap
