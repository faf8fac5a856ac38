"""Fetching (possibly sharded) device arrays to the host, in one process or several; the
lengths of arrays that suit the devices' loops."""

from __future__ import annotations

import jax
import numpy as np

__all__ = ["to_host", "LENGTH_MULTIPLE", "round_length"]

#: the lengths that drumheat chooses itself for arrays that a step loops over (the pair slots of
#: a neighbour list, the blocks of the thermal pair sum) are whole multiples of this. XLA:CPU
#: cuts a long element-wise loop into equal parts for its threads; where the parts did not
#: divide the length evenly, the loop it compiled ran several times slower
#: (scripts/bench_xla_partitions.py; docs/performance.md, lengths that XLA:CPU cuts evenly)
LENGTH_MULTIPLE = 64


def round_length(k: int, multiple: int = LENGTH_MULTIPLE) -> int:
    """``k`` rounded up to a whole multiple of ``multiple`` (:data:`LENGTH_MULTIPLE`)."""
    return -(-int(k) // int(multiple)) * int(multiple)


def to_host(tree):
    """Fetch a PyTree of (possibly sharded) arrays to host NumPy arrays.

    In one process this is ``jax.device_get``. In a multi-process run (``jax.distributed``) an
    array split over the devices of several processes is not addressable from one process;
    it is then gathered to every process with
    ``jax.experimental.multihost_utils.process_allgather`` (every process must call this at
    the same point of the program).
    """
    if jax.process_count() == 1:
        return jax.device_get(tree)
    from jax.experimental import multihost_utils

    def get(a):
        if isinstance(a, jax.Array) and not a.is_fully_addressable:
            return np.asarray(multihost_utils.process_allgather(a, tiled=True))
        return jax.device_get(a)

    return jax.tree_util.tree_map(get, tree)
