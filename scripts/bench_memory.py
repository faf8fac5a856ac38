"""Memory per particle of the 3D rotating-drum DEM with contact conduction (issue 9 target).

For each N the 3D drum of ``scripts/bench_dem.py`` (the LIGGGHTS reference scene of
``peers/liggghts``: d = 8 mm glass, D = 0.25 m, 9.55 rpm, periodic axis at 35 % fill,
k = 1e5 N/m, dt = 1e-5 s, skin 0.5 d, float32 mechanics, float64 temperatures) is built as a
lattice bed in a fresh process and run for ``--steps`` steps with the conduction update in the
loop. Two numbers per N:

* ``state``: bytes of the simulation state (positions, velocities, spins, forces, neighbour
  list with its pair capacity, tangential springs of pairs and wall contacts, temperatures),
  counted from the arrays themselves: exact and independent of the machine's load;
* ``peak RSS``: the process's peak resident memory (``ru_maxrss``) minus that of the same
  process after building an N = 100 bed (JAX runtime, compiled code), i.e. what the run adds,
  with XLA's temporaries for the force kernel and the neighbour-list rebuild included. This
  contains the compiler's own peak for the new shapes (~200 MB, independent of N), so the
  per-particle figure is the slope between successive N (``marginal``);
* ``run peak above the state``: the high-water mark of the resident memory during the timed
  run alone (the chunk compiled by a one-step run first, ``/proc/self/clear_refs`` then resets
  the mark) minus the resident memory before it, per particle: what the chunk adds to the
  state it starts from (its output state, XLA's temporaries as far as the run touches them),
  without the compiler. The children run with ``MALLOC_MMAP_THRESHOLD_=1048576`` so that
  freed large buffers go back to the system and resident memory is live memory;
* ``XLA temp``: ``memory_analysis().temp_size_in_bytes`` of the compiled chunk, per particle:
  XLA's own account of its temporaries (a GPU allocates exactly that for a run), the
  neighbour rebuild's included even where the run does not rebuild.

Nothing is N x N: every array is O(N) or O(pairs) = O(N) (the script prints the largest).

Usage: python scripts/bench_memory.py [--n 2000 10000 50000] [--steps 200] [--kernel jax|cpu]
       [--conduction extra|builtin]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def build(n_: int, kernel: str = "jax", conduction: str = "extra"):
    """``(dem, state)``: the 3D drum bed of N = n_ particles (lattice start, conduction on:
    ``"extra"`` a hand-written ``extra_update`` with per-pair arrays, ``"builtin"`` the same
    law (projected area, h = 100 W/(m^2 K)) as ``make_dem(conduction=PairConduction(...))``,
    summed inside the contact kernel)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    sys.path.insert(0, str(HERE))
    from bench_dem import lattice_bed

    import drumheat  # noqa: F401  (x64)
    from drumheat.geometry import DrumShell
    from drumheat.mechanics import contact_params, make_dem, make_particles
    from drumheat.mechanics.conduction import PairConduction

    r, R, rho = 0.004, 0.125, 2500.0
    length = n_ * math.pi / 6 * (2 * r) ** 3 / (0.35 * 0.6 * math.pi * R**2)
    length = max(length, 6.5 * 2 * r)
    pos = lattice_bed(n_, r, R, 3, length)
    part = make_particles(np.full(n_, r), rho)
    params = contact_params(1e5, restitution=0.5, restitution_model="linear",
                            friction=0.5, wall_friction=0.5)
    mc = jnp.asarray(np.asarray(part.mass) * 836.0)
    area = math.pi * r * r

    def conduction(T, state, c, dt):
        i = jnp.where(c.pair_mask, c.pair_i, 0)
        j = jnp.where(c.pair_mask, c.pair_j, 0)
        q = jnp.where(c.pair_mask, 100.0 * area * (T[j] - T[i]), 0.0)
        dq = (jax.ops.segment_sum(q, i, n_) - jax.ops.segment_sum(q, j, n_))
        return T + dt * dq / mc

    kw = (dict(extra_update=conduction) if conduction == "extra" else
          dict(conduction=PairConduction("projected", 100.0, np.asarray(mc))))
    dem = make_dem(part, [DrumShell(R, rpm=9.55)], params, dim=3, periodic_length=length,
                   dt=1e-5, skin=0.004, dtype=jnp.float32, pair_kernel=kernel, **kw)
    T0 = jnp.asarray(293.0 + 50.0 * (pos[:, 0] > 0), jnp.float64)
    return dem, dem.init(pos, extra=T0)


def proc_status(field: str) -> float:
    """A memory field of /proc/self/status (VmRSS, VmHWM), MB."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    raise KeyError(field)


def measure(n: int, steps: int, kernel: str = "jax", conduction: str = "extra") -> dict:
    """Run in this process: build, run, and report memory numbers for N = n."""
    import resource

    import jax
    import jax.numpy as jnp

    def rss_mb():
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    dem, st = build(100, kernel, conduction)
    st = dem.run(st, steps, chunk=steps)
    jax.block_until_ready(st.position)
    base = rss_mb()
    dem, st = build(n, kernel, conduction)
    # one step first: it compiles the chunk (one executable serves every chunk length); then
    # the kernel's high-water mark is reset (/proc/self/clear_refs 5) so that it records the
    # run alone
    st = dem.run(st, 1, chunk=1)
    jax.block_until_ready(st.position)
    before = proc_status("VmRSS")
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    st = dem.run(st, steps, chunk=steps)
    jax.block_until_ready(st.position)
    run_peak = proc_status("VmHWM") - before
    peak = rss_mb()
    leaves = jax.tree_util.tree_leaves(st)
    state_bytes = sum(x.nbytes for x in leaves if hasattr(x, "nbytes"))
    biggest = max(leaves, key=lambda x: getattr(x, "size", 0))
    # XLA's own account of the chunk (what a GPU allocates for it): arguments, outputs,
    # outputs aliased to donated arguments, temporaries; after the RSS peak was read
    ma = dem._run_steps.lower(st, jnp.asarray(steps, jnp.int32)).compile().memory_analysis()
    return dict(xla_args=ma.argument_size_in_bytes, xla_out=ma.output_size_in_bytes,
                xla_alias=ma.alias_size_in_bytes, xla_temp=ma.temp_size_in_bytes, n=n,
                pairs=int(st.nbrs.idx.shape[1]), state_bytes=state_bytes,
                rebuilds=int(st.n_rebuilds), base_mb=base, peak_mb=peak, run_peak_mb=run_peak,
                largest=list(biggest.shape))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[2000, 10000, 50000])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--kernel", choices=("jax", "cpu"), default="jax",
                    help="contact kernel: the JAX one or the C++ loop (pair_kernel of make_dem)")
    ap.add_argument("--conduction", choices=("extra", "builtin"), default="extra",
                    help="conduction as a hand-written extra_update (per-pair arrays) or "
                         "make_dem(conduction=...) inside the contact kernel")
    ap.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        print(json.dumps(measure(args.child, args.steps, args.kernel, args.conduction)))
        return
    print("| N | pair capacity | rebuilds | state (MB) | state / particle (B) | "
          "peak RSS added (MB) | marginal RSS / particle (kB) | run peak above the state "
          "(B / particle) | XLA temp / particle (B) | largest array |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    prev = None
    for n in args.n:
        env = dict(os.environ, MALLOC_MMAP_THRESHOLD_="1048576")
        out = subprocess.run([sys.executable, __file__, "--child", str(n), "--steps",
                              str(args.steps), "--kernel", args.kernel, "--conduction",
                              args.conduction], capture_output=True,
                             text=True, check=True, env=env)
        d = json.loads(out.stdout.strip().splitlines()[-1])
        added = d["peak_mb"] - d["base_mb"]
        marginal = "" if prev is None else f"{(added - prev[1]) * 1024 / (n - prev[0]):.2f}"
        prev = (n, added)
        print(f"| {n} | {d['pairs']} | {d['rebuilds']} | {d['state_bytes'] / 1e6:.2f} | "
              f"{d['state_bytes'] / n:.0f} | {added:.0f} | {marginal} | "
              f"{d['run_peak_mb'] * 2**20 / n:.0f} | {d['xla_temp'] / n:.0f} | "
              f"{d['largest']} |", flush=True)


if __name__ == "__main__":
    main()
