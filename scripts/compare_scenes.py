"""Run every built-in scene briefly and compare the time series of two code versions.

A refactoring must leave every scene's results unchanged to round-off. Run this script on the
old code and on the new one, then compare::

    python scripts/compare_scenes.py run /tmp/before          # on the old commit
    python scripts/compare_scenes.py run /tmp/after           # on the new one
    python scripts/compare_scenes.py diff /tmp/before /tmp/after

``run`` writes ``<scene>.csv`` (the time series) and ``<scene>.npz`` (particle temperatures)
per scene (a scene that fails leaves ``<scene>.failed`` with its error, and ``run`` exits
with 1); ``diff`` prints, per scene, the largest absolute difference of every time-series
column and of the particle temperatures, and the largest relative one, lists the scenes that
failed on either side, and exits with 1 on a difference or a failure. The overrides below
shorten each scene to a few output intervals while keeping its code path (DEM scenes keep
their recording and replay, the glass drums switch from coupled DEM to replay). With
``--folder`` each scene runs into a result folder (a temporary one), as ``drumheat run`` does:
on the CPU its DEM chunks then advance in place with their start on disk
(``drumheat.runner.spill``), which must give the same numbers.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

#: per-scene overrides that keep each scene's code path but make it short
SHORT = {
    "fluidized-bed-coffee": {"run.duration": 20.0},
    "glass-drum-3d": {"run.duration": 0.3, "run.output_interval": 0.1, "dem.replay_after": 0.2,
                      "dem.replay_cycle": 0.1},
    "herz-sectional-drum": {"run.duration": 0.5, "run.output_interval": 0.25,
                            "groups.0.count": 800},
    "kraychev-channel": {"run.duration": 0.1, "run.output_interval": 0.05,
                         "channel.steady_after": 0.05},
    "kraychev-tube-bundle": {"run.duration": 0.5, "run.output_interval": 0.25,
                             "hopper.settle_time": 0.2},
    "staltner-slag-particle": {},
    "weigler-cooling": {},
    "weigler-heating": {},
    "weigler-static": {},
    "weigler-glass-wall": {"run.duration": 600.0},
    "weigler-glass-random": {"run.duration": 600.0},
    "weigler-glass-drum-47.75": {"run.duration": 30.0, "dem.replay_after": 20.0,
                                 "dem.replay_cycle": 10.0},
    "weigler-glass-drum-9.55": {"run.duration": 30.0, "dem.replay_after": 20.0,
                                "dem.replay_cycle": 10.0},
    "weigler-glass-mixing-47.75": {"run.duration": 2.0},
    "weigler-glass-mixing-9.55": {"run.duration": 2.0},
    "weigler-mixed": {"run.duration": 6.0, "run.output_interval": 2.0},
}


def run_all(out: Path, only: list[str] | None, folder: bool = False) -> list[str]:
    """Run the scenes' short variants into ``out`` (``NAME.csv``, ``NAME.npz``); a scene that
    fails leaves ``NAME.failed`` with its error instead, which :func:`diff` reports. Returns
    the names of the failed scenes."""
    import drumheat as dh

    out.mkdir(parents=True, exist_ok=True)
    names = only or sorted(dh.builtin_scenes())
    failed = []
    for name in names:
        ov = SHORT.get(name)
        if ov is None:
            print(f"{name}: no short variant declared; skipped", flush=True)
            continue
        start = time.perf_counter()
        try:
            with tempfile.TemporaryDirectory() as tmp:  # the result may read its folder
                res = dh.run(dh.load_scene(name, ov), progress=False,
                             out=Path(tmp) / name if folder else None)
                res.timeseries.to_csv(out / f"{name}.csv", index=False, float_format="%.17g")
                np.savez(out / f"{name}.npz", t=res.t, T=res.T)
        except Exception as err:  # noqa: BLE001 - report and go on with the next scene
            print(f"{name}: FAILED {type(err).__name__}: {err}", flush=True)
            (out / f"{name}.failed").write_text(f"{type(err).__name__}: {err}\n")
            failed.append(name)
            continue
        (out / f"{name}.failed").unlink(missing_ok=True)
        print(f"{name}: {len(res.t)} outputs, {time.perf_counter() - start:.1f} s", flush=True)
    return failed


def diff(a: Path, b: Path) -> int:
    """Print each scene's largest difference between the runs in ``a`` and ``b``; a scene
    that failed in either (``NAME.failed``) is listed as failed. Returns 0 where every scene
    of both agrees to 1e-9 and none failed, else 1."""
    worst = 0.0
    rows = []
    failed: dict[str, list[tuple[Path, str]]] = {}  # scene -> (folder, error) where it failed
    for d in (a, b):
        for f in sorted(d.glob("*.failed")):
            failed.setdefault(f.stem, []).append((d, f.read_text().strip()))
    for name, where in sorted(failed.items()):
        rows.append((name, f"FAILED in {' and '.join(str(d) for d, _ in where)}", "",
                     f" ({where[0][1][:120]})"))
    for fa in sorted(a.glob("*.csv")):
        fb = b / fa.name
        name = fa.stem
        if name in failed:
            continue
        if not fb.exists():
            rows.append((name, "missing in " + str(b), "", ""))
            continue
        ta, tb = pd.read_csv(fa), pd.read_csv(fb)
        cols = [c for c in ta.columns if c in tb.columns]
        missing = sorted(set(ta.columns) ^ set(tb.columns))
        if len(ta) != len(tb):
            rows.append((name, f"rows {len(ta)} vs {len(tb)}", "", ""))
            continue
        d_abs, d_rel, which = 0.0, 0.0, ""
        for c in cols:
            x, y = ta[c].to_numpy(float), tb[c].to_numpy(float)
            both_nan = np.isnan(x) & np.isnan(y)
            dx = np.where(both_nan, 0.0, np.abs(x - y))
            if np.any(np.isnan(dx)):
                d_abs, which = np.inf, c
                break
            m = float(np.max(dx)) if len(dx) else 0.0
            scale = np.maximum(np.abs(x), 1e-300)
            r = float(np.max(np.where(both_nan, 0.0, dx / scale))) if len(dx) else 0.0
            if r > d_rel:
                d_rel, d_abs, which = r, m, c
        Ta, Tb = np.load(a / f"{name}.npz")["T"], np.load(b / f"{name}.npz")["T"]
        dT = float(np.max(np.abs(Ta - Tb))) if Ta.shape == Tb.shape else np.inf
        worst = max(worst, d_rel, dT / 300.0)
        note = f" (columns only in one: {missing})" if missing else ""
        rows.append((name, f"{d_rel:.2e} ({which}: {d_abs:.3g})", f"{dT:.3g} K", note))
    width = max(len(r[0]) for r in rows) if rows else 10
    print(f"{'scene':<{width}}  largest relative difference (column: absolute)  max |dT| of "
          "particles")
    for r in rows:
        print(f"{r[0]:<{width}}  {r[1]:<45}  {r[2]}{r[3]}")
    return 0 if worst < 1e-9 and not failed else 1


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("out", type=Path)
    r.add_argument("--only", nargs="*")
    r.add_argument("--folder", action="store_true",
                   help="run each scene into a (temporary) result folder, as drumheat run does")
    d = sub.add_parser("diff")
    d.add_argument("a", type=Path)
    d.add_argument("b", type=Path)
    args = p.parse_args(argv)
    if args.cmd == "run":
        return 1 if run_all(args.out, args.only, args.folder) else 0
    return diff(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
