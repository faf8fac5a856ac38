"""Motion model 'pneumatic' (scene kraychev-channel): drag, convection, plug-flow gas balance,
open inlet/outlet. Each test runs a small channel for a fraction of a second."""

import math
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

from drumheat.motion.pneumatic import PneumaticChannel, cocurrent_outlet, march_gas
from drumheat.models import drag
from drumheat.results.result import energy_balance
from drumheat.runner import simulate
from drumheat.scene import SceneError, load_scene, scene_from_dict

# the steps given here are above the tangential dashpots' limit on purpose (these tests are about
# heat and the run loop, not about the forces of sticking contacts)
pytestmark = pytest.mark.filterwarnings("ignore::drumheat.mechanics.DEMAccuracyWarning")
from drumheat.thermal.convection import _air_clipped, nusselt_alpha

T_GAS = 293.15


def channel_scene(*, d, rho, count, height, gap, depth, u, m_s, v_in=0.0, duration, dt,
                  output_interval=None, T_p=313.15, convection=None, coupling="two-way",
                  cells=20, skin=None, stiffness=1.0, properties="polynomial", steady=None,
                  c=1520.0, spread=0.0):
    raw = {
        "name": "test-channel", "dim": 3,
        "run": {"duration": duration, "output_interval": output_interval or duration, "seed": 3},
        "groups": [{"name": "p", "count": count, "diameter": d, "material": "wheat",
                    "density": rho, "heat_capacity": c, "temperature": T_p}],
        "gas": {"temperature": T_GAS, "heat_capacity": 1000.0, "density": 1.2,
                "kinematic_viscosity": 1.5e-5, "conductivity": 0.026},
        "channel": {"height": height, "gap": gap, "depth": depth, "length": depth,
                    "gas_velocity": u, "solids_mass_flow": m_s, "particle_inlet_velocity": v_in,
                    "inlet_velocity_spread": spread, "cells": cells, "gas_coupling": coupling},
        "dem": {"stiffness": stiffness, "dt": dt, "restitution": 0.5},
        "motion": {"model": "pneumatic"},
    }
    if skin is not None:
        raw["dem"]["skin"] = skin
    if steady is not None:
        raw["channel"]["steady_after"] = steady
    if convection is not None:
        raw["heat"] = {"convection": dict(convection, properties=properties)}
    return scene_from_dict(raw)


def run(scene):
    """The channel model, its trajectory, its final state and the steady-window evaluation."""
    model = PneumaticChannel(scene)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a single particle leaves the feeder "starved"
        traj, state = simulate(model, progress=False, return_state=True)
    return model, traj, state, traj.info.get("channel")


def test_scene_loads_and_wheat_rises():
    scene = load_scene("kraychev-channel")
    model = PneumaticChannel(scene)
    rho, _, _, nu = (float(x) for x in _air_clipped(scene.gas.temperature))
    W_t = float(drag.terminal_velocity(4.07e-3, 1315.0, rho, nu * rho, g=9.81))
    assert 11.0 < W_t < 12.0 < scene.channel.gas_velocity  # wheat is carried up at 16.5 m/s
    est = model.holdup_estimate()
    assert est["holdup_particles"] < 0.8 * scene.n_particles  # the queue never runs dry
    with pytest.raises(SceneError, match="heat.contact"):
        load_scene("kraychev-channel", ["heat.contact.alpha=100"])
    with pytest.raises(SceneError, match="channel.gap"):
        load_scene("kraychev-channel", ["channel.gap=0.004"])


def test_single_particle_reaches_terminal_slip():
    d, rho_p, u = 50e-6, 1315.0, 0.5
    scene = channel_scene(d=d, rho=rho_p, count=1, height=0.2, gap=0.005, depth=0.012, u=u,
                          m_s=1e-3, duration=0.3, dt=2e-4, skin=0.005, stiffness=1e-4)
    model, traj, st, _ = run(scene)
    assert bool(st.extra.active[0])
    rho, _, _, nu = (float(x) for x in _air_clipped(T_GAS))
    W_t = float(drag.terminal_velocity(d, rho_p, rho, nu * rho, "schiller_naumann", g=9.81))
    v = np.asarray(st.velocity[0])
    assert v[1] == pytest.approx(u - W_t, rel=1e-9)
    assert abs(v[0]) < 1e-12 and abs(v[2]) < 1e-12


def test_particle_temperature_follows_gnielinski_exponential():
    # a hovering wheat grain (gas velocity = terminal velocity), gas held at its inlet
    # temperature: T - T_g = (T0 - T_g) exp(-alpha A t / (m c)), alpha at slip = W_t
    d, rho_p, c = 4.07e-3, 1315.0, 1520.0
    rho, cp, lam, nu = (float(x) for x in _air_clipped(T_GAS))
    W_t = float(drag.terminal_velocity(d, rho_p, rho, nu * rho, g=9.81))
    scene = channel_scene(d=d, rho=rho_p, count=1, height=0.1, gap=0.018, depth=0.02, u=W_t,
                          m_s=10.0, duration=0.5, output_interval=0.1, dt=1e-4, stiffness=10.0,
                          convection={"correlation": "gnielinski-kraychev"}, coupling="none")
    model, traj, st, _ = run(scene)
    assert abs(float(st.velocity[0, 1])) < 1e-9 and bool(st.extra.active[0])
    alpha = float(nusselt_alpha("gnielinski-kraychev", d, W_t, rho, cp, lam, nu))
    tau = rho_p * c * d / (6 * alpha)
    t_heat = traj.t - model.dt  # released at the end of the first step
    expected = T_GAS + (313.15 - T_GAS) * np.exp(-np.maximum(t_heat, 0) / tau)
    np.testing.assert_allclose(traj.T[1:, 0] - T_GAS, expected[1:] - T_GAS, rtol=1e-5)
    # the particle's own alpha is the correlation's (slip = W_t): 20 K in, about 300 W/(m2 K)
    assert traj.extra["alpha_mean"][-1] == pytest.approx(alpha, rel=1e-9)


@pytest.fixture(scope="module")
def busy_channel():
    """A short, loaded channel: contacts, exits, re-entries, two-way heat coupling."""
    scene = channel_scene(d=4e-3, rho=1300.0, count=60, height=0.08, gap=0.012, depth=0.016,
                          u=16.0, m_s=0.05, v_in=2.0, duration=0.12, output_interval=0.04, dt=5e-5,
                          stiffness=2e3, convection={"correlation": "gnielinski-kraychev"},
                          cells=8, spread=1.5)
    return run(scene)


def test_energy_balance_closes_to_round_off(busy_channel):
    model, traj, st, _ = busy_channel
    assert float(np.sum(traj.n_contacts)) > 0  # collisions happened
    stored = (traj.T - traj.T[0]) @ traj.capacity
    q_gas, q_flow = traj.Q["gas"], traj.Q["flow"]
    assert abs(q_flow[-1]) > 0 and abs(q_gas[-1]) > 0
    scale = float(np.max(np.abs(q_gas)))
    # particles: stored heat = heat from the gas + enthalpy in - enthalpy out
    np.testing.assert_allclose(stored, q_gas + q_flow, atol=1e-11 * scale)
    # gas side: enthalpy in - out = heat the particles took up
    np.testing.assert_allclose(-traj.extra["H_gas"], -q_gas, atol=1e-11 * scale)
    # gas enthalpy in - out + particle enthalpy in - out = change of stored heat
    np.testing.assert_allclose(traj.extra["H_gas"] + q_flow, stored, atol=1e-11 * scale)
    assert energy_balance(traj)[1] < 1e-11
    assert int(np.sum(np.asarray(st.extra.active))) > 0


def test_exits_are_parked_and_reenter_at_inlet_temperature(busy_channel):
    model, traj, st, steady = busy_channel
    _, _, boundary = model._hooks()
    ex = st.extra
    assert int(steady["released"]) > 0 and np.isfinite(traj.extra["T_particle_out"][-1])
    parked = ~np.asarray(ex.active)
    np.testing.assert_array_equal(np.asarray(ex.T)[parked], model.T_inlet[parked])
    # one particle pushed past the outlet with a marked temperature
    i = int(np.flatnonzero(np.asarray(ex.active))[0])
    T_mark = 350.0
    acc0 = model._zero_acc()
    extra = ex.replace(T=ex.T.at[i].set(T_mark), credit=jnp.zeros(()), acc=acc0,
                       Q={"gas": jnp.zeros(()), "flow": jnp.zeros(())})
    pos = st.position.at[i, 1].set(model.H + 1e-4)
    s1 = boundary(st._replace(position=pos, extra=extra))
    C = model.capacity[i]
    assert not bool(s1.extra.active[i])
    assert float(s1.extra.T[i]) == model.T_inlet[i]
    np.testing.assert_allclose(np.asarray(s1.position[i]), model.park[i])
    assert float(s1.extra.Q["flow"]) == pytest.approx(C * (model.T_inlet[i] - T_mark))
    assert float(s1.extra.acc["CT_exit"]) == pytest.approx(C * T_mark)
    # with feeder credit, the longest-waiting particle enters at y = r at the inlet velocity
    waiting = ~np.asarray(s1.extra.active)
    j = int(np.argmin(np.where(waiting, np.asarray(s1.extra.park_time), np.inf)))
    s2 = boundary(s1._replace(extra=s1.extra.replace(credit=jnp.asarray(1.0))))
    assert bool(s2.extra.active[j])
    assert float(s2.position[j, 1]) == pytest.approx(model.radius[j])
    assert float(s2.extra.T[j]) == model.T_inlet[j]
    v = np.asarray(s2.velocity[j])
    assert v[1] == model.scene.channel.particle_inlet_velocity
    assert np.all(np.abs(v[[0, 2]]) <= model.scene.channel.inlet_velocity_spread)


def test_march_gas_is_the_cellwise_exponential():
    G = jnp.array([0.0, 2.0, 0.5, 3.0])
    T = jnp.array([0.0, 330.0, 320.0, 310.0])
    T_nodes, T_eff = march_gas(G, G * T, 290.0, 1.5)
    Tin = 290.0
    for k in range(4):
        Tb = float(T[k])  # a Python float: pytest.approx must not be handed a JAX array
        Tout = Tb + (Tin - Tb) * math.exp(-float(G[k]) / 1.5) if G[k] > 0 else Tin
        assert float(T_nodes[k + 1]) == pytest.approx(Tout, rel=1e-14)
        if G[k] > 0:  # what the particles get is what the gas gives
            assert float(G[k] * (T_eff[k] - Tb)) == pytest.approx(1.5 * (Tin - Tout), rel=1e-12)
        Tin = Tout


def test_gas_outlet_matches_cocurrent_ntu_solution():
    # a uniform stream: particles fed at their terminal rise velocity never meet, all with
    # the same constant alpha; the co-current two-stream exchanger is then exact
    d, rho_p, c, u = 2e-3, 1000.0, 1000.0, 9.0
    rho_g, nu_g = 1.2, 1.5e-5
    W_t = float(drag.terminal_velocity(d, rho_p, rho_g, nu_g * rho_g, g=9.81))
    v = u - W_t
    m_p = rho_p * math.pi * d**3 / 6
    gap, depth, H = 0.01, 0.04, 0.2
    m_gas = rho_g * u * gap * depth
    m_s = m_gas * 1000.0 / c  # equal capacity rates
    scene = channel_scene(d=d, rho=rho_p, count=200, height=H, gap=gap, depth=depth, u=u,
                          m_s=m_s, v_in=v, duration=0.45, output_interval=0.05, dt=8e-5,
                          stiffness=100.0, convection={"correlation": "constant",
                                                       "alpha": 2000.0},
                          properties="gas", c=c, cells=40, steady=0.15)
    model, traj, _, ev = run(scene)
    assert ev["starved_steps"] == 0 and ev["blocked_steps"] == 0
    assert ev["velocity_mean"] == pytest.approx(v, rel=1e-6)  # nobody collided
    C_s, C_g = ev["solids_mass_flow"] * c, m_gas * 1000.0
    assert C_s == pytest.approx(m_s * c, rel=0.02)
    # UA from the simulated hold-up (alpha x the particle surface in the channel)
    UA = ev["UA"]
    assert UA == pytest.approx(2000.0 * math.pi * d**2 * m_s * (H - d / 2) / (v * m_p), rel=0.03)
    Ts, Tg = cocurrent_outlet(313.15, T_GAS, C_s, C_g, UA)
    # measured: 0.04 % (gas rise) and 0.08 % (particle drop) at NTU = 1.17
    assert ev["T_gas_out"] - T_GAS == pytest.approx(Tg - T_GAS, rel=0.005)
    assert 313.15 - ev["T_particle_out"] == pytest.approx(313.15 - Ts, rel=0.005)


def test_explain_refuses_the_channel_with_a_clear_message():
    """``drumheat explain`` covers network-based beds; the channel gets exit code 2 and a
    message naming motion.model instead of a traceback."""
    from drumheat.cli import main

    assert main(["explain", "kraychev-channel"]) == 2


# ---------------------------------------------------------------------------------------------
# the entrance jet ([channel.entrance]) and the outlet headline of summary.json
# ---------------------------------------------------------------------------------------------

from drumheat.motion.pneumatic import entrance_length, jet_velocity_factor  # noqa: E402


def test_jet_velocity_factor_limits_and_decay():
    gap, b0, K = 0.018, 0.008, 2.47
    y = np.linspace(0.0, 1.3, 2601)
    f = jet_velocity_factor(y, gap, b0, K)
    x_c, x_e = K**2 * b0, entrance_length(gap, b0, K)
    # mass conservation through the slit: the digest's 37 m/s at 16.5 m/s in the channel
    assert 16.5 * f[0] == pytest.approx(37.125, rel=1e-12)
    np.testing.assert_array_equal(f[y <= x_c], gap / b0)  # potential core
    mid = (y > x_c) & (y < x_e)
    np.testing.assert_allclose(f[mid], gap / b0 * np.sqrt(x_c / y[mid]), rtol=1e-14)
    np.testing.assert_array_equal(f[y >= x_e], 1.0)  # the channel's mean beyond x_e
    assert x_e == pytest.approx(K**2 * gap**2 / b0, rel=1e-14)  # 0.247 m for the rig
    assert float(jet_velocity_factor(x_e, gap, b0, K)) == pytest.approx(1.0, rel=1e-12)
    # limits: a slit as wide as the channel, or no decay length: exactly the mean
    np.testing.assert_array_equal(jet_velocity_factor(y, gap, gap, K), 1.0)
    np.testing.assert_array_equal(jet_velocity_factor(y[1:], gap, b0, 0.0), 1.0)
    assert entrance_length(gap, b0, 0.0) == 0.0
    # the JAX version is the numpy one
    np.testing.assert_array_equal(np.asarray(jet_velocity_factor(jnp.asarray(y), gap, b0, K)), f)


def test_entrance_table_is_checked():
    with pytest.raises(SceneError, match="channel.entrance.slit_width"):
        load_scene("kraychev-channel", ["channel.entrance.slit_width=0.02"])
    with pytest.raises(SceneError, match="channel.entrance.decay_constant"):
        load_scene("kraychev-channel", ["channel.entrance.decay_constant=-1"])
    with pytest.raises(SceneError, match="channel.entrance.slit_width"):
        load_scene("kraychev-channel", ["channel.entrance.slit_width=0"])


def test_entrance_acceleration_is_resolved_by_the_dem_step():
    """The wheat scene with the rig's slit: a grain fed at rest crosses the jet's potential
    core (49 mm) in many DEM steps, and its drag relaxation time is many steps long."""
    scene = load_scene("kraychev-channel", ["channel.entrance.slit_width=0.008"])
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # no under-resolution warning
        model = PneumaticChannel(scene)
    info = model.entrance_info()
    assert info["slit_velocity"] == pytest.approx(16.5 * 18 / 8, rel=1e-12)
    assert info["core_length"] == pytest.approx(2.47**2 * 0.008, rel=1e-12)
    assert info["steps_in_core"] > 100 and info["relaxation_steps"] > 100
    assert info["steps_in_entrance"] > info["steps_in_core"]
    # the jet shortens the single-grain ascent
    assert model.holdup_estimate()["residence_time"] < PneumaticChannel(
        load_scene("kraychev-channel")).holdup_estimate()["residence_time"]


def _busy(entrance=None, duration=0.12):
    scene = channel_scene(d=4e-3, rho=1300.0, count=60, height=0.08, gap=0.012, depth=0.016,
                          u=16.0, m_s=0.05, v_in=2.0, duration=duration, output_interval=0.04,
                          dt=5e-5, stiffness=2e3,
                          convection={"correlation": "gnielinski-kraychev"}, cells=8,
                          spread=1.5)
    if entrance is not None:
        from drumheat.scene import to_dict
        raw = to_dict(scene)
        raw["channel"]["entrance"] = entrance
        scene = scene_from_dict(raw)
    return scene


@pytest.mark.parametrize("entrance", [{"slit_width": 0.012}, {"slit_width": 0.004,
                                                                "decay_constant": 0.0}])
def test_entrance_limits_give_todays_channel_exactly(busy_channel, entrance):
    """A slit as wide as the channel (jet velocity = mean velocity) or a zero entrance length
    reproduce the channel without entrance bit for bit."""
    _, traj0, st0, ev0 = busy_channel
    _, traj, st, ev = run(_busy(entrance))
    np.testing.assert_array_equal(traj.T, traj0.T)
    np.testing.assert_array_equal(traj.position, traj0.position)
    np.testing.assert_array_equal(traj.extra["H_gas"], traj0.extra["H_gas"])
    assert ev["T_particle_out"] == ev0["T_particle_out"]


@pytest.fixture(scope="module")
def busy_entrance():
    """The busy channel with a 4 mm slit in its 12 mm gap (jet of 48 m/s, core 24 mm, entrance
    length 0.22 m: the whole 0.08 m channel is entrance)."""
    return run(_busy({"slit_width": 0.004}))


def test_entrance_conserves_energy_and_speeds_up_heat_transfer(busy_channel, busy_entrance):
    model, traj, st, ev = busy_entrance
    stored = (traj.T - traj.T[0]) @ traj.capacity
    q_gas, q_flow = traj.Q["gas"], traj.Q["flow"]
    scale = float(np.max(np.abs(q_gas)))
    np.testing.assert_allclose(stored, q_gas + q_flow, atol=1e-11 * scale)
    # the jet's air is the channel's air: the gas gives off what the particles take up
    np.testing.assert_allclose(traj.extra["H_gas"], q_gas, atol=1e-11 * scale)
    assert energy_balance(traj)[1] < 1e-11
    ev0 = busy_channel[3]
    # faster gas at the foot: more slip, larger alpha, faster grains
    assert ev["slip_mean"] > ev0["slip_mean"] and ev["alpha_mean"] > ev0["alpha_mean"]
    assert ev["velocity_mean"] > ev0["velocity_mean"]
    assert ev["entrance"]["slit_velocity"] == pytest.approx(48.0, rel=1e-12)


def test_gas_velocity_of_the_hooks_is_the_jet(busy_entrance):
    model = busy_entrance[0]
    u = model._gas_velocity()
    rho = jnp.asarray([1.2, 1.2, 1.2])
    y = jnp.asarray([0.002, 0.05, 0.5])
    expect = model.mass_flux / 1.2 * jet_velocity_factor(np.asarray(y), 0.012, 0.004, 2.47)
    np.testing.assert_allclose(np.asarray(u(y, rho)), expect, rtol=1e-14)
    assert float(u(y, rho)[0]) == pytest.approx(3 * model.mass_flux / 1.2, rel=1e-14)


def test_summary_reports_the_outlet(busy_channel, tmp_path):
    """summary.json carries the outlet temperatures and Q_2 of the steady window (the headline
    T_mean includes the queued particles)."""
    import json

    from drumheat.results.files import write_results
    from drumheat.results.result import make_result

    model, traj, _, ev = busy_channel
    result = make_result(model.scene, traj, 0.0)
    write_results(result, tmp_path / "res", figures=False)
    out = json.loads((tmp_path / "res" / "summary.json").read_text())["outlet"]
    assert out["T_particle_out"] == ev["T_particle_out"] and out["T_gas_out"] == ev["T_gas_out"]
    assert out["Q_2"] == ev["Q_2"] == pytest.approx(
        model.W_gas * (ev["T_gas_out"] - T_GAS), rel=1e-12)
    assert out["Q_2_channel"] == pytest.approx(ev["Q_2"] * 1.0, rel=1e-12)  # length = depth
    assert out["window_s"][1] == pytest.approx(traj.t[-1])
    assert out["window_s"][1] - out["window_s"][0] == pytest.approx(ev["window"])
    assert out["entrance"] is False
    # the particles queued at the feeder sit at the inlet temperature, inside T_mean
    assert np.isfinite(out["T_particle_out"]) and out["T_particle_out"] < 313.15
