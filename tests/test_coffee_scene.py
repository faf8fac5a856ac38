"""Built-in scene fluidized-bed-coffee: bed-level model and particle-resolved model."""

import numpy as np
import pytest

import drumheat as dh
from drumheat.models import convection as corr
from drumheat.models.sphere_conduction import internal_transient_nu
from drumheat.scene import load_scene, scene_from_dict


def small(**over):
    raw = load_scene("fluidized-bed-coffee").to_dict()
    raw["groups"][0]["count"] = 20
    raw["motion"]["layers"] = 4
    for k, v in over.items():
        raw[k] = v
    return scene_from_dict(raw)


def bed_level_scene():
    raw = load_scene("fluidized-bed-coffee").to_dict()
    del raw["heat"]["internal"]
    raw["heat"]["convection"]["internal_resistance"] = "transient-sphere"
    raw["groups"][0]["count"] = 10
    raw["motion"]["layers"] = 1
    raw["run"].update(rtol=1e-10, atol=1e-8)
    return scene_from_dict(raw)


def test_bed_level_simulation_is_the_exercise_closed_form():
    res = dh.run(bed_level_scene(), progress=False)
    ts = res.timeseries
    np.testing.assert_allclose(ts["T_mean"], ts["T_bed_level"], atol=1e-5)
    # the exercise's k from independently evaluated alpha_a and alpha_i (sections 3, 5)
    d, nu, lam2, Pr = 0.006, 20e-6, 0.029, 20e-6 * 1.0 * 1000.0 / 0.029
    nu_single = lambda Re: 2 + np.hypot((2 / (1 + 22 * Pr)) ** (1 / 6) * np.sqrt(Re * Pr),
                                        0.037 * Re**0.8 * Pr / (1 + 2.443 * Re**-0.1
                                                                 * (Pr ** (2 / 3) - 1)))
    a_L = (1 + 1.5 * 0.6) * nu_single(1.2 * d / (0.4 * nu)) * lam2 / d
    a_A = nu_single(10.0 * d / nu) * lam2 / d
    a_a = 0.5 * (a_L + a_A)
    Bi, Fo = a_a * d / 0.1, 0.1 * 150.0 / (630 * 1700 * d**2)
    a_i = float(internal_transient_nu(Bi, Fo)) * 0.1 / d
    k = 1 / (1 / a_i + 1 / a_a)
    ntu = k * 6 * 60 / (d * 630) / (3.0 * 1000.0)
    T = float(corr.batch_bed_mean_temperature(150.0, 573.15, 293.15, ntu, 60, 1700, 3.0, 1000))
    assert ts["T_bed_level"].iloc[-1] == pytest.approx(T, abs=1e-9)
    # outlet gas between inlet and bed (exercise section 8)
    assert np.all(ts["T_gas_out"] >= 293.15 - 1e-9) and np.all(ts["T_gas_out"] <= ts["T_mean"] + 1e-9)


def test_particle_resolved_bed_is_conservative_and_close_to_the_bed_level_model():
    res = dh.run(small(), progress=False)
    ts = res.timeseries
    assert res.summary["energy_balance_rel_error"] < 1e-10
    assert np.all(np.diff(ts["T_mean"]) < 0)
    assert np.all(ts["T_gas_out"] >= 293.15 - 1e-9)
    assert np.all(ts["T_surface_mean"] <= ts["T_centre_mean"] + 1e-9)
    assert abs(ts["T_mean"].iloc[-1] - ts["T_bed_level"].iloc[-1]) < 3.0  # K
    assert res.trajectory.position.shape[-1] == 3
