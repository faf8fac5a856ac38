"""Peak memory of a whole product run, phase by phase: glass-drum-3d through ``drumheat.run``.

``bench_memory.py`` measures the DEM chunk alone; a user's run holds more: the set-up, the
contact recording of ``dem.record_interval`` (it grows with the recorded time), the switch to the
cyclic replay at ``dem.replay_after`` (the restart assignment), the replay (the recorded
networks on the device: the whole cycle where it fits in ``REPLAY_BLOCK_BYTES``, else a block
of intervals at a time) and the result files. For each N this runs the built-in scene
``glass-drum-3d`` (its knob: depth = N x 2.6e-5 m) from a packing file, shortened to
``--duration`` with the replay after ``--replay-after`` (cycle: half of it), in a fresh process,
with a thread that attributes the resident memory's high-water mark (``VmHWM``, reset through
``/proc/self/clear_refs`` at each change of phase; sampled every 50 ms) to the phase the run is
in, told by the function on the main thread's stack, and the anonymous resident memory
(``RssAnon``: without the pages of mapped files, which count in ``VmHWM`` while they are
mapped but which the system can drop) sampled alike; "other" is what no phase names, the run
loop itself (above all the output rows it fetches from the device). JAX dispatches
asynchronously, so a phase's peak may hold work that the phase before it dispatched: the run's
first output row waits on the initial state's forces. Printed: each phase's peak above the
resident memory before the run, and the slope between successive N (kB per particle), which
leaves out what does not grow with N (compiled code, the compiler's own peak). (The resets
also lower the process's ``ru_maxrss``, so the run's own ``summary.json`` ``peak_memory_MB`` is
not a measure here.)

The runs keep the process's allocator as a user's run has it: :func:`drumheat.run` fixes
glibc's mmap threshold at 1 MiB (:mod:`drumheat.runner.host_memory`), so that freed large
buffers go back to the system, and gives the heap's freed pages back after each compilation.
``--malloc-threshold BYTES`` sets ``MALLOC_MMAP_THRESHOLD_`` instead (earlier versions of this
script set 1 MiB for every run, which measured code that kept glibc's dynamic threshold as if
it did not).

A run compiles the programs that JAX's persistent compilation cache does not hold, and the
compiler's peak then lies in the phase that compiles: ``DRUMHEAT_CACHE_DIR=EMPTY_FOLDER``
measures a user's first run of the scene, a second run with the same folder the runs after
it.

With ``--record-interval`` (the scene's is 0.05 s) a short run records as many intervals as a
long one (``--record-interval 0.002 --duration 0.5 --replay-after 0.4``: 200 intervals, as the
built-in drum's 250 by its switch), so that the recording's share of the peak shows. A run
writes into a result folder (as ``drumheat run`` does), where it keeps its recording in files
(``.log/``); ``--no-folder`` runs without one (``drumheat.run(scene)`` in a notebook), which
keeps it in memory.

``--precision`` sets the scene's ``dem.precision`` (float64 by default; mixed and float32 keep
the mechanics' arrays in float32).

Usage: python scripts/bench_run_memory.py --n 10000 50000 [--packings DIR]
       [--duration 0.3] [--replay-after 0.2] [--record-interval S] [--no-folder]
       [--precision float64|mixed|float32] [--malloc-threshold BYTES]
The packings are ``bench_vs_liggghts.py``'s (poured there the first time).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_memory import proc_status  # noqa: E402

#: (function on the main thread's stack, phase), innermost match wins
PHASES = (("write_results", "result files"), ("complete", "result files"),
          ("_switch_to_replay", "switch to replay"), ("between", "recording"),
          ("finish", "trajectory"), ("make_result", "trajectory"),
          ("replay", "replay"), ("advance_checked", "steps"), ("estimate", "estimate"),
          ("make_motion", "set-up"), ("initial_state", "set-up"))


def phase_of(frame) -> str:
    names = []
    while frame is not None:
        names.append(frame.f_code.co_name)
        frame = frame.f_back
    for name in names:  # innermost first
        for fn, phase in PHASES:
            if name == fn:
                return phase
    return "other"


def measure(n: int, duration: float, replay_after: float, packings, record_interval=None,
            folder: bool = True, precision: str = "float64") -> dict:
    """Run the scene in this process and return the peaks per phase (MB) and the summary's."""
    from bench_vs_liggghts import scene_for, scene_packing

    import drumheat

    packing = scene_packing(n, packings)
    over = {"run.duration": duration, "run.output_interval": replay_after / 2,
            "dem.replay_after": replay_after, "dem.replay_cycle": replay_after / 2}
    if record_interval is not None:
        over["dem.record_interval"] = record_interval
    scene = scene_for(n, "auto", packing, precision).with_overrides(over)
    main = threading.main_thread()
    peaks, anon, current, done = {}, {}, ["start"], threading.Event()

    def close(phase):
        peaks[phase] = max(peaks.get(phase, 0.0), proc_status("VmHWM"))
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")

    def watch():
        while not done.is_set():
            ph = phase_of(sys._current_frames().get(main.ident))
            if ph != current[0]:
                close(current[0])
                current[0] = ph
            anon[ph] = max(anon.get(ph, 0.0), proc_status("RssAnon"))
            time.sleep(0.05)

    base, base_anon = proc_status("VmRSS"), proc_status("RssAnon")
    t = threading.Thread(target=watch, daemon=True)
    t.start()
    with tempfile.TemporaryDirectory() as out:
        drumheat.run(scene, out=Path(out) / "run" if folder else None, progress=False,
                     allow_long=True)
        done.set()
        t.join()
        close(current[0])
    return dict(n=n, base_mb=base, peaks=peaks, anon=anon,
                base_anon_mb=base_anon)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[10000, 50000])
    ap.add_argument("--duration", type=float, default=0.3)
    ap.add_argument("--replay-after", type=float, default=0.2)
    ap.add_argument("--packings", default=None,
                    help="folder of the scene's poured beds (glass-drum-3d_N.npz)")
    ap.add_argument("--record-interval", type=float, default=None,
                    help="dem.record_interval, s (default: the scene's)")
    ap.add_argument("--no-folder", action="store_true",
                    help="run without a result folder (the recording stays in memory)")
    ap.add_argument("--precision", default="float64", choices=["float64", "mixed", "float32"],
                    help="the scene's dem.precision")
    ap.add_argument("--malloc-threshold", type=int, default=None,
                    help="glibc's MALLOC_MMAP_THRESHOLD_ for the runs, bytes (default: as a "
                         "user's run has it: drumheat.run fixes it at 1 MiB itself; code "
                         "before that kept glibc's dynamic threshold)")
    ap.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        print(json.dumps(measure(args.child, args.duration, args.replay_after, args.packings,
                                 args.record_interval, not args.no_folder, args.precision)))
        return
    rec = (f"recording every {args.record_interval:g} s" if args.record_interval
           else "the scene's recording interval")
    print(f"glass-drum-3d, {args.precision} mechanics, {args.duration:g} s simulated, replay "
          f"after {args.replay_after:g} s, "
          f"{rec}, {'no result folder' if args.no_folder else 'into a result folder'}: the "
          "resident memory's peak in each phase above the resident memory before the run "
          "(imports), MB; last rows: the slope between successive N, kB per particle")
    header()
    rows, anon_rows = [], []
    for n in args.n:
        env = dict(os.environ)
        if args.malloc_threshold:
            env["MALLOC_MMAP_THRESHOLD_"] = str(args.malloc_threshold)
        cmd = [sys.executable, __file__, "--child", str(n), "--duration", str(args.duration),
               "--replay-after", str(args.replay_after), "--precision", args.precision]
        if args.packings:
            cmd += ["--packings", args.packings]
        if args.record_interval:
            cmd += ["--record-interval", str(args.record_interval)]
        if args.no_folder:
            cmd.append("--no-folder")
        out = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if out.returncode:
            print(f"| {n} | failed (exit {out.returncode}): {out.stderr.strip()[-300:]} |")
            continue
        d = json.loads(out.stdout.strip().splitlines()[-1])
        added = [d["peaks"].get(p, float("nan")) - d["base_mb"] for p in ORDER]
        added.append(max(d["peaks"].values()) - d["base_mb"])
        rows.append((n, added))
        anon_rows.append((n, [d["anon"].get(p, float("nan")) - d["base_anon_mb"] for p in ORDER]
                          + [max(d["anon"].values()) - d["base_anon_mb"]], d["base_anon_mb"]))
        row(n, added, d["base_mb"])
    slopes(rows)
    print("\nThe anonymous resident memory (RssAnon: what the process allocated, without the "
          "pages of mapped files, which the system can drop), sampled every 50 ms, the same "
          "columns:")
    header()
    for n, added, base in anon_rows:
        row(n, added, base)
    slopes([r[:2] for r in anon_rows])


#: the phases in the tables' order
ORDER = ["set-up", "estimate", "steps", "recording", "switch to replay", "replay", "trajectory",
         "result files", "other"]


def header():
    """Print a table's header: the phases, the whole run, the memory before the run."""
    print("| N | " + " | ".join(ORDER) + " | whole run | before the run (MB) |")
    print("|---|" + "---|" * (len(ORDER) + 2))


def row(n, added, base):
    """Print one N's row: the peak of each phase and of the whole run above ``base``, MB."""
    print(f"| {n} | " + " | ".join(f"{a:.0f}" for a in added) + f" | {base:.0f} |", flush=True)


def slopes(rows):
    """Print the slope rows (kB per particle) between successive N of a table."""
    for (n0, a0), (n1, a1) in zip(rows, rows[1:]):
        print(f"| {n0} -> {n1} (kB per particle) | " + " | ".join(
            f"{(y - x) * 1024 / (n1 - n0):.2f}" for x, y in zip(a0, a1)) + " | |")


if __name__ == "__main__":
    main()
