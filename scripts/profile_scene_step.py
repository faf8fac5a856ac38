"""Where the step of glass-drum-3d goes on CPU: the product path's cost split per step.

Usage: python scripts/profile_scene_step.py [--n 10000] [--backend cpu] [--steps 2000]
       [--packing-cache DIR] [--trace] [--trace-run]

The built-in scene ``glass-drum-3d`` at N particles (``groups.0.count = N``, ``drum.depth =
N x 2.6e-5 m``) through the product path (``make_motion(scene).dem``), after ``--warm``
steps, timed piece by piece on the same state:

* ``run``: ``dem.run`` over ``--steps`` steps in one chunk (as ``bench_vs_liggghts.py``):
  particle-steps/s and the neighbour rebuilds in it;
* ``step (no rebuild)``: the step with the neighbour list kept (``step(state, "keep")``) in one
  jitted loop: the contact loop, the XLA work around it and the thermal step every
  ``dem.thermal_substeps`` steps;
* ``contact loop``: the contact call alone (the C++ loop on ``--backend cpu``), in a jitted
  loop that feeds its springs back;
* ``rebuild``: one neighbour rebuild (cell list build, pair sort, remap of the springs and the
  contact-time accumulators), and its pieces;
* with ``--trace``: a ``jax.profiler`` trace of the no-rebuild loop, its events summed by
  track and name (the largest twenty of each track), per step; with ``--trace-run`` the same
  of the run's own loop (``dem._run_steps``: the steps between rebuilds without the per-step
  ``lax.cond``, the skin test in the loop's condition or the C++ call), over ``--loop`` steps.

The packing (the pour, minutes at N = 50 000) is kept in ``--packing-cache`` to be reused.
Each line prints the machine's load and the CPU steal during its timing (scripts/machine.py).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import drumheat  # noqa: F401  (x64 for the temperatures)
from machine import cpu_ticks, load, steal_percent  # noqa: E402  (scripts/machine.py)
from trace_summary import print_split, trace_totals  # noqa: E402
from drumheat.mechanics.integrator import JIT_OPTIONS, pair_extra, remap_pair_extra
from drumheat.mechanics.neighbors import remap_pair_data, sort_pairs, take_pair_data


def scene_motion(n, backend, cache):
    """The motion model of glass-drum-3d at N on ``backend`` and its initial state, the bed
    poured once into ``cache`` and read from there (bench_vs_liggghts.py's scene and packing)."""
    from bench_vs_liggghts import scene_for, scene_packing
    from drumheat.motion import make_motion

    motion = make_motion(scene_for(n, backend, scene_packing(n, cache)))
    return motion, motion.initial_state()


def timed(fn, *args, repeat=3):
    """``(best seconds of repeat calls, load before, steal during)``; one call first."""
    jax.block_until_ready(fn(*args))
    ld, c0, best = load(), cpu_ticks(), float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - t0)
    return best, ld, steal_percent(c0, cpu_ticks())


def loops(dem):
    """Jitted ``(steps without rebuild, contact calls, rebuild)`` functions of ``dem``."""
    step, forces, nb, n = dem.step_fn, dem._forces.__wrapped__.func, dem.neighbor, dem.particles.n

    @jax.jit
    def keep_loop(state, k):
        return jax.lax.fori_loop(0, k, lambda _, s: step(s, "keep")[0], state)

    def contact_loop(state, k):
        def body(_, c):
            sp, ws = c
            r = forces(state.position, state.velocity, state.angular_velocity, state.time,
                       state.nbrs, sp, ws)
            return r[2], r[3]
        return jax.lax.fori_loop(0, k, body, (state.pair_spring, state.wall_spring))

    def rebuilder(setup):
        def rebuild(state):
            new, src = setup.rebuild_with_sources(state.position, state.nbrs)
            remap = lambda a: take_pair_data(a, src)  # noqa: E731
            return new, remap(state.pair_spring), remap_pair_extra(
                type(state.extra), pair_extra(state.extra), remap)
        return rebuild

    def build_only(state):
        pos = nb.to_box(state.position)
        return nb.grid.build(pos, state.nbrs.max_occupancy, state.nbrs.cell_list_capacity)

    def sort_only(state):
        return sort_pairs(state.nbrs, n).idx

    def remap_only(state):
        remap = lambda a: remap_pair_data(state.nbrs.idx, a, state.nbrs.idx, n)  # noqa: E731
        return remap(state.pair_spring), remap_pair_extra(type(state.extra),
                                                          pair_extra(state.extra), remap)

    jit = lambda f: jax.jit(f, compiler_options=JIT_OPTIONS)  # noqa: E731
    return dict(keep=jax.jit(keep_loop.__wrapped__, compiler_options=JIT_OPTIONS),
                contact=jit(contact_loop), rebuild=jit(rebuilder(nb)),
                rebuild_jax=jit(rebuilder(dataclasses.replace(nb, builder="jax"))),
                rebuild_cpu=jit(rebuilder(dataclasses.replace(nb, builder="cpu"))),
                build=jit(build_only),
                sort=jit(sort_only), remap=jit(remap_only))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=10000)
    ap.add_argument("--backend", default="cpu", choices=["cpu", "jax"])
    ap.add_argument("--steps", type=int, default=2000, help="steps of the dem.run timing")
    ap.add_argument("--loop", type=int, default=200, help="steps of the piece timings")
    ap.add_argument("--warm", type=int, default=500)
    ap.add_argument("--packing-cache", default="/tmp/drumheat_packings")
    ap.add_argument("--trace", action="store_true")
    ap.add_argument("--trace-run", action="store_true")
    args = ap.parse_args()
    motion, state = scene_motion(args.n, args.backend, args.packing_cache)
    dem = motion.dem
    n, m = dem.particles.n, state.nbrs.idx.shape[1]
    state = dem.run(state, args.warm, chunk=args.warm)
    touching = int(jnp.sum(dem.contacts(state).pair_mask))
    print(f"N = {n}, backend {motion.contact_backend().backend}, {m} pair slots, {touching} "
          f"touching, dt = {dem.dt:.3g} s, thermal step every {motion.substeps}")
    r0, ld, c0 = int(state.n_rebuilds), load(), cpu_ticks()
    t0 = time.perf_counter()
    out = dem.run(state, args.steps, chunk=args.steps)
    jax.block_until_ready(out.position)
    wall = time.perf_counter() - t0
    rb = int(out.n_rebuilds) - r0
    print(f"run: {args.steps} steps {wall:.2f} s = {1e3 * wall / args.steps:.3f} ms/step, "
          f"{n * args.steps / wall:.3g} particle-steps/s, {rb} rebuilds (every "
          f"{args.steps / max(rb, 1):.0f} steps), load {ld:.2f}, steal "
          f"{steal_percent(c0, cpu_ticks()):.0f} %")
    f = loops(dem)
    k = jnp.asarray(args.loop, jnp.int32)
    rows = [("step (no rebuild)", *timed(f["keep"], state, k), args.loop),
            ("contact call", *timed(f["contact"], state, k), args.loop)]
    for name in ("rebuild", "rebuild_jax", "rebuild_cpu", "build", "sort", "remap"):
        rows.append((name, *timed(f[name], state, repeat=5), 1))
    for name, t, ld, st, per in rows:
        print(f"  {name:18s} {1e3 * t / per:8.3f} ms (load {ld:.2f}, steal {st:.0f} %)")
    if args.trace:
        print("trace of the no-rebuild loop, per step:")
        _, totals, _ = trace_totals(f["keep"], (state, k), "/tmp/drumheat_profile_scene_step")
        print_split(totals, args.loop)
    if args.trace_run:
        start = dem.adopt(state)
        r0 = int(start.n_rebuilds)
        end = dem._run_steps(start, k)
        print(f"trace of the run's loop (dem._run_steps), per step ({int(end.n_rebuilds) - r0} "
              f"rebuilds in {args.loop} steps):")
        _, totals, _ = trace_totals(dem._run_steps, (start, k), "/tmp/drumheat_profile_run")
        print_split(totals, args.loop, top=30)


if __name__ == "__main__":
    main()
