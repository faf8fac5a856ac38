"""The fault battery of the reliability issue: every mistake a user can make ends in one
paragraph naming the key, exit code 2 and nothing written (no traceback, no silent wrong
result)."""

import numpy as np
import pandas as pd
import pytest

from drumheat.analysis.calibrate import CalibrationDataError, fit
from drumheat.cli import main
from drumheat.scene import load_scene


def refused(capsys, tmp_path, args, key):
    out = tmp_path / "out"
    code = main(["run"] + args + ["--out", str(out), "--quiet"])
    err = " ".join(capsys.readouterr().err.split())
    assert code == 2, err
    assert key in err, err
    assert err.startswith("drumheat: error:") and "Traceback" not in err
    assert not out.exists()  # nothing half-written
    return err


def test_dem_time_step_above_the_critical_one(capsys, tmp_path):
    refused(capsys, tmp_path, ["weigler-mixed", "--set", "dem.dt=0.01"], "dem.dt")


def test_temperatures_in_celsius(capsys, tmp_path):
    err = refused(capsys, tmp_path, ["weigler-static", "--set", "groups.0.temperature=25",
                                     "--set", "groups.1.temperature=45"],
                  "groups.0.temperature")
    assert "degrees Celsius" in err and "298.15" in err


def test_deposition_that_cannot_place_the_particles(capsys, tmp_path):
    refused(capsys, tmp_path, ["weigler-static", "--set", "groups.0.count=80",
                               "--set", "groups.1.count=80"], "groups")


@pytest.mark.parametrize("content", [b"this is no npz", None])
def test_corrupt_or_missing_packing_file(content, capsys, tmp_path):
    f = tmp_path / "p.npz"
    if content is not None:
        f.write_bytes(content)
    refused(capsys, tmp_path, ["weigler-static", "--set", "packing.method=file",
                               "--set", f"packing.file={f}"], "packing.file")


def test_packing_with_particles_at_one_point_or_outside_the_drum(capsys, tmp_path):
    f = tmp_path / "p.npz"
    np.savez(f, position=np.zeros((70, 2)))
    assert "overlap" in refused(capsys, tmp_path, ["weigler-static", "--set",
                                                   "packing.method=file", "--set",
                                                   f"packing.file={f}"], "packing.file")
    np.savez(f, position=np.random.default_rng(0).uniform(1.0, 2.0, (70, 2)))
    assert "outside the drum" in refused(capsys, tmp_path, ["weigler-static", "--set",
                                                            "packing.method=file", "--set",
                                                            f"packing.file={f}"],
                                         "packing.file")


def test_corrupt_recording_and_one_of_other_particles(capsys, tmp_path):
    f = tmp_path / "contacts.npz"
    f.write_bytes(b"garbage")
    refused(capsys, tmp_path, ["weigler-glass-random", "--set", "motion.model=replay",
                               "--set", f"replay.file={f}"], "replay.file")
    # a recording of other particles (4 mm instead of 8 mm) is refused
    np.savez(f, interval=0.05, n_particles=370, pair_ptr=np.zeros(3, int),
             diameter=np.full(370, 0.004))
    err = refused(capsys, tmp_path, ["weigler-glass-random", "--set", "motion.model=replay",
                                     "--set", f"replay.file={f}", "--set",
                                     "run.output_interval=0.1", "--set", "run.duration=0.1"],
                  "replay.file")
    assert "diameters" in err


def test_unstable_replay_step_of_a_coupled_drum(capsys, tmp_path):
    """wall alpha 1e6 with 50 ms recording intervals: once ran to -745 K and 1238 K."""
    refused(capsys, tmp_path, ["weigler-glass-drum-47.75", "--set", "heat.wall.alpha=1e6"],
            "dem.record_interval")


def test_stiff_scene_on_the_adaptive_solver(capsys, tmp_path):
    refused(capsys, tmp_path, ["weigler-glass-wall", "--set", "heat.wall.alpha=1e9",
                               "--set", "run.duration=60", "--set", "run.output_interval=60"],
            "run.solver")


def test_run_estimated_above_an_hour_needs_yes(capsys, tmp_path):
    """The documented default stiffness (E A_p / d_p) of a 30-minute DEM run: days."""
    err = refused(capsys, tmp_path, ["weigler-static", "--set", "motion.model=dem",
                                     "--set", "dem.safety_factor=0.1"], "--yes")
    assert "dem.stiffness" in err and "dem.replay_after" in err and "estimated" in err


def test_calibration_refuses_unusable_data(tmp_path):
    scene = load_scene("weigler-heating", {"run.duration": 600.0})
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    with pytest.raises(CalibrationDataError, match="CSV"):
        fit(scene, empty, ["heat.loss.alphaA"])
    mixed = pd.DataFrame({"t": [0.0, 60.0, 120.0], "T_mean": [300.0, 35.0, 310.0]})
    with pytest.raises(CalibrationDataError, match="degrees Celsius"):
        fit(scene, mixed, ["heat.loss.alphaA"])
    good = pd.DataFrame({"t": [0.0, 60.0, 120.0], "T_mean": [300.0, 305.0, 310.0]})
    with pytest.raises(CalibrationDataError, match="does not allow"):
        fit(scene, good, ["heat.loss.alphaA"], bounds={"heat.loss.alphaA": (-1e-3, 1e-3)})
    with pytest.raises(CalibrationDataError, match="finite"):
        fit(scene, good, {"heat.loss.alphaA": float("nan")})
