"""Wall time of the built-in 2D turning-drum scenes on each contact backend.

For each scene and ``dem.contact_backend`` (jax: the JAX kernel, every scene's path before the
C++ backend was reachable from scenes; cpu: the C++ contact loop, what ``auto`` now takes on a
CPU), ``drumheat run SCENE --set run.duration=D --set dem.contact_backend=B`` runs in a fresh
process, one after the other (the whole scene as built in, or ``--duration`` seconds of it); reported are the run's own wall time (``summary.json``: set-up,
compilation and the run, not the Python start), the whole process, and the CPU steal during it.

Usage: python scripts/bench_2d_scenes.py [--scenes weigler-mixed weigler-glass-drum-9.55]
       [--duration SECONDS] [--backends jax cpu]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from machine import cpu_ticks, load, print_table, steal_percent  # scripts/machine.py


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["weigler-mixed", "weigler-glass-drum-9.55"])
    ap.add_argument("--duration", type=float, help="simulated seconds (default: the scene's)")
    ap.add_argument("--backends", nargs="+", default=["jax", "cpu"])
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for scene in args.scenes:
            for backend in args.backends:
                out = Path(tmp) / f"{scene}-{backend}"
                cmd = [sys.executable, "-m", "drumheat", "run", scene, "--quiet", "--yes",
                       "--out", str(out), "--set", f"dem.contact_backend={backend}"]
                if args.duration:
                    cmd += ["--set", f"run.duration={args.duration}", "--set",
                            f"run.output_interval={args.duration / 4}"]
                ld = load()
                c0, t0 = cpu_ticks(), time.perf_counter()
                p = subprocess.run(cmd, capture_output=True, text=True)
                wall = time.perf_counter() - t0
                steal = steal_percent(c0, cpu_ticks())
                if p.returncode != 0:
                    print(f"{scene} {backend}: failed\n{p.stderr[-2000:]}")
                    continue
                s = json.loads((out / "summary.json").read_text())
                rows.append((scene, backend, s.get("contact_backend", "?"), s["n_particles"],
                             s["wall_time_s"], wall, ld, steal))
                print(f"{scene} {backend}: run {s['wall_time_s']:.1f} s, process {wall:.1f} s",
                      flush=True)
    print("\n" + (f"{args.duration:g} s simulated per run" if args.duration
                   else "each scene as built in") + "\n")
    print_table(["scene", "backend asked", "ran", "N", "run (s)", "process (s)", "load",
                 "steal %"], rows, ["", "", "", "d", ".1f", ".1f", ".1f", ".1f"])


if __name__ == "__main__":
    main()
