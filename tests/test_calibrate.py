"""Differentiable calibration: gradients, fits, data refusals, the alpha_pp -> lambda_bed line."""

from importlib.resources import files

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np
import pandas as pd
import pytest

from drumheat.analysis.calibrate import (CalibrationDataError, Experiment, calibrate_lambda_bed, fit,
                                read_measurements)
from drumheat.motion import make_motion
from drumheat.runner import trace
from drumheat.scene import load_scene, scene_from_dict

DATA = files("drumheat") / "data"


def mini_wall():
    """70 glass spheres in a 100 mm drum heated through the wall (a small A7 bed)."""
    raw = dict(name="mini-wall", dim=2,
               run=dict(duration=3000.0, output_interval=100.0, seed=3, rtol=1e-12, atol=1e-10),
               drum=dict(diameter=0.1, wall_temperature=343.0),
               groups=[dict(name="glass", count=70, diameter=0.008, material="glass",
                            temperature=293.0)],
               heat=dict(contact=dict(alpha=57.0), wall=dict(alpha=114.0)))
    return scene_from_dict(raw)


# -- gradients ------------------------------------------------------------------------------

KEYS = ("heat.contact.alpha", "heat.wall.alpha", "groups.0.temperature")


def _objective(bed):
    w = np.linspace(1.0, 2.0, 70)  # weighted particle average: depends on all three keys

    def f(p):
        T, Q = trace(bed, dict(zip(KEYS, p)))
        return T[-1] @ w / w.sum() + 1e-3 * Q["wall"][-1]

    return f


def _central_differences(f, p0, rel=1e-4):
    """Central differences with h = rel * p: truncation ~ (h/p)^2 ~ 1e-8 relative, round-off
    ~ 1e-16 * 300 K / h, both far below the 1e-6 asked for (float64, rtol 1e-12)."""
    out = []
    for i in range(len(p0)):
        h = rel * float(p0[i])
        e = jnp.zeros(len(p0)).at[i].set(h)
        out.append(float((f(p0 + e) - f(p0 - e)) / (2 * h)))
    return np.array(out)


def _bed(autodiff="reverse"):
    return make_motion(mini_wall()).with_options(times=np.array([0.0, 100.0, 300.0]),
                                                 autodiff=autodiff)


def test_forward_mode_gradient_of_a_full_run_matches_central_differences():
    bed = _bed("forward")
    f = _objective(bed)
    p0 = jnp.array([57.0, 114.0, 293.0])
    g = np.asarray(jax.jacfwd(f)(p0))
    np.testing.assert_allclose(g, _central_differences(f, p0), rtol=1e-6)


@pytest.mark.slow
def test_reverse_mode_gradient_matches_central_differences():
    bed = _bed()
    f = _objective(bed)
    p0 = jnp.array([57.0, 114.0, 293.0])
    g = np.asarray(jax.grad(f)(p0))  # diffrax RecursiveCheckpointAdjoint (slow to compile)
    np.testing.assert_allclose(g, _central_differences(f, p0), rtol=1e-6)


# -- fitting the synthetic curves ------------------------------------------------------------


def synthetic():
    return [Experiment("weigler-heating", DATA / "synthetic_heating.csv", name="heating"),
            Experiment("weigler-cooling", DATA / "synthetic_cooling.csv", name="cooling")]


def test_fit_recovers_the_generating_heat_loss_parameter():
    """scripts/make_synthetic_data.py: alphaA = 2.5e-4 W/K, noise 0.15 K."""
    res = fit(synthetic()[:1], params={"heat.loss.alphaA": 1.5e-4})  # the heating curve
    assert res.converged, res.message
    a, se_a = res.estimate["heat.loss.alphaA"], res.stderr["heat.loss.alphaA"]
    assert abs(a - 2.5e-4) < 2 * se_a and se_a < 0.02 * a  # within 2 standard errors (95 %)
    assert res.sigma == pytest.approx(0.15, rel=0.3)  # the noise that was added
    assert np.all(np.diff(res.history["loss"]) <= 1e-15)  # monotone with the line search
    fig = res.plot()
    assert isinstance(fig, matplotlib.figure.Figure)
    # the data points lie off the scene's 30 s output grid: the model is evaluated at them
    assert set(res.residuals["t"]) == set(np.arange(60.0, 1801.0, 60.0))


@pytest.mark.slow
def test_fit_recovers_loss_parameter_and_gas_temperature():
    res = fit(synthetic(), params={"heat.loss.alphaA": 1.0e-4, "gas.temperature": 305.0})
    assert res.converged, res.message
    a, se_a = res.estimate["heat.loss.alphaA"], res.stderr["heat.loss.alphaA"]
    Tg, se_T = res.estimate["gas.temperature"], res.stderr["gas.temperature"]
    assert abs(a - 2.5e-4) < 2 * se_a and se_a < 0.02 * a  # within 2 standard errors (95 %)
    assert abs(Tg - 310.65) < 2 * se_T and se_T < 0.1
    assert res.n_data == 60 and res.dof == 58
    assert abs(res.residuals["residual"].mean()) < 0.05


@pytest.mark.slow
def test_adam_reaches_the_same_estimate():
    res = fit(synthetic()[:1], params={"heat.loss.alphaA": 2.0e-4}, optimizer="adam",
              learning_rate=0.05, max_iter=100)
    ref = fit(synthetic()[:1], params={"heat.loss.alphaA": 2.0e-4})
    assert res.estimate["heat.loss.alphaA"] == pytest.approx(
        ref.estimate["heat.loss.alphaA"], abs=0.2 * ref.stderr["heat.loss.alphaA"])


# -- refusals ---------------------------------------------------------------------------------


def curve(**cols):
    return pd.DataFrame({"t": [60.0, 120.0, 180.0], **cols})


@pytest.mark.parametrize("data, match", [
    (curve(T_mean=[300.0, np.nan, 302.0]), "NaN"),
    (pd.DataFrame({"t": [60.0, 180.0, 120.0], "T_mean": [300.0, 301.0, 302.0]}),
     "strictly increasing"),
    (curve(T_mean=[27.0, 28.0, 29.0]), "degrees Celsius"),
    (curve(T_mean=[300.0, 301.0, 302.0], T_core=[1.0, 2.0, 3.0]), "unknown column 'T_core'"),
    (curve(**{"T_mean:hot": [300.0, 301.0, 302.0]}), "group 'hot'"),
    (pd.DataFrame({"time": [1.0], "T_mean": [300.0]}), "no time column"),
    (pd.DataFrame({"t": [1.0, 2.0]}), "no temperature column"),
])
def test_unusable_data_are_refused(data, match):
    with pytest.raises(CalibrationDataError, match=match):
        read_measurements(data, load_scene("weigler-heating"))


def test_data_file_with_comments_is_read(tmp_path):
    df = read_measurements(DATA / "synthetic_cooling.csv", load_scene("weigler-cooling"))
    assert list(df.columns) == ["t", "T_mean"] and len(df) == 30
    with pytest.raises(CalibrationDataError, match="no such file"):
        read_measurements(tmp_path / "missing.csv", load_scene("weigler-cooling"))


@pytest.mark.parametrize("params, match", [
    (["heat.loss.alphaA", "gas.temperature"], "1 data point.*2 parameter"),
    (["heat.loss.alpha"], "not a key"),
    (["groups.3.temperature"], "not a key"),
    (["run.seed"], "not a float"),
    (["heat.contact.alpha"], "not set"),   # no [heat.contact] in weigler-heating
    (["groups.0.density"], "not set"),     # a library value
])
def test_bad_parameters_are_refused(params, match):
    with pytest.raises(CalibrationDataError, match=match):
        fit("weigler-heating", pd.DataFrame({"t": [60.0], "T_mean": [300.0]}), params)


# -- calibration line -------------------------------------------------------------------------


def test_calibration_line_and_its_inverse_round_trip():
    cal = calibrate_lambda_bed(mini_wall(), [40.0, 80.0], n_times=120)
    tab = cal.table()
    assert list(tab["criterion"]) and set(tab["criterion"]) <= {"slope", "inflection"}
    assert np.all(tab["time"] > 0) and np.all(np.diff(tab["lambda_bed"]) > 0)
    # the line goes through both points and inverts exactly
    for p in cal.points:
        assert cal.lambda_bed(p.alpha_pp) == pytest.approx(p.lambda_bed, rel=1e-12)
        assert cal.alpha_pp(p.lambda_bed, method="line").alpha_pp == pytest.approx(p.alpha_pp)
    # lambda_bed is not exactly proportional to alpha_pp, even at a fixed read-off time (the
    # wall resistance is in series with the bed): the ratio differs from 1
    assert abs(cal.proportional["ratio"] - 1.0) > 0.01
    # Newton on the differentiable map: alpha_pp = 57 -> lambda_bed -> alpha_pp
    target = cal._ctx.point(57.0)
    inv = cal.alpha_pp(target.lambda_bed)
    assert inv.alpha_pp == pytest.approx(57.0, rel=1e-6)
    assert inv.time == pytest.approx(target.time, rel=1e-6)
    assert inv.lambda_achieved == pytest.approx(target.lambda_bed, rel=1e-8)
    assert abs(inv.line_estimate - 57.0) > abs(inv.alpha_pp - 57.0)
