"""The built-in 3D drum scene at large N on whatever JAX device is default (a GPU where one is
present): particle-steps per second and memory per particle, through the product path.

Scene: ``glass-drum-3d`` (the LIGGGHTS benchmark drum: glass d = 8 mm, D = 0.25 m, 9.55 rpm,
periodic axis at 35 % fill, k = 1e5 N/m, dt = 0.1 t_crit = 1.6e-5 s, contact conduction with
the gap tolerance, contact times every step and a thermal step every ``dem.thermal_substeps``
= 10) with ``groups.0.count = N`` and ``drum.depth = N x 2.6e-5 m`` (the scene's documented
knob), ``dem.contact_backend = "jax"`` and the mechanics in ``--precision`` (the scene's default
is float64; temperatures are float64 always).

Packing: pouring 1e6 particles would cost more device time than the benchmark itself, so the
bed is the scene's own poured N = 2000 slice (0.052 m deep, periodic along the axis; made by
``--make-base`` on any machine, or on the spot if the file is missing) tiled N / 2000 times
along the axis, given to the scene as ``packing.method = "file"``. The tiled bed is the poured
one repeated, so contact counts per particle are those of the poured bed; it starts at rest,
and the timing starts after ``--warm`` steps (compilation, first neighbour-list builds).

For each (N, precision) a fresh process builds the motion model (``make_motion``) and times
``DEM.run`` (chunked, with its overflow / NaN / escape checks) over enough steps for about
``--seconds`` of wall time. Reported: particle-steps/s, neighbour-list rebuilds in the timed
steps, the device's peak memory (``memory_stats()['peak_bytes_in_use']``, GPU) or the process's
peak resident memory (CPU), both per particle, the mean temperature change as a sanity
check that heat moved, and what the precision resolves (``spacing/dg``: the spacing of the
coordinates the contact law reads, at their largest value, over the overlap under a bead's own
weight, :mod:`drumheat.mechanics.precision`). float32 reaches 1 from N = 4e4 on: its rows at
1e5 and 1e6 time the card on a bed float32 gets wrong (at 1e6 the kinetic energy 15-18 % off
float64's, docs/performance.md, precision); ``mixed`` (float64 positions, the contact law
reading them folded along the axis) stays below 0.5 at every N.

With ``--trace STEPS``, each case then runs ``dem.run_steps`` over STEPS steps under the JAX
profiler and prints the device's kernels and the host's work summed per step
(``scripts/trace_summary.py``); ``--trace-dir`` keeps the trace files.

Usage: python scripts/bench_gpu.py [--n 100000 1000000] [--precision float32 float64 mixed]
       [--seconds 15] [--warm 300] [--base FILE] [--json FILE] [--trace STEPS --trace-dir DIR]
       python scripts/bench_gpu.py --make-base FILE     (pour the N = 2000 slice, save it)
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

BASE_N, BASE_DEPTH = 2000, 0.052
DEFAULT_BASE = Path(__file__).resolve().parents[1] / ".bench" / "glass-drum-3d-2000.npz"


def scene(n: int, precision: str, packing_file=None):
    """glass-drum-3d at N particles (depth = N x 2.6e-5 m), JAX contact backend."""
    from drumheat.scene import load_scene

    over = {"groups.0.count": n, "drum.depth": n * BASE_DEPTH / BASE_N,
            "dem.contact_backend": "jax", "dem.precision": precision}
    if packing_file is not None:
        over.update({"packing.method": "file", "packing.file": str(packing_file)})
    return load_scene("glass-drum-3d", over)


def make_base(path: Path) -> None:
    """Pour the scene's N = 2000 slice and save its positions (packing file format)."""
    import numpy as np

    from drumheat.motion import make_motion

    motion = make_motion(scene(BASE_N, "float64"))
    pos = np.asarray(motion.packing_positions(), float)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, position=pos, diameter=np.full(BASE_N, 0.008), group=np.zeros(BASE_N, int))
    print(f"poured {BASE_N} particles, saved {path}")


def tiled(base: Path, n: int, out: Path) -> Path:
    """The poured slice in ``base`` (any N0, depth N0 x 2.6e-5 m, the scene's knob) repeated
    n / N0 times along the periodic axis (seamless: the slice is periodic with its depth)."""
    import numpy as np

    with np.load(base) as f:
        pos = f["position"]
    n0 = len(pos)
    if n % n0:
        raise SystemExit(f"N must be a multiple of {n0} (the poured slice {base} is tiled)")
    k = n // n0
    shift = np.zeros((k, 1, 3))
    shift[:, 0, 2] = n0 * BASE_DEPTH / BASE_N * np.arange(k)
    np.savez(out, position=(pos[None] + shift).reshape(n, 3), diameter=np.full(n, 0.008),
             group=np.zeros(n, int))
    return out


def mean_temperature(state) -> float:
    """Mean particle temperature (K) of a coupled DEM state (``CoupledHeat.T``), NaN without
    heat."""
    import jax.numpy as jnp

    T = getattr(state.extra, "T", None)
    return float(jnp.mean(T)) if T is not None else float("nan")


def measure(n: int, precision: str, base: Path, seconds: float, warm: int,
            donate: bool = False, trace: int = 0, trace_dir=None) -> dict:
    """In this process: build the scene at N, warm up, time; one dict of numbers. With
    ``trace`` > 0, then a profiler trace of ``dem.run_steps`` over ``trace`` steps (the
    compiled loop without the chunk checks), printed per step by track (device kernels apart
    from host work) and saved into ``trace_dir``."""
    import resource
    import tempfile

    import jax
    import numpy as np

    from drumheat.motion import make_motion

    t0 = time.perf_counter()
    tmp = Path(tempfile.mkdtemp()) / f"packing-{n}.npz"
    motion = make_motion(scene(n, precision, tiled(base, n, tmp)))
    state = motion.initial_state()
    dem = motion.dem
    t_setup = time.perf_counter() - t0

    t0 = time.perf_counter()
    state = dem.run(state, warm, chunk=warm, donate=donate)
    jax.block_until_ready(state.position)
    t_warm = time.perf_counter() - t0
    probe = max(50, warm // 2)  # a first estimate of the rate, compiled already
    t0 = time.perf_counter()
    state = dem.run(state, probe, chunk=probe, donate=donate)
    jax.block_until_ready(state.position)
    per_step = (time.perf_counter() - t0) / probe
    steps = int(max(200, min(50000, seconds / per_step)))
    steps = -(-steps // probe) * probe  # whole chunks: the compiled chunk length is reused
    T_before = mean_temperature(state)
    r0 = int(state.n_rebuilds)
    t0 = time.perf_counter()
    out = dem.run(state, steps, chunk=probe, donate=donate)
    jax.block_until_ready(out.position)
    wall = time.perf_counter() - t0
    T_after = mean_temperature(out)
    dev = jax.devices()[0]
    stats = dev.memory_stats() or {}
    peak = stats.get("peak_bytes_in_use")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    if trace:
        from trace_summary import print_split, trace_totals

        t_wall, totals, path = trace_totals(dem.run_steps, (out, trace), tempfile.mkdtemp())
        if trace_dir is not None:
            shutil.copyfile(path, Path(trace_dir) / f"trace-{n}-{precision}.json.gz")
        print(f"trace: {trace} steps in {t_wall:.3f} s under the profiler "
              f"({1e6 * t_wall / trace:.1f} us per step)")
        print_split(totals, trace, top=25)
    return dict(n=n, precision=precision, donate=str(donate), device=f"{dev.platform}:{dev.device_kind}",
                jax=jax.__version__, steps=steps, wall_s=wall, rate=n * steps / wall,
                rebuilds=int(out.n_rebuilds) - r0, setup_s=t_setup, warm_s=t_warm,
                pair_capacity=int(out.nbrs.idx.shape[1]),
                device_peak_bytes=peak, peak_rss_bytes=rss,
                bytes_per_particle=(peak if peak else rss) / n,
                dT_mean=T_after - T_before, finite=bool(np.all(np.isfinite(
                    np.asarray(out.position)))),
                spacing_over_weight_overlap=dem.position_resolution().spacing_over_weight_overlap)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[100000, 1000000])
    ap.add_argument("--precision", nargs="+", default=["float32", "float64"],
                    choices=["float32", "float64", "mixed"])
    ap.add_argument("--seconds", type=float, default=15.0, help="wall time of each timing")
    ap.add_argument("--warm", type=int, default=300, help="steps before the timing")
    ap.add_argument("--base", type=Path, default=DEFAULT_BASE, help="the poured N=2000 slice")
    ap.add_argument("--json", type=Path, help="append each result as a JSON line here")
    ap.add_argument("--timeout", type=float, default=600, help="per case (s)")
    ap.add_argument("--make-base", type=Path, metavar="FILE")
    ap.add_argument("--donate", nargs="+", default=["off"], choices=["on", "off"],
                    help="buffer donation of DEM.run's chunks (DEM.run(donate=...)); several "
                         "values time each")
    ap.add_argument("--trace", type=int, default=0, metavar="STEPS",
                    help="after each timing, a profiler trace of STEPS steps, summed per step "
                         "(printed; the trace file into --trace-dir)")
    ap.add_argument("--trace-dir", type=Path, help="where the trace files go")
    ap.add_argument("--one", nargs=3, metavar=("N", "PRECISION", "DONATE"),
                    help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.make_base:
        make_base(args.make_base)
        return
    if args.one:
        donate = args.one[2] == "on"
        print("RESULT " + json.dumps(measure(int(args.one[0]), args.one[1], args.base,
                                             args.seconds, args.warm, donate, args.trace,
                                             args.trace_dir)), flush=True)
        return
    if not args.base.exists():
        make_base(args.base)
    env = dict(os.environ, XLA_PYTHON_CLIENT_PREALLOCATE="false")
    rows = []
    cases = [(prec, n, don) for prec in args.precision for n in args.n for don in args.donate]
    for prec, n, don in cases:
        cmd = [sys.executable, __file__, "--one", str(n), prec, don, "--base",
               str(args.base), "--seconds", str(args.seconds), "--warm", str(args.warm),
               "--trace", str(args.trace)] + (["--trace-dir", str(args.trace_dir)]
                                              if args.trace_dir else [])
        try:
            p = subprocess.run(cmd, env=env, capture_output=True, text=True,
                               timeout=args.timeout)
        except subprocess.TimeoutExpired:
            print(f"N={n} {prec} donate {don}: over {args.timeout:.0f} s, skipped",
                  flush=True)
            continue
        res = [line[7:] for line in p.stdout.splitlines() if line.startswith("RESULT ")]
        if args.trace:
            print("\n".join(line for line in p.stdout.splitlines()
                             if not line.startswith("RESULT ")), flush=True)
        if not res:
            print(f"N={n} {prec} donate {don}: failed\n{p.stderr[-3000:]}", flush=True)
            continue
        r = json.loads(res[0])
        rows.append(r)
        if args.json:
            with open(args.json, "a") as f:
                f.write(json.dumps(r) + "\n")
        print(f"N={n} {prec} donate {don}: {r['rate']:.3g} particle-steps/s "
              f"({r['steps']} steps in {r['wall_s']:.1f} s), "
              f"{r['bytes_per_particle'] / 1e3:.2f} kB/particle", flush=True)
    if not rows:
        return
    print(f"\ndevice {rows[0]['device']}, JAX {rows[0]['jax']}")
    print(f"{'N':>9} {'precision':>9} {'donate':>6} {'p-steps/s':>10} {'steps':>6} {'wall s':>7} "
          f"{'rebuilds':>8} {'kB/part':>8} {'set-up s':>8} {'warm s':>7} {'dT_mean K':>10} "
          f"{'spacing/dg':>10}")
    for r in rows:
        print(f"{r['n']:>9} {r['precision']:>9} {r['donate']:>6} {r['rate']:>10.3g} {r['steps']:>6} "
              f"{r['wall_s']:>7.1f} {r['rebuilds']:>8} {r['bytes_per_particle'] / 1e3:>8.2f} "
              f"{r['setup_s']:>8.0f} {r['warm_s']:>7.0f} {r['dT_mean']:>10.3g} "
              f"{r.get('spacing_over_weight_overlap') or float('nan'):>10.3g}")
    print("spacing/dg: the spacing of the coordinates the contact law reads, at their largest, "
          "over the overlap under a bead's own weight (drumheat.mechanics.precision); from 1 on "
          "the float type cannot resolve a resting contact: such a row times a wrong bed "
          "(docs/performance.md, precision; use mixed)")


if __name__ == "__main__":
    main()
