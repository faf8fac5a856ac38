"""The DEM contact kernel as one C++ loop (``make_dem(..., pair_kernel="cpu")``) against
drumheat's JAX kernel on CPU: the force kernel alone, and the whole step.

docs/performance.md explains why the JAX force kernel stays at about a third of LIGGGHTS' speed
per core on XLA:CPU: some twenty passes over the pair slots plus a scatter-add.
:mod:`drumheat.mechanics.cpu_kernel` computes the same contact law in one C++ loop called
through ``jax.ffi``. This script takes a settled state of the 3D drum slice (d = 8 mm,
D = 0.25 m, 9.55 rpm, periodic z), advances it 200 steps in the rotating drum and times on it,
once with ``pair_kernel="jax"`` and once with ``"cpu"``:

* forces: ``DEM._forces`` of a DEM without walls (gravity + pairs), best of 3 x ``--repeat``
  calls; and the largest spring difference of the two kernels (float32 round-off; a contact at
  the stick/slip threshold may flip and differ by more);
* step: ``DEM.run_steps`` of the drum (pairs, the drum wall, the kicks and drift, neighbour
  rebuilds as they come), best of 3 runs of ``--steps`` steps, per step.

On a shared machine compare the two kernels' columns of one run (the ratio), not absolute
times across runs. The whole step against LIGGGHTS: ``scripts/bench_vs_liggghts.py``.

Usage::

    python scripts/bench_cpu_pair_kernel.py [--n 2000 10000] [--dtype float32]
        [--conduction overlap] [--data-dir /tmp/drumheat_vs_liggghts/restart]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import drumheat  # noqa: F401  (x64 for the host side)
from drumheat.geometry import DrumShell
from drumheat.mechanics import contact_params, cpu_kernel, make_dem, make_particles
from drumheat.mechanics.conduction import PairConduction


SETTLE = 20000  # steps of 1e-5 s from the lattice to a settled bed


def state_of(n, data_dir, cache_dir):
    """A settled rotating-drum state: the LIGGGHTS data file if present, else a lattice bed
    (scripts/bench_dem.py) run for SETTLE steps, kept in ``cache_dir`` for the next runs (so that
    runs of different code versions time the same state)."""
    sys.path.insert(0, str(Path(__file__).parent))
    f = Path(data_dir) / f"drum_N{n}.data" if data_dir else None
    if f is not None and f.exists():
        import bench_vs_liggghts as B

        pos, vel, omega, radius, L = B.read_data(str(f))
        return pos, vel, omega, np.asarray(radius), L, f"LIGGGHTS state {f.name}"
    cached = Path(cache_dir) / f"lattice_bed_N{n}_{SETTLE}.npz" if cache_dir else None
    what = f"lattice bed after {SETTLE} steps"
    if cached is not None and cached.exists():
        z = np.load(cached)
        return (z["pos"], z["vel"], z["omega"], z["radius"], float(z["L"]), what)
    import bench_dem

    dem, st = bench_dem.build(3, n, False, jnp.float32)
    # poured and settled into a rolling bed (0.2 s), with the faster kernel
    dem = make_dem(dem.particles, dem.walls, dem.params, dim=3, dt=dem.dt, skin=0.004,
                   periodic_length=dem.neighbor.periodic_length, dtype=jnp.float32,
                   pair_kernel="cpu")
    st = dem.run(st, SETTLE, chunk=5000)
    out = (np.asarray(st.position), np.asarray(st.velocity), np.asarray(st.angular_velocity),
           np.asarray(dem.particles.radius), dem.neighbor.periodic_length)
    if cached is not None:
        cached.parent.mkdir(parents=True, exist_ok=True)
        np.savez(cached, pos=out[0], vel=out[1], omega=out[2], radius=out[3], L=out[4])
    return out + (what,)


def best_of(f, repeat):
    """Best of 3 mean times (ms) of ``repeat`` calls of f()."""
    jax.block_until_ready(f())
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(repeat):
            r = f()
        jax.block_until_ready(r)
        times.append((time.perf_counter() - t0) / repeat * 1e3)
    return min(times)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[2000, 10000])
    ap.add_argument("--data-dir", default="/tmp/drumheat_vs_liggghts/restart")
    ap.add_argument("--state-cache", default="/tmp/drumheat_bench_cpu_pair_kernel",
                    help="folder for the settled lattice beds ('' = none)")
    ap.add_argument("--repeat", type=int, default=50, help="force calls per timing")
    ap.add_argument("--steps", type=int, default=200, help="steps per step timing")
    ap.add_argument("--dtype", default="float32", choices=["float32", "float64"])
    ap.add_argument("--conduction", default=None, choices=["projected", "overlap"],
                    help="time the step with per-step pair conduction of this law")
    a = ap.parse_args(argv)
    ok, why = cpu_kernel.available()
    if not ok:
        raise SystemExit(f"C++ contact kernel unavailable: {why}")
    dtype = jnp.dtype(a.dtype)
    print(f"{os.cpu_count()} CPU cores, load {os.getloadavg()[0]:.1f}, JAX {jax.__version__}, "
          f"{a.dtype}{', conduction ' + a.conduction if a.conduction else ''}, "
          f"drumheat from {Path(drumheat.__file__).parent}\n")
    print("| N | state | pair slots | touching | forces: JAX (ms) | C++ (ms) | JAX / C++ | "
          "step: JAX (ms) | C++ (ms) | JAX / C++ | max spring difference / max spring |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for n in a.n:
        pos, vel, omega, radius, L, what = state_of(n, a.data_dir, a.state_cache)
        part = make_particles(radius, 2500.0)
        params = contact_params(1.001e5, restitution=0.5, restitution_model="linear",
                                friction=0.5, wall_friction=0.5)
        kw = dict(dim=3, periodic_length=L, dt=1e-5, skin=0.004, dtype=dtype)
        cond = {}
        if a.conduction:
            h = 1e3 if a.conduction == "projected" else 2.0
            cond = dict(conduction=PairConduction(a.conduction, h,
                                                  np.asarray(part.mass) * 836.0))
        drums = {k: make_dem(part, [DrumShell(0.125, rpm=9.55)], params, pair_kernel=k,
                             **kw, **cond) for k in ("jax", "cpu")}
        T0 = np.full(n, 300.0) + 50.0 * (pos[:, 0] > 0) if a.conduction else None
        st = drums["jax"].init(pos, velocity=vel, angular_velocity=omega, extra=T0)
        st = drums["jax"].run(st, 200, chunk=200)  # springs built up, buffers sized
        # the step, walls and all
        steps = jnp.asarray(a.steps, jnp.int32)
        ts = {}
        for k, dem in drums.items():
            ts[k] = best_of(lambda dem=dem: dem._run_steps(st, steps), 1) / a.steps
            if bool(dem._run_steps(st, steps).nbrs.did_buffer_overflow):
                print(f"  (N = {n}, {k}: the neighbour list overflowed during the timing)")
        # the forces alone, no walls
        sw = jnp.zeros((n, 0, 3), dtype)
        box = dict(bounds=(drums["jax"].domain_lo, drums["jax"].domain_hi))
        kernels = {k: make_dem(part, [], params, pair_kernel=k, **box, **kw)
                   for k in ("jax", "cpu")}

        def forces_of(dem):
            def f(pos, vel, w, idx, spring):
                nb = dataclasses.replace(st.nbrs, idx=idx)
                return dem._forces(pos, vel, w, st.time, nb, spring, sw)[:3]
            return f

        args = (st.position, st.velocity, st.angular_velocity, st.nbrs.idx, st.pair_spring)
        fj, fc = forces_of(kernels["jax"]), forces_of(kernels["cpu"])
        ra, rb = fc(*args), fj(*args)
        dspring = float(jnp.max(jnp.abs(ra[2] - rb[2])) / jnp.max(jnp.abs(rb[2])))
        touching = int(jnp.sum(kernels["jax"].contacts(st._replace(wall_spring=sw)).pair_mask))
        tj = best_of(lambda: fj(*args), a.repeat)
        tc = best_of(lambda: fc(*args), a.repeat)
        print(f"| {n} | {what} | {st.nbrs.idx.shape[1]} | {touching} | {tj:.2f} | {tc:.2f} | "
              f"{tj / tc:.1f} | {ts['jax']:.2f} | {ts['cpu']:.2f} | {ts['jax'] / ts['cpu']:.1f} "
              f"| {dspring:.1e} |", flush=True)


if __name__ == "__main__":
    main()
