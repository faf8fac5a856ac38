"""Accuracy and its cost for a mixed bed: coupled reference versus the cheaper variants.

Runs the built-in scene ``weigler-mixed`` (70 aluminium spheres, 12 rpm) with the drum wall
heated as well (so that ``alpha_overall`` exists: wall 333.15 K, alpha_wp = 210 W/(m2 K), the
Schluender value for 4 mm), over a short horizon, as

* a coupled reference (stiffer contacts, thermal step = mechanical step),
* the same with another packing (``run.seed``): the spread any single DEM run has anyway,
* thermal sub-cycling (one thermal step per k mechanical steps),
* softened stiffness with a larger time step,
* a larger neighbour-list skin,
* replay of a recording of the first k revolutions, cyclically, for the rest of the horizon,
* contacts that conduct only while they overlap (conducting gap 0 instead of the default 1 % of
  d), at the reference stiffness and softened,

and prints a table (variant, wall time, speed-up, error of the mean and of each fraction's mean
temperature, error of alpha_overall, all at the end of the horizon and as maxima over time)
and writes the same as ``accuracy_cost.csv`` and a figure ``accuracy_cost.png`` (error versus
wall time).

drumheat's contact conduction is ``alpha A_p`` with ``A_p = pi d^2 / 4`` (weigler eq. [2.7]):
it does not depend on the overlap, so softening the contacts does not inflate the conductance
and needs no area correction. Which contacts conduct does depend on the stiffness when only
overlapping pairs count (a softer bed overlaps more); with the default gap tolerance (a pair
conducts while its gap is at most 1 % of d) softening acts only through the motion. The two
"conducting gap 0" rows show the difference.

Usage::

    python scripts/accuracy_cost.py [--horizon 20] [--out results/accuracy_cost] [--quick]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

import drumheat as dh

BASE = {"drum.wall_temperature": 333.15, "heat.wall.alpha": 210.0, "dem.replay_after": None}
#: contacts conduct only while they overlap (the definition before the gap tolerance)
GAP0 = {"heat.contact.gap_tolerance": 0.0, "heat.wall.gap_tolerance": 0.0}


def variants(horizon: float, quick: bool):
    k_ref = 2.0e4 if quick else 2.0e5
    ref = {"dem.stiffness": k_ref, "dem.thermal_substeps": 1}
    rev = 5.0  # s per revolution at 12 rpm
    v = [
        ("reference (k = %.0e N/m, coupled)" % k_ref, ref),
        ("reference, another packing (seed 2)", {**ref, "run.seed": 2}),
        ("sub-cycling 10", {**ref, "dem.thermal_substeps": 10}),
        ("sub-cycling 100", {**ref, "dem.thermal_substeps": 100}),
        ("skin 1.0 d", {**ref, "dem.skin": 0.004}),
        ("softened k / 10", {**ref, "dem.stiffness": k_ref / 10}),
        ("softened k / 100", {**ref, "dem.stiffness": k_ref / 100}),
        ("conducting gap 0 (overlap only)", {**ref, **GAP0}),
        ("softened k / 10, conducting gap 0", {**ref, **GAP0, "dem.stiffness": k_ref / 10}),
    ]
    for n_rev in (1, 2):  # after one revolution of start-up, replay the next n_rev cyclically
        if (n_rev + 1) * rev < horizon:
            v.append((f"replay of {n_rev} revolution(s)",
                      {**ref, "dem.record_interval": 0.05, "dem.replay_after": (n_rev + 1) * rev,
                       "dem.replay_cycle": n_rev * rev, "dem.thermal_substeps": 10}))
    return v


def main(argv=None):  # noqa: C901
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--horizon", type=float, default=20.0, help="simulated time, s")
    p.add_argument("--out", default="results/accuracy_cost")
    p.add_argument("--quick", action="store_true", help="softer reference (for a smoke test)")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scene = dh.load_scene("weigler-mixed")
    base = {k: v for k, v in BASE.items() if v is not None}
    base.update({"run.duration": args.horizon, "run.output_interval": 1.0})
    raw = scene.with_overrides(base).to_dict()
    raw["dem"].pop("replay_after", None)
    raw["dem"].pop("record_interval", None)
    from drumheat.scene import scene_from_dict

    scene = scene_from_dict(raw)
    rows, ref = [], None
    for name, over in variants(args.horizon, args.quick):
        s = scene.with_overrides(over)
        t0 = time.perf_counter()
        res = dh.run(s, progress=False)
        wall = time.perf_counter() - t0
        ts = res.timeseries
        if ref is None:
            ref, ref_wall = ts, wall
        row = {"variant": name, "wall_time_s": wall, "speedup": ref_wall / wall}
        for col in ("T_mean", "T_mean:cold", "T_mean:warm", "alpha_overall"):
            d = np.abs(ts[col].to_numpy() - ref[col].to_numpy())
            row[f"err_end {col}"] = d[-1]
            row[f"err_max {col}"] = np.nanmax(d[1:])
        rows.append(row)
        print(f"{name:<40} {wall:8.1f} s", flush=True)
    table = pd.DataFrame(rows)
    table.to_csv(out / "accuracy_cost.csv", index=False)
    import os
    import platform

    print(f"\nmachine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"horizon {args.horizon:g} s; errors in K (alpha in W/(m2 K)) against the reference")
    cols = ["variant", "wall_time_s", "speedup", "err_max T_mean", "err_max T_mean:cold",
            "err_max T_mean:warm", "err_end alpha_overall"]
    print(table[cols].to_string(index=False, float_format=lambda x: f"{x:.3g}"))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for _, r in table.iloc[1:].iterrows():
        err = max(r["err_max T_mean:cold"], r["err_max T_mean:warm"], 1e-12)
        ax.loglog(r["wall_time_s"], err, "o")
        ax.annotate(r["variant"], (r["wall_time_s"], err), fontsize=7, xytext=(4, 2),
                    textcoords="offset points")
    ax.axvline(table["wall_time_s"].iloc[0], color="k", ls=":", lw=1, label="reference cost")
    ax.set_xlabel("wall time / s")
    ax.set_ylabel("max error of the fraction means / K")
    ax.set_title("weigler-mixed (wall-heated): accuracy versus cost")
    ax.grid(alpha=0.3, which="both")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "accuracy_cost.png", dpi=120)
    print(f"\nwritten: {out / 'accuracy_cost.csv'}, {out / 'accuracy_cost.png'}")


if __name__ == "__main__":
    main()
