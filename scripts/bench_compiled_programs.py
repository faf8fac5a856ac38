"""The programs a product run compiles, where in drumheat each is asked for, and the host memory
they keep.

Every program XLA compiles stays in memory for the life of the process (JAX's caches hold the
executable); on XLA:CPU each keeps host memory however small it is (``--probe`` measures
how much on this machine). A ``jnp`` operation outside ``jit`` is such a program
(one per operation, shape and dtype: ``jit(multiply)``, and ``jit(stage)`` for ``jnp.asarray`` of
a numpy array), so set-up code written in eager ``jnp`` costs host memory and compile time that
the run's size does not explain. This script runs a built-in scene through ``drumheat.run`` in a
fresh process with ``jax_log_compiles`` on and prints, per compiled program and the drumheat
function that asked for it (the innermost drumheat frame on the stack), how often it was
compiled and the seconds it took; then the totals, and the anonymous resident memory that
``jax.clear_caches()`` gives back at the end of the run (the programs, their executables and
JAX's caches of them). Programs loaded from the persistent compilation cache are counted too
(they are kept in memory as well); ``--no-cache`` switches that cache off for the run.

Usage: python scripts/bench_compiled_programs.py [SCENE] [--set KEY=VALUE ...]
           [--duration S] [--no-cache] [--probe]
SCENE: a built-in scene (default glass-drum-3d, with ``--set`` knobs as ``drumheat run``).
"""

from __future__ import annotations

import argparse
import collections
import ctypes
import gc
import json
import logging
import os
import re
import subprocess
import sys
import tempfile
import traceback
from pathlib import Path

PACKAGE = str(Path(__file__).resolve().parents[1] / "drumheat")
COMPILED = re.compile(r"Finished XLA compilation of (.+) in ([0-9.eE+-]+) sec")


def rss_anon_mb() -> float:
    """The process's anonymous resident memory (``RssAnon``), MB."""
    for line in open("/proc/self/status"):
        if line.startswith("RssAnon:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def trimmed_anon_mb() -> float:
    """``RssAnon`` after the garbage collector and glibc's ``malloc_trim`` (freed heap pages
    back to the system), MB."""
    gc.collect()
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    return rss_anon_mb()


def asking_site() -> str:
    """The innermost drumheat frame on the stack, as ``module.py:line function``."""
    for f in reversed(traceback.extract_stack()):
        if f.filename.startswith(PACKAGE):
            rel = Path(f.filename).relative_to(PACKAGE)
            return f"{rel}:{f.lineno} {f.name}"
    return "(outside drumheat)"


class CompileLog(logging.Handler):
    """Collects (program, seconds, site) of every ``Finished XLA compilation`` message."""

    def __init__(self):
        super().__init__(logging.DEBUG)
        self.compiles = []

    def emit(self, record):
        m = COMPILED.match(record.getMessage())
        if m:
            self.compiles.append((m.group(1), float(m.group(2)), asking_site()))


def child(scene_name: str, sets: list[str], duration: float | None) -> dict:
    """Run the scene in this process; return the compiles and the memory they keep."""
    import jax

    import drumheat

    scene = drumheat.load_scene(scene_name, list(sets))  # the --set of ``drumheat run``
    if duration is not None:
        scene = scene.with_overrides({"run.duration": duration})
    log = CompileLog()
    logger = logging.getLogger("jax")
    logger.addHandler(log)
    logger.setLevel(logging.DEBUG)
    jax.config.update("jax_log_compiles", True)
    before = trimmed_anon_mb()
    with tempfile.TemporaryDirectory() as out:
        result = drumheat.run(scene, out=Path(out) / "run", progress=False, allow_long=True)
    jax.config.update("jax_log_compiles", False)
    del result
    after = trimmed_anon_mb()
    jax.clear_caches()
    cleared = trimmed_anon_mb()
    return dict(compiles=log.compiles, anon_added=after - before, anon_cleared=after - cleared)


def probe(k: int = 60) -> dict:
    """Host memory kept per compiled program: ``k`` programs of one multiply each."""
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    jax.block_until_ready(jnp.zeros(1) + 1)
    before = trimmed_anon_mb()
    for n in range(1, k + 1):  # a new shape each: a new program
        jax.block_until_ready(jax.jit(lambda a: a * 2.0)(jax.device_put(jnp.zeros(n))))
    kept = trimmed_anon_mb() - before
    jax.clear_caches()
    return dict(k=k, kept_mb=kept, after_clear_mb=trimmed_anon_mb() - before)


def report(d: dict):
    """Print the table of compiled programs by site and the totals."""
    groups = collections.defaultdict(lambda: [0, 0.0])
    for name, sec, site in d["compiles"]:
        g = groups[(site, name)]
        g[0] += 1
        g[1] += sec
    print("| asked for at | program | compiles | seconds |")
    print("|---|---|---|---|")
    for (site, name), (count, sec) in sorted(groups.items(), key=lambda kv: -kv[1][1]):
        print(f"| {site} | {name} | {count} | {sec:.3f} |")
    total = len(d["compiles"])
    seconds = sum(c[1] for c in d["compiles"])
    print(f"\n{total} programs compiled or loaded, {seconds:.2f} s in XLA; anonymous memory "
          f"kept after the run {d['anon_added']:.0f} MB, of which jax.clear_caches() gives "
          f"back {d['anon_cleared']:.0f} MB")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="?", default="glass-drum-3d")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--duration", type=float, default=None, help="run.duration, s")
    ap.add_argument("--no-cache", action="store_true",
                    help="switch the persistent compilation cache off (DRUMHEAT_CACHE_DIR=off)")
    ap.add_argument("--probe", action="store_true",
                    help="measure the host memory one compiled program keeps on this machine")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        out = probe() if args.probe else child(args.scene, args.set, args.duration)
        print(json.dumps(out))
        return
    env = dict(os.environ, MPLBACKEND="Agg")
    if args.no_cache:
        env["DRUMHEAT_CACHE_DIR"] = "off"
    cmd = [sys.executable, __file__, args.scene, "--child"]
    cmd += sum((["--set", s] for s in args.set), [])
    if args.duration is not None:
        cmd += ["--duration", str(args.duration)]
    if args.probe:
        cmd.append("--probe")
    out = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if out.returncode:
        sys.exit(f"the run failed (exit {out.returncode}):\n{out.stderr[-2000:]}")
    d = json.loads(out.stdout.strip().splitlines()[-1])
    if args.probe:
        print(f"{d['k']} programs of one multiply each kept {d['kept_mb']:.1f} MB of anonymous "
              f"memory ({d['kept_mb'] / d['k']:.2f} MB each); after jax.clear_caches() "
              f"{d['after_clear_mb']:.1f} MB")
        return
    print(f"{args.scene} {' '.join(args.set)}: the programs the run compiled (or loaded from the "
          f"persistent cache{', off' if args.no_cache else ''}), by the drumheat function that "
          "asked for them")
    report(d)


if __name__ == "__main__":
    main()
