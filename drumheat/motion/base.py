"""The contract every motion model fulfils, and the registry of motion models by name.

A motion model says how the particles of a scene move and what that means for their heat. It is
built from a scene (the scene was checked when it was built, including this motion model's
requirements, :mod:`drumheat.scene.rules`) and then driven by the one run loop,
:func:`drumheat.runner.simulate`::

    state = motion.initial_state(params)            # params: dotted keys -> values (fits)
    log = motion.start_log(state, params)
    rows = [motion.observe(state)]
    for t0, t1 in zip(motion.times[:-1], motion.times[1:]):
        new = motion.advance(state, t0, t1)         # pure where motion.vmappable
        # motion.check(state, new) may hand back a new start state: the chunk is redone
        rows.append(motion.observe(new))            # at the output times (output_index)
        state, log = motion.between(new, log, t1)   # host-side work between chunks
    trajectory = motion.finish(rows, log, state)

``run_ensemble`` is the same loop with :meth:`AbstractMotion.advance_batch` (``jax.vmap`` of
``advance``) over the stacked states of all variants, for every motion model whose
``vmappable`` is True. What a run produces travels in the returned
:class:`~drumheat.motion.trajectory.Trajectory` (and from there in the Result), never on the
motion object, which stays as it was built: the same object can run again.

Each motion model lives in its own module and registers itself with :func:`register` under the
name ``[motion] model`` uses.
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar

import equinox as eqx
import jax
import numpy as np

from drumheat import assemble
from drumheat.assemble import output_times
from drumheat.motion.rows import stack_rows
from drumheat.motion.trajectory import Trajectory
from drumheat.scene import Scene

__all__ = ["AbstractMotion", "MOTIONS", "register"]


class AbstractMotion(abc.ABC):
    """A motion model (module docstring).

    Class attributes
    ----------------
    name : str
        The ``[motion] model`` value.
    vmappable : bool
        :meth:`advance` is a pure function of the state (``jax.jit`` and ``jax.vmap`` apply),
        so an ensemble runs its variants as one vmapped program.
    differentiable : bool
        The temperatures are differentiable with respect to ``params`` through
        :meth:`initial_state`, :meth:`advance` and :meth:`observe` (calibration).
    particle_shardable : bool
        The state's per-particle arrays may be split over devices (``drumheat.run(...,
        devices=)``).

    Attributes
    ----------
    scene : Scene
    times : ndarray
        The chunk ends of the run loop, s (the output times; ``times[0]`` is the start).
    """

    name: ClassVar[str] = ""
    vmappable: ClassVar[bool] = False
    differentiable: ClassVar[bool] = False
    particle_shardable: ClassVar[bool] = False

    def __init__(self, scene: Scene):
        self.scene = scene
        self.times = output_times(scene)
        #: indices of the chunk ends in :attr:`times` that are output times (None: all)
        self.output_index = None

    def model(self, params: dict | None = None):
        """``(ThermalModel, T0)``: the thermal model as this motion model builds it and the
        initial particle temperatures (K), for parameter values ``params``; the model is
        None for a motion model that couples its gas itself (``pneumatic``)."""
        return assemble.thermal_model(self.scene, params)

    # -- the loop ---------------------------------------------------------------------------
    @abc.abstractmethod
    def initial_state(self, params: dict | None = None) -> Any:
        """The state (a PyTree) at ``times[0]`` for parameter values ``params`` (dotted scene
        keys to numbers, possibly traced), the scene's own values where absent."""

    @abc.abstractmethod
    def advance(self, state, t0: float, t1: float):
        """The state at ``t1`` from the state at ``t0`` (concrete floats)."""

    def check(self, start, end, attempt: int = 0):
        """Host-side check after a chunk (``attempt`` counts the redos of this chunk): None
        accepts ``end``; a state hands back a new start from which the chunk is redone (e.g.
        with larger neighbour buffers); an exception stops the run."""
        return None

    def advances_in_place(self, state) -> bool:
        """Whether :meth:`advance_in_place` reuses the buffers of ``state`` for the result
        (then ``state`` is unusable after it, and the run keeps the start elsewhere:
        :class:`drumheat.runner.spill.StartSpill`). Default: no."""
        return False

    def advance_in_place(self, state, t0: float, t1: float):
        """:meth:`advance`, free to reuse the buffers of ``state`` for the result (buffer
        donation: a chunk then holds one state in memory instead of two) where
        :meth:`advances_in_place` says so. Default: :meth:`advance`."""
        return self.advance(state, t0, t1)

    def passes(self, end) -> bool:
        """Whether :meth:`check` accepts ``end`` as it is (no redo, no error), told without
        the start state (which an in-place chunk no longer has in memory). Default: yes."""
        return True

    def start_log(self, state, params: dict | None = None, spool=None) -> Any:
        """Host-side record a run keeps between chunks (e.g. the contact recording); it may
        keep the run's ``params`` for :meth:`finish`. ``spool``: a folder where the log may
        keep its large arrays on disk (a run with a result folder: ``<out>/.log``), or None
        (in memory)."""
        return None

    def between(self, state, log, t: float):
        """Host-side work after the chunk ending at ``t``: ``(state, log)``."""
        return state, log

    def between_note(self, t: float) -> str | None:
        """What :meth:`between` does after the chunk ending at ``t`` when that takes a while
        (the progress bar shows it meanwhile), else None."""
        return None

    @abc.abstractmethod
    def observe(self, state) -> dict:
        """One output row: ``{"T": (N,) K, "Q": {account: J}, ...}`` (arrays)."""

    @abc.abstractmethod
    def finish(self, rows: list[dict], log, state) -> Trajectory:
        """The :class:`Trajectory` of a run from its output rows (host arrays), its log and
        its last state."""

    def cost(self, state, in_place: bool = False) -> dict | None:
        """What the run will cost, for the estimate shown before it starts: a dict with
        ``seconds`` (estimated wall time) and the step counts, or None where no estimate is
        made (runs without mechanics are short). ``in_place``: a timed warm-up may advance in
        the buffers of ``state`` (:meth:`advance_in_place`'s chunk, the one such a run will
        run), which uses ``state`` up."""
        return None

    def progress_work(self, t0: float, t1: float) -> float:
        """The share of the run's cost in advancing from ``t0`` to ``t1``, in any unit: the
        progress bar's ETA assumes the run advances at a constant rate in it. Default: the
        simulated time (every second of process time costs alike)."""
        return t1 - t0

    # -- checkpoints ------------------------------------------------------------------------
    def checkpoint_meta(self, state) -> dict:
        """JSON-serialisable facts of ``state`` that are not array leaves but are needed to
        rebuild it (e.g. neighbour-list capacities); see :mod:`drumheat.runner.checkpoint`."""
        return {}

    def save_log(self, log) -> dict:
        """The host-side log as a (nested) dict of arrays, for a checkpoint."""
        return {}

    def load_log(self, arrays: dict, log, spool=None):
        """The log of a checkpoint: ``log`` (a fresh :meth:`start_log`) with ``arrays`` (what
        :meth:`save_log` gave) put back; ``spool``: the folder of :meth:`start_log`, where the
        run that wrote the checkpoint kept its large arrays."""
        return log

    def restore_state(self, template, leaves: list, meta: dict, log):
        """The state of a checkpoint: the array ``leaves`` put onto ``template`` (a fresh
        :meth:`initial_state`, whose non-array parts are the same); returns ``(state, log)``.
        ``meta["structure"]`` (written with the checkpoint) must equal the template's layout,
        else the leaves would land in the wrong places (ValueError)."""
        dyn, static = eqx.partition(template, eqx.is_array)
        treedef = jax.tree_util.tree_structure(dyn)
        if meta.get("structure") != str(treedef):  # (drumheat.runner.checkpoint.state_structure)
            raise ValueError("the checkpoint's state is laid out otherwise than this code's "
                             f"(motion model {self.name!r}; written by another development "
                             "version of drumheat): start anew without --resume")
        if treedef.num_leaves != len(leaves):
            raise ValueError(f"the checkpoint holds {len(leaves)} state arrays, the motion model "
                             f"{self.name!r} builds {treedef.num_leaves}")
        new = [_like(t, a) for t, a in zip(jax.tree_util.tree_leaves(dyn), leaves)]
        return eqx.combine(jax.tree_util.tree_unflatten(treedef, new), static), log

    def stack_rows(self, rows) -> dict:
        """The rows (a list or a :class:`~drumheat.motion.rows.RowSpool`) stacked along a
        leading output axis (host arrays; disk-backed for a spool's particle frames)."""
        return stack_rows(rows)

    # -- ensembles --------------------------------------------------------------------------
    def shared(self) -> dict[str, Any]:
        """What every variant of an ensemble must share, by description (compared with
        ``==`` after :func:`repr`): the output times, and what else the motion model compiles
        into its program."""
        return {"the output times": tuple(np.round(self.times, 12))}

    def align(self, states: list) -> list:
        """The states of an ensemble's variants, made stackable (equal shapes)."""
        return states

    def advance_batch(self, states, axes, t0: float, t1: float):
        """:meth:`advance` of all variants at once: ``jax.vmap`` over the stacked states
        (``axes``: 0 for batched leaves, None for shared ones)."""
        return jax.vmap(lambda s: self.advance(s, t0, t1), in_axes=(axes,))(states)

    def not_vmappable(self) -> str | None:
        """Why this motion model's variants cannot run as one vmapped program (None if they
        can)."""
        return None if self.vmappable else "its host-side control flow is not batched"

    def check_batch(self, start, end, n: int, unstack, stack, attempt: int = 0):
        """:meth:`check` of a batch of ``n`` stacked states (``unstack``/``stack`` convert):
        None accepts; else the new stacked start state."""
        starts, ends = unstack(start), unstack(end)
        redo = [self.check(s, e, attempt) for s, e in zip(starts, ends)]
        if all(r is None for r in redo):
            return None
        return stack(self.align([s if r is None else r for s, r in zip(starts, redo)]))


def _like(template, values):
    """``values`` as a device array of the template's dtype and weak type (so that a restored
    state promotes in arithmetic exactly like the original)."""
    template = jax.numpy.asarray(template)
    values = np.asarray(values)
    if values.dtype.kind != template.dtype.kind and values.size:  # float seconds into counts...
        raise ValueError(f"a checkpoint array of {values.dtype} where this code keeps "
                         f"{template.dtype}: written by another development version of "
                         "drumheat; start anew without --resume")
    values = values.astype(template.dtype, copy=False)  # e.g. float64 -> float32
    if template.shape == values.shape:
        return template.at[...].set(values)
    return jax.numpy.asarray(values)


#: ``[motion] model`` -> motion class (filled by :func:`register`)
MOTIONS: dict[str, type] = {}


def register(cls):
    """Class decorator: register a motion model under its ``name``."""
    MOTIONS[cls.name] = cls
    return cls

