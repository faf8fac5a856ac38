"""Ensemble throughput: vmapped ``drumheat.run_ensemble`` against ``drumheat.run`` one by one.

Prints a Markdown table, one row per (scene, variant count):

* one by one: the variants run with ``drumheat.run`` in a loop, after one warm-up run of the
  same scene (so the single-run program is already compiled where JAX can reuse it; the DEM
  builds its step per run and compiles it every time, as a user's loop would);
* vmapped, first call: ``run_ensemble`` as a user sees it the first time, compilation of the
  batched program included (the batch size is part of the program);
* vmapped, repeat: the same ensemble again (compiled program reused).

Usage::

    python scripts/bench_ensemble.py                       # static sweep + DEM seeds
    python scripts/bench_ensemble.py --static 1 4 16 --dem 2 --dem-duration 0.01
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

import drumheat as dh
from drumheat.scene import load_scene, scene_from_dict


def static_variants(n: int, duration: float):
    alphas = np.linspace(60.0, 150.0, n) if n > 1 else [105.0]
    return load_scene("weigler-static", {"run.duration": duration}), [
        {"heat.contact.alpha": float(a)} for a in alphas]


def dem_variants(n: int, duration: float):
    raw = load_scene("weigler-static").to_dict()
    raw["name"] = "dem-bench"
    raw["groups"][0]["count"] = raw["groups"][1]["count"] = 15
    raw["run"].update(duration=duration, output_interval=duration / 2, solver="explicit")
    raw["drum"]["rpm"] = 12.0
    raw["motion"] = {"model": "dem"}
    raw["dem"] = {"stiffness": 2.0e4, "thermal_substeps": 10}
    return scene_from_dict(raw), [{"run.seed": k + 1} for k in range(n)]


def one_by_one(scene, variants) -> float:
    dh.run(scene.with_overrides(variants[0]), progress=False)  # warm-up
    start = time.perf_counter()
    for v in variants:
        dh.run(scene.with_overrides(v), progress=False)
    return time.perf_counter() - start


def bench(kind: str, scene, variants) -> dict:
    seq = one_by_one(scene, variants)
    first = dh.run_ensemble(scene, variants, progress=False)
    repeat = dh.run_ensemble(scene, variants, progress=False)
    return dict(kind=kind, n=len(variants), N=scene.n_particles, seq=seq,
                first=first.wall_time_s, repeat=repeat.wall_time_s, vmapped=first.vmapped)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--static", type=int, nargs="*", default=[1, 4, 16, 64],
                   help="variant counts of the static sweep (heat.contact.alpha)")
    p.add_argument("--static-duration", type=float, default=1800.0, help="s")
    p.add_argument("--dem", type=int, nargs="*", default=[2, 4],
                   help="variant counts of the DEM seed ensemble")
    p.add_argument("--dem-duration", type=float, default=0.02, help="s")
    args = p.parse_args(argv)
    import jax

    print(f"machine: {platform.machine()}, {os.cpu_count()} CPU cores, "
          f"JAX {jax.__version__} on {jax.devices()[0].platform} "
          f"({len(jax.devices())} device(s)); load average "
          f"{', '.join(f'{x:.1f}' for x in os.getloadavg())}")
    rows = []
    for n in args.static:
        rows.append(bench(f"static weigler-static, {args.static_duration:g} s, alpha sweep",
                          *static_variants(n, args.static_duration)))
        print(rows[-1], flush=True)
    for n in args.dem:
        rows.append(bench(f"dem 30 spheres 12 rpm, {args.dem_duration:g} s, seeds",
                          *dem_variants(n, args.dem_duration)))
        print(rows[-1], flush=True)
    print()
    print("| ensemble | variants | one by one (s) | vmapped, first call (s) | speed-up | "
          "vmapped, repeat (s) | speed-up |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['kind']} | {r['n']} | {r['seq']:.2f} | {r['first']:.2f} | "
              f"{r['seq'] / r['first']:.2f}x | {r['repeat']:.2f} | "
              f"{r['seq'] / r['repeat']:.2f}x |")
    print(f"\nload average at the end: {', '.join(f'{x:.1f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
