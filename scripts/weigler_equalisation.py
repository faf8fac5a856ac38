"""Resting and turning equalisation of the thesis' aluminium beds on every criterion (issue 16).

Runs the built-in scenes ``weigler-static`` (experiments 1-4) and ``weigler-mixed``
(experiments 5-8, 12 rpm) over ``--duration`` seconds and prints

* the equalisation times of :mod:`drumheat.results.equalisation` (all particles within 1 K of
  each other, fraction means within 1 K, all particles within 1 K and 0.5 K of the chamber air);
* the fraction means at 60, 120, 300 and 480 s of model time;

and draws the fraction means, the spread and the largest distance from the chamber air of
both beds into one figure (``--figure``).

Time axes: the thesis counts experiment time from the start of the ~60 s filling, and the
motor of the mixed runs starts after the first image at 60 s (digest section 7.2); its models
start at 26 / 45 degC, the state of that first image, and the digest (section 12.3) notes that
the source does not say whether model t = 0 is experiment t = 0 or 60 s. The table therefore
gives model times; add 60 s for experiment time on the second reading.

Usage::

    python scripts/weigler_equalisation.py [--duration 1200] [--figure docs/img/weigler_equalisation.png]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import drumheat as dh
from drumheat.results.equalisation import equalisation_times

TIMES = (60.0, 120.0, 300.0, 480.0)
SCENES = ("weigler-static", "weigler-mixed")


def run(name: str, duration: float):
    scene = dh.load_scene(name).replace(**{"run.duration": duration})
    t0 = time.perf_counter()
    res = dh.run(scene)
    return scene, res, time.perf_counter() - t0


def fmt(x):
    return "never" if x is None else f"{x:.0f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=1200.0)
    ap.add_argument("--figure", type=Path, default=None)
    args = ap.parse_args(argv)

    rows, curves = [], {}
    for name in SCENES:
        scene, res, wall = run(name, args.duration)
        traj = res.trajectory
        T_gas = scene.gas.temperature
        eq1 = equalisation_times(traj.t, traj.T, traj.group, traj.mass, T_gas=T_gas, threshold=1.0)
        eq05 = equalisation_times(traj.t, traj.T, traj.group, traj.mass, T_gas=T_gas,
                                  threshold=0.5)
        ts = res.timeseries
        names = [g.name for g in scene.groups]
        means = {g: np.interp(TIMES, ts["t"], ts[f"T_mean:{g}"]) - 273.15 for g in names}
        rows.append((name, eq1, eq05, means, wall, res.summary.get("n_contacts")))
        curves[name] = (ts, names, T_gas, traj)

    print(f"| scene | spread <= 1 K (s) | fraction means within 1 K (s) | all within 1 K of "
          f"T_g (s) | all within 0.5 K of T_g (s) | " +
          " | ".join(f"cold / warm at {t:.0f} s (degC)" for t in TIMES) + " | wall time (s) |")
    print("|---" * (6 + len(TIMES)) + "|")
    for name, eq1, eq05, means, wall, _ in rows:
        g0, g1 = list(means)
        print(f"| {name} | {fmt(eq1['spread'])} | {fmt(eq1['fraction_means'])} | "
              f"{fmt(eq1['gas'])} | {fmt(eq05['gas'])} | " +
              " | ".join(f"{means[g0][k]:.2f} / {means[g1][k]:.2f}" for k in range(len(TIMES)))
              + f" | {wall:.0f} |")

    if args.figure is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=False)
        for name, (ts, names, T_gas, traj) in curves.items():
            style = "-" if name == "weigler-mixed" else "--"
            for g, c in zip(names, ("tab:blue", "tab:red")):
                axes[0].plot(ts["t"], ts[f"T_mean:{g}"] - 273.15, style, color=c,
                             label=f"{name}: {g}")
            spread = traj.T.max(axis=1) - traj.T.min(axis=1)
            to_gas = np.abs(traj.T - T_gas).max(axis=1)
            axes[1].semilogy(traj.t, spread, style, color="k", label=f"{name}: spread")
            axes[1].semilogy(traj.t, to_gas, style, color="tab:green",
                             label=f"{name}: max |T - T_g|")
        axes[0].axhline(T_gas - 273.15, color="grey", lw=0.8)
        axes[0].set(xlabel="model time (s)", ylabel="fraction mean (degC)")
        axes[1].axhline(1.0, color="grey", lw=0.8)
        axes[1].axhline(0.5, color="grey", lw=0.8, ls=":")
        axes[1].set(xlabel="model time (s)", ylabel="K", ylim=(1e-2, 30.0))
        for ax in axes:
            ax.legend(fontsize=7)
            ax.grid(alpha=0.3)
        fig.tight_layout()
        args.figure.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.figure, dpi=120)
        print(f"figure: {args.figure}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
