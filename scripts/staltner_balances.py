"""Staltner (2018) granulator: zone and freeboard-air temperatures from the source's own balances.

The scene ``staltner-slag-particle`` simulates one droplet; the temperatures it needs as inputs
(bed and slots T_2 = T_3 = T_WS, outlet T_5 = T_L,aus, freeboard air T_FB, the fluid temperature
of the convection) are outputs of the freeboard balances [7.7], [7.12], [7.16] over all four
size classes (staltner-slag-particle.md section 8), which the source solves by fixed-point
iteration. This script does the same:

1. run the droplet model (the scene, with its geometry, emissivities, correlations and grid) for
   the four size classes of Tab. 4.5 at the current (T_WS, T_FB, T_L,aus);
2. mass-weight (weights p of Tab. 4.5) the mean enthalpies after Phase 1, at the FBK/FBZ
   boundary of Phase 3 (3*: the fraction h4/(2 h3 + h4) of the fall path, digest section 1) and
   after Phase 3, and the radiation of Phases 1 and 3 (number flow times energy per droplet);
3. solve the three balances for the three temperatures
   (:func:`drumheat.models.granulator_balance.freeboard_state`) and repeat until they change by
   less than 0.01 K.

The base case of Tab. 8.1 (170000 Nm3/h, 70 % through the bed, 750 kg/min, 1350 degC, 20 degC
air) is the default. The numbers printed at the end are the ones written into the scene file.

Usage::

    PYTHONPATH=. python scripts/staltner_balances.py [--set KEY=VALUE ...]
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.models import granulator_balance as gb
from drumheat.motion import make_motion
from drumheat.scene import load_scene
from drumheat.scene.files import parse_override

CLASSES = (0.0005, 0.001, 0.002, 0.004)  # m, Tab. 4.5
WEIGHTS = (0.051, 0.172, 0.408, 0.369)  # Tab. 4.5 / Fig. 4.5
BASE_CASE = dict(volume_flow_normal=170000.0, bed_share=0.70, T_air_in=293.15)  # Tab. 8.1, 4.4


def droplet(overrides):
    """One droplet run: specific enthalpies (J/kg) after phases 1, 3*, 3 and radiation (J)."""
    m = make_motion(load_scene("staltner-slag-particle", overrides))
    rec = m._run(*m.model())
    it = rec["model"].internal
    mass = rec["mass"]
    H = np.asarray(jax.vmap(lambda x: jnp.sum(it.stored_heat(x)))(jnp.asarray(rec["T"])))
    ph = rec["phases"]
    t3_start, t3 = float(ph[2]["t_start_s"]), float(ph[2]["duration_s"])
    t_star = t3_start + m.path["fbk_fraction"] * t3
    h_star = float(np.interp(t_star, rec["t"], H)) / mass
    h0 = float(H[0]) / mass
    h1 = float(H[rec["phase"] == 1][-1]) / mass
    h3 = float(H[-1]) / mass
    rad1 = -ph[0]["Q_radiation_J"]
    rad3 = -(ph[2]["Q_radiation_J"] - ph[1]["Q_radiation_J"])
    return dict(h0=h0, h1=h1, h3star=h_star, h3=h3, rad1=rad1, rad3=rad3, mass=mass,
                phases=ph, material=it.material)


def iterate(base_overrides, T_ws, T_fb, T_aus, tol=0.01, max_iter=30, verbose=True):
    scene = load_scene("staltner-slag-particle", base_overrides)
    g = scene.granulator
    slag_rate = g.slag_rate
    for k in range(max_iter):
        ov = dict(base_overrides)
        ov.update({"gas.temperature": T_fb,
                   "heat.radiation.surfaces.0.temperature": T_ws,
                   "heat.radiation.surfaces.1.temperature": T_ws,
                   "heat.radiation.surfaces.3.temperature": T_aus})
        runs = {d: droplet({**ov, "groups.0.diameter": d}) for d in CLASSES}
        w = dict(zip(CLASSES, WEIGHTS))
        mean = lambda key: sum(w[d] * runs[d][key] for d in CLASSES)
        m_s = slag_rate / 60.0
        # number flow of class d = w_d m_S / m_d; radiation per class = that times J per droplet
        Q1 = sum(w[d] * m_s / runs[d]["mass"] * runs[d]["rad1"] for d in CLASSES)
        Q3 = sum(w[d] * m_s / runs[d]["mass"] * runs[d]["rad3"] for d in CLASSES)
        mat = runs[CLASSES[0]]["material"]
        h_slag = lambda T: float(mat.enthalpy(jnp.asarray(T, float)))
        st = gb.freeboard_state(slag_rate=slag_rate, h_slag_0=mean("h0"), h_slag_1=mean("h1"),
                                h_slag_3star=mean("h3star"), h_slag_3=mean("h3"),
                                Q_radiation_1=Q1, Q_radiation_3=Q3, slag_enthalpy=h_slag,
                                h3=g.h3, h4=g.h4, **BASE_CASE)
        change = max(abs(st.T_bed - T_ws), abs(st.T_freeboard - T_fb), abs(st.T_outlet - T_aus))
        if verbose:
            print(f"iteration {k + 1}: T_WS = {st.T_bed - 273.15:.3f} degC, T_FB = "
                  f"{st.T_freeboard - 273.15:.3f} degC, T_L,aus = {st.T_outlet - 273.15:.3f} degC "
                  f"(change {change:.3g} K)")
        T_ws, T_fb, T_aus = st.T_bed, st.T_freeboard, st.T_outlet
        if change < tol:
            return st, runs, Q1, Q3
    raise RuntimeError(f"no fixed point within {max_iter} iterations")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="scene override for every droplet run")
    args = ap.parse_args(argv)
    base = dict(parse_override(s) for s in args.set)
    sc = load_scene("staltner-slag-particle", base)
    surf = sc.heat.radiation.surfaces
    st, runs, Q1, Q3 = iterate(base, surf[0].temperature, sc.gas.temperature, surf[3].temperature)
    m_s = sc.granulator.slag_rate / 60.0
    m_ws, m_sb, m_tot = gb.air_streams(BASE_CASE["volume_flow_normal"], BASE_CASE["bed_share"])
    print("\nfixed point (base case, Tab. 8.1):")
    print(f"  bed and slots  T_2 = T_3 = T_WS = {st.T_bed:.2f} K ({st.T_bed - 273.15:.1f} degC)")
    print(f"  freeboard air  T_FB              = {st.T_freeboard:.2f} K "
          f"({st.T_freeboard - 273.15:.1f} degC)")
    print(f"  outlet         T_5 = T_L,aus     = {st.T_outlet:.2f} K "
          f"({st.T_outlet - 273.15:.1f} degC); air heating T_5 - T_L,ein = "
          f"{st.T_outlet - BASE_CASE['T_air_in']:.1f} K")
    print(f"  air: m_L,WS = {m_ws:.3f} kg/s, m_L,SB = {m_sb:.3f} kg/s; slag m_S = {m_s:.3f} kg/s")
    print(f"  wall Q_W = {st.Q_wall / 1e6:.4f} MW [4.8]; radiation Q_Str = {st.Q_radiation / 1e6:.4f}"
          f" MW (Phase 1 {Q1 / 1e6:.4f}, Phase 3 {Q3 / 1e6:.4f}); [7.18] residual "
          f"{st.total_residual:.3g} W")
    conv = m_tot * (gb.air_enthalpy(st.T_outlet) - gb.air_enthalpy(BASE_CASE["T_air_in"]))
    print(f"  air heating m_L,ges (h_L,aus - h_L,ein) = {conv / 1e6:.4f} MW")
    print("\nmean temperature after flight / contact / fall per class at the fixed point, degC:")
    for d in CLASSES:
        ph = runs[d]["phases"]
        print(f"  d = {1e3 * d:g} mm: " + " / ".join(f"{r['T_mean_K'] - 273.15:.1f}" for r in ph)
              + f"   (t1, t2, t3 = " + ", ".join(f"{1e3 * r['duration_s']:.2f}" for r in ph)
              + " ms)")


if __name__ == "__main__":
    main()
