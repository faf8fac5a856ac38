"""save_npz writes numpy's own .npz entries and gives back the pages of memory maps."""

import sys
import zipfile

import numpy as np
import pytest

from drumheat.motion import npz_files
from drumheat.motion.npz_files import release_pages, save_npz


def _arrays(tmp_path):
    rng = np.random.default_rng(3)
    c = np.lib.format.open_memmap(tmp_path / "c.npy", "w+", np.float64, (300, 7))
    c[:] = rng.normal(size=c.shape)
    c.flush()
    f = np.lib.format.open_memmap(tmp_path / "f.npy", "w+", np.int32, (40, 9), fortran_order=True)
    f[:] = rng.integers(0, 1000, size=f.shape)
    f.flush()
    ro = np.memmap(tmp_path / "raw.bin", np.float32, "w+", shape=(1000,))
    ro[:] = rng.normal(size=1000)
    ro.flush()
    return {"c": np.load(tmp_path / "c.npy", mmap_mode="r"),
            "f": np.load(tmp_path / "f.npy", mmap_mode="r"),
            "raw": np.memmap(tmp_path / "raw.bin", np.float32, "r", shape=(1000,)),
            "strided": np.load(tmp_path / "c.npy", mmap_mode="r")[::3, 1:4],
            "plain": rng.normal(size=(5, 2)), "names": np.array(["glass", "steel"]),
            "scalar": np.float64(0.25), "empty": np.zeros((0, 3))}


@pytest.mark.parametrize("compressed", [True, False])
def test_entries_are_numpys_own(tmp_path, compressed, monkeypatch):
    monkeypatch.setattr(npz_files, "BLOCK_BYTES", 1000)  # many blocks per array
    arrays = _arrays(tmp_path)
    ours, theirs = tmp_path / "ours.npz", tmp_path / "theirs.npz"
    save_npz(ours, arrays, compressed=compressed)
    (np.savez_compressed if compressed else np.savez)(theirs, **arrays)
    with zipfile.ZipFile(ours) as a, zipfile.ZipFile(theirs) as b:
        assert a.namelist() == b.namelist()
        for name in a.namelist():
            assert a.read(name) == b.read(name), name  # header and data byte for byte
            assert a.getinfo(name).compress_type == b.getinfo(name).compress_type
    with np.load(ours) as z:
        for k, v in arrays.items():
            np.testing.assert_array_equal(z[k], v)
            assert z[k].dtype == np.asarray(v).dtype


def test_file_object_and_object_arrays(tmp_path):
    with open(tmp_path / "a.npz", "wb") as fh:
        save_npz(fh, {"x": np.arange(4)})
    with np.load(tmp_path / "a.npz") as z:
        np.testing.assert_array_equal(z["x"], np.arange(4))
    with pytest.raises(ValueError, match="object array"):
        save_npz(tmp_path / "b.npz", {"o": np.array([None, 1], dtype=object)})


def test_release_pages_only_for_maps(tmp_path):
    assert not release_pages(np.zeros(3))
    m = np.lib.format.open_memmap(tmp_path / "m.npy", "w+", np.float64, (10,))
    m[:] = 1.5
    assert release_pages(m) and release_pages(m[2:5])
    np.testing.assert_array_equal(m, 1.5)  # written data survive the release (shared map)
    c = np.load(tmp_path / "m.npy", mmap_mode="c")
    c[0] = 7.0
    assert not release_pages(c)  # copy-on-write: its change would be lost
    assert c[0] == 7.0


def _rss_file_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("RssFile:"):
                return int(line.split()[1]) / 1024
    raise KeyError("RssFile")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
def test_a_written_map_does_not_stay_resident(tmp_path, monkeypatch):
    monkeypatch.setattr(npz_files, "BLOCK_BYTES", 1 << 20)
    size_mb = 48
    m = np.lib.format.open_memmap(tmp_path / "big.npy", "w+", np.float64, (size_mb << 17,))
    m[:] = np.arange(m.size, dtype=np.float64)
    m.flush()
    del m
    big = np.load(tmp_path / "big.npy", mmap_mode="r")
    before = _rss_file_mb()
    save_npz(tmp_path / "big.npz", {"big": big}, compressed=False)
    grown = _rss_file_mb() - before
    float(big.sum())  # the measure: reading the whole map makes it resident
    read = _rss_file_mb() - before
    if read < 0.75 * size_mb:
        pytest.skip(f"this system shows {read:.0f} of {size_mb} MB read as resident")
    assert grown < 0.25 * size_mb, (grown, read)
    release_pages(big)
    assert _rss_file_mb() - before < 0.25 * size_mb
    with np.load(tmp_path / "big.npz") as z:
        np.testing.assert_array_equal(z["big"], big)
