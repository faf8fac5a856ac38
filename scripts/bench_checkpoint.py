"""What checkpoints cost: wall time with and without, and their size per particle.

For each scene, two runs in fresh processes into a result folder (``drumheat run SCENE --out
DIR``): without checkpoints (``run.checkpoint_every = 0``) and with one every
``--interval`` seconds of simulated time (``run.checkpoint_interval``). Reported: the runs'
own wall times (``summary.json``), the number of checkpoints written, the overhead per
checkpoint, and the largest ``checkpoint.npz`` seen while the run went (the folder is polled;
a completed run deletes its checkpoint), per particle.

Usage: python scripts/bench_checkpoint.py [--scene weigler-mixed:60:2.5 glass-drum-3d:2:0.25]
       (SCENE:DURATION:INTERVAL, seconds of simulated time)
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from machine import cpu_ticks, print_table, steal_percent  # scripts/machine.py


def run(scene, duration, out, extra) -> tuple[dict, int, float]:
    cmd = [sys.executable, "-m", "drumheat", "run", scene, "--quiet", "--yes", "--out", str(out),
           "--set", f"run.duration={duration}"] + [a for k in extra for a in ("--set", k)]
    c0 = cpu_ticks()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    biggest = 0
    ck = out / "checkpoint.npz"
    while p.poll() is None:
        try:
            biggest = max(biggest, ck.stat().st_size)
        except FileNotFoundError:
            pass
        time.sleep(0.02)
    if p.returncode != 0:
        raise SystemExit(f"{scene}: {p.stderr.read()[-2000:]}")
    return json.loads((out / "summary.json").read_text()), biggest, steal_percent(c0, cpu_ticks())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", nargs="+", default=["weigler-mixed:60:2.5",
                                                    "glass-drum-3d:2:0.25"])
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for spec in args.scene:
            scene, duration, interval = spec.split(":")
            duration, interval = float(duration), float(interval)
            common = [f"run.output_interval={min(interval, duration)}"]
            s0, _, st0 = run(scene, duration, Path(tmp) / f"{scene}-off",
                        common + ["run.checkpoint_every=0"])
            s1, size, st1 = run(scene, duration, Path(tmp) / f"{scene}-on",
                           common + ["run.checkpoint_every=0",
                                     f"run.checkpoint_interval={interval}"])
            n_ck = int(round(duration / interval))
            n = s0["n_particles"]
            over = s1["wall_time_s"] - s0["wall_time_s"]
            rows.append((scene, n, duration, n_ck, s0["wall_time_s"], s1["wall_time_s"],
                         1e3 * over / n_ck, size / 1e3, size / n, max(st0, st1)))
            print(f"{scene}: without {s0['wall_time_s']:.1f} s, with {n_ck} checkpoints "
                  f"{s1['wall_time_s']:.1f} s, largest {size / 1e3:.0f} kB", flush=True)
    print()
    print_table(["scene", "N", "simulated (s)", "checkpoints", "without (s)", "with (s)",
                 "per checkpoint (ms)", "largest (kB)", "per particle (B)", "steal %"], rows,
                ["", "d", "g", "d", ".1f", ".1f", ".0f", ".0f", ".0f", ".1f"])


if __name__ == "__main__":
    main()
