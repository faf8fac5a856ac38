"""SpooledArray: rows appended in memory or to a file read back the same; a file is cut to
the rows the array counts (what a stopped run wrote after its checkpoint goes)."""

import numpy as np
import pytest

from drumheat.motion.spooled_array import SpooledArray


@pytest.mark.parametrize("in_file", [False, True])
def test_appended_rows_read_back(in_file, tmp_path):
    a = SpooledArray(np.float32, None, tmp_path / "a.bin" if in_file else None)
    assert a.read().shape == (0,)  # nothing appended: no row shape yet
    blocks = [np.arange(6.0).reshape(1, 2, 3), np.ones((2, 2, 3)), np.zeros((0, 2, 3))]
    for b in blocks:
        a.append(b)
    whole = np.concatenate(blocks).astype(np.float32)
    assert len(a) == 3 and a.row_shape == (2, 3)
    for start in range(4):
        got = a.read(start)
        assert got.dtype == np.float32
        np.testing.assert_array_equal(got, whole[start:])
    assert isinstance(a.read(1), np.memmap) == in_file
    with pytest.raises(ValueError, match="rows of shape"):
        a.append(np.ones((1, 3, 2)))


def test_a_file_is_cut_to_the_rows_counted(tmp_path):
    path = tmp_path / "a.bin"
    a = SpooledArray(np.int32, (), path)
    a.append(np.arange(5))
    a.append(np.arange(3))  # written after a checkpoint at 5 rows
    kept = SpooledArray(np.int32, (), path, length=5)  # the resumed run adopts 5 rows
    np.testing.assert_array_equal(kept.read(), np.arange(5))
    kept.append(np.array([7]))
    assert path.stat().st_size == 6 * 4
    np.testing.assert_array_equal(kept.read(), [0, 1, 2, 3, 4, 7])
    with pytest.raises(ValueError, match="fewer than the 9"):
        SpooledArray(np.int32, (), path, length=9)
    with pytest.raises(ValueError, match="only a file"):
        SpooledArray(np.int32, (), None, length=1)
