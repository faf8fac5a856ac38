"""Is the machine itself steady? One fixed piece of work timed over and over on every core.

Each core runs its own process (pinned with ``os.sched_setaffinity`` where the system has it,
one NumPy thread) that repeats a fixed unit of work for ``--seconds``: 20 passes of an
element-wise multiply over two 8 MB arrays (16 MB, the size of a drum's working set at N =
50 000; it streams through the shared caches and memory like the contact loop does). No
drumheat code runs, so whatever changes in the unit's time is the machine: a neighbour on the
same host using the shared caches or memory bandwidth, or the host's clock.

Output, per core: the unit's median time, its 10th and 90th percentiles, and the median of
every ``--bin`` seconds divided by the overall median (1.00 = typical, 1.50 = that stretch ran
the same work 1.5x slower), with the CPU steal over the whole probe. On the development machine
stretches of 1.4-2.2x lasting tens of seconds showed on both cores at once, with no steal
reported (docs/performance.md, "Slow stretches"): a single timing of a benchmark can fall into
one, which is why ``bench_vs_liggghts.py --rounds`` lets the codes take turns.

Usage: python scripts/bench_machine_stretches.py [--seconds 90] [--bin 3]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from machine import cpu_ticks, print_table, steal_percent  # scripts/machine.py


def probe(out: str, seconds: float) -> None:
    """The worker: time the unit of work until ``seconds`` have passed; save (start time, s)."""
    a = np.random.default_rng(0).random(1 << 20)
    b = np.empty_like(a)
    rows = []
    t_end = time.time() + seconds
    while time.time() < t_end:
        t0 = time.perf_counter()
        for _ in range(20):
            np.multiply(a, 1.0001, out=b)
            a, b = b, a
        rows.append((time.time(), time.perf_counter() - t0))
    np.save(out, np.array(rows))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=90.0)
    ap.add_argument("--bin", type=float, default=3.0, help="s per stretch in the profile")
    ap.add_argument("--worker", nargs=2, metavar=("OUT", "CPU"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        if hasattr(os, "sched_setaffinity"):
            os.sched_setaffinity(0, {int(args.worker[1])})
        probe(args.worker[0], args.seconds)
        return
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else \
        list(range(os.cpu_count() or 1))
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    with tempfile.TemporaryDirectory() as tmp:
        outs = [str(Path(tmp) / f"core{c}.npy") for c in cpus]
        c0 = cpu_ticks()
        procs = [subprocess.Popen([sys.executable, __file__, "--seconds", str(args.seconds),
                                   "--worker", o, str(c)], env=env) for o, c in zip(outs, cpus)]
        for p in procs:
            if p.wait() != 0:
                sys.exit(f"a probe process failed (exit {p.returncode})")
        steal = steal_percent(c0, cpu_ticks())
        t_first = min(np.load(o)[0, 0] for o in outs)
        print(f"{len(cpus)} cores, {args.seconds:.0f} s, CPU steal over the probe {steal:.1f} %")
        print()
        rows = []
        for c, o in zip(cpus, outs):
            d = np.load(o)
            t = d[:, 1] * 1e3
            med = np.median(t)
            k = ((d[:, 0] - t_first) // args.bin).astype(int)
            prof = " ".join(f"{np.median(t[k == i]) / med:.2f}" for i in np.unique(k))
            p10, p90 = np.percentile(t, [10, 90])
            rows.append((c, len(t), med, f"{p10:.2f} - {p90:.2f}", prof))
        print_table(["core", "units", "median ms", "p10 - p90 ms",
                     "median of each stretch / overall median"], rows,
                    ["d", "d", ".2f", "s", "s"])

if __name__ == "__main__":
    main()
