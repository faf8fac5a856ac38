"""``.npz`` files written from memory-mapped arrays without keeping their pages resident.

A run with a result folder keeps its contact recording and its output frames in files and reads
them back memory-mapped (:class:`drumheat.motion.spooled_array.SpooledArray`,
:func:`drumheat.motion.rows.stack_arrays`). ``np.savez_compressed`` reads such an array through
its mapping, and every page it reads stays in the process's resident memory for as long as the
mapping lives: writing ``contacts.npz`` and ``particles.npz`` at the end of a run made the whole
recording and all frames resident at once (docs/performance.md, "Mapped files and the restart
assignment at the end of a run"). The pages are the files' (the system may drop them), but
they count in the resident memory a user sees.

:func:`save_npz` writes the same file as ``np.savez_compressed`` (``np.savez`` with
``compressed=False``): one ``.npy`` entry per array, the header of ``np.lib.format``, the data
in C order. A memory-mapped array is written in blocks of :data:`BLOCK_BYTES`, and after each
block the mapping's resident pages are given back (:func:`release_pages`: ``madvise`` with
``MADV_DONTNEED``, which on a file mapping drops the process's pages only; the data stays in
the file and in the system's page cache, and a later read maps it in again).
"""

from __future__ import annotations

import mmap
import zipfile
from pathlib import Path

import numpy as np

__all__ = ["save_npz", "release_pages", "BLOCK_BYTES"]

#: bytes of a memory-mapped array written between two releases of its pages (numpy's own
#: buffer size in ``np.lib.format.write_array``)
BLOCK_BYTES = 16 << 20


def release_pages(array) -> bool:
    """Give back the resident pages of the memory mapping under ``array`` (a ``np.memmap`` or
    a view of one); returns whether there was one to give back.

    The mapping stays valid: its contents are read from the file again where they are used.
    Only mappings of files opened read-only or shared (``np.memmap`` modes ``"r"``, ``"r+"``,
    ``"w+"``) are released; a copy-on-write mapping (mode ``"c"``) would lose its changes and
    is left alone.
    """
    base = _memmap_base(array)
    if base is None or base.mode == "c" or not hasattr(mmap, "MADV_DONTNEED"):
        return False
    base._mmap.madvise(mmap.MADV_DONTNEED)
    return True


def save_npz(path, arrays: dict, compressed: bool = True) -> None:
    """Write ``arrays`` to the ``.npz`` file ``path`` as ``np.savez_compressed`` (or
    ``np.savez``) does, giving back the pages of memory-mapped arrays as they are written.

    Main arguments
    --------------
    path : path or binary file object
        The file (written as given, no ``.npz`` added).
    arrays : dict of str to array-like
        Entry names (without ``.npy``) and their arrays. Object arrays are refused, as
        ``np.load`` refuses them without ``allow_pickle``.

    Other arguments
    ---------------
    compressed : bool
        Deflate the entries (``np.savez_compressed``); False stores them (``np.savez``).
    """
    method = zipfile.ZIP_DEFLATED if compressed else zipfile.ZIP_STORED
    target = path if hasattr(path, "write") else Path(path)
    with zipfile.ZipFile(target, mode="w", compression=method, allowZip64=True) as zf:
        for name, value in arrays.items():
            array = np.asanyarray(value)
            if array.dtype.hasobject:
                raise ValueError(f"save_npz: {name!r} is an object array")
            with zf.open(name + ".npy", "w", force_zip64=True) as fh:
                if _memmap_base(array) is not None and (array.flags.c_contiguous
                                                        or array.flags.f_contiguous):
                    _write_mapped(fh, array)
                else:  # numpy's writer (a strided view of a mapping: released at the end)
                    np.lib.format.write_array(fh, array, allow_pickle=False)
                    release_pages(array)


def _write_mapped(fh, array) -> None:
    """One ``.npy`` entry of a memory-mapped array: header, then the data block by block, the
    mapping's pages given back after each block."""
    header = np.lib.format.header_data_from_array_1_0(array)
    try:
        np.lib.format.write_array_header_1_0(fh, header)
    except ValueError:  # a header too long for format 1.0 (numpy then writes 2.0)
        np.lib.format.write_array_header_2_0(fh, header)
    flat = np.ravel(array, order="F" if header["fortran_order"] else "C")  # a view: contiguous
    per = max(BLOCK_BYTES // max(array.itemsize, 1), 1)
    for i in range(0, flat.size, per):
        fh.write(flat[i:i + per].tobytes())
        release_pages(array)


def _memmap_base(array):
    """The ``np.memmap`` holding the mapping under ``array`` (the array itself or the memmap it
    is a view of), or None."""
    a = array
    while isinstance(a, np.ndarray):
        if isinstance(a, np.memmap) and isinstance(getattr(a, "_mmap", None), mmap.mmap):
            return a
        a = a.base
    return None
