"""The output rows of a run, with their large arrays on disk (:class:`RowSpool`).

A motion model's :meth:`~drumheat.motion.base.AbstractMotion.observe` gives one row per output
time (particle temperatures, positions, heat accounts, ...). A run that writes into a result
folder keeps its rows in a :class:`RowSpool`: every array of at least ``min_size`` elements
(a particle frame) is written to its own ``.npy`` file as soon as the row arrives, and read
back memory-mapped; only the small arrays stay in memory. :func:`stack_rows` and
:func:`stack_arrays` stack rows into one disk-backed array, so the frames of a long run are
never all in memory at once (issue 18: "outputs of long runs no longer held whole in memory").

A plain ``list`` of rows (runs without a result folder, ensembles) works with the same
functions and stays in memory.
"""

from __future__ import annotations

import shutil
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from drumheat.motion.npz_files import release_pages

__all__ = ["RowSpool", "stack_rows", "stack_arrays", "flatten_dict", "unflatten_dict"]


def flatten_dict(tree, prefix: str = "") -> dict:
    """A nested dict of arrays as ``{"a/b/c": array}`` (keys must not contain ``/``); an empty
    dict is kept as the key ``"a/b/"`` with an empty array, so that it comes back."""
    out = {}
    for k, v in tree.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and not v:
            out[key + "/"] = np.zeros(0)
        elif isinstance(v, dict):
            out.update(flatten_dict(v, key + "/"))
        else:
            out[key] = v if isinstance(v, OnDisk) else np.asarray(v)
    return out


def unflatten_dict(flat: dict) -> dict:
    """The inverse of :func:`flatten_dict`."""
    out: dict = {}
    for key, v in flat.items():
        parts = key.split("/")
        node = out
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        if parts[-1]:  # "a/b/" is an empty dict, made by the loop above
            node[parts[-1]] = v
    return out


class OnDisk(str):
    """The file name (relative to the spool's folder) of an array kept on disk."""


class RowSpool(Sequence):
    """Output rows whose large arrays live in ``.npy`` files of ``directory``.

    Behaves as a read-only list of row dicts (``len``, indexing, slicing, iteration); a row's
    large arrays come back as read-only memory maps.

    Parameters
    ----------
    directory : path
        Folder for the arrays (made if missing). Rows already there are adopted only through
        :meth:`from_state`.
    min_size : int, optional
        Arrays with at least this many elements go to disk (default :attr:`MIN_SIZE`).
    """

    #: arrays with at least this many elements go to disk unless ``min_size`` says otherwise
    MIN_SIZE = 4096

    def __init__(self, directory, min_size: int | None = None):
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.min_size = int(self.MIN_SIZE if min_size is None else min_size)
        self._rows: list[dict] = []

    def append(self, row: dict) -> None:
        """Add one row; its large arrays are written now."""
        i = len(self._rows)
        kept = {}
        for key, v in flatten_dict(row).items():
            if not isinstance(v, OnDisk) and v.size >= self.min_size:
                name = OnDisk(f"{i:07d}/{key.replace('/', '.')}.npy")
                (self.directory / name).parent.mkdir(exist_ok=True)
                np.save(self.directory / name, v)
                v = name
            kept[key] = v
        self._rows.append(kept)

    def __len__(self) -> int:
        return len(self._rows)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        return unflatten_dict({k: self._load(v) for k, v in self._rows[i].items()})

    def _load(self, v):
        return np.load(self.directory / v, mmap_mode="r") if isinstance(v, OnDisk) else v

    def truncate(self, n: int) -> None:
        """Keep the first ``n`` rows (the files of later rows are removed by
        :meth:`from_state` or overwritten)."""
        del self._rows[n:]

    def state(self) -> list[dict]:
        """The rows as a checkpoint stores them: small arrays, and the file names of the large
        ones (a string array each)."""
        return [unflatten_dict({k: (np.array(str(v)) if isinstance(v, OnDisk) else v)
                                for k, v in r.items()}) for r in self._rows]

    @classmethod
    def from_state(cls, directory, rows: list[dict], min_size: int | None = None) -> "RowSpool":
        """The spool of a checkpoint's rows (:meth:`state`) in ``directory``; arrays written
        for later rows (after the checkpoint) are removed."""
        spool = cls(directory, min_size)
        for r in rows:
            flat = flatten_dict(r)
            spool._rows.append({k: (OnDisk(str(v)) if v.dtype.kind == "U" else v)
                                for k, v in flat.items()})
        for d in spool.directory.iterdir():
            if d.is_dir() and d.name.isdigit() and int(d.name) >= len(spool._rows):
                shutil.rmtree(d)
        return spool

    def stacked_file(self, name: str) -> Path:
        """Where :func:`stack_arrays` puts a stacked array of this spool."""
        return self.directory / f"stacked.{name}.npy"


def stack_arrays(rows, name: str, arrays: Iterable) -> np.ndarray:
    """Stack per-row arrays along a new leading axis.

    For a :class:`RowSpool` the result is a memory map of a ``.npy`` file in the spool's folder,
    filled one array at a time (never all in memory); for a list, ``np.stack``.

    Parameters
    ----------
    rows : RowSpool or list
        Decides where the result lives.
    name : str
        Name of the stacked array (its file name in the spool).
    arrays : iterable of arrays of one shape and dtype
    """
    if not isinstance(rows, RowSpool):
        return np.stack([np.asarray(a) for a in arrays])
    it = iter(arrays)
    try:
        first = np.asarray(next(it))
    except StopIteration:
        raise ValueError(f"stack_arrays({name!r}): no arrays") from None
    n = len(rows)
    out = np.lib.format.open_memmap(rows.stacked_file(name), mode="w+", dtype=first.dtype,
                                    shape=(n,) + first.shape)
    out[0] = first
    release_pages(out)  # written rows go to the file, not the resident memory
    k = 1
    for a in it:
        if k >= n:
            raise ValueError(f"stack_arrays({name!r}): more arrays than rows ({n})")
        out[k] = a
        release_pages(out)
        k += 1
    out.flush()
    return out[:k] if k < n else out


def stack_rows(rows) -> dict:
    """The rows stacked along a leading output axis: a dict like one row, with host arrays
    (memory maps for a spool's large arrays)."""
    if not isinstance(rows, RowSpool):
        import jax

        return jax.tree_util.tree_map(lambda *a: np.stack([np.asarray(x) for x in a]), *rows)
    keys = rows._rows[0].keys()
    flat = {}
    for key in keys:
        if isinstance(rows._rows[0][key], OnDisk):
            flat[key] = stack_arrays(rows, key.replace("/", "."),
                                     (rows._load(r[key]) for r in rows._rows))
        else:
            flat[key] = np.stack([r[key] for r in rows._rows])
    return unflatten_dict(flat)
