"""Staltner (2018) granulator: how the reading of the convection correlation moves the droplets.

The source states the sphere correlation [3.25]-[3.28] with the characteristic length L = pi r
but neither the air-property temperature nor the velocity (staltner-slag-particle.md section 5,
digest notes). This script runs the scene ``staltner-slag-particle`` (geometry and zone
temperatures as in the scene file) for the four size classes under each reading and prints

* the Reynolds and Prandtl numbers and alpha at the start of the flight (T_s = T_S,0);
* the effective mean alpha of Phase 1, ``-Q_gas / (pi d^2 int (T_s - T_FB) dt)``, and the
  shares of convection and radiation in the Phase-1 heat loss;
* the mean temperature after Phase 1 (flight) and after Phase 3 (fall).

Readings (nothing is fitted; each is a physical alternative the source leaves open):

* ``scene``: L = pi d/2, Nu_lam = 0.664 Re^1/2 Pr^1/3, Nu_min = 2 ([3.25]-[3.28]), air at the
  film temperature, w = v_S;
* ``T_FB``: the same with the air properties at the freeboard air temperature;
* ``L = d``: the same Gnielinski sphere on the diameter (the form of kraychev-tube-bundle.md
  (3-16)-(3-18) and, with the all-Pr laminar part, of fluidized-bed-exercise.md section 3). With
  L = pi d/2 the conduction limit Nu_min = 2 gives alpha = 4 lambda/(pi d), 36 % below the exact
  limit 2 lambda/d of a sphere in a still gas (kraychev (3-3));
* ``L = d, T_FB``: both;
* ``rising air``: w = sqrt(v_S^2 + u^2) with the superficial velocity u of the freeboard air
  (m_L,ges over rho_L(T_FB) pi r2^2), across the horizontal flight;
* ``thesis scheme``: the source's explicit finite differences on a coarse grid (n = 10), to show
  the size of the numerical part;
* ``no radiation`` / ``no convection``: the effect switched off, for the shares.

Usage::

    PYTHONPATH=. python scripts/staltner_convection.py [--md FILE]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from drumheat.models import air
from drumheat.models import convection as corr
from drumheat.models import granulator_balance as gb
from drumheat.models.granulator import droplet_speed
from drumheat.motion import make_motion
from drumheat.scene import load_scene

CLASSES = (0.0005, 0.001, 0.002, 0.004)


def readings(scene):
    g = scene.granulator
    v = droplet_speed(g)
    _, _, m_air = gb.air_streams(170000.0, 0.70)  # Tab. 8.1 base case
    u = m_air / (float(air.density(scene.gas.temperature)) * math.pi * g.r2**2)
    n = 10
    return {
        "scene (L = pi d/2, film, w = v_S)": {},
        "air properties at T_FB": {"heat.convection.property_temperature": "gas"},
        "L = d": {"heat.convection.correlation": "gnielinski-kraychev"},
        "L = d, air at T_FB": {"heat.convection.correlation": "gnielinski-kraychev",
                               "heat.convection.property_temperature": "gas"},
        f"rising air (w = {math.hypot(v, u):.2f} m/s, u = {u:.2f} m/s)": {
            "heat.convection.velocity": math.hypot(v, u)},
        f"thesis explicit scheme, n = {n}": {"heat.internal.scheme": "explicit",
                                             "heat.internal.shells": n,
                                             "heat.internal.on_unstable": "refuse",
                                             "__explicit_n": n},
        "no radiation": {"heat.radiation": None},
        "no convection": {"heat.convection": None},
    }


def alpha_start(d, scene, reading):
    """Re (on the reading's L), Pr and alpha at T_s = T_S,0 for the scene and L = d readings."""
    Tg = scene.gas.temperature
    Ts = scene.groups[0].temperature
    film = "gas" not in reading.get("heat.convection.property_temperature", "film")
    Tp = 0.5 * (Ts + Tg) if film else Tg
    Tp = min(Tp, air.T_MAX)
    p = air.properties(Tp)
    w = reading.get("heat.convection.velocity", droplet_speed(scene.granulator))
    L = d if reading.get("heat.convection.correlation") == "gnielinski-kraychev" else math.pi * d / 2
    Re = float(corr.reynolds(w, L, p.nu))
    Nu = float(corr.gnielinski_sphere_nu(Re, p.Pr))
    return Re, float(p.Pr), Nu * float(p.lam) / L


def run(d, reading):
    ov = {k: v for k, v in reading.items() if not k.startswith("__")}
    if "__explicit_n" in reading:
        n = reading["__explicit_n"]
        dr = 0.5 * d / (n - 0.5)
        ov["heat.internal.dt"] = 0.5 * dr**2 * 1132.0 * 2690.0 / (4 * 2.15)  # [A.4], digest s. 4
    ov["groups.0.diameter"] = d
    m = make_motion(load_scene("staltner-slag-particle", ov))
    rec = m._run(*m.model())
    ph = rec["phases"]
    p1 = rec["phase"] == 1
    t, Ts = rec["t"][p1], rec["T"][p1, 0, -1]
    Tg = m.scene.gas.temperature
    integral = float(np.sum(0.5 * (Ts[1:] + Ts[:-1] - 2 * Tg) * np.diff(t)))
    q_gas = -ph[0].get("Q_gas_J", 0.0)
    q_rad = -ph[0].get("Q_radiation_J", 0.0)
    alpha_eff = q_gas / (math.pi * d**2 * integral) if q_gas else float("nan")
    return dict(T1=ph[0]["T_mean_K"] - 273.15, T3=ph[2]["T_mean_K"] - 273.15,
                alpha_eff=alpha_eff, conv_share=q_gas / (q_gas + q_rad) if q_gas + q_rad else 0.0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--md", help="write the markdown tables here")
    args = ap.parse_args(argv)
    scene = load_scene("staltner-slag-particle")
    rd = readings(scene)
    lines = ["Start of flight (T_s = T_S,0, T_FB from the scene): Re on the reading's L, Pr, "
             "alpha in W/(m2 K)", "",
             "| reading | " + " | ".join(f"{1e3 * d:g} mm: Re / Pr / alpha" for d in CLASSES) + " |",
             "|---|" + "---|" * len(CLASSES)]
    for name in list(rd)[:4]:
        cells = [" / ".join((f"{Re:.0f}", f"{Pr:.3f}", f"{a:.0f}")) for Re, Pr, a in
                 (alpha_start(d, scene, rd[name]) for d in CLASSES)]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    print("\n".join(lines), flush=True)
    res = {(name, d): run(d, r) for name, r in rd.items() for d in CLASSES}
    out = ["", "Mean temperature after flight / after fall (degC); effective Phase-1 alpha "
           "(W/(m2 K)) and convective share of the Phase-1 heat loss", "",
           "| reading | " + " | ".join(f"{1e3 * d:g} mm" for d in CLASSES) + " |",
           "|---|" + "---|" * len(CLASSES)]
    for name in rd:
        cells = []
        for d in CLASSES:
            r = res[name, d]
            a = "" if math.isnan(r["alpha_eff"]) else (f"; alpha {r['alpha_eff']:.0f}, "
                                                      f"conv. {100 * r['conv_share']:.0f} %")
            cells.append(f"{r['T1']:.1f} / {r['T3']:.1f}{a}")
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    print("\n".join(out))
    if args.md:
        open(args.md, "w").write("\n".join(lines + out) + "\n")


if __name__ == "__main__":
    main()
