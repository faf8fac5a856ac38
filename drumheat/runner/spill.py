"""The start of a chunk kept on disk while the chunk advances in place.

A motion model whose chunks may reuse the buffers of their start state for the result
(:meth:`~drumheat.motion.base.AbstractMotion.advance_in_place`, buffer donation) holds one copy
of its state in memory during a chunk instead of two, the start and the end. The run still
needs the start when the chunk fails a check: a neighbour-buffer overflow redoes the chunk from
it, and a failure writes it as the last good state into the failure checkpoint. The run loop
(:func:`drumheat.runner.loop.simulate`, with a result folder on the CPU) therefore writes it to
files in the folder's log directory before each such chunk and reads it back only then. The
files hold one state (about 0.5 kB per particle in float64), are overwritten by every chunk and
removed when the run ends; the writing costs a pass over the state per chunk (a chunk is
thousands of steps).
"""

from __future__ import annotations

import shutil
import weakref
from pathlib import Path

import jax
import numpy as np

from drumheat.devices import device_copy

__all__ = ["StartSpill", "copy_leaves", "own_copy"]

#: the folder in the run's log directory that holds the start of the running chunk
SPILL_DIR = "chunk-start"


def own_copy(x) -> jax.Array:
    """A copy of the array ``x`` (a JAX or numpy array) on the default device, in a buffer of
    its own (one a donation may take), made without a compiled program
    (:func:`drumheat.devices.device_copy`)."""
    return jax.block_until_ready(device_copy(x))


def copy_leaves(leaves: list) -> list:
    """Each array of ``leaves`` replaced by :func:`own_copy`, one at a time and in the list
    itself, so that an original no one else holds is freed before the next is copied. Returns
    ``leaves``. A caller that copies a state this way drops its own references to the state
    first and keeps only the list (``leaves, treedef = jax.tree_util.tree_flatten(state)``,
    then ``jax.tree_util.tree_unflatten(treedef, copy_leaves(leaves))``): one state in memory,
    and one array more."""
    for k in range(len(leaves)):
        leaves[k] = own_copy(leaves[k])
    return leaves


class StartSpill:
    """The start state of the running chunk, on disk.

    Parameters
    ----------
    folder : path
        Where its files go (the run's log directory, made here if missing), in a folder
        :data:`SPILL_DIR`.

    :meth:`save` writes a state before its chunk; :meth:`load` reads it back onto the default
    device (the same tree, shapes and dtypes); :meth:`owns` tells whether a state's buffers are
    the loop's own, as donation needs (the state a chunk ended with, :meth:`adopt`); any other
    is copied into buffers of its own (:func:`copy_leaves`), so that the caller's arrays are
    never donated.
    """

    def __init__(self, folder):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.path = self.folder / SPILL_DIR
        self._treedef = None
        self._kept: dict = {}  # leaf index -> the weakly typed leaves of the state, in memory
        self._own: list = []  # weak references to the arrays of the last chunk's end

    def save(self, state) -> None:
        """Write ``state`` (a PyTree of JAX arrays) to the folder, one ``.npy`` file per leaf (no
        second copy of the whole state in memory: on the CPU the arrays are written from their
        own buffers).

        A weakly typed leaf (a scalar computed with ``jnp`` from Python numbers, such as a
        heat-transfer coefficient of Schluender's model) is kept in memory instead, as a copy
        of its own, weakly typed as it was: a file has no weak type, and a strongly typed leaf
        would change how the programs that read it promote their dtypes (and so compile them
        anew)."""
        leaves, treedef = jax.tree_util.tree_flatten(state)
        for x in leaves:
            if not isinstance(x, jax.Array):
                raise TypeError("a state kept on disk must consist of JAX arrays; got "
                                f"{type(x).__name__}")
        self.path.mkdir(exist_ok=True)
        kept = {}
        for k, x in enumerate(leaves):
            if x.weak_type:
                kept[k] = own_copy(x)  # before the chunk donates `x`
            else:
                np.save(self.path / f"{k}.npy", np.asarray(x), allow_pickle=False)
        self._kept = kept
        self._treedef = treedef

    def load(self):
        """The state last saved, on the default device, in buffers of its own.

        The files are read one at a time, each into memory and from there into its new buffer,
        so that besides the state only one array is read at a time (mapping the files instead,
        all of their pages stayed resident until the last was copied). The weakly typed leaves
        kept in memory are copied again (a redo may donate what it is given)."""
        if self._treedef is None:
            raise RuntimeError("no state has been saved")
        leaves = [own_copy(self._kept[k]) if k in self._kept
                  else own_copy(np.load(self.path / f"{k}.npy", allow_pickle=False))
                  for k in range(self._treedef.num_leaves)]
        return jax.tree_util.tree_unflatten(self._treedef, leaves)

    def owns(self, state) -> bool:
        """Whether the arrays of ``state`` are those a chunk returned (:meth:`adopt`), which no
        one else holds; any other state (the initial one, one that the host-side work between
        chunks rebuilt, a restored one) is to be copied into buffers of its own
        (:func:`copy_leaves`, after the caller has dropped its references) before its buffers
        may be donated."""
        own = {id(r()) for r in self._own if r() is not None}
        leaves = jax.tree_util.tree_leaves(state)
        return bool(leaves) and all(id(x) in own for x in leaves)

    def adopt(self, state) -> None:
        """Record ``state`` (the end of a chunk) as the loop's own (:meth:`owns`)."""
        self._own = [weakref.ref(x) for x in jax.tree_util.tree_leaves(state)]

    def close(self) -> None:
        """Remove the files."""
        shutil.rmtree(self.path, ignore_errors=True)
        self._treedef = None
        self._kept = {}
        self._own = []
