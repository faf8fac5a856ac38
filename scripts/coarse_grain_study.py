"""Coarse-grained thermal DEM of the 3D glass drum against the fine bed: one run, one table.

Runs the built-in drum ``glass-drum-3d`` (glass beads d = 8 mm, D = 250 mm, 9.55 rpm, wall
343 K, beads 293 K; docs/models/coarse-graining.md) at coarse-graining factors s = 1, 2, 3, 4
(``--set dem.coarse_grain=s``), mechanics and heat coupled all the way
(``dem.replay_after = none``), and prints for each s and three times: the bed's mean
temperature rise T_mean - T_0, the wall heat flow (W, mean over the third of the run before
the time: the difference of the time series' ``Q_wall``, the heat received since t = 0),
the temperature spread of the simulated particles (T_max - T_min and the standard deviation;
parcels for s > 1) and the wall time of the whole run (pouring, compiling and simulating).
The deviations are relative to s = 1; nothing is fitted.

The slice is the benchmark drum's N knob (depth = N x 2.6e-5 m, the fill level kept) at
N = 3456 (= 2^7 x 27: 432, 128 and 54 whole parcels at s = 2, 3, 4), depth 0.0899 m, so that
a parcel of s = 4 (32 mm) still fits the periodic slice (at least twice the neighbour cutoff,
0.08 m). Starting from the poured bed at rest, 6 s of drum time (about one revolution at 9.55
rpm) cost about 8 minutes at s = 1 on 2 CPU cores. Usage::

    PYTHONPATH=. python scripts/coarse_grain_study.py            # s = 1 2 3 4, 6 s of drum time
    PYTHONPATH=. python scripts/coarse_grain_study.py --s 1 2 --duration 1.5
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

#: the drum of the study: glass-drum-3d with N = 3000 in a 0.078 m slice, coupled all the way
BASE = {"dem.replay_after": None, "dem.record_interval": None, "dem.replay_cycle": None}


def run_one(s: float, count: int, depth: float, duration: float, interval: float,
            seed: int = 1) -> dict:
    """Run the drum at coarse-graining factor ``s``; its time series, spread and cost."""
    import drumheat as dh

    scene = dh.load_scene("glass-drum-3d", {
        **BASE, "groups.0.count": count, "drum.depth": depth, "run.duration": duration,
        "run.output_interval": interval, "dem.coarse_grain": s, "run.seed": seed})
    start = time.perf_counter()
    res = dh.run(scene, progress=False)
    wall = time.perf_counter() - start
    T = np.asarray(res.trajectory.T)
    ts = res.timeseries
    return dict(s=s, n=scene.n_parcels, t=ts["t"].to_numpy(), T_mean=ts["T_mean"].to_numpy(),
                Q_wall=ts["Q_wall"].to_numpy(), spread=T.max(axis=1) - T.min(axis=1),
                std=T.std(axis=1), wall=wall,
                energy=res.summary["energy_balance_rel_error"])


def window_flow(t: np.ndarray, Q: np.ndarray, t0: float, t1: float) -> float:
    """Mean heat flow (W) between t0 and t1 from the time series' heat received since t = 0
    (``Q_wall``, J)."""
    k0, k1 = int(np.argmin(np.abs(t - t0))), int(np.argmin(np.abs(t - t1)))
    return float((Q[k1] - Q[k0]) / (t[k1] - t[k0]))


def table(runs: list[dict], times: list[float]) -> str:
    """The study's table: one row per s and time, deviations relative to s = 1."""
    ref = runs[0]
    head = (f"{'s':>3} {'parcels':>7} {'t/s':>5} {'dT_mean/mK':>10} {'err %':>7} "
            f"{'Q_wall/W':>9} {'err %':>7} {'Tmax-Tmin/K':>11} {'std/K':>7} {'wall s':>7}")
    lines = [head, "-" * len(head)]
    for r in runs:
        prev = 0.0
        for t in times:
            k = int(np.argmin(np.abs(r["t"] - t)))
            kr = int(np.argmin(np.abs(ref["t"] - t)))
            rise = r["T_mean"][k] - r["T_mean"][0]
            rise_ref = ref["T_mean"][kr] - ref["T_mean"][0]
            q = window_flow(r["t"], r["Q_wall"], prev, t)
            q_ref = window_flow(ref["t"], ref["Q_wall"], prev, t)
            lines.append(f"{r['s']:>3g} {r['n']:>7d} {t:>5.2f} {1e3 * rise:>10.2f} "
                         f"{100 * (rise / rise_ref - 1):>7.1f} {q:>9.2f} "
                         f"{100 * (q / q_ref - 1):>7.1f} {r['spread'][k]:>11.3f} "
                         f"{r['std'][k]:>7.4f} {r['wall']:>7.1f}")
            prev = t
    return "\n".join(lines)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--s", type=float, nargs="+", default=[1.0, 2.0, 3.0, 4.0],
                   help="coarse-graining factors; the first is the reference (default 1 2 3 4)")
    p.add_argument("--count", type=int, default=3456,
                   help="real particles (default 3456 = 2^7 x 27: whole parcels at s = 2, 3, 4)")
    p.add_argument("--depth", type=float, default=None,
                   help="slice depth, m (default count x 2.6e-5, the benchmark's fill level)")
    p.add_argument("--duration", type=float, default=6.0,
                   help="drum time, s (default 6, about one revolution)")
    p.add_argument("--interval", type=float, default=0.1, help="output interval, s")
    p.add_argument("--seed", type=int, nargs="+", default=[1],
                   help="run.seed of each run (one for all, or one per s; the pour)")
    a = p.parse_args(argv)
    depth = a.depth if a.depth is not None else a.count * 2.6e-5
    times = [a.duration / 3, 2 * a.duration / 3, a.duration]
    runs = []
    seeds = a.seed * len(a.s) if len(a.seed) == 1 else a.seed
    for s, seed in zip(a.s, seeds):
        runs.append(run_one(s, a.count, depth, a.duration, a.interval, seed))
        print(f"s = {s:g}: {runs[-1]['n']} particles, {runs[-1]['wall']:.1f} s wall time, "
              f"energy balance {runs[-1]['energy']:.1e}", flush=True)
    print(f"\nglass-drum-3d, N = {a.count} beads of 8 mm, depth {depth:g} m, "
          f"{a.duration:g} s of drum time coupled (no replay); Q_wall: mean heat flow since "
          f"the previous time; machine: {platform.node()} ({platform.processor() or 'cpu'})"
          f", {time.strftime('%Y-%m-%d')}\n")
    print(table(runs, times))


if __name__ == "__main__":
    main()
