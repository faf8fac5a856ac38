"""Does the particles' order in memory matter? glass-drum-3d through the product path (C++ loop).

The contact loop reads the data of both partners of every listed pair; how far apart in memory
neighbours lie decides how often that misses the cache. Since 2026-11-27 the C++ loop's lists
go over to the cell order (``NeighborList.order``: the pairs grouped in the order of the
particles' cells, the particles' data laid out in it) once the particles' numbering has fewer
than half as many pairs near in memory as that order (``NeighborSetup.layout_order``); this
script shows what the numbering and the two layouts cost (before, a bed numbered at random ran
up to twice as slowly). Its measurements:

* ``--orders asis random morton`` (default): the scene's poured bed at N (the pour numbers the
  particles by height, as it fills the insertion sites lowest first), the same bed with the
  particles numbered at random, and numbered along a Morton curve of 8 mm cells. Each is given
  to the scene as a packing file, run 300 steps, then: the median |i - j| of the listed pairs,
  the contact call (best of 7 loops of 200 calls, as ``profile_scene_step.py``) and a run of
  1000 steps (particle-steps/s).
* ``--revolutions R``: the poured bed run for R drum revolutions in chunks of ``--chunk``
  steps, printing each chunk's rate and the median |i - j| as the turning bed mixes.
* ``--frame FILE:K``: the first measurement on the positions of output K of a run's
  ``particles.npz`` instead of the pour (a bed numbered as a long run has mixed it; given to the
  scene as a packing, at rest), to tell what the numbering costs at that point of a run.
* ``--layouts FILE:K1,K2,...``: the two layouts of the C++ loop on the same state, for each
  output K of a run's ``particles.npz`` (at rest, 300 steps as above): the list in canonical
  order (the particles' own numbering, order 0 .. N-1) and in the cell order
  (``NeighborList.order``), their contact calls alternating (``--repeat`` loops of 100 calls
  each; median and best), beside the pairs near in memory in each (``NeighborSetup.near_pairs``)
  and which layout ``layout_order`` takes: to tell where along a run the switch pays.
* ``--diffuse S1,S2,...``: the same on the poured bed renumbered as by diffusion over S places
  (the particles sorted by index plus a normal deviate of standard deviation S), a stand-in
  for the frames of a long run at sizes where such a run takes too long.

Usage: python scripts/bench_particle_order.py [--n 10000] [--orders asis random morton]
       python scripts/bench_particle_order.py --n 10000 --revolutions 1.2 [--chunk 20000]
       python scripts/bench_particle_order.py --n 10000 --frame results/drum/particles.npz:25
       python scripts/bench_particle_order.py --n 10000 --layouts results/drum/particles.npz:0,9,25
       python scripts/bench_particle_order.py --n 50000 --diffuse 100,300,1000
The packings are cached in ``--packing-cache`` (bench_vs_liggghts.py's).
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from bench_vs_liggghts import D_P, scene_for, scene_packing
from machine import cpu_ticks, steal_percent
from profile_scene_step import loops, timed

from drumheat.mechanics.integrator import _carry_pairs
from drumheat.mechanics.neighbors import sort_pairs


def morton_order(pos, cell=D_P):
    """Permutation that numbers the particles along a Morton (Z-order) curve of cubic cells."""
    c = np.floor((pos - pos.min(0)) / cell).astype(np.uint64)
    code = np.zeros(len(pos), np.uint64)
    for bit in range(16):
        for k in range(pos.shape[1]):
            one = (c[:, k] >> np.uint64(bit)) & np.uint64(1)
            code |= one << np.uint64(pos.shape[1] * bit + k)
    return np.argsort(code, kind="stable")


def locality(state, n) -> float:
    """Median |i - j| over the listed pairs of the state's neighbour list."""
    idx = np.asarray(state.nbrs.idx)
    ok = idx[0] < n
    return float(np.median(np.abs(idx[0][ok] - idx[1][ok])))


def motion_for(n, packing):
    from drumheat.motion import make_motion

    return make_motion(scene_for(n, "cpu", packing))


def frame_positions(spec: str, n: int) -> np.ndarray:
    """The positions of output K of a ``particles.npz`` (``spec`` = ``FILE:K``)."""
    path, k = spec.rsplit(":", 1)
    with np.load(path) as f:
        pos = np.asarray(f["position"][int(k)], float)
    if len(pos) != n:
        raise SystemExit(f"{path} holds {len(pos)} particles, not --n {n}")
    return pos


def bed_state(n, pos, name="bed"):
    """The scene's motion model on the bed ``pos`` (given as a packing file) and its state
    after 300 steps from rest."""
    path = Path(tempfile.mkdtemp()) / f"{name}.npz"
    np.savez(path, position=pos, diameter=np.full(n, D_P), group=np.zeros(n, int))
    motion = motion_for(n, path)
    return motion, motion.dem.run(motion.initial_state(), 300, chunk=300)


def frames(spec, n):
    """``(label, t, positions)`` of the outputs K of ``spec`` (``FILE:K1,K2,...``)."""
    path, ks = spec.rsplit(":", 1)
    with np.load(path) as f:
        times = np.asarray(f["t"], float)
    for k in (int(x) for x in ks.split(",")):
        yield f"output {k}", f"{times[k]:g}", frame_positions(f"{path}:{k}", n)


def diffused(spec, n, cache):
    """``(label, "", positions)`` of the poured bed renumbered as by diffusion over S places for
    each S of ``spec`` (``S1,S2,...``): the particles sorted by their index plus a normal
    deviate of standard deviation S, so that partners drift apart by about S sqrt 2 places
    while the numbering stays locally ordered: a stand-in for a turning bed's mixing."""
    with np.load(scene_packing(n, cache)) as f:
        pos = np.asarray(f["position"], float)
    rng = np.random.default_rng(0)
    for sd in (float(x) for x in spec.split(",")):
        perm = np.argsort(np.arange(n) + rng.normal(0.0, sd, n), kind="stable")
        yield f"pour, diffused {sd:g}", "", pos[perm]


def layouts(n, beds, repeat):
    """For each ``(label, t, positions)`` of ``beds``: the contact call with the list in
    canonical order and in the cell order, on the same state (module docstring)."""
    print("| bed | t (s) | median abs(i - j) | near pairs, numbering / cell order | layout taken "
          "| contact call, canonical (ms): median, best | cell order | canonical / cell order "
          "(medians) | steal |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, t, pos in beds:
        motion, state = bed_state(n, pos, "bed")
        dem = motion.dem
        nb = dem.neighbor
        near_num, near_cell, cells = nb.near_pairs(nb.to_box(state.position), state.nbrs.idx)
        taken = "cell" if state.nbrs.order is not None and not bool(
            jnp.all(state.nbrs.order == jnp.arange(n))) else "canonical"
        states = {}
        for name, order in (("canonical", jnp.arange(n, dtype=jnp.int32)), ("cell", cells)):
            new = sort_pairs(dataclasses.replace(state.nbrs, order=order), n, order)
            states[name] = _carry_pairs(state, new, n)
        call, calls = loops(dem)["contact"], jnp.asarray(100, jnp.int32)
        ms = {name: [] for name in states}
        for s in states.values():
            jax.block_until_ready(call(s, calls))
        c0 = cpu_ticks()
        for _ in range(repeat):
            for name, s in states.items():
                t0 = time.perf_counter()
                jax.block_until_ready(call(s, calls))
                ms[name].append(10.0 * (time.perf_counter() - t0))
        med = {name: float(np.median(v)) for name, v in ms.items()}
        print(f"| {label} | {t} | {locality(state, n):.0f} | {int(near_num) / n:.2f} / "
              f"{int(near_cell) / n:.2f} per particle | {taken} | {med['canonical']:.3f}, "
              f"{min(ms['canonical']):.3f} | {med['cell']:.3f}, {min(ms['cell']):.3f} | "
              f"{med['canonical'] / med['cell']:.2f} | "
              f"{steal_percent(c0, cpu_ticks()):.0f} % |", flush=True)


def orders(n, names, cache, frame=None):
    if frame is None:
        with np.load(scene_packing(n, cache)) as f:
            pos = f["position"]
    else:
        pos = frame_positions(frame, n)
    perms = {"asis": np.arange(n), "random": np.random.default_rng(0).permutation(n),
             "morton": morton_order(pos)}
    print(f"| N | order | median abs(i - j) | contact call (ms) | run (particle-steps/s) | steal |")
    print("|---|---|---|---|---|---|")
    for name in names:
        motion, state = bed_state(n, pos[perms[name]], name)
        dem = motion.dem
        c0 = cpu_ticks()
        best = timed(loops(dem)["contact"], state, jnp.asarray(200, jnp.int32), repeat=7)[0]
        t0 = time.perf_counter()
        jax.block_until_ready(dem.run(state, 1000, chunk=1000).position)
        rate = n * 1000 / (time.perf_counter() - t0)
        print(f"| {n} | {name} | {locality(state, n):.0f} | {1e3 * best / 200:.3f} | {rate:.3g} "
              f"| {steal_percent(c0, cpu_ticks()):.0f} % |", flush=True)


def revolutions(n, revs, chunk, cache):
    motion = motion_for(n, scene_packing(n, cache))
    dem = motion.dem
    state = dem.run(motion.initial_state(), 300, chunk=300)
    period = 60.0 / float(motion.scene.drum.rpm)
    while float(state.time) < revs * period:
        c0, t0 = cpu_ticks(), time.perf_counter()
        state = dem.run(state, chunk, chunk=chunk)
        jax.block_until_ready(state.position)
        wall = time.perf_counter() - t0
        print(f"{float(state.time) / period:5.2f} rev: {n * chunk / wall:.3g} particle-steps/s, "
              f"median abs(i - j) {locality(state, n):.0f}, steal "
              f"{steal_percent(c0, cpu_ticks()):.0f} %", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=10000)
    ap.add_argument("--orders", nargs="+", default=["asis", "random", "morton"],
                    choices=["asis", "random", "morton"])
    ap.add_argument("--revolutions", type=float, default=0.0)
    ap.add_argument("--chunk", type=int, default=20000)
    ap.add_argument("--packing-cache", default="/tmp/drumheat_packings")
    ap.add_argument("--frame", metavar="FILE:K", help="start from output K of a particles.npz")
    ap.add_argument("--layouts", metavar="FILE:K1,K2,...",
                    help="the two layouts on the beds of these outputs of a particles.npz")
    ap.add_argument("--diffuse", metavar="S1,S2,...",
                    help="the two layouts on the poured bed renumbered as by diffusion over S "
                         "places")
    ap.add_argument("--repeat", type=int, default=9,
                    help="alternating loops of 100 contact calls per layout (--layouts, "
                         "--diffuse)")
    args = ap.parse_args()
    if args.layouts:
        layouts(args.n, frames(args.layouts, args.n), args.repeat)
    elif args.diffuse:
        layouts(args.n, diffused(args.diffuse, args.n, args.packing_cache), args.repeat)
    elif args.revolutions > 0:
        revolutions(args.n, args.revolutions, args.chunk, args.packing_cache)
    else:
        orders(args.n, args.orders, args.packing_cache, args.frame)


if __name__ == "__main__":
    main()
