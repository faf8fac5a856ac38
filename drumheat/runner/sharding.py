"""Spreading work over several devices with ``jax.sharding``.

Two kinds of data parallelism are offered, both on a one-dimensional device mesh:

* **ensemble axis** (:func:`shard_batch`): the variants of :func:`drumheat.run_ensemble` are
  split over the devices; every device runs whole variants. The variant count is padded to a
  multiple of the device count (copies of the last variant) and the padding is dropped
  afterwards (:func:`unpad`).
* **particle axis** (:func:`shard_particles`): the per-particle arrays of a single run
  (temperatures, positions, velocities, particle properties) are split into contiguous blocks
  of particles, one block per device. The program itself is unchanged: XLA's SPMD partitioner
  inserts the communication (gathers for the contact pairs, reductions for sums). Results equal
  those of one device to round-off. The particle count must be a multiple of the device count
  (otherwise the arrays are left replicated, with a warning).

The mesh axis is named ``"d"``. Everything here works on any JAX backend; on a CPU the devices
can be simulated with ``XLA_FLAGS=--xla_force_host_platform_device_count=4`` (set before JAX is
imported). Several hosts: see ``docs/scaling.md`` (``jax.distributed.initialize`` first, then
the mesh spans ``jax.devices()`` of all processes).
"""

from __future__ import annotations

import warnings
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from drumheat.devices import round_length
from drumheat.devices import to_host  # noqa: F401 (re-exported)

AXIS = "d"

__all__ = ["AXIS", "make_mesh", "resolve_devices", "pad_to_multiple", "unpad", "shard_batch",
           "shard_particles", "replicate", "to_host"]


def resolve_devices(devices=None) -> list | None:
    """The device list meant by a ``devices=`` argument.

    Parameters
    ----------
    devices : None, "all", int, or sequence of jax.Device
        None: no sharding (the default device). ``"all"`` or True: ``jax.devices()``. An int
        ``k``: the first ``k`` of ``jax.devices()``. A sequence: those devices.

    Returns
    -------
    list of jax.Device or None
        None where no sharding is asked for.

    Raises
    ------
    ValueError
        If more devices are asked for than exist, or the argument is not understood.
    """
    if devices is None or devices is False:
        return None
    if devices is True or devices == "all":
        return list(jax.devices())
    if isinstance(devices, (int, np.integer)):
        avail = jax.devices()
        if not 1 <= devices <= len(avail):
            raise ValueError(f"devices = {devices}: this process sees {len(avail)} device(s) "
                             f"({avail[0].platform}); on a CPU more can be simulated with "
                             "XLA_FLAGS=--xla_force_host_platform_device_count=N set before "
                             "JAX is imported")
        return list(avail[:devices])
    if isinstance(devices, Sequence):
        return list(devices)
    raise ValueError(f"devices must be None, 'all', an int or a list of devices, got {devices!r}")


def make_mesh(devices=None) -> Mesh:
    """A one-dimensional mesh (axis ``"d"``) over ``devices`` (default: all of ``jax.devices()``).

    In a multi-process run (after ``jax.distributed.initialize``) ``jax.devices()`` lists the
    devices of every process, so the default mesh is global.
    """
    devs = resolve_devices("all" if devices is None else devices)
    return Mesh(np.array(devs), (AXIS,))


def pad_to_multiple(tree, n: int, multiple: int):
    """Pad the leading axis (length ``n``) of every array in ``tree`` to a multiple of
    ``multiple`` by repeating the last entry. Returns ``(padded_tree, n_padded)``."""
    n_pad = round_length(n, multiple)
    if n_pad == n:
        return tree, n

    def pad(a):
        a = jnp.asarray(a)
        return jnp.concatenate([a, jnp.repeat(a[-1:], n_pad - n, axis=0)], axis=0)

    return jax.tree_util.tree_map(pad, tree), n_pad


def unpad(tree, n: int):
    """Drop the padding added by :func:`pad_to_multiple`: keep the first ``n`` entries."""
    return jax.tree_util.tree_map(lambda a: a[:n], tree)


def shard_batch(tree, mesh: Mesh, batched=None):
    """Place a batch PyTree on ``mesh``: leading (variant) axis split over the devices.

    Parameters
    ----------
    tree : PyTree of arrays
        Leading axis = variants, already a multiple of the device count
        (:func:`pad_to_multiple`).
    mesh : Mesh
    batched : PyTree of bool, optional
        Same structure as ``tree``; False marks an unbatched leaf, which is replicated.
    """
    split = NamedSharding(mesh, PartitionSpec(AXIS))
    rep = NamedSharding(mesh, PartitionSpec())
    if batched is None:
        return jax.tree_util.tree_map(lambda a: jax.device_put(a, split), tree)
    return jax.tree_util.tree_map(
        lambda a, b: jax.device_put(a, split if b else rep), tree, batched)


def replicate(tree, mesh: Mesh):
    """Place every array of ``tree`` on all devices of ``mesh`` (replicated)."""
    rep = NamedSharding(mesh, PartitionSpec())
    return jax.tree_util.tree_map(lambda a: jax.device_put(a, rep), tree)


def shard_particles(tree, mesh: Mesh, n: int, warn: bool = True):
    """Split the particle axis of the per-particle arrays in ``tree`` over ``mesh``.

    Every array whose leading axis has length ``n`` (the particle count) is split into one
    contiguous block of particles per device; every other array is replicated. Integer and
    float arrays alike (temperatures, positions, velocities, masses, capacities).

    Parameters
    ----------
    tree : PyTree
        Non-array leaves are passed through.
    mesh : Mesh
    n : int
        Particle count.
    warn : bool
        Warn (once) when ``n`` is not a multiple of the device count; the arrays are then
        replicated (the run still gives the same results, without the memory split).
    """
    k = mesh.devices.size
    split = NamedSharding(mesh, PartitionSpec(AXIS))
    rep = NamedSharding(mesh, PartitionSpec())
    if n % k:
        if warn:
            warnings.warn(f"{n} particles do not divide over {k} devices; the particle arrays "
                          "are replicated instead of split", stacklevel=2)
        split = rep

    def place(a):
        if not isinstance(a, (jax.Array, np.ndarray)):
            return a
        return jax.device_put(a, split if a.ndim >= 1 and a.shape[0] == n else rep)

    return jax.tree_util.tree_map(place, tree)
