"""The built-in 3D drum (glass-drum-3d, the LIGGGHTS benchmark drum): it loads with the
benchmark's set-up, and a small slice of it runs, heats from the wall and keeps its energy."""

import pytest

import drumheat as dh


def test_scene_is_the_benchmark_drum():
    s = dh.load_scene("glass-drum-3d")
    assert s.dim == 3 and s.n_particles == 2000
    assert s.drum.diameter == 0.25 and s.drum.rpm == 9.55 and s.drum.depth == 0.052
    assert s.dem.stiffness == 1.0e5 and s.dem.friction == 0.5 and s.dem.restitution == 0.5
    # the documented N knob keeps the fill level: depth = N x 2.6e-5 m
    big = s.replace({"groups.0.count": 10000, "drum.depth": 0.26})
    assert big.n_particles / big.drum.depth == pytest.approx(s.n_particles / s.drum.depth)


def test_a_small_slice_runs_and_heats():
    s = dh.load_scene("glass-drum-3d", {
        "groups.0.count": 150, "drum.depth": 0.026, "run.duration": 0.02,
        "run.output_interval": 0.01, "dem.replay_after": None, "dem.record_interval": None,
        "dem.replay_cycle": None})
    res = dh.run(s, progress=False)
    assert res.summary["complete"] and res.summary["energy_balance_rel_error"] < 1e-10
    assert res.timeseries["Q_wall"].iloc[-1] > 0  # the poured bed lies on the hot wall
    assert res.trajectory.position.shape == (3, 150, 3)
