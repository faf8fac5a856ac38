"""Fetching (possibly sharded) device arrays to the host, in one process or several."""

from __future__ import annotations

import jax
import numpy as np

__all__ = ["to_host"]


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
