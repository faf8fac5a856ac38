"""Staltner (2018) granulator: how the wall-contact time t_2 depends on the radial grid.

Phase 2 (staltner-slag-particle.md section 3, [5.29]-[5.32]) switches the droplet surface from a
flux to a Dirichlet condition at the contact temperature T_m of two semi-infinite bodies, and
t_2 is the time at which the droplet has given Q_W/m_S to the wall ([4.8], [4.9]). The jump of
the surface temperature to T_m is not resolved by any finite grid, so t_2 depends on the shell
count n, and does so in opposite directions for the two readings of the boundary
(``granulator.contact_mode``):

* ``"surface"`` (node n held at T_m, the digest's consistent reading): the outer half-cell drops to
  T_m at once and its heat is booked to the wall in the first step. On a coarse grid that half
  cell holds a large share of Q_W/m_S, so t_2 is too short; it grows towards the converged value
  as n grows.
* ``"ghost"`` (T_m one cell outside the sphere, the thesis' literal reading [5.31]-[5.32]): a
  contact resistance of one cell, dr/lambda, sits between droplet and wall, so t_2 is too long on
  a coarse grid; it falls towards the converged value.

The source reports neither n nor dt (digest section 12), so its t_2 carries the same grid
dependence. This script runs the scene ``staltner-slag-particle`` for the four size classes,
both modes, the implicit scheme over n = 10..600 and the thesis' explicit scheme for n = 10..40
(stable step from [A.4] with a margin), and writes

* a markdown table of t_2 (and the mean temperature after Phase 3) to stdout and to ``--md``;
* ``--png``: t_2 over n, one panel per droplet size.

Usage::

    PYTHONPATH=. python scripts/staltner_contact_grid.py --png docs/img/staltner_contact_grid.png \\
        --json grid.json
    PYTHONPATH=. python scripts/staltner_contact_grid.py --from-json grid.json   # tables only
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from drumheat.motion import make_motion
from drumheat.scene import load_scene

CLASSES = (0.0005, 0.001, 0.002, 0.004)
N_IMPLICIT = (10, 20, 40, 80, 150, 300, 600)
N_EXPLICIT = (10, 20, 40)
RHO, C_MIN, LAM_MAX = 2690.0, 1132.0, 2.15  # staltner digest section 9 (worst-case diffusivity)


def explicit_dt(d, n, margin=0.5):
    """Explicit step below the centre bound [A.4] dt <= dr^2 c rho / (2 (lam_1 + lam_2)),
    evaluated with the largest conductivity and the smallest c_p of the slag (digest section 4,
    'a_max'); ``margin`` leaves room for the surface bound [A.7] with convection and radiation."""
    dr = 0.5 * d / (n - 0.5)
    return margin * dr**2 * C_MIN * RHO / (4.0 * LAM_MAX)


def run(d, n, mode, scheme, steps=None):
    ov = {"groups.0.diameter": d, "heat.internal.shells": n, "granulator.contact_mode": mode,
          "heat.internal.scheme": scheme}
    if scheme == "explicit":
        ov.update({"heat.internal.dt": explicit_dt(d, n), "heat.internal.on_unstable": "refuse"})
    if steps:
        ov["granulator.steps_per_phase"] = steps
    m = make_motion(load_scene("staltner-slag-particle", ov))
    rec = m._run(*m.model())
    return dict(t2_ms=1e3 * float(rec["phases"][1]["duration_s"]),
                T3_C=float(rec["phases"][2]["T_mean_K"]) - 273.15,
                T2_C=float(rec["phases"][1]["T_mean_K"]) - 273.15)


def study():
    rows = []
    for d in CLASSES:
        for mode in ("surface", "ghost"):
            for n in N_IMPLICIT:
                rows.append(dict(d_mm=1e3 * d, mode=mode, scheme="implicit", n=n, **run(d, n, mode, "implicit")))
                print(rows[-1], flush=True)
            for n in N_EXPLICIT:
                rows.append(dict(d_mm=1e3 * d, mode=mode, scheme="explicit", n=n, **run(d, n, mode, "explicit")))
                print(rows[-1], flush=True)
        # time-step check at the finest production-like grid
        for mode in ("surface", "ghost"):
            rows.append(dict(d_mm=1e3 * d, mode=mode, scheme="implicit, 4x steps", n=300,
                             **run(d, 300, mode, "implicit", steps=1600)))
            print(rows[-1], flush=True)
    return rows


def table(rows):
    lines = ["| d (mm) | mode | scheme | " + " | ".join(f"n = {n}" for n in N_IMPLICIT) + " |",
             "|---|---|---|" + "---|" * len(N_IMPLICIT)]
    for d in CLASSES:
        for mode in ("surface", "ghost"):
            for scheme in ("implicit", "explicit", "implicit, 4x steps"):
                cells = []
                for n in N_IMPLICIT:
                    r = [x for x in rows if x["d_mm"] == 1e3 * d and x["mode"] == mode
                         and x["scheme"] == scheme and x["n"] == n]
                    cells.append(f"{r[0]['t2_ms']:.2f}" if r else "")
                lines.append(f"| {1e3 * d:g} | {mode} | {scheme} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def extrapolated(rows):
    """Richardson extrapolation of the two finest implicit grids (n = 300, 600), per size and
    mode, both as first order in dr (the ghost cell's resistance is O(dr)):
    ``t(0) ~ 2 t(600) - t(300)``."""
    lines = ["| d (mm) | surface: n = 600 | surface: extrapolated | ghost: n = 600 | "
             "ghost: extrapolated | n = 150 vs n = 600, surface |", "|---|---|---|---|---|---|"]
    for d in CLASSES:
        cells = []
        for mode in ("surface", "ghost"):
            g = {x["n"]: x["t2_ms"] for x in rows if x["d_mm"] == 1e3 * d
                 and x["mode"] == mode and x["scheme"] == "implicit"}
            cells += [f"{g[600]:.3f}", f"{2 * g[600] - g[300]:.3f}"]
            if mode == "surface":
                rel = 100 * (g[150] - g[600]) / g[600]
        lines.append(f"| {1e3 * d:g} | " + " | ".join(cells) + f" | {rel:+.2f} % |")
    return "\n".join(lines)


def figure(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(15, 3.8))
    for ax, d in zip(axes, CLASSES):
        for mode, col in (("surface", "C0"), ("ghost", "C3")):
            for scheme, mk, ls in (("implicit", "o", "-"), ("explicit", "x", "none")):
                r = [x for x in rows if x["d_mm"] == 1e3 * d and x["mode"] == mode
                     and x["scheme"] == scheme]
                ax.plot([x["n"] for x in r], [x["t2_ms"] for x in r], marker=mk, ls=ls, color=col,
                        label=f"{mode}, {scheme}")
        ax.set_xscale("log")
        ax.set_xlabel("shells n")
        ax.set_title(f"d = {1e3 * d:g} mm")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("contact time t_2 / ms")
    axes[0].legend(fontsize="x-small")
    fig.suptitle("staltner-slag-particle: wall-contact time over the radial grid "
                 "(surface: T_m on node n; ghost: T_m one cell outside)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--png", help="write the figure here")
    ap.add_argument("--md", help="write the markdown table here")
    ap.add_argument("--json", help="write the rows here")
    ap.add_argument("--from-json", help="tabulate the rows of an earlier --json run")
    args = ap.parse_args(argv)
    rows = json.load(open(args.from_json)) if args.from_json else study()
    md = table(rows) + "\n\n" + extrapolated(rows)
    print(md)
    if args.md:
        open(args.md, "w").write(md + "\n")
    if args.json and not args.from_json:
        json.dump(rows, open(args.json, "w"), indent=1)
    if args.png:
        figure(rows, args.png)


if __name__ == "__main__":
    main()
