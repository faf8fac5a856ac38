"""Thermal network core: conservation, equilibria, analytic solutions, solvers, effect wiring."""

import math

import jax
import numpy as np
import pytest

import drumheat as dh
from drumheat.motion.static import StaticBed
from drumheat.results.result import energy_balance
from drumheat.scene import SceneError, load_scene, scene_from_dict
from drumheat.thermal.contact import ContactConduction
from drumheat.thermal.solvers import _vector_field, initial_state


def closed_bed(**run):
    """Two equal fractions (30 + 30 Al spheres) with contact conduction only."""
    raw = load_scene("weigler-static").to_dict()
    raw["groups"][0]["count"] = raw["groups"][1]["count"] = 30
    del raw["heat"]["loss"], raw["gas"]
    raw["run"].update(duration=900.0, output_interval=30.0, **run)
    return scene_from_dict(raw)


def test_closed_bed_conserves_energy_to_round_off():
    res = dh.run(closed_bed(), progress=False)
    traj = res.trajectory
    stored = traj.T @ traj.capacity
    assert np.max(np.abs(stored - stored[0])) / stored[0] < 1e-13
    assert res.summary["energy_balance_rel_error"] < 1e-12


def test_two_equal_fractions_reach_the_mixing_temperature():
    scene = closed_bed().with_overrides({"run.duration": 20000.0, "run.output_interval": 1000.0,
                                         "run.atol": 1e-10, "run.rtol": 1e-10})
    res = dh.run(scene, progress=False)
    T_mix = 0.5 * (299.15 + 318.15)  # equal masses, equal c: caloric mean, weigler eq. [4.1]
    assert res.T[-1] == pytest.approx(np.full(60, T_mix), abs=1e-6)
    assert res.timeseries["T_mean"].to_numpy() == pytest.approx(T_mix, abs=1e-9)


@pytest.mark.parametrize("name", ["weigler-heating", "weigler-cooling"])
def test_heat_loss_only_matches_the_lumped_solution(name):
    scene = load_scene(name)
    res = dh.run(scene, progress=False)
    g = scene.groups[0]
    m = g.diameter**3 * math.pi / 6 * 2700.0
    tau = m * 900.0 / scene.heat.loss.alphaA  # weigler section 7.5: about 326 s
    assert tau == pytest.approx(326.0, rel=0.01)
    t = res.timeseries["t"].to_numpy()
    T_exact = scene.gas.temperature + (g.temperature - scene.gas.temperature) * np.exp(-t / tau)
    np.testing.assert_allclose(res.timeseries["T_mean"], T_exact, rtol=0, atol=1e-6)
    # the heat lost to the gas equals the stored heat change
    assert res.summary["energy_balance_rel_error"] < 1e-8


def test_explicit_scheme_agrees_with_diffrax():
    scene = load_scene("weigler-static", {"run.duration": 600.0})
    ref = dh.run(scene, progress=False).T
    exp = dh.run(scene.with_overrides({"run.solver": "explicit", "run.dt": 0.05}),
                 progress=False).T
    exp2 = dh.run(scene.with_overrides({"run.solver": "explicit", "run.dt": 0.025}),
                  progress=False).T
    err1, err2 = np.max(np.abs(exp - ref)), np.max(np.abs(exp2 - ref))
    assert err1 < 5e-3  # K
    assert err2 == pytest.approx(err1 / 2, rel=0.1)  # forward Euler: first order


def test_explicit_step_above_the_stability_limit_is_refused():
    scene = load_scene("weigler-static", {"run.solver": "explicit", "run.dt": 100.0})
    with pytest.raises(SceneError, match="run.dt.*stability limit"):
        dh.run(scene, progress=False)


def test_default_explicit_step_respects_maximum_principle():
    scene = load_scene("weigler-static", {"run.solver": "explicit", "run.duration": 300.0})
    res = dh.run(scene, progress=False)
    T = res.T
    assert T.min() >= 299.15 - 1e-9 and T.max() <= 318.15 + 1e-9


def test_adaptive_and_implicit_agree():
    scene = load_scene("weigler-glass-wall", {"run.duration": 500.0, "groups.0.count": 120})
    a = dh.run(scene, progress=False).T
    b = dh.run(scene.with_overrides({"run.solver": "implicit"}), progress=False).T
    np.testing.assert_allclose(a, b, atol=1e-4)


def _traced_rhs(scene):
    """The jaxpr of a scene's thermal right-hand side (always traced afresh, no jit cache)."""
    bed = StaticBed(scene)
    model, T0 = bed.model()
    return jax.make_jaxpr(lambda y: _vector_field(0.0, y, (model, bed.net)))(
        initial_state(model, T0))


def _primitives(jaxpr):
    return {eqn.primitive.name for eqn in jaxpr.jaxpr.eqns}


def test_scene_with_only_heat_loss_computes_no_contact_terms(monkeypatch):
    calls = {"n": 0}
    original = ContactConduction.heat_flow

    def counting(self, *args):
        calls["n"] += 1
        return original(self, *args)

    monkeypatch.setattr(ContactConduction, "heat_flow", counting)
    loss_only = _traced_rhs(load_scene("weigler-heating"))
    assert calls["n"] == 0
    # no gathers/scatters over contact pairs in the traced program
    assert not {"gather", "scatter-add"} & _primitives(loss_only)
    with_contacts = _traced_rhs(load_scene("weigler-static"))
    assert calls["n"] == 1
    assert {"gather", "scatter-add"} <= _primitives(with_contacts)


def test_contact_flow_is_antisymmetric_and_sparse():
    bed = StaticBed(load_scene("weigler-static"))
    model, T0 = bed.model()
    q, ext = model.heat_flows(T0, bed.net)
    contact = model.effects[0].heat_flow(T0, model.particles, bed.net)
    assert abs(float(contact.sum())) < 1e-15
    assert bed.net.pair_i.shape == (len(bed.pairs),)  # pair list, not N x N
    assert set(ext) == {"gas"}


def test_pair_sum_in_blocks_counts_every_slot_once(monkeypatch):
    # ContactNetwork.pair_sum takes many slots in blocks (the last one shifted back to end at
    # the last slot): every slot counts once, as in one pass, to round-off; unused slots
    # (index N, weight 0) add nothing
    import jax.numpy as jnp

    from drumheat.thermal import network
    from drumheat.thermal.network import ContactNetwork

    rng = np.random.default_rng(4)
    n, m = 40, 203
    i = rng.integers(0, n, m)
    j = rng.integers(0, n, m)
    w = rng.uniform(0.0, 1.0, m)
    i[-15:], j[-15:], w[-15:] = n, n, 0.0  # padding
    T = rng.uniform(290.0, 310.0, n)
    net = ContactNetwork(jnp.asarray(i), jnp.asarray(j), jnp.asarray(w), jnp.zeros(0, int),
                         jnp.zeros(0, int), jnp.zeros(0))
    flow = lambda a, b, wt: 2.5 * wt * (jnp.asarray(T)[b] - jnp.asarray(T)[a])  # noqa: E731
    ref_q, ref_g = np.zeros(n + 1), np.zeros(n + 1)
    q = 2.5 * w * (T[np.minimum(j, n - 1)] - T[np.minimum(i, n - 1)])
    np.add.at(ref_q, i, q)
    np.add.at(ref_q, j, -q)
    np.add.at(ref_g, i, 2.5 * w)
    np.add.at(ref_g, j, 2.5 * w)
    # one pass; 4 blocks of 64 slots (8 of 26 rounded up to the lengths' multiple), the last one
    # shifted back to end at the last slot
    for block in (1 << 16, 16):
        monkeypatch.setattr(network, "PAIR_BLOCK", block)
        got = net.pair_sum(flow, jnp.zeros(n))
        np.testing.assert_allclose(got, ref_q[:n], rtol=0, atol=1e-12 * np.abs(q).max())
        g = net.pair_sum(lambda a, b, wt: 2.5 * wt, jnp.zeros(n), sign=1.0)
        np.testing.assert_allclose(g, ref_g[:n], rtol=1e-14)
    assert abs(float(jnp.sum(got))) < 1e-12 * np.abs(q).max()


def test_wall_heated_bed_energy_balance_and_alpha():
    res = dh.run(load_scene("weigler-glass-wall", {"run.duration": 3000.0}), progress=False)
    ts = res.timeseries
    assert res.summary["energy_balance_rel_error"] < 1e-8
    assert res.summary["n_wall_contacts"] > 10
    a = ts["alpha_overall"].to_numpy()
    assert math.isnan(a[0])
    # early on the overall coefficient approaches the wall coefficient (A7 convention:
    # alpha_wp A_p per wall particle on d^2 area -> pi/4 alpha_wp), and it then decreases
    assert a[1] < 114.0 * math.pi / 4 * 1.001
    assert np.all(np.diff(a[1:]) < 0)
    assert np.all(np.diff(ts["T_mean"]) > 0) and ts["T_max"].max() <= 343.0


def test_result_files(tmp_path):
    res = dh.run("weigler-heating", out=tmp_path / "r", progress=False)
    import json

    import pandas as pd

    out = tmp_path / "r"
    ts = pd.read_csv(out / "timeseries.csv")
    assert list(ts.columns[:3]) == ["t", "T_mean", "T_mean:spheres"]
    summary = json.loads((out / "summary.json").read_text())
    for key in ("scene", "n_particles", "duration_s", "wall_time_s", "energy_balance_rel_error",
                "T_mean", "T_mean:spheres", "n_wall_contacts"):
        assert key in summary
    with np.load(out / "particles.npz") as f:
        assert f["T"].shape == (len(ts), 70)
        assert f["position"].shape == (len(ts), 70, 2)
        assert f["group"].shape == (70,)
    assert (out / "mean_temperatures.png").stat().st_size > 1000
    assert (out / "temperature_distributions.png").stat().st_size > 1000
    assert summary["T_mean"] == pytest.approx(res.timeseries["T_mean"].iloc[-1])


def test_energy_balance_detects_a_leak():
    res = dh.run("weigler-heating", progress=False)
    traj = res.trajectory
    traj.Q["gas"] = traj.Q["gas"] * 0.9
    _, rel = energy_balance(traj)
    assert rel > 0.05
