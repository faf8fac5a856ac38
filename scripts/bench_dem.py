"""Throughput of the drumheat DEM (particle-steps per second) in 2D and 3D rotating drums.

For each dimension and N it builds a drum bed as a lattice of touching spheres in the lower
part of the drum (every particle starts with its lattice contacts, as in a packed bed), lets it
run ``warm`` steps and times ``steps`` more, mechanics only and with a contact-conduction
update (alpha A_p (T_j - T_i) over the contact pairs and alpha A_p (T_w - T_i) over the wall
contacts, Weigler digest [2.7]) plugged into the same jitted loop through ``extra_update``.

Scenes:
* 3D: the LIGGGHTS reference scene (peers/liggghts/README.md): glass-like spheres d = 8 mm,
  rho = 2500, drum D = 0.25 m, periodic axis with length set for 35 % fill, 9.55 rpm,
  k_n = k_t = 1e5 N/m, e = 0.5 (LIGGGHTS convention), mu = 0.5, dt = 1e-5 s, skin 0.5 d.
* 2D: aluminium spheres d = 4 mm (rho 2700) in a monolayer, drum sized for ~50 % fill,
  12 rpm, k_n = 2.18e5 N/m (Table 2-1 value softened 1000x), viscous damping 0.3,
  friction 0.9 / 0.6, dt = 0.2 t_crit.

Usage: python scripts/bench_dem.py [--quick] [--dtype float32|float64] [--n 1000 10000]
       [--dims 2 3]
The compile time is that of the jitted loop (``lower().compile()``); the wall time excludes it.
"""

from __future__ import annotations

import argparse
import math
import time

import jax
import jax.numpy as jnp
import numpy as np

import drumheat  # noqa: F401  (x64)
from drumheat.geometry import DrumShell
from drumheat.mechanics import contact_params, make_dem, make_particles


def lattice_bed(n, r, R, dim, length=None):
    """n touching spheres (spacing 2r(1 - 1e-4)) on a hexagonal (2D) / cubic (3D) lattice,
    lowest sites of the drum first."""
    a = 2 * r * (1 - 1e-4)
    if dim == 2:
        ny = int(2 * R / (a * math.sqrt(3) / 2)) + 2
        nx = int(2 * R / a) + 2
        jj, ii = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
        x = -R + (ii + 0.5 * (jj % 2)) * a
        y = -R + jj * a * math.sqrt(3) / 2
        pts = np.stack([x.ravel(), y.ravel()], 1)
        keep = np.linalg.norm(pts, axis=1) < R - 1.01 * r
    else:
        nz = int(round(length / a))
        az = length / nz
        g = np.arange(-R, R, a)
        X, Y, Z = np.meshgrid(g, g, (np.arange(nz) + 0.5) * az, indexing="ij")
        pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
        keep = np.linalg.norm(pts[:, :2], axis=1) < R - 1.01 * r
    pts = pts[keep]
    pts = pts[np.argsort(pts[:, 1], kind="stable")]
    if len(pts) < n:
        raise ValueError("drum too small for the lattice")
    return pts[:n]


def conduction_update(mc, alpha_a, t_wall, n):
    def update(T, state, c, dt):
        q = jnp.where(c.pair_mask, alpha_a * (T[c.pair_j] - T[c.pair_i]), 0.0)
        dq = jax.ops.segment_sum(q, c.pair_i, n) - jax.ops.segment_sum(q, c.pair_j, n)
        qw = jnp.where(c.wall_mask, alpha_a * (t_wall - T[c.wall_particle]), 0.0)
        dq = dq + jax.ops.segment_sum(qw, c.wall_particle, n)
        return T + dt * dq / mc
    return update


def build(dim, n, thermal, dtype):
    if dim == 3:
        r, rho, R = 0.004, 2500.0, 0.125
        vp = 4 / 3 * math.pi * r**3
        length = max(n * vp / (0.35 * 0.6 * math.pi * R * R), 0.026)
        params = contact_params(1e5, restitution=0.5, restitution_model="linear",
                                friction=0.5, wall_friction=0.5)
        walls = [DrumShell(R, rpm=9.55)]
        kw = dict(periodic_length=length, dt=1e-5, skin=0.004)
    else:
        r, rho = 0.002, 2700.0
        R = r * math.sqrt(n / (0.5 * 0.85))
        length = None
        params = contact_params(2.18e5, damping_ratio=0.3, friction=0.9, wall_friction=0.6)
        walls = [DrumShell(R, rpm=12.0)]
        kw = {}
    pos = lattice_bed(n, r, R, dim, length)
    part = make_particles(np.full(n, r), rho)
    extra = None
    if thermal:
        mc = np.asarray(part.mass) * 836.0
        extra = conduction_update(jnp.asarray(mc), 57.0 * math.pi * r * r, 343.0, n)
    dem = make_dem(part, walls, params, dim=dim, dtype=dtype, extra_update=extra, **kw)
    T0 = jnp.full(n, 293.0) if thermal else None
    state = dem.init(pos, extra=T0)
    return dem, state


def bench(dim, n, thermal, steps, warm, dtype):
    dem, state = build(dim, n, thermal, dtype)
    k = jnp.asarray(warm, jnp.int32)
    t0 = time.perf_counter()
    compiled = dem._run_steps.lower(state, k).compile()
    t_compile = time.perf_counter() - t0
    state = jax.block_until_ready(compiled(state, k))
    if bool(state.nbrs.did_buffer_overflow):
        state = dem.reallocate(state, 2 * state.nbrs.idx.shape[1],
                               state.nbrs.cell_list_capacity)
        compiled = dem._run_steps.lower(state, k).compile()
    r0 = int(state.n_rebuilds)
    t0 = time.perf_counter()
    out = jax.block_until_ready(compiled(state, jnp.asarray(steps, jnp.int32)))
    wall = time.perf_counter() - t0
    assert not bool(out.nbrs.did_buffer_overflow), "overflow during the timed run"
    assert bool(jnp.all(jnp.isfinite(out.position)))
    c = dem.contacts(out)
    return dict(dim=dim, n=n, thermal=thermal, steps=steps, compile=t_compile, wall=wall,
                rate=n * steps / wall, contacts=float(c.pair_mask.sum()) / n,
                rebuilds=int(out.n_rebuilds) - r0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="only N = 1000")
    ap.add_argument("--dtype", default="float64", choices=["float32", "float64"])
    ap.add_argument("--n", type=int, nargs="+", default=None,
                    help="particle numbers (default 1e3 1e4 1e5; --quick: 1e3)")
    ap.add_argument("--dims", type=int, nargs="+", default=[2, 3])
    args = ap.parse_args()
    dtype = jnp.float32 if args.dtype == "float32" else jnp.float64
    plan = {1000: (2000, 200), 10000: (300, 50), 100000: (40, 10)}
    ns = args.n or ([1000] if args.quick else [1000, 10000, 100000])
    sizes = [(n,) + plan.get(n, (max(20, 2 * 10**6 // n), max(10, 2 * 10**5 // n)))
             for n in ns]
    print(f"jax {jax.__version__} on {jax.devices()[0].platform}, mechanics dtype {args.dtype}")
    print(f"{'dim':>3} {'N':>7} {'heat':>5} {'steps':>6} {'compile s':>10} {'wall s':>8} "
          f"{'p-steps/s':>10} {'contacts/p':>10} {'rebuilds':>8}")
    for dim in args.dims:
        for n, steps, warm in sizes:
            for thermal in (False, True):
                r = bench(dim, n, thermal, steps, warm, dtype)
                print(f"{r['dim']:>3} {r['n']:>7} {'on' if thermal else 'off':>5} "
                      f"{r['steps']:>6} {r['compile']:>10.2f} {r['wall']:>8.2f} "
                      f"{r['rate']:>10.3g} {r['contacts']:>10.2f} {r['rebuilds']:>8}",
                      flush=True)


if __name__ == "__main__":
    main()
