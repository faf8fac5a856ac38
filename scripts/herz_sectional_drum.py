"""Sectional drum (Herz 2024): contact lengths and angle of repose, DEM vs the closed-form model.

Runs the scene ``herz-sectional-drum`` (or reads a finished run's result folder), measures in
every output after the warm-up and in every section the contact lengths P1, P2, Wo, Wi, l_SG
and the free-surface angle (drumheat.mechanics.analysis.section_contact_lengths), evaluates
drumheat.models.sectional_drum.contact_lengths at the measured mean angle (same R1, R2, fill),
and writes

* ``herz_sectional_drum.png``: model lines vs DEM points over delta = 0..360 (one panel per
  length) and a snapshot of the bed with the model's bed outlines;
* ``herz_sectional_drum.md``: the tables (angle of repose, cycle means and mean contact-length
  rates model vs DEM, heat flow per surface), ready for docs/herz-sectional-drum.md;
* ``herz_sectional_drum.json``: the same numbers.

The 8 sections are identical and 45 deg apart, so 45 deg of rotation after the warm-up
(7.5 s at 1 rpm) samples every delta in [0, 360) once across the sections.

Usage::

    python scripts/herz_sectional_drum.py                      # run the scene, then evaluate
    python scripts/herz_sectional_drum.py --results DIR        # evaluate a finished run
    python scripts/herz_sectional_drum.py --results DIR --out docs/img
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from drumheat.mechanics.analysis import SECTION_LENGTHS, angle_of_repose, \
    section_contact_lengths
from drumheat.mechanics.pour import section_of
from drumheat.models import sectional_drum as sd
from drumheat.scene import load_scene

LABELS = {"P1": "P1 (plate 1)", "P2": "P2 (plate 2)", "Wo": "Wo (shell)",
          "Wi": "Wi (inner cylinder)", "l_SG": "l_SG (free surface)"}


def plate_angle(scene, t):
    """Polar angle of plate 0 at time t, rad."""
    d = scene.drum
    phase = 180.0 if d.plate_phase is None else d.plate_phase
    return math.radians(phase) + 2.0 * math.pi * d.rpm / 60.0 * t


def measure(scene, t, position, diameter, warmup, min_surface=8):
    """Contact lengths of every section at every output time in [warmup, warmup + 45 deg)."""
    d = scene.drum
    R1, R2, n_sec = 0.5 * d.diameter, 0.5 * (d.inner_diameter or 0.0), d.sections
    span = (360.0 / n_sec) / (6.0 * abs(d.rpm))  # time of one section angle, s
    keep = np.flatnonzero((t >= warmup - 1e-9) & (t < warmup + span - 1e-9))
    if len(keep) == 0:
        raise SystemExit(f"no outputs in [{warmup}, {warmup + span}) s; run longer")
    r = 0.5 * np.asarray(diameter)
    # first pass: free-surface angles of the sections with a long surface
    rows = []
    for i in keep:
        m = section_contact_lengths(position[i], r, R1=R1, R2=R2, n_sections=n_sec,
                                    plate_angle=plate_angle(scene, t[i]))
        m["t"] = np.full(n_sec, t[i])
        m["section"] = np.arange(n_sec)
        # the existing method (drumheat.mechanics.analysis.angle_of_repose) per section
        sec = section_of(position[i], n_sec, plate_angle(scene, t[i]))
        aor = np.full(n_sec, np.nan)
        for k in range(n_sec):
            sel = sec == k
            if m["n_surface"][k] >= min_surface:
                try:
                    aor[k] = -angle_of_repose(position[i][sel], r[sel])
                except ValueError:
                    pass
        m["gamma_aor"] = aor
        rows.append(pd.DataFrame(m))
    df = pd.concat(rows, ignore_index=True)
    good = df["n_surface"] >= min_surface
    gamma = float(df.loc[good, "gamma_deg"].mean())
    # second pass: sections with a short surface take the mean angle for l_SG
    rows = []
    for i in keep:
        m = section_contact_lengths(position[i], r, R1=R1, R2=R2, n_sections=n_sec,
                                    plate_angle=plate_angle(scene, t[i]), gamma_deg=gamma)
        rows.append(pd.DataFrame(m)[["l_SG", "c"]])
    df[["l_SG", "c"]] = pd.concat(rows, ignore_index=True).to_numpy()
    df["fill"] = [float(sd.bed_area(dl, c, R1=R1, R2=R2, gamma_deg=gamma)
                        / sd.section_area(R1, R2)) if np.isfinite(c) else np.nan
                  for dl, c in zip(df["delta_deg"], df["c"])]
    return df, gamma, good


def heat_table(ts, warmup, t_end, slice_depth):
    """Mean heat flow from each surface in [warmup, t_end] (W for the slice, W per m)."""
    cols = [c for c in ts.columns if c.startswith("Q_wall")]
    a = ts.iloc[(ts["t"] - warmup).abs().argmin()]
    b = ts.iloc[(ts["t"] - t_end).abs().argmin()]
    out = {}
    for c in cols:
        q = (b[c] - a[c]) / (b["t"] - a["t"])
        out[c] = {"W_slice": float(q), "W_per_m": float(q / slice_depth),
                  "J_total": float(ts[c].iloc[-1])}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, default=None,
                    help="result folder of a finished run (default: run the scene into "
                         "results/herz-sectional-drum)")
    ap.add_argument("--scene", default="herz-sectional-drum")
    ap.add_argument("--warmup", type=float, default=1.5, help="s left out at the start")
    ap.add_argument("--out", type=Path, default=None, help="folder for figure and tables "
                                                           "(default: the result folder)")
    args = ap.parse_args(argv)

    if args.results is None or not (args.results / "particles.npz").exists():
        import drumheat

        out = args.results or Path("results") / args.scene
        drumheat.run(args.scene, out=out)
        args.results = out
    scene = load_scene(args.results / "scene.toml")
    z = np.load(args.results / "particles.npz")
    t, pos = z["t"], z["position"]
    diam = np.concatenate([np.full(g.count, g.diameter) for g in scene.groups])
    ts = pd.read_csv(args.results / "timeseries.csv")
    summary = json.loads((args.results / "summary.json").read_text())
    out_dir = args.out or args.results
    out_dir.mkdir(parents=True, exist_ok=True)

    d = scene.drum
    R1, R2, n_sec = 0.5 * d.diameter, 0.5 * (d.inner_diameter or 0.0), d.sections
    fill = 0.30
    df, gamma, good = measure(scene, t, pos, diam, args.warmup)
    g_all = df.loc[good, "gamma_deg"]
    g_aor = df.loc[good, "gamma_aor"].dropna()
    model_means = sd.cycle_means(R1=R1, R2=R2, fill=fill, gamma_deg=gamma)
    dem_means = {k: float(df[k].mean()) for k in SECTION_LENGTHS}
    n = abs(d.rpm)
    rates_model = sd.contact_length_rates(model_means, n)
    rates_dem = sd.contact_length_rates(dem_means, n)
    # R^2 of the DEM points against the model at their delta
    cl = sd.contact_lengths(df["delta_deg"].to_numpy(), R1=R1, R2=R2, fill=fill,
                            gamma_deg=gamma)
    r2, rmse = {}, {}
    for k in SECTION_LENGTHS:
        y, f = df[k].to_numpy(), np.asarray(getattr(cl, k))
        ok = np.isfinite(y)
        r2[k] = float(1 - np.sum((y[ok] - f[ok]) ** 2) / np.sum((y[ok] - y[ok].mean()) ** 2))
        rmse[k] = float(np.sqrt(np.mean((y[ok] - f[ok]) ** 2)))
    span = (360.0 / n_sec) / (6.0 * n)
    heat = heat_table(ts, args.warmup, min(args.warmup + span, float(t[-1])),
                      float(np.mean(diam)))

    # ---- figure
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(14, 8.5))
    dd = np.linspace(0, 360, 721)
    clm = sd.contact_lengths(dd, R1=R1, R2=R2, fill=fill, gamma_deg=gamma)
    bnds = sd.region_boundaries(R1=R1, R2=R2, fill=fill, gamma_deg=gamma)
    for ax, k in zip(axes.ravel(), SECTION_LENGTHS):
        ax.plot(dd, 1e3 * np.asarray(getattr(clm, k)), "k-", lw=1.5,
                label=f"model, gamma = {gamma:.1f} deg")
        sc = ax.scatter(df["delta_deg"], 1e3 * df[k], c=df["section"], cmap="tab10", s=9,
                        vmin=-0.5, vmax=9.5, label="DEM (colour: section)")
        for b in bnds:
            ax.axvline(b.delta_deg, color="0.7", ls=":", lw=0.8)
        ax.set_xlim(0, 360)
        ax.set_xticks(range(0, 361, 45))
        ax.set_title(f"{LABELS[k]}: R2 = {r2[k]:.2f}, rmse = {1e3 * rmse[k]:.1f} mm",
                     fontsize=10)
        ax.set_xlabel("rotation angle delta (deg)")
        ax.set_ylabel("contact length (mm)")
    axes[0, 0].legend(fontsize=8, loc="upper right")
    ax = axes[1, 2]
    i_last = int(np.flatnonzero(t < args.warmup + span - 1e-9)[-1])
    p = pos[i_last]
    ax.scatter(p[:, 0], p[:, 1], s=0.6, c="tab:brown")
    pa = plate_angle(scene, t[i_last])
    for j in range(n_sec):
        a = pa - j * 2 * math.pi / n_sec
        ax.plot([R2 * math.cos(a), R1 * math.cos(a)], [R2 * math.sin(a), R1 * math.sin(a)],
                "k-", lw=1)
        dl = math.degrees(math.pi - a) % 360.0
        poly = sd.bed_polygon(dl, R1=R1, R2=R2, fill=fill, gamma_deg=gamma)
        ax.plot(np.append(poly[:, 0], poly[0, 0]), np.append(poly[:, 1], poly[0, 1]), "b-",
                lw=0.8)
    th = np.linspace(0, 2 * math.pi, 400)
    for R in (R1, R2):
        ax.plot(R * np.cos(th), R * np.sin(th), "k-", lw=1)
    ax.set_aspect("equal")
    ax.set_title(f"t = {t[i_last]:.2f} s: DEM beads, model bed outlines (blue)", fontsize=10)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.suptitle(f"Sectional drum D = {d.diameter * 1e3:.0f} mm, R2/R1 = {R2 / R1:.3f}, "
                 f"{n_sec} sections, f = {fill:.0%}, {len(diam)} glass beads d = "
                 f"{np.mean(diam) * 1e3:.0f} mm, {n:g} rpm: model vs 2D DEM", fontsize=11)
    fig.tight_layout()
    png = out_dir / "herz_sectional_drum.png"
    fig.savefig(png, dpi=110)

    # ---- tables
    lines = []
    lines.append(f"DEM free-surface angle (line fit per section, {int(good.sum())} section "
                 f"snapshots with >= 8 surface points, of {len(df)}): gamma = "
                 f"{g_all.mean():.1f} deg, standard deviation {g_all.std():.1f} deg, "
                 f"median {g_all.median():.1f} deg, 10-90 % range {g_all.quantile(0.1):.1f}-"
                 f"{g_all.quantile(0.9):.1f} deg; existing angle_of_repose (central 60 % of "
                 f"the section's surface) {g_aor.mean():.1f} +- {g_aor.std():.1f} deg. "
                 f"Measured bed fill from the fitted surface: "
                 f"{df['fill'].mean():.3f} +- {df['fill'].std():.3f} (nominal {fill}).")
    lines.append("")
    lines.append("| length | model mean (mm) | DEM mean (mm) | DEM/model | model rate (mm/s) | "
                 "DEM rate (mm/s) | R2 | rmse (mm) |")
    lines.append("|---|---|---|---|---|---|---|---|")
    for k in (*SECTION_LENGTHS, "plates", "walls", "all_walls"):
        mm = model_means[k]
        dm = dem_means[k] if k in dem_means else sum(
            dem_means[x] for x in {"plates": ("P1", "P2"), "walls": ("Wi", "Wo"),
                                   "all_walls": ("P1", "P2", "Wi", "Wo")}[k])
        rd = dm * n / 60.0
        extra = f"{r2[k]:.2f} | {1e3 * rmse[k]:.1f}" if k in r2 else "- | -"
        lines.append(f"| {k} | {1e3 * mm:.1f} | {1e3 * dm:.1f} | {dm / mm:.3f} | "
                     f"{1e3 * rates_model[k]:.3f} | {1e3 * rd:.3f} | {extra} |")
    lines.append("")
    lines.append("| surface | heat flow into the bed, slice (W) | per m of drum (W/m) |")
    lines.append("|---|---|---|")
    for c, v in heat.items():
        lines.append(f"| {c} | {v['W_slice']:.4g} | {v['W_per_m']:.4g} |")
    lines.append("")
    lines.append(f"Energy balance relative error of the run: "
                 f"{summary.get('energy_balance_rel_error', float('nan')):.2g}; wall time "
                 f"{summary.get('wall_time_s', float('nan')):.0f} s.")
    md = "\n".join(lines) + "\n"
    (out_dir / "herz_sectional_drum.md").write_text(md)
    (out_dir / "herz_sectional_drum.json").write_text(json.dumps({
        "gamma_deg": {"mean": float(g_all.mean()), "std": float(g_all.std()),
                      "median": float(g_all.median()), "n": int(good.sum()),
                      "angle_of_repose_mean": float(g_aor.mean()),
                      "angle_of_repose_std": float(g_aor.std())},
        "fill_measured": float(df["fill"].mean()),
        "model_means_m": model_means, "dem_means_m": dem_means,
        "model_rates_m_per_s": rates_model, "dem_rates_m_per_s": rates_dem,
        "R2": r2, "rmse_m": rmse, "heat": heat}, indent=2) + "\n")
    df.to_csv(out_dir / "herz_sectional_drum_samples.csv", index=False)
    print(md)
    print(f"figure: {png}")


if __name__ == "__main__":
    main()
