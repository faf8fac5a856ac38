"""Cold and warm start of ``drumheat run SCENE`` from a fresh process (issue 9 target: under
20 s for weigler-static including JAX compilation).

* cold: an empty persistent compilation cache (``DRUMHEAT_CACHE_DIR`` pointed at a new empty
  folder), so every kernel is compiled;
* warm: the same cache folder again, filled by the cold run, as a user's second run.

Each run is a new Python process running the ``drumheat`` command; the table gives the whole
process time (interpreter start, imports, scene, packing, compilation or cache load, the
simulation, result files and figures) and the ``wall_time_s`` the run itself reports in
``summary.json``, plus the machine's load average when it started (this machine has 2 cores;
compare only rows taken at low load).

Usage: python scripts/bench_startup.py [--scene weigler-static] [--repeat 2]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def one_run(scene: str, cache: Path, out: Path) -> dict:
    env = dict(os.environ, DRUMHEAT_CACHE_DIR=str(cache))
    cmd = [sys.executable, "-m", "drumheat.cli", "run", scene, "--out", str(out)]
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    total = time.perf_counter() - t0
    summary = json.loads((out / "summary.json").read_text())
    shutil.rmtree(out)
    return dict(process_s=total, run_s=float(summary["wall_time_s"]), load=load)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="weigler-static")
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    print(f"| scene | start | process (s) | run, summary.json (s) | load avg |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.repeat):
            cache = Path(tmp) / f"cache{k}"
            cache.mkdir()
            for kind in ("cold", "warm"):
                r = one_run(args.scene, cache, Path(tmp) / "out")
                print(f"| {args.scene} | {kind} | {r['process_s']:.1f} | {r['run_s']:.1f} | "
                      f"{r['load']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
