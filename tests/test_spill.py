"""Chunks advanced in place, their start kept on disk (drumheat.runner.spill).

A run with a result folder on the CPU advances the coupled DEM's chunks in place (buffer
donation: one state in memory instead of two) and keeps each chunk's start in a file of the
folder's log directory, read back only for a redo after a neighbour-buffer overflow or as the
last good state of a failure. Such a run gives the numbers of a run without a folder (which
keeps the start in memory) bit for bit, through an overflow, and a failure inside a chunk
leaves a checkpoint from which the run resumes to the same numbers.
"""

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import drumheat as dh
from drumheat.mechanics import DEM, DEMError
from drumheat.motion import MOTIONS
from drumheat.runner.spill import SPILL_DIR, StartSpill

from test_resume import assert_identical, dem_scene


def _tree():
    return {"x": jnp.arange(12.0).reshape(4, 3), "i": jnp.arange(5, dtype=jnp.int32),
            "b": jnp.array([True, False]), "f": jnp.ones(3, jnp.float32)}


def test_a_saved_state_reads_back_as_it_was(tmp_path):
    spill = StartSpill(tmp_path / "log")
    tree = _tree()
    spill.save(tree)
    back = spill.load()
    assert (tmp_path / "log" / SPILL_DIR / "0.npy").is_file()
    for k in tree:
        assert back[k].dtype == tree[k].dtype and back[k].shape == tree[k].shape
        np.testing.assert_array_equal(back[k], tree[k])
    # in buffers of their own, not the files' mappings (on the CPU jax.device_put of a mapped
    # array keeps the mapping as its buffer, which a donation must not write)
    maps = Path("/proc/self/maps")
    if maps.exists():
        assert str(spill.path) not in maps.read_text()
    # a state the loop did not make is not its own (it is read back before a donation) ...
    assert not spill.owns(tree) and all(back[k] is not tree[k] for k in tree)
    # ... one that a chunk returned is
    spill.adopt(back)
    assert spill.owns(back) and not spill.owns(tree)
    spill.close()
    assert not any((tmp_path / "log").iterdir())


def test_a_weakly_typed_leaf_stays_in_memory_weakly_typed(tmp_path):
    """A weakly typed scalar (Schluender's coefficients in the state of herz-sectional-drum's
    heat model) has no file; it comes back weakly typed with its value, also after the chunk
    donated (deleted) the state's own."""
    spill = StartSpill(tmp_path)
    weak = jnp.asarray(2.5) * 3.0  # weakly typed: from Python numbers
    tree = {"alpha": weak, "x": jnp.arange(6.0)}
    assert weak.weak_type
    spill.save(tree)
    weak.delete()  # as the chunk's donation does
    back = spill.load()
    assert back["alpha"].weak_type and float(back["alpha"]) == 7.5
    assert not back["x"].weak_type
    np.testing.assert_array_equal(back["x"], np.arange(6.0))
    assert sorted(p.name for p in spill.path.iterdir()) == ["1.npy"]  # x alone
    again = spill.load()  # a copy each time: a redo may donate the one it was given
    assert again["alpha"] is not back["alpha"] and again["alpha"].weak_type


def test_only_jax_arrays_are_spilled(tmp_path):
    spill = StartSpill(tmp_path)
    with pytest.raises(TypeError, match="JAX arrays"):
        spill.save({"t": np.ones(3)})
    with pytest.raises(RuntimeError, match="no state"):
        spill.load()


#: the run loop keeps a chunk's start on disk on the CPU only (on a GPU it stays in host memory)
cpu_only = pytest.mark.skipif(jax.default_backend() != "cpu",
                              reason="the start is kept on disk in runs on the CPU")


def _count_in_place(monkeypatch):
    calls = {"in_place": 0}
    original = DEM.run_steps_in_place

    def counted(self, state, n_steps):
        calls["in_place"] += 1
        return original(self, state, n_steps)

    monkeypatch.setattr(DEM, "run_steps_in_place", counted)
    return calls


@cpu_only
def test_a_run_into_a_folder_advances_in_place_with_the_same_numbers(tmp_path, monkeypatch):
    scene = dem_scene()
    ref = dh.run(scene, progress=False)
    calls = _count_in_place(monkeypatch)
    res = dh.run(scene, out=tmp_path / "run", progress=False)
    assert calls["in_place"] == 2 + 4  # the estimate's two warm-ups, the scene's four chunks
    assert_identical(res, ref)
    assert not (tmp_path / "run" / ".log").exists()  # the spill went with the running folder


@cpu_only
def test_the_estimate_warms_up_in_place_on_the_runs_own_chunk():
    """For a run into a folder the estimate's timed warm-up runs the chunk the run will run,
    in the buffers of an initial state of its own (one state in memory, one compilation for
    both), and leaves the motion model's own arrays alone."""
    from drumheat.motion import make_motion
    from drumheat.runner.loop import estimate

    motion = make_motion(dem_scene())
    cost = estimate(motion, in_place=True)
    assert cost["seconds"] > 0 and cost["warmup_steps"] >= 1
    assert motion.dem._run_chunk._cache_size() == 1  # compiled for the run's chunks
    assert motion.dem._run_steps._cache_size() == 0  # the plain chunk was not compiled
    again = estimate(motion)  # the initial state's shared arrays were not donated
    assert again["mechanical_steps"] == cost["mechanical_steps"]
    assert motion.dem._run_steps._cache_size() == 1


@cpu_only
def test_a_failed_chunk_in_place_is_redone_from_the_spill(tmp_path, monkeypatch):
    """The first chunk fails its check (as a neighbour-list overflow does): its start comes
    back from the file and the chunk is redone from it, as a run without a folder redoes it
    from the start it kept in memory; the same numbers as a run whose chunks all pass."""
    scene = dem_scene()
    ref = dh.run(scene, progress=False)
    cls = MOTIONS["dem"]
    passes, check = cls.passes, cls.check
    calls = {"passes": 0, "redo": 0, "loads": 0}

    def fails_once(self, new):
        calls["passes"] += 1
        return passes(self, new) and calls["passes"] > 1

    def redo_once(self, start, end, attempt=0):
        if calls["redo"] == 0:  # the first chunk is redone from its start, unchanged
            calls["redo"] += 1
            return start
        return check(self, start, end, attempt)

    load = StartSpill.load

    def counted(self):
        calls["loads"] += 1
        return load(self)

    monkeypatch.setattr(cls, "passes", fails_once)
    monkeypatch.setattr(cls, "check", redo_once)
    monkeypatch.setattr(StartSpill, "load", counted)
    res = dh.run(scene, out=tmp_path / "run", progress=False)
    assert calls["loads"] == 1 and calls["redo"] == 1
    assert_identical(res, ref)


@cpu_only
def test_a_failure_inside_an_in_place_chunk_checkpoints_its_start(tmp_path, monkeypatch):
    """The second chunk fails its check (as a NaN would): the failure checkpoint holds the
    chunk's start, read back from the file (the start's buffers went into the chunk), and the
    run resumes from it to the numbers of a run that did not fail."""
    scene = dem_scene()
    ref = dh.run(scene, progress=False)
    cls = MOTIONS["dem"]
    passes, check = cls.passes, cls.check
    count = {"n": 0}

    def failing_passes(self, end):
        count["n"] += 1
        return False if count["n"] == 2 else passes(self, end)

    def failing_check(self, start, end, attempt=0):
        if count["n"] == 2:
            raise DEMError("chunk 2 failed (test)", start)
        return check(self, start, end, attempt)

    out = tmp_path / "run"
    with monkeypatch.context() as m:
        m.setattr(cls, "passes", failing_passes)
        m.setattr(cls, "check", failing_check)
        with pytest.raises(DEMError, match="chunk 2 failed"):
            dh.run(scene, out=out, progress=False)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] is False and "chunk 2 failed" in summary["status"]
    assert not (out / ".log" / SPILL_DIR).exists()  # the spill is removed once written out
    res = dh.run(scene, out=out, progress=False, resume=True)
    assert_identical(res, ref)
