"""Host arrays to the device without a compiled program; fetching (possibly sharded) device
arrays to the host, in one process or several; the lengths of arrays that suit the devices'
loops."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["to_device", "device_copy", "to_host", "LENGTH_MULTIPLE", "round_length"]

#: the lengths that drumheat chooses itself for arrays that a step loops over (the pair slots of
#: a neighbour list, the blocks of the thermal pair sum) are whole multiples of this. XLA:CPU
#: cuts a long element-wise loop into equal parts for its threads; where the parts did not
#: divide the length evenly, the loop it compiled ran several times slower
#: (scripts/bench_xla_partitions.py; docs/performance.md, lengths that XLA:CPU cuts evenly)
LENGTH_MULTIPLE = 64


def round_length(k: int, multiple: int = LENGTH_MULTIPLE) -> int:
    """``k`` rounded up to a whole multiple of ``multiple`` (:data:`LENGTH_MULTIPLE`)."""
    return -(-int(k) // int(multiple)) * int(multiple)


def to_device(x, dtype=None, ndmin: int = 0):
    """``x`` (a numpy array, a list, a number) as a JAX array on the default device: the array
    ``jnp.array(x, dtype, ndmin=ndmin)`` gives, made without a compiled program.

    Outside a trace ``jnp.asarray`` of a numpy array runs a staging program (``lax.stage``)
    and a change of dtype a ``convert_element_type`` program, each compiled once per shape and
    dtype, and XLA:CPU keeps host memory for every compiled program, however small, for the
    life of the process (docs/performance.md, "Programs that stay in memory"). ``jax.device_put``
    copies the buffer without one. A tracer, or a list holding one, goes to ``jnp.array``
    (inside a trace nothing is compiled), and a JAX array already of the dtype and rank is
    returned as it is. A Python number becomes an array of the default dtype of its kind
    (float64, int64), not a weakly typed one as in ``jnp.asarray``: where weak typing matters
    (a scalar that must take a float32 array's dtype), keep ``jnp.asarray``.
    """
    if dtype is not None:
        dtype = jax.dtypes.canonicalize_dtype(dtype)
    if isinstance(x, jax.Array) and not isinstance(x, jax.core.Tracer) and (
            dtype is None or x.dtype == dtype) and x.ndim >= ndmin:
        return x
    try:
        host = np.array(x, dtype, copy=None, ndmin=ndmin)
    except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
        return jnp.array(x, dtype, ndmin=ndmin)
    return jax.device_put(host)


def device_copy(x) -> jax.Array:
    """A copy of the array ``x`` (a JAX or numpy array) on the default device, in a buffer of
    its own, made without a compiled program (``jnp.array(x, copy=True)`` of a JAX array
    compiles a ``copy`` program per shape and dtype: :func:`to_device`)."""
    return jax.device_put(x, may_alias=False)


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
