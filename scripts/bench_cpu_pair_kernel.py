"""The DEM pair kernel as one C++ loop (``make_dem(..., pair_kernel="cpu")``) against
drumheat's JAX pair kernel on CPU, kernel against kernel.

docs/performance.md explains why the JAX force kernel stays at about a third of LIGGGHTS' speed
per core on XLA:CPU: some twenty passes over the pair slots plus a scatter-add.
:mod:`drumheat.mechanics.cpu_kernel` computes the same contact law (3D, one material, float32,
optional periodic z) in one C++ loop called through ``jax.ffi``. This script times both on the
same state of the 3D drum slice, advanced 200 steps in the rotating drum: ``DEM._forces`` of a
DEM without walls (gravity + pairs), built once with ``pair_kernel="jax"`` and once with
``"cpu"``. It also checks that both give the same springs to float32 round-off (a contact at
the stick/slip threshold may flip and differ by more). The whole step against LIGGGHTS:
``scripts/bench_vs_liggghts.py``.

Usage::

    python scripts/bench_cpu_pair_kernel.py [--n 2000 10000]
        [--data-dir /tmp/drumheat_vs_liggghts/restart]   # states of bench_vs_liggghts.py
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


def state_of(n, data_dir):
    """A settled rotating-drum state: the LIGGGHTS data file if present, else a lattice bed
    (scripts/bench_dem.py) run for 3000 steps."""
    sys.path.insert(0, str(Path(__file__).parent))
    f = Path(data_dir) / f"drum_N{n}.data" if data_dir else None
    if f is not None and f.exists():
        import bench_vs_liggghts as B

        pos, vel, omega, radius, L = B.read_data(str(f))
        return pos, vel, omega, np.asarray(radius), L, f"LIGGGHTS state {f.name}"
    import bench_dem

    dem, st = bench_dem.build(3, n, False, jnp.float32)
    st = dem.run(st, 3000, chunk=3000)
    return (np.asarray(st.position), np.asarray(st.velocity), np.asarray(st.angular_velocity),
            np.asarray(dem.particles.radius), dem.neighbor.periodic_length,
            "lattice bed after 3000 steps")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[2000, 10000])
    ap.add_argument("--data-dir", default="/tmp/drumheat_vs_liggghts/restart")
    ap.add_argument("--repeat", type=int, default=50)
    a = ap.parse_args(argv)
    ok, why = cpu_kernel.available()
    if not ok:
        raise SystemExit(f"C++ contact kernel unavailable: {why}")
    print(f"{os.cpu_count()} CPU cores, load {os.getloadavg()[0]:.1f}, JAX {jax.__version__}\n")
    print("| N | state | pair slots | touching | JAX kernel (ms) | C++ loop (ms) | JAX / C++ | "
          "max spring difference / max spring |")
    print("|---|---|---|---|---|---|---|---|")
    for n in a.n:
        pos, vel, omega, radius, L, what = state_of(n, a.data_dir)
        part = make_particles(radius, 2500.0)
        params = contact_params(1.001e5, restitution=0.5, restitution_model="linear",
                                friction=0.5, wall_friction=0.5)
        kw = dict(dim=3, periodic_length=L, dt=1e-5, skin=0.004, dtype=jnp.float32)
        drum = make_dem(part, [DrumShell(0.125, rpm=9.55)], params, **kw)
        st = drum.init(pos, velocity=vel, angular_velocity=omega)
        st = drum.run_steps(st, 200)  # tangential springs built up, bed still in the drum
        st = st._replace(wall_spring=jnp.zeros((n, 0, 3), jnp.float32))
        box = dict(bounds=(drum.domain_lo, drum.domain_hi))
        kernels = {k: make_dem(part, [], params, pair_kernel=k, **box, **kw)
                   for k in ("jax", "cpu")}

        def forces_of(dem):
            def f(pos, vel, w, idx, spring):
                nb = dataclasses.replace(st.nbrs, idx=idx)
                return dem._forces(pos, vel, w, st.time, nb, spring, st.wall_spring)[:3]
            return f

        args = (st.position, st.velocity, st.angular_velocity, st.nbrs.idx, st.pair_spring)
        fj, fc = forces_of(kernels["jax"]), forces_of(kernels["cpu"])
        ra, rb = fc(*args), fj(*args)
        dspring = float(jnp.max(jnp.abs(ra[2] - rb[2])) / jnp.max(jnp.abs(rb[2])))
        touching = int(jnp.sum(kernels["jax"].contacts(st).pair_mask))

        def timed(f):
            jax.block_until_ready(f(*args))
            t0 = time.perf_counter()
            for _ in range(a.repeat):
                r = f(*args)
            jax.block_until_ready(r)
            return (time.perf_counter() - t0) / a.repeat * 1e3

        tj = min(timed(fj) for _ in range(3))
        tc = min(timed(fc) for _ in range(3))
        print(f"| {n} | {what} | {st.nbrs.idx.shape[1]} | {touching} | {tj:.2f} | {tc:.2f} | "
              f"{tj / tc:.1f} | {dspring:.1e} |", flush=True)


if __name__ == "__main__":
    main()
