"""Checkpoints of a run: everything the run loop needs to continue, as plain arrays.

A checkpoint holds the complete state of a run at a chunk boundary (the motion model's state:
positions, velocities, spins, springs, neighbour lists, temperatures, shell profiles, heat
accounts, the random state it carries), the host-side log (e.g. the contact recording so far),
the output rows so far (their particle frames stay in the result folder's spool, see
:mod:`drumheat.motion.rows`), the scene as run and the drumheat version. It is one ``.npz`` file of
arrays (never a pickle) written atomically (a temporary file renamed into place), so a run
killed while writing leaves the previous checkpoint intact.

A state is stored as the array leaves of ``eqx.partition(state, eqx.is_array)``; it is
restored onto a template state built anew from the scene (``motion.initial_state``), whose
non-array parts (static structure, functions) are the same, by
:meth:`~drumheat.motion.base.AbstractMotion.restore_state`. Resuming from a checkpoint gives
the same numbers, bit for bit, as the run that was not interrupted (tests/test_resume.py).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import equinox as eqx
import jax
import numpy as np

from drumheat._version import __version__
from drumheat.devices import to_host
from drumheat.motion.rows import RowSpool, flatten_dict, unflatten_dict

__all__ = ["CHECKPOINT", "CheckpointError", "save_checkpoint", "load_checkpoint",
           "state_structure",
           "flatten_dict", "unflatten_dict"]

#: file name of the checkpoint in a result folder
CHECKPOINT = "checkpoint.npz"


class CheckpointError(ValueError):
    """A checkpoint cannot be used (another scene, another drumheat version, damaged)."""


def state_leaves(state) -> list:
    """The array leaves of a state (host arrays)."""
    dyn, _ = eqx.partition(state, eqx.is_array)
    return [np.asarray(a) for a in to_host(jax.tree_util.tree_leaves(dyn))]


def state_structure(state) -> str:
    """The structure of a state's array leaves (types, field names and dict keys, in leaf
    order): two states whose structures are equal put their leaves in the same places
    (:meth:`~drumheat.motion.base.AbstractMotion.restore_state` compares them)."""
    dyn, _ = eqx.partition(state, eqx.is_array)
    return str(jax.tree_util.tree_structure(dyn))


def save_checkpoint(path: Path, *, scene_toml: str, motion_name: str, chunk: int, time: float,
                    state, state_meta: dict, log_arrays: dict, rows: list,
                    extra_meta: dict | None = None) -> Path:
    """Write a checkpoint atomically; returns its path.

    Parameters
    ----------
    path : Path
        The checkpoint file (``<result folder>/checkpoint.npz``).
    scene_toml : str
        The scene as run (compared when resuming).
    chunk : int
        Number of chunks done (the loop resumes with chunk ``chunk``).
    time : float
        Simulated time reached, s.
    state, state_meta :
        The motion model's state and its JSON-serialisable static facts
        (:meth:`~drumheat.motion.base.AbstractMotion.checkpoint_meta`).
    log_arrays : dict
        The host-side log as arrays (:meth:`~drumheat.motion.base.AbstractMotion.save_log`).
    rows : list of dict or RowSpool
        The output rows so far (of a spool: its small arrays and the file names of its
        particle frames, which stay in the spool's folder).
    """
    leaves = state_leaves(state)
    arrays = {f"state/{k}": a for k, a in enumerate(leaves)}
    arrays.update({f"log/{k}": np.asarray(v) for k, v in flatten_dict(log_arrays).items()})
    if isinstance(rows, RowSpool):
        rows = rows.state()
    for i, row in enumerate(rows):
        arrays.update({f"rows/{i}/{k}": v for k, v in flatten_dict(row).items()})
    meta = dict(drumheat=__version__, scene=scene_toml, motion=motion_name, chunk=int(chunk),
                time=float(time), n_leaves=len(leaves), n_rows=len(rows),
                state=dict(state_meta, structure=state_structure(state)),
                **(extra_meta or {}))
    arrays["meta"] = np.array(json.dumps(meta))
    path = Path(path)
    tmp = path.with_name(f".{path.name}.writing")
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    return path


def load_checkpoint(path: Path, scene_toml: str | None = None) -> dict:
    """Read a checkpoint: ``{"meta", "state" (leaves), "log" (dict), "rows" (list)}``.

    Raises
    ------
    CheckpointError
        If the file cannot be read, was written by another drumheat version, or (when
        ``scene_toml`` is given) belongs to another scene.
    """
    try:
        with np.load(path, allow_pickle=False) as f:
            data = {k: f[k] for k in f.files}
        meta = json.loads(str(data.pop("meta")))
    except (OSError, ValueError, KeyError) as err:
        raise CheckpointError(f"checkpoint '{path}' cannot be read ({err})") from None
    if meta.get("drumheat") != __version__:
        raise CheckpointError(f"checkpoint '{path}' was written by drumheat "
                              f"{meta.get('drumheat')}, this is {__version__}: a checkpoint "
                              "can only be continued by the version that wrote it")
    if scene_toml is not None and meta["scene"] != scene_toml:
        raise CheckpointError(f"checkpoint '{path}' belongs to another scene (or the same "
                              "scene with other values): resume with the scene as it was run "
                              "(its scene.toml in the result folder), or start anew without "
                              "--resume")
    state = [data[f"state/{k}"] for k in range(meta["n_leaves"])]
    log = unflatten_dict({k[4:]: v for k, v in data.items() if k.startswith("log/")})
    rows = []
    for i in range(meta["n_rows"]):
        pre = f"rows/{i}/"
        rows.append(unflatten_dict({k[len(pre):]: v for k, v in data.items()
                                    if k.startswith(pre)}))
    return dict(meta=meta, state=state, log=log, rows=rows)
