"""Nothing lost: checkpoints, resume bit for bit, results written as the run goes.

A run is killed in-process by raising at a chosen chunk (the motion model's host-side step
between chunks raises); its result folder then holds a readable partial time series, the
summary marked incomplete and a checkpoint of the last completed chunk, from which
``run(..., resume=True)`` continues to exactly the numbers of a run that was not interrupted.
One real Ctrl-C (SIGINT) on the command line does the same.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import equinox as eqx
import jax
import numpy as np
import pandas as pd
import pytest

import drumheat as dh
from drumheat.motion import MOTIONS, make_motion
from drumheat.runner.checkpoint import CheckpointError
from drumheat.scene import load_scene, scene_from_dict

ROOT = Path(__file__).resolve().parents[1]


class Killed(RuntimeError):
    pass


def kill_at(monkeypatch, name: str, chunk: int):
    """Make motion model ``name`` raise in its host-side step after chunk ``chunk``."""
    cls = MOTIONS[name]
    original = cls.between
    count = {"n": 0}

    def between(self, state, log, t):
        count["n"] += 1
        if count["n"] == chunk:
            raise Killed(f"killed after chunk {chunk}")
        return original(self, state, log, t)

    monkeypatch.setattr(cls, "between", between)


def assert_identical(a, b):
    np.testing.assert_array_equal(a.T, b.T)
    np.testing.assert_array_equal(a.trajectory.position, b.trajectory.position)
    pd.testing.assert_frame_equal(a.timeseries, b.timeseries, check_exact=True)


def dem_scene(**over):
    """30 aluminium spheres in the 50 mm drum at 12 rpm (as tests/test_coupled.py)."""
    raw = load_scene("weigler-static").to_dict()
    raw["name"] = "resume-test"
    raw["groups"][0]["count"] = raw["groups"][1]["count"] = 15
    raw["run"].update(duration=0.2, output_interval=0.05, solver="explicit")
    raw["drum"]["rpm"] = 12.0
    raw["motion"] = {"model": "dem"}
    raw["dem"] = {"stiffness": 2.0e4, "thermal_substeps": 1, "safety_factor": 0.2}
    scene = scene_from_dict(raw)
    return scene.replace(over) if over else scene


def kill_and_resume(scene, name, chunk, tmp_path, monkeypatch, inspect=None):
    """Kill a run into a folder after ``chunk`` chunks, resume it, and check that the result
    equals a straight run's bit for bit; ``inspect(checkpoint path)`` is called before the
    resume."""
    ref = dh.run(scene, progress=False)
    out = tmp_path / "run"
    with monkeypatch.context() as m:
        kill_at(m, name, chunk)
        with pytest.raises(Killed):
            dh.run(scene, out=out, progress=False)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] is False and "Killed" in summary["status"]
    assert (out / "checkpoint.npz").is_file()
    partial = pd.read_csv(out / "timeseries.csv")  # readable, one row per output so far
    assert 1 <= len(partial) < len(ref.timeseries)
    np.testing.assert_allclose(partial["T_mean"], ref.timeseries["T_mean"][:len(partial)],
                               rtol=1e-9)  # the file holds 10 significant digits
    if inspect is not None:
        inspect(out / "checkpoint.npz")
    res = dh.run(scene, out=out, progress=False, resume=True)
    assert_identical(res, ref)
    assert json.loads((out / "summary.json").read_text())["complete"] is True
    assert not (out / "checkpoint.npz").exists()
    return res


def test_static_bed_resumes_bit_for_bit(tmp_path, monkeypatch):
    scene = load_scene("weigler-static", {"run.duration": 300.0})
    kill_and_resume(scene, "static", 4, tmp_path, monkeypatch)


def test_coupled_dem_resumes_bit_for_bit(tmp_path, monkeypatch):
    kill_and_resume(dem_scene(), "dem", 2, tmp_path, monkeypatch)


def test_coupled_dem_with_friction_heat_resumes_bit_for_bit(tmp_path, monkeypatch):
    """The friction-heat accumulators (a FrictionBook in the state) travel in the checkpoint."""
    res = kill_and_resume(dem_scene(**{"heat.friction.partition": "half"}), "dem", 2, tmp_path,
                          monkeypatch)
    assert res.timeseries["Q_friction"].iloc[-1] > 0


def test_coupled_dem_with_a_drum_wall_resumes_bit_for_bit(tmp_path, monkeypatch):
    """The drum wall's segment temperatures and accounts travel in the checkpoint."""
    res = kill_and_resume(dem_scene(**{
        "drum.wall_temperature": 320.0, "heat.wall.alpha": 114.0,
        "heat.drum_wall.thickness": 0.002, "heat.drum_wall.outside": "temperature",
        "heat.drum_wall.outer_temperature": 350.0}), "dem", 2, tmp_path, monkeypatch)
    assert res.timeseries["Q_outside"].iloc[-1] > 0


@pytest.mark.parametrize("chunk", [3, 6])  # while coupled / during the replay
def test_dem_with_replay_after_resumes_bit_for_bit(chunk, tmp_path, monkeypatch):
    scene = dem_scene(**{"run.duration": 0.4, "run.output_interval": 0.1,
                         "dem.record_interval": 0.05, "dem.replay_after": 0.2})

    phases = []

    def replay_phase_holds_no_networks(path):
        """A checkpoint of the replay phase holds the thermal model, the temperatures, the
        accounts and the interval counter, not the recorded networks (the recording stays in
        the folder's files)."""
        with np.load(path) as ck:
            meta = json.loads(str(ck["meta"]))
        phases.append(meta["state"]["phase"])
        if phases[-1] == "replay":
            assert "Recording(2 intervals of 0.05 s, 30 particles)" in meta["state"]["structure"]
            model = make_motion(scene).model()[0]
            model_arrays = len(jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_array)))
            assert meta["n_leaves"] == model_arrays + 1 + len(model.accounts) + 1  # T, Q, g

    res = kill_and_resume(scene, "dem", chunk, tmp_path, monkeypatch,
                          inspect=replay_phase_holds_no_networks)
    assert phases == ["dem" if chunk == 3 else "replay"]
    assert (tmp_path / "run" / "contacts.npz").is_file()
    assert res.summary["energy_balance_rel_error"] < 1e-12


def test_recording_stays_in_the_folder_and_resumes(tmp_path, monkeypatch):
    """The contact recording of a run with a result folder goes to ``.log/`` as it is
    recorded; the checkpoint names its lengths instead of holding it; the resumed run gives
    the numbers of a run without a folder (recording in memory), and its ``contacts.npz`` is
    that of a run that was not interrupted, array for array."""
    scene = dem_scene(**{"run.duration": 0.3, "run.output_interval": 0.1,
                         "dem.record_interval": 0.025})
    dh.run(scene, out=tmp_path / "ref", progress=False)
    out = tmp_path / "run"
    with monkeypatch.context() as m:
        kill_at(m, "dem", 7)
        with pytest.raises(Killed):
            dh.run(scene, out=out, progress=False)
    assert (out / ".log" / "contacts.pair_i.bin").stat().st_size > 0
    with np.load(out / "checkpoint.npz") as ck:
        assert ck["log/recorder/spooled"] and "log/recorder/pair_i" not in ck.files
        assert len(ck["log/recorder/pair_ptr"]) == 7  # six intervals recorded before the stop
    res = dh.run(scene, out=out, progress=False, resume=True)
    assert_identical(res, dh.run(scene, progress=False))  # as the run with it in memory
    assert not (out / ".log").exists()  # the complete result replaced the running folder
    res.save(tmp_path / "again", figures=False)  # the result still has its recording
    for folder in (out, tmp_path / "again"):
        with np.load(tmp_path / "ref" / "contacts.npz") as a, \
                np.load(folder / "contacts.npz") as b:
            assert a.files == b.files
            for key in a.files:
                np.testing.assert_array_equal(a[key], b[key])


def test_resume_without_the_recorded_files_says_so(tmp_path, monkeypatch):
    """A checkpoint whose recording files were removed from the folder cannot be continued:
    a CheckpointError that says so, not a traceback from deep inside."""
    import shutil

    scene = dem_scene(**{"dem.record_interval": 0.025})
    out = tmp_path / "run"
    with monkeypatch.context() as m:
        kill_at(m, "dem", 3)
        with pytest.raises(Killed):
            dh.run(scene, out=out, progress=False)
    shutil.rmtree(out / ".log")
    with pytest.raises(CheckpointError, match="contacts.pair_i.bin.*start anew"):
        dh.run(scene, out=out, progress=False, resume=True)


def test_replay_resumes_bit_for_bit(tmp_path, monkeypatch):
    rec = dem_scene(**{"dem.record_interval": 0.01})
    dh.run(rec, out=tmp_path / "rec", progress=False)
    raw = rec.to_dict()
    raw["motion"] = {"model": "replay"}
    raw["replay"] = {"file": str(tmp_path / "rec" / "contacts.npz")}
    raw["run"]["duration"] = 0.6
    del raw["dem"]
    kill_and_resume(scene_from_dict(raw), "replay", 5, tmp_path, monkeypatch)


@pytest.mark.parametrize("chunk", [2, 6])  # while coupled / during the replay
def test_frames_on_disk_resume_bit_for_bit(chunk, tmp_path, monkeypatch):
    """Every array of every output row spooled to disk (RowSpool.MIN_SIZE = 1): the frames of
    a stopped run stay in the folder, the checkpoint names them, the resumed run reads them."""
    from drumheat.motion.rows import RowSpool

    monkeypatch.setattr(RowSpool, "MIN_SIZE", 1)
    scene = dem_scene(**{"run.duration": 0.4, "run.output_interval": 0.1,
                         "dem.record_interval": 0.05, "dem.replay_after": 0.2})
    out = tmp_path / "run"
    with monkeypatch.context() as m:
        kill_at(m, "dem", chunk)
        with pytest.raises(Killed):
            dh.run(scene, out=out, progress=False)
    frames = sorted(p.name for p in (out / ".frames").iterdir() if p.name.isdigit())
    assert frames and frames[0] == "0000000"  # the first row's arrays went to disk
    with np.load(out / "checkpoint.npz") as ck:  # the checkpoint names them, holds none
        assert not any(k.startswith("rows/") and ck[k].size > 1 for k in ck.files)
    with np.load(out / "particles.npz") as part:  # the partial frames of the stopped run
        assert part["T"].shape[0] == len(pd.read_csv(out / "timeseries.csv"))
    res = dh.run(scene, out=out, progress=False, resume=True)
    assert_identical(res, dh.run(scene, progress=False))
    assert not (out / ".frames").exists()  # the complete result replaced the running folder


def test_row_spool_is_a_list_of_rows(tmp_path):
    from drumheat.motion.rows import RowSpool, stack_arrays, stack_rows

    rows = [{"T": np.arange(6.0) + k, "Q": {"gas": np.float64(k)}} for k in range(4)]
    spool = RowSpool(tmp_path / "spool", min_size=5)
    for r in rows:
        spool.append(r)
    assert len(spool) == 4 and isinstance(spool[2]["T"], np.memmap)
    np.testing.assert_array_equal(spool[3]["T"], rows[3]["T"])
    stacked = stack_rows(spool)
    np.testing.assert_array_equal(stacked["T"], np.stack([r["T"] for r in rows]))
    np.testing.assert_array_equal(stacked["Q"]["gas"], [0.0, 1.0, 2.0, 3.0])
    assert isinstance(stacked["T"], np.memmap)
    assert stack_arrays(rows, "T", (r["T"] for r in rows)).shape == (4, 6)
    # an empty dict (a run without heat accounts) comes back as one
    empty = RowSpool(tmp_path / "empty", min_size=5)
    empty.append({"T": np.arange(6.0), "Q": {}})
    assert empty[0]["Q"] == {} and stack_rows(empty)["Q"] == {}
    # a checkpoint's view of it, and the spool rebuilt from it without the later rows
    again = RowSpool.from_state(tmp_path / "spool", spool.state()[:2], min_size=5)
    assert len(again) == 2 and not (tmp_path / "spool" / "0000003").exists()
    np.testing.assert_array_equal(again[1]["T"], rows[1]["T"])


def test_checkpoint_of_another_scene_is_refused(tmp_path, monkeypatch):
    scene = load_scene("weigler-static", {"run.duration": 300.0})
    with monkeypatch.context() as m:
        kill_at(m, "static", 3)
        with pytest.raises(Killed):
            dh.run(scene, out=tmp_path / "run", progress=False)
    with pytest.raises(CheckpointError, match="another scene"):
        dh.run(scene.replace({"heat.contact.alpha": 90.0}), out=tmp_path / "run",
               progress=False, resume=True)


def _interrupted_dem_checkpoint(tmp_path, monkeypatch):
    """``(result folder, checkpoint arrays)`` of the coupled DEM scene killed after its
    second chunk."""
    out = tmp_path / "run"
    with monkeypatch.context() as m:
        kill_at(m, "dem", 2)
        with pytest.raises(Killed):
            dh.run(dem_scene(), out=out, progress=False)
    with np.load(out / "checkpoint.npz") as f:
        return out, {k: f[k] for k in f.files}


def test_checkpoint_of_another_state_layout_is_refused(tmp_path, monkeypatch):
    """A checkpoint stores its state's layout (drumheat.runner.checkpoint.state_structure):
    leaves of a state laid out otherwise (an earlier development version) are refused instead
    of landing in the wrong places."""
    out, data = _interrupted_dem_checkpoint(tmp_path, monkeypatch)
    meta = json.loads(str(data["meta"]))
    assert "CoupledHeat" in meta["state"]["structure"]
    meta["state"]["structure"] = meta["state"]["structure"].replace("CoupledHeat", "dict")
    data["meta"] = np.array(json.dumps(meta))
    np.savez(out / "checkpoint.npz", **data)
    with pytest.raises(ValueError, match="laid out otherwise"):
        dh.run(dem_scene(), out=out, progress=False, resume=True)


def test_checkpoint_array_of_another_kind_is_refused(tmp_path, monkeypatch):
    """A state array of another kind (the contact times of the coupled heat were float64
    seconds until 0.2.0.dev3, whole steps in int32 since) is refused instead of being cast
    (seconds read as step counts)."""
    out, data = _interrupted_dem_checkpoint(tmp_path, monkeypatch)
    dyn = eqx.partition(make_motion(dem_scene()).initial_state(), eqx.is_array)[0]
    paths = [jax.tree_util.keystr(p) for p, _ in jax.tree_util.tree_leaves_with_path(dyn)]
    k = paths.index(".extra.pair.time")  # the pairs' contact times since the thermal step
    assert data[f"state/{k}"].dtype == np.int32
    data[f"state/{k}"] = data[f"state/{k}"] * 1e-5  # as seconds of 1e-5 s steps
    np.savez(out / "checkpoint.npz", **data)
    with pytest.raises(ValueError, match="another development version"):
        dh.run(dem_scene(), out=out, progress=False, resume=True)


def test_a_failing_run_keeps_the_earlier_result(tmp_path, monkeypatch):
    scene = load_scene("weigler-static", {"run.duration": 300.0})
    out = tmp_path / "run"
    dh.run(scene, out=out, progress=False)
    before = (out / "timeseries.csv").read_text()
    with monkeypatch.context() as m:
        kill_at(m, "static", 3)
        with pytest.raises(Killed):
            dh.run(scene.replace({"heat.contact.alpha": 90.0}), out=out, progress=False)
    kept = tmp_path / "run.previous"
    assert (kept / "timeseries.csv").read_text() == before  # the earlier result, intact
    assert json.loads((kept / "summary.json").read_text())["complete"] is True
    # a new run that completes replaces the partial one and removes the kept result
    dh.run(scene, out=out, progress=False)
    assert not kept.exists() and (out / "timeseries.csv").read_text() == before


def test_two_runs_into_one_folder_are_refused(tmp_path):
    from drumheat.results.files import RUN_LOCK, ResultFolderError, check_out_dir, register_outputs

    out = tmp_path / "run"
    out.mkdir()
    (out / "summary.json").write_text('{"complete": false}')
    (out / "scene.toml").write_text("")
    register_outputs(out, ["summary.json", "scene.toml", RUN_LOCK])
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (out / RUN_LOCK).write_text(json.dumps({"pid": sleeper.pid,
                                                "host": os.uname().nodename}))
        with pytest.raises(ResultFolderError, match="still going"):
            check_out_dir(out)
    finally:
        sleeper.kill()
        sleeper.wait()
    check_out_dir(out)  # the run ended: its lock no longer counts


def test_ctrl_c_on_the_command_line_stops_cleanly_and_resumes(tmp_path):
    """A real SIGINT: exit code 3, partial results and a checkpoint; --resume completes."""
    out = tmp_path / "run"
    sets = ["--set", "run.duration=1800", "--set", "run.output_interval=5",
            "--set", "run.solver=explicit"]
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "drumheat.cli", "run", "weigler-static", "--out", str(out),
           "--quiet"] + sets
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    csv = out / "timeseries.csv"
    deadline = time.time() + 300
    while time.time() < deadline and proc.poll() is None:
        if csv.is_file() and len(csv.read_text().splitlines()) >= 3:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 3, err
    assert "--resume" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] is False and (out / "checkpoint.npz").is_file()
    assert len(pd.read_csv(csv)) >= 2
    done = subprocess.run(cmd + ["--resume"], env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    ref = subprocess.run([sys.executable, "-m", "drumheat.cli", "run", "weigler-static",
                          "--out", str(tmp_path / "ref"), "--quiet"] + sets, env=env,
                         capture_output=True, text=True, timeout=600)
    assert ref.returncode == 0, ref.stderr
    pd.testing.assert_frame_equal(pd.read_csv(csv), pd.read_csv(tmp_path / "ref" /
                                                                "timeseries.csv"))


def test_a_run_without_heat_accounts_completes_into_a_folder(tmp_path):
    """Mechanics only (the mixing scenes have no heat tables): the output rows carry an empty
    heat-account dict, which the spool and the checkpoint must keep."""
    scene = load_scene("weigler-glass-mixing-9.55", {
        "groups.0.count": 10, "groups.1.count": 10, "run.duration": 0.1,
        "run.output_interval": 0.05, "run.checkpoint_interval": 0.05})
    res = dh.run(scene, out=tmp_path / "mix", progress=False)
    assert res.summary["complete"] and "interfraction_contacts" in res.timeseries
