"""An array that grows by appended rows, in memory or in a file (:class:`SpooledArray`).

The contact recording of a DEM run (``dem.record_interval``) grows by every recording
interval; over a long run it outgrows the mechanics' own working memory (docs/performance.md,
"A whole run of the built-in drum"). A run that writes into a result folder keeps it in files
there instead (``<out>/.log``), as it keeps its output frames
(:class:`drumheat.motion.rows.RowSpool`): each interval is appended to the files when it is
recorded and read back memory-mapped, so a long run never holds its recording in memory,
and its checkpoints name the recorded lengths instead of holding the arrays.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["SpooledArray"]


class SpooledArray:
    """Rows of one dtype and shape appended one block at a time: in a list of blocks in memory
    (``path=None``), or in the raw binary file ``path`` (C order, no header).

    Parameters
    ----------
    dtype : numpy dtype
        Appended blocks are converted to it.
    row_shape : tuple, optional
        The shape of one row (``()`` for a 1D array); None: that of the first block appended.
    path : path, optional
        The file. It is written from row ``length`` on: whatever a file holds past the rows
        this array counts (written by a run after its last checkpoint) is cut off at the next
        append.
    length : int
        Rows already in ``path`` that belong to the array (adopting a file a stopped run
        wrote, :meth:`drumheat.motion.dem.ContactRecorder.from_arrays`).
    """

    def __init__(self, dtype, row_shape=(), path=None, length: int = 0):
        self.dtype = np.dtype(dtype)
        self.path = None if path is None else Path(path)
        self.length = int(length)
        self._blocks: list[np.ndarray] = []
        self.row_shape = None
        if row_shape is not None:
            self._set_row_shape(row_shape)
        if self.length and (self.path is None or self.row_shape is None):
            raise ValueError("only a file with a given row shape can hold rows from the start")
        if self.path is not None and self.length:
            size = self.path.stat().st_size if self.path.is_file() else 0
            if size < self.length * self._row_bytes:
                raise ValueError(f"'{self.path}' holds {size // max(self._row_bytes, 1)} rows, "
                                 f"fewer than the {self.length} that were recorded in it")

    def _set_row_shape(self, row_shape):
        self.row_shape = tuple(int(s) for s in row_shape)
        self._row_bytes = self.dtype.itemsize * int(np.prod(self.row_shape, dtype=np.int64))

    def __len__(self) -> int:
        return self.length

    def append(self, block) -> None:
        """Append the rows of ``block`` (shape ``(k, *row_shape)``)."""
        block = np.ascontiguousarray(block, self.dtype)
        if self.row_shape is None:
            self._set_row_shape(block.shape[1:])
        if block.shape[1:] != self.row_shape:
            raise ValueError(f"rows of shape {block.shape[1:]} appended to an array of rows "
                             f"of shape {self.row_shape}")
        if self.path is None:
            self._blocks.append(block)
        else:
            offset = self.length * self._row_bytes
            with open(self.path, "r+b" if self.path.is_file() else "wb") as fh:
                fh.truncate(offset)
                fh.seek(offset)
                fh.write(block.tobytes())
        self.length += len(block)

    def read(self, start: int = 0) -> np.ndarray:
        """Rows ``start`` to the end as one array: a read-only memory map of the file (no copy),
        or the blocks in memory concatenated."""
        if self.row_shape is None:  # nothing appended yet
            return np.zeros(0, self.dtype)
        shape = (self.length - start,) + self.row_shape
        if shape[0] <= 0 or self._row_bytes == 0:
            return np.zeros((max(shape[0], 0),) + self.row_shape, self.dtype)
        if self.path is not None:
            return np.memmap(self.path, self.dtype, "r", offset=start * self._row_bytes,
                             shape=shape)
        parts, seen = [], 0
        for b in self._blocks:
            if seen + len(b) > start:
                parts.append(b[max(start - seen, 0):])
            seen += len(b)
        return parts[0] if len(parts) == 1 else np.concatenate(parts)
