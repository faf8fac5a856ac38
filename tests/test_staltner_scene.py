"""Built-in scene staltner-slag-particle: one slag droplet through the granulator phases."""

import importlib.util
import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

import drumheat as dh
from drumheat.models import granulator_balance as gb
from drumheat.models.granulator import droplet_speed, path_geometry, wall_heat_per_mass
from drumheat.models.sphere_conduction import ghost_node_contact_flux
from drumheat.scene import load_scene
from drumheat.thermal import shells
from drumheat.thermal.internal import staltner_slag

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"


def script(name):
    spec = importlib.util.spec_from_file_location(name, SCRIPTS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


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


def test_geometry_reproduces_the_published_flight_and_fall_times():
    """Tab. 8.2 base case: t1 = 97.3 ms, t3 = 53.1 ms (printed to 0.1 ms) for every size; the
    scene's plant is the round member of the family scripts/staltner_geometry.py derives."""
    geo = script("staltner_geometry")
    g = load_scene("staltner-slag-particle").granulator
    p, v = path_geometry(g), droplet_speed(g)
    assert abs(p["s1"] / v - 97.3e-3) <= 0.05e-3
    assert abs(p["s3"] / v - 53.1e-3) <= 0.05e-3
    # the inversion (h4, r2) <- (t1, t3) and back is exact
    for d_disc, a in ((0.75, 45.0), (1.0, 45.0), (0.8, 55.0)):
        h4, r2 = geo.geometry_from_times(d_disc, a)
        t1, t3 = geo.times_of(d_disc, a, h4, r2)
        assert (t1, t3) == pytest.approx((97.3e-3, 53.1e-3), rel=1e-12)
    h4, r2 = geo.geometry_from_times(g.disc_diameter, g.alpha4)
    dh4, dr2 = geo.tolerance(g.disc_diameter, g.alpha4)
    assert abs(h4 - g.h4) <= dh4 and abs(r2 - g.r2) <= dr2
    assert [s[:2] for s in geo.round_solutions()] == [(0.75, 45.0)]
    # the mid-cone disc reproduces the path shares 2 h3 : h4 of [7.11]/[7.15]
    assert p["fbk_fraction"] == pytest.approx(g.h4 / (2 * g.h3 + g.h4), rel=1e-12)


def test_freeboard_balances_hold_and_sum_to_the_total():
    """[7.7], [7.12], [7.16] each hold at the returned temperatures; [7.18] is their sum."""
    mat = staltner_slag()
    h_s = lambda T: float(mat.enthalpy(jnp.asarray(T, float)))
    kw = dict(slag_rate=750.0, h_slag_0=h_s(1623.15), h_slag_1=h_s(1500.0),
              h_slag_3star=h_s(1420.0), h_slag_3=h_s(1390.0), Q_radiation_1=4e5,
              Q_radiation_3=6e4, volume_flow_normal=170000.0, bed_share=0.7, T_air_in=293.15,
              h3=1.0, h4=1.0)
    st = gb.freeboard_state(slag_enthalpy=h_s, **kw)
    m_s = 750.0 / 60
    m_ws, m_sb, m_tot = gb.air_streams(170000.0, 0.7)
    assert m_tot == pytest.approx(1.293 * 170000.0 / 3600, rel=1e-14)
    assert m_ws / m_tot == pytest.approx(0.7, rel=1e-14)
    hL = lambda T: float(gb.air_enthalpy(T))
    Q_fbz, Q_fbk = gb.radiation_split(4e5, 6e4, 1.0, 1.0)
    assert (Q_fbz, Q_fbk) == pytest.approx((4e4, 4e5 + 2e4), rel=1e-14)
    scale = m_s * kw["h_slag_0"]
    ws = m_s * kw["h_slag_3"] + m_ws * hL(293.15) - m_s * h_s(st.T_bed) - m_ws * hL(st.T_bed)
    fbz = (m_sb * hL(293.15) + m_ws * hL(st.T_bed) + m_s * kw["h_slag_3star"]
           - m_tot * hL(st.T_freeboard) - m_s * kw["h_slag_3"] - Q_fbz)
    fbk = (m_tot * hL(st.T_freeboard) + m_s * kw["h_slag_0"] - m_tot * hL(st.T_outlet)
           - m_s * kw["h_slag_3star"] - Q_fbk - gb.wall_heat(750.0))
    for r in (ws, fbz, fbk, st.total_residual):
        assert abs(r) < 1e-9 * scale
    assert gb.wall_heat(750.0) == pytest.approx((0.0036207 * 750 - 0.1139) * 1e6)
    # the air enthalpy is the integral of the Tab. 4.6 c_p polynomial
    from drumheat.models import air

    T = 600.0
    assert (hL(T + 1e-3) - hL(T - 1e-3)) / 2e-3 == pytest.approx(float(air.heat_capacity(T)),
                                                                 rel=1e-7)
    assert gb.air_temperature(hL(T)) == pytest.approx(T, abs=1e-8)


def test_scene_temperatures_are_the_fixed_point_of_the_balances(runs):
    """The scene's T_WS, T_FB, T_L,aus are the fixed point scripts/staltner_balances.py finds
    with the scene's own droplet model (printed there to 0.01 K)."""
    bal = script("staltner_balances")
    sc = load_scene("staltner-slag-particle")
    surf = sc.heat.radiation.surfaces
    st, _, _, _ = bal.iterate({}, surf[0].temperature, sc.gas.temperature, surf[3].temperature,
                              tol=0.02, max_iter=1, verbose=False)
    assert abs(st.T_bed - surf[0].temperature) < 0.02
    assert surf[1].temperature == surf[0].temperature  # T_2 = T_3
    assert abs(st.T_freeboard - sc.gas.temperature) < 0.02
    assert abs(st.T_outlet - surf[3].temperature) < 0.02


def test_ghost_contact_flux_is_the_thesis_stencil():
    """The thesis' literal Phase-2 node-n update [5.32] (explicit, T_m in node n+1) removes
    from a uniform droplet exactly the heat of ghost_node_contact_flux over its surface."""
    mat = staltner_slag()
    grid = shells.make_grid(0.001, 12)
    T = jnp.full((1, 12), 1500.0)
    T_m = 560.0
    dt = 1e-6
    T1, _ = shells.explicit_step(T, dt, grid, mat, shells.FixedSurfaceTemperature(T_m, "ghost"))
    R, dr = float(grid.radius[0]), float(grid.dr[0])
    # finite-difference node n: capacity rho c 4 pi r_n^2 dr (the stencil's M~ of [5.14])
    c = float(mat.heat_capacity(jnp.asarray(1500.0)))
    heat = -(float(T1[0, -1]) - 1500.0) * 2690.0 * c * 4 * math.pi * R**2 * dr
    q = float(ghost_node_contact_flux(1500.0, T_m, mat.conductivity(jnp.asarray(1500.0)),
                                      mat.conductivity(jnp.asarray(T_m)), R, dr))
    assert heat == pytest.approx(q * 4 * math.pi * R**2 * dt, rel=1e-12)
    assert np.allclose(np.asarray(T1[0, :-1]), 1500.0)  # interior untouched in one step


def test_contact_modes_bracket_the_converged_contact_time():
    """t2 grows with the shell count for 'surface' (the outer half-cell drops to T_m at once)
    and falls for 'ghost' (one cell of contact resistance); both remove Q_W/m_S."""
    t2 = {}
    for mode in ("surface", "ghost"):
        for n in (20, 150):
            res = dh.run(load_scene("staltner-slag-particle", {
                "groups.0.diameter": 0.004, "heat.internal.shells": n,
                "granulator.contact_mode": mode}), progress=False)
            ph = res.trajectory.info["phases"]
            t2[mode, n] = ph[1]["duration_s"]
            mass = 2690.0 * math.pi * 0.004**3 / 6
            assert -(ph[1]["Q_wall_J"] - ph[0]["Q_wall_J"]) == pytest.approx(
                wall_heat_per_mass(res.scene.granulator) * mass, rel=1e-9)
    assert t2["surface", 20] < t2["surface", 150] < t2["ghost", 150] < t2["ghost", 20]


def test_contact_mode_ghost_with_the_thesis_explicit_scheme():
    res = dh.run(load_scene("staltner-slag-particle", {
        "groups.0.diameter": 0.002, "heat.internal.shells": 10, "heat.internal.scheme": "explicit",
        "heat.internal.dt": 2e-5, "heat.internal.on_unstable": "refuse",
        "granulator.contact_mode": "ghost"}), progress=False)
    assert 0 < res.trajectory.info["phases"][1]["duration_s"] < 0.5
