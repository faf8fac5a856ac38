"""Built-in scene staltner-slag-particle: one slag droplet through the granulator phases."""

import math

import numpy as np
import pandas as pd
import pytest

import drumheat as dh
from drumheat.models.granulator import droplet_speed, path_geometry, wall_heat_per_mass
from drumheat.scene import load_scene


@pytest.fixture(scope="module")
def runs():
    return {d: dh.run(load_scene("staltner-slag-particle", {"groups.0.diameter": d}),
                      progress=False) for d in (0.0005, 0.001, 0.002, 0.004)}


def test_phase_times_and_enthalpy_matched_contact(runs):
    for d, res in runs.items():
        ph = res.trajectory.info["phases"]
        assert res.summary["phases"] == ph
        g = res.scene.granulator
        p, v = path_geometry(g), droplet_speed(g)
        assert v == pytest.approx(0.8 * math.pi * 0.75 * 15.0)  # [4.1]
        assert ph[0]["duration_s"] == pytest.approx(p["s1"] / v, rel=1e-12)
        assert ph[2]["duration_s"] == pytest.approx(p["s3"] / v, rel=1e-12)
        assert ph[1]["duration_s"] > 0
        # Phase 2 removes exactly Q_W/m_S per kg ([4.8], [4.9])
        m = 2690.0 * math.pi * d**3 / 6
        assert -ph[1]["Q_wall_J"] + ph[0]["Q_wall_J"] == pytest.approx(
            wall_heat_per_mass(g) * m, rel=1e-9)
        T = [row["T_mean_K"] for row in ph]
        assert 1623.15 > T[0] > T[1] > T[2] > 373.15
    # larger droplets stay hotter and need longer contact
    T_end = [r.timeseries["T_mean"].iloc[-1] for r in runs.values()]
    assert np.all(np.diff(T_end) > 0)


def test_result_files_and_balance(runs, tmp_path):
    res = runs[0.002]
    assert res.summary["energy_balance_rel_error"] < 1e-7
    out = res.save(tmp_path / "slag")
    for name in ("timeseries.csv", "summary.json", "particles.npz", "phases.csv",
                 "radial_profiles.png", "profiles.npz"):
        assert (out / name).exists()
    ts = pd.read_csv(out / "timeseries.csv")
    assert {"t", "T_mean", "T_mean:slag", "T_surface", "T_centre", "phase", "Q_radiation",
            "Q_loss", "Q_wall"} <= set(ts.columns)
    prof = np.load(out / "profiles.npz")
    assert prof["T"].shape == (len(prof["t"]), 150)
    assert np.all(np.isfinite(prof["T"]))


@pytest.mark.slow
def test_shell_and_step_convergence():
    res = {}
    for shells, steps in ((150, 400), (300, 1600)):
        r = dh.run(load_scene("staltner-slag-particle", {
            "groups.0.diameter": 0.004, "heat.internal.shells": shells,
            "granulator.steps_per_phase": steps}), progress=False)
        res[shells] = r.trajectory.info["phases"]
    for a, b in zip(res[150], res[300]):
        assert a["T_mean_K"] == pytest.approx(b["T_mean_K"], abs=0.2)
        assert a["duration_s"] == pytest.approx(b["duration_s"], rel=0.01)
