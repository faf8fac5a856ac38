"""A ``jax.profiler`` trace of one call, summed by track and event name (benchmark scripts'
helper: where the time of a compiled loop goes, on the CPU or on a GPU)."""

from __future__ import annotations

import glob
import gzip
import json
import time
from collections import defaultdict
from pathlib import Path

import jax


def trace_totals(fn, args, out_dir):
    """``(wall seconds, totals, trace file)`` of one call of ``fn(*args)`` under the profiler.

    ``fn`` is called once before, so that compilation stays out of the trace. ``totals`` maps
    ``(track, event name)`` to ``[microseconds, count]``, summed over the complete events
    ("X") of the Perfetto trace; ``track`` is the trace's process name (``/host:CPU``,
    ``/device:GPU:0 ...`` and the like), so device kernels and host work stay apart.
    """
    out = Path(out_dir)
    jax.block_until_ready(fn(*args))
    with jax.profiler.trace(str(out), create_perfetto_trace=True):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        wall = time.perf_counter() - t0
    path = max(glob.glob(str(out / "**" / "perfetto_trace.json.gz"), recursive=True),
               key=lambda p: Path(p).stat().st_mtime)
    data = json.load(gzip.open(path))
    events = data["traceEvents"] if isinstance(data, dict) else data
    tracks = {e["pid"]: e.get("args", {}).get("name", "") for e in events
              if e.get("ph") == "M" and e.get("name") == "process_name"}
    totals = defaultdict(lambda: [0.0, 0])
    for e in events:
        if e.get("ph") == "X" and "dur" in e:
            t = totals[(tracks.get(e.get("pid"), str(e.get("pid"))), e["name"])]
            t[0] += e["dur"]
            t[1] += 1
    return wall, dict(totals), Path(path)


def print_split(totals, per: int, top: int = 20, track_filter=None) -> None:
    """The largest ``top`` entries of ``totals`` (from :func:`trace_totals`) per track, in us
    and events per ``per`` (steps), with each track's sum first."""
    by_track = defaultdict(list)
    for (track, name), (us, count) in totals.items():
        if track_filter is None or track_filter(track):
            by_track[track].append((us / per, count / per, name))
    for track, rows in sorted(by_track.items()):
        rows.sort(reverse=True)
        print(f"[{track}] sum {sum(r[0] for r in rows):.1f} us, "
              f"{sum(r[1] for r in rows):.1f} events per step")
        for us, count, name in rows[:top]:
            print(f"  {us:9.1f} us {count:7.2f} x  {name[:110]}")
