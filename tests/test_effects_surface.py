"""Convection, radiation and intra-particle conduction as scene effects ([heat.convection],
[heat.radiation], [heat.internal]): analytic solutions, book-keeping, absent effects not traced."""

import math

import jax
import numpy as np
import pytest

import drumheat as dh
from drumheat.motion.static import StaticBed
from drumheat.models import convection as corr
from drumheat.models.sphere_conduction import sphere_mean_temperature
from drumheat.scene import SceneError, load_scene, scene_from_dict
from drumheat.thermal.solvers import _vector_field, initial_state
from drumheat.thermal.radiation import Radiation

SIGMA = 5.670374419e-8


def single(**heat):
    """One aluminium-sized sphere (d = 4 mm) in a 2D drum, only the given effects."""
    raw = load_scene("weigler-heating").to_dict()
    raw["groups"] = [dict(name="p", count=1, diameter=0.004, material="aluminium",
                          temperature=400.0)]
    raw["gas"] = {"temperature": 300.0}
    raw["heat"] = heat
    raw["run"].update(duration=600.0, output_interval=60.0, rtol=1e-10, atol=1e-8)
    return scene_from_dict(raw)


def test_constant_convection_is_the_lumped_exponential():
    s = single(convection={"correlation": "constant", "alpha": 20.0})
    res = dh.run(s, progress=False)
    m = 2700 * math.pi * 0.004**3 / 6
    tau = m * 900 / (20.0 * math.pi * 0.004**2)  # alpha on the whole surface pi d^2
    T = 300 + 100 * np.exp(-res.t / tau)
    np.testing.assert_allclose(res.timeseries["T_mean"], T, atol=1e-6)
    assert res.summary["energy_balance_rel_error"] < 1e-9
    assert "Q_loss" in res.timeseries  # convection books on the gas account


def test_correlation_alpha_matches_an_independent_evaluation():
    raw = single().to_dict()
    raw["gas"].update(kinematic_viscosity=2e-5, conductivity=0.029, heat_capacity=1000.0,
                      density=1.0)
    raw["heat"] = {"convection": {"correlation": "gnielinski", "velocity": 2.0,
                                  "properties": "gas"}}
    s = scene_from_dict(raw)
    model, _ = StaticBed(s).model()
    a = float(model.effects[0].alpha(model.particles.diameter * 0 + 350.0, model.particles)[0])
    d, nu, lam, Pr = 0.004, 2e-5, 0.029, 2e-5 * 1.0 * 1000 / 0.029
    Re = 2.0 * d / nu
    lam_part = (2 / (1 + 22 * Pr)) ** (1 / 6) * math.sqrt(Re * Pr)
    turb = 0.037 * Re**0.8 * Pr / (1 + 2.443 * Re**-0.1 * (Pr ** (2 / 3) - 1))
    assert a == pytest.approx((2 + math.hypot(lam_part, turb)) * lam / d, rel=1e-12)
    # staltner form: L = pi d / 2
    s2 = s.with_overrides({"heat.convection.correlation": "gnielinski-staltner"})
    m2, _ = StaticBed(s2).model()
    a2 = float(m2.effects[0].alpha(m2.particles.diameter * 0 + 350.0, m2.particles)[0])
    L = math.pi * d / 2
    assert a2 == pytest.approx(float(corr.gnielinski_sphere_nu(2.0 * L / nu, Pr)) * lam / L)


def test_radiation_to_a_sink_matches_the_analytic_cooling_curve():
    s = single(radiation={"enclosure": "sink", "sink_temperature": 300.0, "emissivity": 0.8})
    s = s.with_overrides({"groups.0.temperature": 900.0, "run.duration": 300.0,
                          "run.output_interval": 30.0})
    res = dh.run(s, progress=False)
    m = 2700 * math.pi * 0.004**3 / 6
    k = 0.8 * SIGMA * math.pi * 0.004**2 / (m * 900)
    Ts = 300.0

    def F(T):  # t(T) of dT/dt = -k (T^4 - Ts^4)
        return (math.log((T + Ts) / (T - Ts)) / 2 + math.atan(T / Ts)) / (2 * k * Ts**3)

    for t, T in zip(res.t[1:], res.timeseries["T_mean"].to_numpy()[1:]):
        assert F(T) - F(900.0) == pytest.approx(t, rel=1e-6)
    assert res.summary["energy_balance_rel_error"] < 1e-9
    assert res.timeseries["Q_radiation"].iloc[-1] < 0


def test_shells_with_convection_match_the_sphere_series():
    lam, alpha = 1.0, 200.0
    s = single(convection={"correlation": "constant", "alpha": alpha},
               internal={"shells": 60, "dt": 0.01})
    s = s.with_overrides({"groups.0.conductivity": lam, "groups.0.material": "glass",
                          "run.duration": 120.0, "run.output_interval": 20.0})
    res = dh.run(s, progress=False)
    R, rho, c = 0.002, 2500.0, 836.0
    Bi = alpha * R / lam
    Fo = lam / (rho * c) * res.t / R**2
    ref = np.asarray(sphere_mean_temperature(Fo[1:], Bi, 400.0, 300.0))
    np.testing.assert_allclose(res.timeseries["T_mean"].to_numpy()[1:], ref, atol=0.02)  # BE, O(dt)
    assert res.summary["energy_balance_rel_error"] < 1e-10


def test_shells_in_a_contact_bed_reduce_to_the_lumped_model_for_small_biot():
    base = load_scene("weigler-static", {"run.duration": 300.0})
    lumped = dh.run(base, progress=False)
    shells = dh.run(base.with_overrides({"heat.internal.shells": 4}), progress=False)
    assert shells.T.shape == lumped.T.shape  # particle means, (n_out, N)
    assert np.max(np.abs(shells.T - lumped.T)) < 0.1  # K (Bi ~ 1e-3; backward Euler dt)
    assert shells.summary["energy_balance_rel_error"] < 1e-4  # Newton-Jacobi residual of contacts


def test_absent_effects_are_not_traced_and_lumped_state_is_kept(monkeypatch):
    calls = {"n": 0}
    orig = Radiation.heat_flow

    def counting(self, *a):
        calls["n"] += 1
        return orig(self, *a)

    monkeypatch.setattr(Radiation, "heat_flow", counting)
    bed = StaticBed(load_scene("weigler-static"))
    model, T0 = bed.model()
    assert model.internal is None and initial_state(model, T0)["T"].ndim == 1
    jaxpr = jax.make_jaxpr(lambda y: _vector_field(0.0, y, (model, bed.net)))(
        initial_state(model, T0))
    prims = {e.primitive.name for e in jaxpr.jaxpr.eqns}
    assert calls["n"] == 0 and "tridiagonal_solve" not in prims
    s = load_scene("weigler-static", {"heat.radiation.sink_temperature": 320.0})
    bed2 = StaticBed(s)
    m2, T2 = bed2.model()
    j2 = jax.make_jaxpr(lambda y: _vector_field(0.0, y, (m2, bed2.net)))(initial_state(m2, T2))
    assert calls["n"] == 1 and len(j2.jaxpr.eqns) > len(jaxpr.jaxpr.eqns)


def test_scene_validation_of_the_new_tables():
    with pytest.raises(SceneError, match="heat.convection.alpha"):
        single(convection={"correlation": "constant"})
    with pytest.raises(SceneError, match="heat.convection.velocity"):
        single(convection={"correlation": "gnielinski"})
    with pytest.raises(SceneError, match="heat.radiation.sink_temperature"):
        single(radiation={"enclosure": "sink"})
    with pytest.raises(SceneError, match="heat.radiation.surfaces"):
        load_scene("staltner-slag-particle", {"heat.radiation.surfaces.0.name": "floor"})
    with pytest.raises(SceneError, match="heat.internal.shells"):
        single(internal={"shells": 1})
    with pytest.raises(SceneError, match="'drum'"):
        raw = load_scene("weigler-static").to_dict()
        del raw["drum"]
        scene_from_dict(raw)
