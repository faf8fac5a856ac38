"""Staltner (2018) granulator: the pilot-plant geometry recovered from the published flight times.

The thesis shows the VASL pilot plant only in a figure (Fig. 8.1; digest
staltner-slag-particle.md section 12), but its base case reports the flight and fall times,
Tab. 8.2: t_1 = 97.3 ms and t_3 = 53.1 ms, the same for every droplet size (project issue 20
quotes them). With the digest's path reconstruction (section 1, digest note: the disc and the
horizontal Phase-1 path at mid-cone height z_D = h3 + h4/2, specular reflection at the cone)

    t_1 = s_1 / v_S,   s_1 = r_w = r2 - (h4/2)/tan(alpha4)
    t_3 = s_3 / v_S,   s_3 = z_D / sin(2 alpha4),   z_D = h3 + h4/2
    v_S = 0.8 pi d_Dt n_Dt                                                  [4.1]

and h3 = 1 m (Tab. 4.3), n_Dt = 900 1/min (Tab. 8.1 base case), the two times fix two of the
four unknowns (d_Dt, alpha4, h4, r2); for every disc diameter d_Dt and inclination alpha4:

    h4 = 2 (v_S t_3 sin(2 alpha4) - h3),    r2 = v_S t_1 + h4 / (2 tan(alpha4)).

The script scans d_Dt over its range 0.5-1 m (Tab. 4.3) and alpha4 over 45-60 deg (Tab. 4.3),
keeps the (h4, r2) that lie inside region A or B (Tabs. 4.1, 4.2), prints the family, marks the
members whose dimensions are round to the resolution the rounded times allow (+-0.05 ms), and
compares the two candidate plants (a 0.75 m and a 1.0 m disc) in the droplet model: the times are
the same by construction; the view factors, and with them the radiation, differ.

Usage::

    PYTHONPATH=. python scripts/staltner_geometry.py            # table + choice
    PYTHONPATH=. python scripts/staltner_geometry.py --no-run   # geometry only (no droplet runs)
"""

from __future__ import annotations

import argparse
import math

import numpy as np

T1_PUBLISHED = 97.3e-3  # s, Staltner Tab. 8.2 (base case, all sizes), rounded to 0.1 ms
T3_PUBLISHED = 53.1e-3  # s, Staltner Tab. 8.2
TIME_RESOLUTION = 0.05e-3  # s, half the last printed digit
H3 = 1.0  # m, Tab. 4.3
N_DT = 900.0  # 1/min, Tab. 8.1 base case
REGIONS = {"A": dict(r2=(2.0, 3.25), h4=(0.75, 1.75)),  # Tab. 4.1
           "B": dict(r2=(3.25, 5.0), h4=(1.0, 3.0))}  # Tab. 4.2
ALPHA_RANGE = (45.0, 60.0)  # deg, Tab. 4.3
DISC_RANGE = (0.5, 1.0)  # m, Tab. 4.3


def droplet_speed(d_disc, n_disc=N_DT):
    """v_S = 0.8 pi d_Dt n_Dt, m/s (staltner-slag-particle.md [4.1]; n in 1/min)."""
    return 0.8 * math.pi * d_disc * n_disc / 60.0


def geometry_from_times(d_disc, alpha4_deg, t1=T1_PUBLISHED, t3=T3_PUBLISHED, h3=H3):
    """(h4, r2) in m that give the flight and fall times t1, t3 (module docstring)."""
    v = droplet_speed(d_disc)
    a = math.radians(alpha4_deg)
    h4 = 2.0 * (v * t3 * math.sin(2.0 * a) - h3)
    r2 = v * t1 + h4 / (2.0 * math.tan(a))
    return h4, r2


def times_of(d_disc, alpha4_deg, h4, r2, h3=H3):
    """(t1, t3) in s of a plant (digest section 1, mid-cone disc)."""
    v = droplet_speed(d_disc)
    a = math.radians(alpha4_deg)
    s1 = r2 - 0.5 * h4 / math.tan(a)
    s3 = (h3 + 0.5 * h4) / math.sin(2.0 * a)
    return s1 / v, s3 / v


def regions_of(h4, r2):
    return "".join(k for k, b in REGIONS.items()
                   if b["r2"][0] - 1e-9 <= r2 <= b["r2"][1] + 1e-9
                   and b["h4"][0] - 1e-9 <= h4 <= b["h4"][1] + 1e-9)


def tolerance(d_disc, alpha4_deg):
    """Spread of (h4, r2) allowed by the +-0.05 ms rounding of the published times, m."""
    v = droplet_speed(d_disc)
    a = math.radians(alpha4_deg)
    dh4 = 2.0 * v * TIME_RESOLUTION * math.sin(2.0 * a)
    dr2 = v * TIME_RESOLUTION + dh4 / (2.0 * math.tan(a))
    return dh4, dr2


def is_round(x, step, tol):
    return abs(x - step * round(x / step)) <= tol + 1e-12


def family(d_discs=(0.5, 0.6, 0.7, 0.75, 0.8, 0.9, 1.0), alphas=(45.0, 47.5, 50.0, 52.5, 55.0,
                                                                  57.5, 60.0)):
    rows = []
    for d in d_discs:
        for a in alphas:
            h4, r2 = geometry_from_times(d, a)
            dh4, dr2 = tolerance(d, a)
            reg = regions_of(h4, r2)
            rows.append(dict(d_disc=d, alpha4=a, h4=h4, r2=r2, region=reg or "-",
                             round_=bool(reg) and is_round(h4, 0.25, dh4)
                             and is_round(r2, 0.25, dr2)))
    return rows


def round_solutions():
    """Members of the family (d_Dt on a 5 cm grid, alpha4 on a 2.5 deg grid) whose h4 and r2
    are multiples of 0.25 m within the rounding of the published times, inside region A or B."""
    out = []
    for d in np.round(np.arange(DISC_RANGE[0], DISC_RANGE[1] + 1e-9, 0.05), 2):
        for a in np.arange(ALPHA_RANGE[0], ALPHA_RANGE[1] + 1e-9, 2.5):
            h4, r2 = geometry_from_times(float(d), float(a))
            dh4, dr2 = tolerance(float(d), float(a))
            if regions_of(h4, r2) and is_round(h4, 0.25, dh4) and is_round(r2, 0.25, dr2):
                out.append((float(d), float(a), h4, r2))
    return out


def droplet_runs(plants, diameters=(0.0005, 0.001, 0.002, 0.004)):
    """Mean temperature after each phase for every plant (scene staltner-slag-particle)."""
    from drumheat.motion import make_motion
    from drumheat.scene import load_scene

    res = {}
    for name, (d_disc, a, h4, r2) in plants.items():
        for d in diameters:
            m = make_motion(load_scene("staltner-slag-particle", {
                "groups.0.diameter": d, "granulator.disc_diameter": d_disc,
                "granulator.alpha4": a, "granulator.h4": h4, "granulator.r2": r2}))
            rec = m._run(*m.model())
            res[name, d] = [(r["duration_s"], r["T_mean_K"]) for r in rec["phases"]]
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--no-run", action="store_true", help="skip the droplet runs")
    args = ap.parse_args(argv)

    print(f"published (Tab. 8.2): t1 = {1e3 * T1_PUBLISHED:.1f} ms, t3 = "
          f"{1e3 * T3_PUBLISHED:.1f} ms; h3 = {H3} m, n_Dt = {N_DT:g} 1/min\n")
    print("family of plants with these times (mid-cone disc):")
    print(f"{'d_Dt/m':>7} {'alpha4':>7} {'h4/m':>7} {'r2/m':>7}  region")
    for r in family():
        print(f"{r['d_disc']:7.2f} {r['alpha4']:7.1f} {r['h4']:7.3f} {r['r2']:7.3f}  {r['region']}"
              + ("   <- round" if r["round_"] else ""))
    sols = round_solutions()
    print("\nmembers with h4 and r2 on a 0.25 m grid (within the +-0.05 ms rounding):")
    for d, a, h4, r2 in sols:
        t1, t3 = times_of(d, a, round(h4 / 0.25) * 0.25, round(r2 / 0.25) * 0.25)
        print(f"  d_Dt = {d:.2f} m, alpha4 = {a:.1f} deg: h4 = {h4:.4f} m, r2 = {r2:.4f} m "
              f"(region {regions_of(h4, r2)}); rounded plant gives t1 = {1e3 * t1:.2f} ms, "
              f"t3 = {1e3 * t3:.2f} ms")

    chosen = (0.75, 45.0, 1.0, 3.25)
    h4_1, r2_1 = geometry_from_times(1.0, 45.0)
    other = (1.0, 45.0, h4_1, r2_1)
    t1, t3 = times_of(*chosen)
    print(f"\nchosen: d_Dt = 0.75 m, alpha4 = 45 deg, h4 = 1.0 m, r2 = 3.25 m: t1 = "
          f"{1e3 * t1:.2f} ms, t3 = {1e3 * t3:.2f} ms "
          f"(published {1e3 * T1_PUBLISHED:.1f}, {1e3 * T3_PUBLISHED:.1f})")
    t1, t3 = times_of(*other)
    print(f"alternative: d_Dt = 1.0 m, alpha4 = 45 deg, h4 = {h4_1:.3f} m, r2 = {r2_1:.3f} m: "
          f"t1 = {1e3 * t1:.2f} ms, t3 = {1e3 * t3:.2f} ms")
    print("""
why the first: (1) every dimension is a round number and the plant sits on the corner
(r2,min, h4,min, alpha4,min) = (3.25 m, 1.0 m, 45 deg) of the source's view-factor region B,
whose corners are the geometries the source evaluated exactly (digest section 7.1, [6.22]-[6.28]);
(2) the disc stays at the middle of its range (0.75 m), the assumption the scene made before;
(3) a 1.0 m disc needs r2 = 4.67 m, which is on no grid of the source's tables.
Neither reason is proof: the thesis states the plant only in Fig. 8.1.""")

    if not args.no_run:
        plants = {"chosen (0.75 m disc)": chosen, "alternative (1.0 m disc)": other}
        res = droplet_runs(plants)
        print("\nmean temperature after flight / contact / fall, degC (scene "
              "staltner-slag-particle with each geometry):")
        for d in (0.0005, 0.001, 0.002, 0.004):
            cells = []
            for name in plants:
                ph = res[name, d]
                cells.append(f"{name}: " + " / ".join(f"{T - 273.15:.1f}" for _, T in ph)
                             + f" (t2 = {1e3 * ph[1][0]:.2f} ms)")
            print(f"  d = {1e3 * d:g} mm: " + ";  ".join(cells))


if __name__ == "__main__":
    main()
