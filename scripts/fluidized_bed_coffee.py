"""Fluidised-bed exercise (coffee beans): the exercise's bed-level model vs the resolved bed.

Runs the built-in scene ``fluidized-bed-coffee`` (200 beans with 20 radial shells, gas in plug
flow through 10 layers, re-mixed every second) and evaluates the exercise's own bed-level model
from the same values (fluidized-bed-exercise.md sections 3-5: alpha_a, alpha_i at Fo(t_E),
k = 1/(1/alpha_i + 1/alpha_a), NTU, closed form of section 4). Writes

* ``--png``: both cooling curves, the resolved bean surface and centre, and the outlet gas of
  both models (left); the difference resolved - bed-level (right);
* a markdown table of the exercise's quantities (section 8 order) and of both end temperatures,
  to stdout and ``--md``.

Why the two differ (docs/fluidized-bed-coffee.md): with NTU = kA/(f mdot_2 c_p,2) of order 3
the air leaving the bed is nearly saturated. The bed-level model lets it approach the *mean*
bean temperature (the internal resistance is folded into k); in the resolved bed the air
exchanges heat with the bean *surfaces* (alpha_a alone, NTU_a ~ 6) and so approaches the
surface temperature, which at Bi = alpha_a d/lambda_1 ~ 12 lies well below the mean. The air,
not the beans' interior, limits the cooling, and a cooler outlet air removes less heat.

Usage::

    PYTHONPATH=. python scripts/fluidized_bed_coffee.py --png docs/img/fluidized_bed_coffee.png
"""

from __future__ import annotations

import argparse
import math

import numpy as np

import drumheat as dh
from drumheat.models import convection as corr
from drumheat.models.sphere_conduction import internal_transient_nu
from drumheat.motion import make_motion
from drumheat.scene import load_scene


def exercise_numbers(scene):
    """The exercise's quantities (section 8 order), with drumheat.models functions."""
    g, gas, cv = scene.groups[0], scene.gas, scene.heat.convection
    d, lam1, rho1, c1 = g.diameter, g.conductivity, g.density, g.heat_capacity
    nu, rho2, c2, lam2 = gas.kinematic_viscosity, gas.density, gas.heat_capacity, gas.conductivity
    Pr = float(corr.prandtl(nu, rho2, c2, lam2))
    Re_L = float(corr.interstitial_reynolds(cv.loosening_velocity, d, nu, cv.loosening_porosity))
    Re_A = float(corr.reynolds(cv.velocity, d, nu))
    f_a = float(corr.packed_bed_factor(cv.loosening_porosity))
    Nu_L = f_a * float(corr.fluidized_bed_sphere_nu(Re_L, Pr))
    Nu_A = float(corr.fluidized_bed_sphere_nu(Re_A, Pr))
    a_L, a_A = Nu_L * lam2 / d, Nu_A * lam2 / d
    a_a = 0.5 * (a_L + a_A)
    t_E = scene.run.duration
    Bi, Fo = a_a * d / lam1, lam1 * t_E / (rho1 * c1 * d**2)
    Nu_i = float(internal_transient_nu(Bi, Fo))
    a_i = Nu_i * lam1 / d
    k = float(corr.series_coefficient(a_i, a_a))
    A_f = float(corr.bed_area_per_cross_section(scene.motion.loading, d, rho1))
    ntu = float(corr.bed_ntu(k, A_f, gas.mass_flux, c2))
    ntu_a = float(corr.bed_ntu(a_a, A_f, gas.mass_flux, c2))
    return dict(Pr=Pr, Re_L=Re_L, Re_A=Re_A, f_a=f_a, Nu_L=Nu_L, Nu_A=Nu_A, alpha_L=a_L,
                alpha_A=a_A, alpha_a=a_a, Bi=Bi, Fo=Fo, Nu_i=Nu_i, alpha_i=a_i, k=k, A_per_f=A_f,
                NTU=ntu, NTU_a=ntu_a, tau=scene.motion.loading * c1 / (gas.mass_flux * c2))


LABELS = [("Pr", "Pr", "{:.4f}"), ("Re_L", "Re at the loosening point (interstitial)", "{:.1f}"),
          ("Re_A", "Re at the discharge point", "{:.1f}"), ("f_a", "bed factor f_a(psi_L)", "{:.2f}"),
          ("Nu_L", "Nu_L (with f_a)", "{:.3f}"), ("Nu_A", "Nu_A", "{:.3f}"),
          ("alpha_L", "alpha_a,L / W/(m2 K)", "{:.2f}"), ("alpha_A", "alpha_a,A / W/(m2 K)", "{:.2f}"),
          ("alpha_a", "alpha_a / W/(m2 K)", "{:.2f}"), ("Bi", "Bi = alpha_a d/lambda_1", "{:.3f}"),
          ("Fo", "Fo(t_E)", "{:.4f}"), ("Nu_i", "Nu_i", "{:.3f}"),
          ("alpha_i", "alpha_i / W/(m2 K)", "{:.2f}"), ("k", "k / W/(m2 K)", "{:.2f}"),
          ("A_per_f", "A/f / (m2/m2)", "{:.3f}"), ("NTU", "NTU = kA/(f mdot_2 c_p,2)", "{:.4f}"),
          ("NTU_a", "NTU_a = alpha_a A/(f mdot_2 c_p,2) (surface only)", "{:.4f}"),
          ("tau", "time constant m_1 c_p,1/(mdot_2 c_p,2) / s", "{:.1f}")]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--png", help="write the figure here")
    ap.add_argument("--md", help="write the markdown tables here")
    ap.add_argument("--convergence", action="store_true",
                    help="also run the resolved bed with finer shells, layers, step, more beans")
    ap.add_argument("--t-R", dest="t_R", type=float, nargs="*", default=[4.0, 0.25, 0.05],
                    help="re-mixing periods to compare with the scene's (s)")
    args = ap.parse_args(argv)
    scene = load_scene("fluidized-bed-coffee")
    num = exercise_numbers(scene)
    motion = make_motion(scene)
    _, info = motion.bed_level_model()
    res = dh.run(scene, progress=False)
    ts = res.timeseries
    t = ts["t"].to_numpy()
    T_in = scene.gas.temperature
    T_bed = ts["T_bed_level"].to_numpy()
    gas_bed = T_bed - (T_bed - T_in) * math.exp(-info["NTU"])  # section 4 outlet (NTU form)
    lines = ["| quantity | drumheat (exercise's procedure) |", "|---|---|"]
    for key, label, fmt in LABELS:
        lines.append(f"| {label} | {fmt.format(num[key])} |")
    C = lambda T: T - 273.15
    out = ["", "| model | T_1 at t_E = 150 s (degC) | outlet air at t_E (degC) | "
           "bean surface / centre at t_E (degC) |", "|---|---|---|---|",
           f"| bed-level (exercise, section 4; column T_bed_level) | {C(T_bed[-1]):.2f} | "
           f"{C(gas_bed[-1]):.2f} | - |",
           f"| particle-resolved, 20 shells (column T_mean) | {C(ts['T_mean'].iloc[-1]):.2f} | "
           f"{C(ts['T_gas_out'].iloc[-1]):.2f} | {C(ts['T_surface_mean'].iloc[-1]):.2f} / "
           f"{C(ts['T_centre_mean'].iloc[-1]):.2f} |"]
    print("\n".join(lines + out))
    print(f"\nk from the scene's bed-level model: {info['k']:.6f} W/(m2 K), NTU {info['NTU']:.6f}; "
          f"energy balance error of the resolved run {res.summary['energy_balance_rel_error']:.2e}")
    eff_res = (ts["T_gas_out"].to_numpy() - T_in) / (ts["T_mean"].to_numpy() - T_in)
    eff_bed = (gas_bed - T_in) / (T_bed - T_in)
    print("air heating per bean excess (T_gas,out - T_2,ein)/(T_1 - T_2,ein), bed-level / "
          "resolved, at t = " + ", ".join(f"{ti:g} s: {a:.3f} / {b:.3f}" for ti, a, b in
                                          zip(t, eff_bed, eff_res) if ti % 30 == 0 and ti > 0))
    print("T_mean - T_bed_level (K) at t = " + ", ".join(
        f"{ti:g} s: {a - b:.3f}" for ti, a, b in zip(t, ts["T_mean"], T_bed)))
    # re-mixing period: the exercise's "perfectly mixed" bed is the limit t_R -> 0
    remix = {}
    for tR in args.t_R:
        r = dh.run(load_scene("fluidized-bed-coffee", {"motion.t_R": tR}), progress=False)
        remix[tR] = r.timeseries["T_mean"].to_numpy()
    rows = ["", "| re-mixing period t_R (s) | T_mean at t_E (degC) | minus T_bed_level at t_E (K) | "
            "largest difference during the run (K) |", "|---|---|---|---|"]
    for tR, T in sorted({**remix, scene.motion.t_R: ts["T_mean"].to_numpy()}.items(),
                        reverse=True):
        rows.append(f"| {tR:g}{' (scene)' if tR == scene.motion.t_R else ''} | {C(T[-1]):.3f} | "
                    f"{T[-1] - T_bed[-1]:.3f} | {np.max(T - T_bed):.3f} |")
    out += rows
    print("\n".join(rows), flush=True)
    if args.convergence:
        conv = ["", "| resolved bed variant (t_R = 1 s) | T_mean at t_E (degC) | minus T_bed_level (K) |",
                "|---|---|---|", f"| scene (20 shells, 10 layers, dt 0.05 s, 200 beans) | "
                f"{C(ts['T_mean'].iloc[-1]):.3f} | {ts['T_mean'].iloc[-1] - T_bed[-1]:.3f} |"]
        for label, ov in (("40 shells", {"heat.internal.shells": 40}),
                          ("20 layers", {"motion.layers": 20}),
                          ("dt 0.0125 s", {"heat.internal.dt": 0.0125}),
                          ("400 beans", {"groups.0.count": 400})):
            r = dh.run(load_scene("fluidized-bed-coffee", ov), progress=False)
            T_end = r.timeseries["T_mean"].iloc[-1]
            conv.append(f"| {label} | {C(T_end):.3f} | {T_end - T_bed[-1]:.3f} |")
        out += conv
        print("\n".join(conv))
    if args.md:
        open(args.md, "w").write("\n".join(lines + out) + "\n")
    if args.png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.3))
        a1.plot(t, C(T_bed), "k-", lw=2, label="bed-level model (exercise): mean bean")
        a1.plot(t, C(ts["T_mean"]), "C3-", lw=2, label="particle-resolved: mean bean")
        a1.plot(t, C(ts["T_surface_mean"]), "C3--", label="particle-resolved: bean surface")
        a1.plot(t, C(ts["T_centre_mean"]), "C3:", label="particle-resolved: bean centre")
        a1.plot(t, C(gas_bed), "k-.", label="bed-level model: outlet air")
        a1.plot(t, C(ts["T_gas_out"]), "C0-.", label="particle-resolved: outlet air")
        a1.set_xlabel("t / s")
        a1.set_ylabel("temperature / °C")
        a1.grid(alpha=0.3)
        a1.legend(fontsize="small")
        a1.set_title("coffee beans in a batch fluidised bed")
        a2.plot(t, ts["T_mean"] - T_bed, "C3o-", label=f"t_R = {scene.motion.t_R:g} s (scene)")
        for k, (tR, T) in enumerate(sorted(remix.items(), reverse=True)):
            a2.plot(t, T - T_bed, ls="--", color=f"C{k + 4}", label=f"t_R = {tR:g} s")
        a2.axhline(0.0, color="k", lw=0.8)
        a2.set_xlabel("t / s")
        a2.set_ylabel("T_mean (resolved) - T_bed_level / K")
        a2.grid(alpha=0.3)
        a2.legend(fontsize="small", title="re-mixing period")
        a2.set_title("resolved minus bed-level (exercise)")
        fig.tight_layout()
        fig.savefig(args.png, dpi=110)
        plt.close(fig)


if __name__ == "__main__":
    main()
