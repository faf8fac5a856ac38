"""The cyclic replay's restart assignment: time and quality against the block size.

At a cyclic restart every particle, back at its recorded start position, takes the temperature
of the particle whose end position is closest (``drumheat.motion.replay.restart_assignment``).
The exact optimal assignment needs an (n, n) cost matrix; above ``--blocks`` particles the
group is cut by median bisection and solved per block. For a recording (``contacts.npz`` of a
``dem`` run with ``dem.record_interval``) this prints, per block size, the wall time, the mean
squared hand-over distance in particle diameters and, with ``--exact`` (the dense assignment,
(n, n) float64: 0.8 GB at n = 10 000, minutes), its excess over the optimum and the share of
particles matched differently.

Usage: python scripts/bench_restart_assignment.py RECORDING [--first K] [--blocks 512 2048]
       [--exact] [--tile T]
``--first``: the recorded interval the cycle starts at (default 0: the whole recording);
``--tile T``: the recording's bed repeated T times along its periodic axis z (the drum's
periodic slice), to time large N from a small recording.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from machine import cpu_ticks, print_table, steal_percent

from drumheat.motion.replay import restart_assignment


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("recording")
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--blocks", type=int, nargs="+", default=[512, 1024, 2048, 4096])
    ap.add_argument("--exact", action="store_true")
    ap.add_argument("--tile", type=int, default=1)
    args = ap.parse_args()

    with np.load(args.recording) as f:
        pos = f["positions"].astype(float)
        d = float(np.mean(f["diameter"]))
        group = np.asarray(f["group"])
    start, end = pos[args.first], pos[-1]
    if args.tile > 1:  # copies along the periodic axis, each shifted by the slice's length
        span = np.ptp(np.concatenate([start[:, 2], end[:, 2]])) + d
        start, end = (np.concatenate([x + [0, 0, k * span] for k in range(args.tile)])
                      for x in (start, end))
        group = np.tile(group, args.tile)
    n = len(start)
    print(f"{args.recording}: N = {n}, cycle from interval {args.first} of {len(pos) - 1}, "
          f"d = {d * 1e3:.1f} mm")

    def cost(m):
        return float(np.mean(np.sum((start - end[m]) ** 2, axis=1))) / d**2

    exact = None
    rows = []
    for block in ([n] if args.exact else []) + args.blocks:
        c0, t0 = cpu_ticks(), time.perf_counter()
        m = restart_assignment(end, start, group, block=block)
        t = time.perf_counter() - t0
        st = steal_percent(c0, cpu_ticks())
        if exact is None and block >= n:
            exact = m
        rows.append((f"{block}" + (" (exact)" if block >= n else ""), t, cost(m),
                     100 * (cost(m) / cost(exact) - 1) if exact is not None else float("nan"),
                     100 * np.mean(m != exact) if exact is not None else float("nan"), st))
    print_table(["block", "time (s)", "mean squared distance (d^2)", "above optimum (%)",
                 "matched differently (%)", "steal (%)"], rows,
                ["s", ".2f", ".4f", ".2f", ".1f", ".0f"])


if __name__ == "__main__":
    main()
