"""eq. [1.10] on three area conventions (issue 16): alphaA_overall (W/K), alpha_overall (running
mean of the wall contacts, drumheat) and alpha_overall_A9 (the thesis' fixed A = 45 d^2)."""

import numpy as np
import pytest

import drumheat as dh
from drumheat.results import observe


def test_three_conventions_of_one_curve():
    scene = dh.load_scene("weigler-glass-wall", {"run.duration": 600.0,
                                                 "heat.wall.reference_contacts": 45.0})
    res = dh.run(scene, progress=False)
    ts, traj = res.timeseries, res.trajectory
    T_cap = traj.T @ traj.capacity / traj.capacity.sum()
    Tw = scene.drum.wall_temperature
    alpha_A = np.asarray(observe.alpha_overall(traj.t, T_cap, Tw, T_cap[0], traj.capacity.sum(),
                                               1.0))
    ok = traj.t > 0
    np.testing.assert_allclose(ts["alphaA_overall"][ok], alpha_A[ok], rtol=1e-12)
    np.testing.assert_allclose(ts["alpha_overall"][ok] * traj.wall_area[ok], alpha_A[ok],
                               rtol=1e-12)
    d2 = float(np.mean(traj.diameter**2))
    np.testing.assert_allclose(ts["alpha_overall_A9"][ok] * 45.0 * d2, alpha_A[ok], rtol=1e-12)
    assert "alpha_overall_A9" not in dh.run(scene.replace({"heat.wall.reference_contacts": None,
                                                           "run.duration": 60.0}),
                                            progress=False).timeseries
