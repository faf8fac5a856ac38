"""XLA's working memory of the built-in drum's DEM chunk, and where its temporaries peak.

For each N the built-in scene ``glass-drum-3d`` (its knob: depth = N x 2.6e-5 m; the
benchmark's poured bed from ``--packings``, as ``bench_vs_liggghts.py`` makes it) is built
through the product path (``make_motion``), and the chunk the run loop runs
(``motion.dem._run_steps``; with ``--in-place`` the chunk that runs in the state's own buffers,
``motion.dem._run_chunk``, which a run into a result folder runs on the CPU) is compiled, not
run. Printed per N, in bytes per particle, XLA's own account of it (``memory_analysis()``): the
arguments (the state), the outputs (the new state), the part of them that shares the
arguments' buffers (aliased) and the temporaries, which is what a GPU allocates for a run and
what the CPU's resident memory holds at the chunk's peak besides the compiler.

With ``--peak`` each N is compiled in a child process that dumps XLA's buffer assignment and
live ranges (``XLA_FLAGS=--xla_dump_to``), and the script reads them against each other: the
instruction at which the temporaries' live bytes are highest, and the values live there (the
largest first). That tells which part of the step sets the peak (docs/performance.md, memory).

Usage: python scripts/bench_xla_memory.py --n 20000 50000 [--precision float64|mixed|float32]
       [--backend auto|cpu|jax] [--packings DIR] [--in-place] [--peak] [--top 12]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path


def analyse(n: int, precision: str, backend: str, packings, in_place: bool = False) -> dict:
    """XLA's memory account of the scene's compiled chunk at N (``in_place``: the donated
    one), bytes per particle."""
    import jax.numpy as jnp

    from bench_vs_liggghts import scene_for, scene_packing
    from drumheat.motion import make_motion

    motion = make_motion(scene_for(n, backend, scene_packing(n, packings), precision))
    state = motion.initial_state()
    chunk = motion.dem._run_chunk if in_place else motion.dem._run_steps
    ma = chunk.lower(state, jnp.asarray(100, jnp.int32)).compile()
    ma = ma.memory_analysis()
    return dict(backend=motion.contact_backend().backend,
                slots=int(state.nbrs.idx.shape[1]),
                arguments=ma.argument_size_in_bytes / n, outputs=ma.output_size_in_bytes / n,
                temporaries=ma.temp_size_in_bytes / n, aliased=ma.alias_size_in_bytes / n)


def peak_values(dump: Path, top: int) -> dict:
    """The temporaries' high-water mark in an XLA dump of ``jit_run_steps``: the instruction
    and the values live there (name, bytes, shape), from the buffer assignment's temporary
    allocation (each value's offset and size) and the live ranges (each value's first and last
    instruction); values that share bytes (in-place updates) count once."""
    stem = sorted(dump.glob("*jit_run_steps.cpu_after_optimizations-live-range.txt"),
                  key=lambda p: p.stat().st_mtime)[-1].name.replace(
                      ".cpu_after_optimizations-live-range.txt", "")
    assignment = (dump / f"{stem}.cpu_after_optimizations-buffer-assignment.txt").read_text()
    live = (dump / f"{stem}.cpu_after_optimizations-live-range.txt").read_text()
    block = re.search(r"allocation \d+: size (\d+), preallocated-temp:\n((?: value:.*\n)+)",
                      assignment)
    values = []
    for line in block.group(2).splitlines():
        m = re.match(r" value: <\d+ (\S+) @0> \(size=(\d+),offset=(\d+)\): (\S+)", line)
        if m and int(m.group(2)) > 0:
            values.append((m.group(1), int(m.group(2)), int(m.group(3)), m.group(4)))
    ranges = {}
    for m in re.finditer(r"^\s+(\S+?)(?:\{\})?:(\d+)-(\d+)$", live, re.M):
        ranges.setdefault(m.group(1), (int(m.group(2)), int(m.group(3))))
    order = dict(re.findall(r"^\s+(\d+):(\S+)$", live, re.M))
    span = [(name, size, off, shape, ranges[name]) for name, size, off, shape in values
            if name in ranges]

    def occupied(t):
        cuts = sorted((off, off + size) for _, size, off, _, (a, b) in span if a <= t <= b)
        total, end = 0, -1
        for lo, hi in cuts:
            total += max(0, hi - max(lo, end))
            end = max(end, hi)
        return total

    last = max(b for *_, (a, b) in span)
    t = max(range(last + 1), key=occupied)
    alive = sorted(((size, name, shape) for name, size, _, shape, (a, b) in span
                    if a <= t <= b), reverse=True)
    return dict(allocation=int(block.group(1)), peak=occupied(t), at=order.get(str(t), "?"),
                values=alive[:top])


def child(args) -> dict:
    out = analyse(args.child, args.precision, args.backend, args.packings, args.in_place)
    if args.dump:
        out.update(peak_values(Path(args.dump), args.top))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[20000, 50000])
    ap.add_argument("--precision", default="float64", choices=["float64", "mixed", "float32"])
    ap.add_argument("--backend", default="auto", choices=["auto", "cpu", "jax"])
    ap.add_argument("--packings", default=None,
                    help="folder of the scene's poured beds (glass-drum-3d_N.npz), poured there "
                         "when missing; default: pour in every run")
    ap.add_argument("--in-place", action="store_true",
                    help="the chunk that runs in the state's buffers (a run into a result "
                         "folder on the CPU) instead of the one that keeps its start")
    ap.add_argument("--peak", action="store_true",
                    help="also the instruction and the values at the temporaries' peak")
    ap.add_argument("--top", type=int, default=12, help="values listed at the peak")
    ap.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--dump", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        print(json.dumps(child(args)))
        return
    which = "in place (donated)" if args.in_place else "keeping its start"
    print(f"glass-drum-3d, {args.precision} mechanics: XLA's account of the compiled chunk, "
          f"{which} (bytes per particle; total: arguments + outputs - aliased + temporaries)")
    print("| N | backend | pair slots | arguments | outputs | aliased | temporaries | total |")
    print("|---|---|---|---|---|---|---|---|")
    peaks = []
    for n in args.n:
        with tempfile.TemporaryDirectory() as dump:
            env = dict(os.environ)
            cmd = [sys.executable, __file__, "--child", str(n), "--precision", args.precision,
                   "--backend", args.backend, "--top", str(args.top)]
            if args.in_place:
                cmd.append("--in-place")
            if args.packings:
                cmd += ["--packings", args.packings]
            if args.peak:
                env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + f" --xla_dump_to={dump}").strip()
                cmd += ["--dump", dump]
            out = subprocess.run(cmd, capture_output=True, text=True, env=env)
            if out.returncode != 0:
                print(f"| {n} | failed (exit {out.returncode}): {out.stderr.strip()[-300:]} |")
                continue
            r = json.loads(out.stdout.strip().splitlines()[-1])
        total = r["arguments"] + r["outputs"] - r["aliased"] + r["temporaries"]
        print(f"| {n} | {r['backend']} | {r['slots']} | {r['arguments']:.0f} | "
              f"{r['outputs']:.0f} | {r['aliased']:.0f} | {r['temporaries']:.0f} | "
              f"{total:.0f} |", flush=True)
        if args.peak:
            peaks.append((n, r))
    for n, r in peaks:
        print(f"\nN = {n}: the temporaries peak at {r['at']}, {r['peak'] / n:.0f} B per particle "
              f"live (allocation {r['allocation'] / n:.0f}); the values live there (one "
              "updated in place shares its bytes with its input, and both are listed):")
        for size, name, shape in r["values"]:
            print(f"  {size / n:7.1f} B/particle  {shape:28s} {name}")


if __name__ == "__main__":
    main()
