"""What float32 mechanics (``[dem] precision = "float32"``, or ``"mixed"``: float64 positions,
the rest float32) does to the built-in 3D drum.

Usage: python scripts/precision_drum.py [--n 10000 50000] [--warm-seconds 1.0]
       [--seconds 0.5] [--samples 3] [--offset 50] [--probe 20] [--packings DIR]
       [--tile FILE] [--backend auto|cpu|jax] [--compare float32 mixed]

float32 mechanics store the positions in float32 too (mixed keeps them in float64, and its
contact law reads them folded along the axis: drumheat.mechanics.precision), so float32
resolves a coordinate x only to its spacing ulp(x) (2^-23 |x| and less): the coordinates of
glass-drum-3d reach 0.125 m across the drum and the slice's depth (N x 2.6e-5 m) along the
periodic axis. Two things follow from the set-up alone, printed first for each N and axis
(for float32):

* a drift dt v smaller than half the spacing leaves the coordinate unchanged, so a particle
  slower than ulp / (2 dt) along that axis does not move along it at all in a step;
* a contact's overlap, and with it the normal force k_n delta, is resolved only to about the
  spacing: k_n ulp against a particle's weight m g is the force quantum per contact, and the
  spacing against the median overlap of the touching pairs (measured in the float64 bed) its
  relative size.

Then measured, for each N: the scene from its poured bed (``--packings``, as the benchmarks; or,
with ``--tile FILE``, a poured slice of N0 particles repeated N / N0 times along the periodic
axis, as ``bench_gpu.py`` does for the GPU sizes) is run ``--warm-seconds`` in float64 (the
start-up of the turning bed); from there ``--samples`` starts, each ``--offset`` float64 steps
after the previous one and its positions moved by random 1e-13 m (far below anything physical:
the flow, which is chaotic, turns it into independent samples of the same flow; without the
move float64 would retrace the first start's trajectory, and float32's rounding erases the
move, so its starts differ by the offset), and from each start runs of ``--seconds``: float64,
and each precision of ``--compare`` (default float32; the float64 state put onto that
precision's state as a checkpoint is restored: rounded, the positions kept in float64 with
mixed).
For each run: the bed's mean temperature rise (the product's answer), the axial mean squared
displacement (the periodic axis, where float32's spacing is the coarsest), the share of
particles whose axial coordinate did not change in one step (over ``--probe`` steps at the
end), and the mean kinetic energy per particle; then the mean and the spread (max - min) of
each precision. A precision is as good as float64 for a quantity where its mean lies within the
float64 samples' scatter.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import drumheat  # noqa: F401  (x64 for the temperatures)
from bench_gpu import tiled  # noqa: E402  (scripts/)
from bench_vs_liggghts import scene_for, scene_packing  # noqa: E402  (scripts/)
from drumheat.mechanics.precision import position_resolution
from drumheat.motion import make_motion
from drumheat.runner.checkpoint import state_structure


def motion_for(n, precision, packing, backend):
    """glass-drum-3d at N on the contact ``backend`` ("auto": the C++ loop on a CPU, the JAX
    kernel on a GPU), the mechanics in ``precision``, from the ``packing`` file."""
    return make_motion(scene_for(n, backend, packing, precision))


def as_template(motion, template, state):
    """``state``'s arrays put onto ``template`` (a fresh state of ``motion``, here the other
    precision) as a checkpoint is restored, in the template's dtypes."""
    leaves = jax.tree_util.tree_leaves(eqx.partition(state, eqx.is_array)[0])
    return motion.restore_state(template, leaves, {"structure": state_structure(state)}, None)[0]


def resolution(motion, state):
    """Rows (axis, largest coordinate, float32 spacing, slowest moving speed, spacing / (m g /
    k_n), spacing / median overlap) at the bed's own largest coordinates
    (:func:`drumheat.mechanics.precision.position_resolution`), and the median overlap."""
    dem = motion.dem
    x = np.abs(np.asarray(state.position, np.float64)).max(axis=0)
    res = position_resolution(np.float32, -x, x, dem.dt, dem.m_min, dem.k_max, dem.gravity)
    c = dem.contacts(state)
    med = float(np.median(np.asarray(c.pair_overlap)[np.asarray(c.pair_mask)]))
    return [(axis, ext, u, v, u / res.weight_overlap, u / med)
            for axis, ext, u, v in zip("xyz", x, res.spacing, res.slowest_speed)], med


def sample(motion, state, seconds, probe, chunk=2000):
    """Run ``seconds`` from ``state``: (mean temperature rise K, axial MSD m^2, share of
    particles with an unchanged axial coordinate per step, mean kinetic energy J, wall s)."""
    dem = motion.dem
    steps = int(round(seconds / dem.dt))
    length = float(motion.periodic)
    z0 = np.asarray(state.position[:, 2], np.float64)
    dz = np.zeros_like(z0)
    t0_mean = float(jnp.mean(state.extra.T))
    ke, done, t0 = [], 0, time.perf_counter()
    while done < steps:
        k = min(chunk, steps - done)
        state = dem.run(state, k, chunk=k)
        z1 = np.asarray(state.position[:, 2], np.float64)
        d = z1 - z0
        dz += d - length * np.round(d / length)  # the periodic image: |d| << L per chunk
        z0 = z1
        v = np.asarray(state.velocity, np.float64)
        ke.append(0.5 * float(np.mean(np.asarray(dem.particles.mass) * np.sum(v * v, axis=1))))
        done += k
    wall = time.perf_counter() - t0
    frozen = []
    for _ in range(probe):
        z1 = np.asarray(state.position[:, 2])
        state = dem.run(state, 1, chunk=1)
        frozen.append(float(np.mean(np.asarray(state.position[:, 2]) == z1)))
    rise = float(jnp.mean(state.extra.T)) - t0_mean
    return rise, float(np.mean(dz**2)), float(np.mean(frozen)), float(np.mean(ke)), wall


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[10000, 50000])
    ap.add_argument("--warm-seconds", type=float, default=1.0)
    ap.add_argument("--seconds", type=float, default=0.5)
    ap.add_argument("--samples", type=int, default=3, help="starts (each run in both precisions)")
    ap.add_argument("--offset", type=int, default=50, help="float64 steps between the starts")
    ap.add_argument("--probe", type=int, default=20, help="single steps probed at the end")
    ap.add_argument("--packings", default="/tmp/drumheat_packings")
    ap.add_argument("--tile", type=Path, help="poured slice to repeat along the axis to N "
                    "(instead of --packings)")
    ap.add_argument("--backend", default="auto", choices=["auto", "cpu", "jax"])
    ap.add_argument("--compare", nargs="+", default=["float32"], choices=["float32", "mixed"],
                    help="precisions run against float64 from each start")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    for n in args.n:
        packing = (tiled(args.tile, n, tmp / f"tiled_{n}.npz") if args.tile
                   else scene_packing(n, args.packings))
        m64 = motion_for(n, "float64", packing, args.backend)
        others = {p: motion_for(n, p, packing, args.backend) for p in args.compare}
        s = m64.initial_state()
        t0 = time.perf_counter()
        s = m64.dem.run(s, int(round(args.warm_seconds / m64.dem.dt)), chunk=5000)
        jax.block_until_ready(s.position)
        print(f"N = {n} on {jax.devices()[0].device_kind}, contact backend "
              f"{m64.contact_backend().backend}: dt = {m64.dem.dt:.3g} s, k_n = {m64.k_n:.3g} "
              f"N/m, periodic length {float(m64.periodic):.3f} m; warm-up {args.warm_seconds} s "
              f"in float64 ({time.perf_counter() - t0:.0f} s wall)", flush=True)
        rows, med = resolution(m64, s)
        print(f"  float32 resolution at the bed's largest coordinates (median overlap of the "
              f"touching pairs {med:.3g} m):")
        print("  | axis | largest abs coordinate (m) | float32 spacing (m) | slowest speed that "
              "moves in a step (m/s) | k_n spacing / m g | spacing / median overlap |")
        print("  |---|---|---|---|---|---|")
        for axis, ext, u, vmin, fq, rel in rows:
            print(f"  | {axis} | {ext:.3f} | {u:.3g} | {vmin:.3g} | {fq:.2f} | {rel:.2f} |")
        print(f"  over {args.seconds} s from each of {args.samples} starts {args.offset} steps "
              "apart:")
        print("  | run | mean temperature rise (K) | axial MSD (mm^2) | axial coordinate "
              "unchanged in a step | mean kinetic energy (uJ) | wall (s) |")
        print("  |---|---|---|---|---|---|")
        templates = {p: mo.initial_state() for p, mo in others.items()}
        got, start = {p: [] for p in ("float64", *others)}, s
        for k in range(args.samples):
            if k:
                start = m64.dem.run(start, args.offset, chunk=args.offset)
                start = start._replace(position=start.position + 1e-13 * jax.random.normal(
                    jax.random.PRNGKey(k), start.position.shape, start.position.dtype))
            runs = [("float64", m64, start)] + [
                (p, mo, as_template(mo, templates[p], start)) for p, mo in others.items()]
            for name, mo, st in runs:
                r = sample(mo, st, args.seconds, args.probe)
                got[name].append(r)
                print(f"  | {name}, start {k} | {r[0]:.5f} | {1e6 * r[1]:.3f} | "
                      f"{100 * r[2]:.1f} % | {1e6 * r[3]:.3f} | {r[4]:.1f} |", flush=True)
        for name, rs in got.items():
            a = np.array(rs)
            mean, spread = a.mean(axis=0), a.max(axis=0) - a.min(axis=0)
            print(f"  | {name}, mean (spread) | {mean[0]:.5f} ({spread[0]:.5f}) | "
                  f"{1e6 * mean[1]:.3f} ({1e6 * spread[1]:.3f}) | {100 * mean[2]:.1f} % | "
                  f"{1e6 * mean[3]:.3f} ({1e6 * spread[3]:.3f}) | |")


if __name__ == "__main__":
    main()
