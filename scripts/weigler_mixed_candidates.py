"""Mechanical and heat-model candidates for the fast equalisation of the turning mixed bed (issue 16).

Runs the built-in scene ``weigler-mixed`` (70 aluminium spheres, 12 rpm) once per candidate,
each a change of scene keys against the base scene (``drumheat.load_scene(..., overrides=)``,
nothing patched), and prints a table: the candidate, its overrides, the time from which all
particles stay within 1 K of each other (the "spread" criterion of
:mod:`drumheat.results.equalisation`, read at the scene's output times, every 2.5 s), the
spread at 120 s, the time the two fraction means come within 1 K, the time-mean count of
conducting contacts per particle, the simulated duration and the wall time of the run.

The candidates (docs/weigler-moving-bed.md, "Mechanical candidates"):

* the base scene on three packings (``run.seed`` 1, 2, 3): the pour-to-pour spread that every
  other row is to be judged against (the other rows use seed 1, the scene's own);
* in-plane gravity of the thesis' 45-degree tilt, g sin 45 = 6.94 m/s2, and of spheres rolling
  on the tilted back plate, g sin 45 x 5/7 = 4.95 m/s2 (``dem.gravity``);
* rolling resistance 0.05 and 0.2 (``dem.rolling_friction``);
* contact stiffness x 0.1 and x 10 of the scene's value (``dem.stiffness``);
* wall friction 0.3 and 0.9 (``dem.wall_friction``; the scene has 0.6);
* filling order: the geometric deposition lays the groups in scene order, the first group at
  the bottom (``packing.arrangement = 'layers'``, drumheat.mechanics.deposition.deposit_2d), so
  "warm first" swaps the two groups' names and start temperatures (same positions, warm
  spheres at the bottom); "shuffled" is ``packing.arrangement = 'mixed'``;
* coupled DEM and heat for the whole run (``dem.replay_after = none``) instead of the default
  10 s coupled then cyclic replay; the expensive row, so it runs 300 s (the base is within 1 K
  after about 100 s);
* the heat-model side: conduction through overlapping contacts only
  (``heat.contact.gap_tolerance = 0``) instead of the default 1 % of d (the base rows).

Not expressible by scene keys, so not run (printed as skipped): sliding friction of the
monolayer on a back plate turning with the drum, and PFC2D discs (disc mass, inertia and heat
capacity) instead of spheres.

Usage::

    python scripts/weigler_mixed_candidates.py [--duration 600] [--only LABEL ...] [--list]
                                               [--json out.json]

``--list`` prints the candidates and their overrides without running them.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

import drumheat as dh
from drumheat.results.equalisation import equalisation_times

SCENE = "weigler-mixed"
DURATION = 600.0  # s; the base scene is within 1 K after ~100 s
COUPLED_DURATION = 300.0  # s; the fully coupled row, the expensive one
T_SPREAD = 120.0  # s, the spread reported beside the time
G = 9.81

SKIPPED = (
    ("sliding friction on the back plate", "no scene key: the 2D DEM has no back plate "
     "(the earlier study patched internals for it)"),
    ("PFC2D discs", "no scene key: 2D beds are sphere monolayers (mass, inertia and heat "
     "capacity of spheres); the earlier study patched disc properties in"),
)


def candidates(base=None):
    """``[(label, [KEY=VALUE, ...]), ...]`` in the order run, the most informative first.

    ``base`` is the loaded base scene (read for the stiffness and the groups); loaded when
    not given. Every row but the seed rows keeps the scene's seed (1).
    """
    base = dh.load_scene(SCENE) if base is None else base
    k = base.dem.stiffness
    g0, g1 = base.groups
    tilt = G * math.sin(math.radians(45.0))
    return [
        ("base, seed 1", ["run.seed=1"]),
        ("base, seed 2", ["run.seed=2"]),
        ("base, seed 3", ["run.seed=3"]),
        ("45 deg tilt: g sin 45", [f"dem.gravity={tilt:.2f}"]),
        ("rolling on the tilted plate: g sin 45 x 5/7", [f"dem.gravity={tilt * 5 / 7:.2f}"]),
        ("coupled DEM for the whole run", ["dem.replay_after=none",
                                           f"run.duration={COUPLED_DURATION:g}"]),
        ("overlap-only conduction", ["heat.contact.gap_tolerance=0"]),
        ("rolling resistance 0.05", ["dem.rolling_friction=0.05"]),
        ("rolling resistance 0.2", ["dem.rolling_friction=0.2"]),
        ("stiffness x 0.1", [f"dem.stiffness={k * 0.1:g}"]),
        ("stiffness x 10", [f"dem.stiffness={k * 10:g}"]),
        ("wall friction 0.3", ["dem.wall_friction=0.3"]),
        ("wall friction 0.9", ["dem.wall_friction=0.9"]),
        (f"filling: {g1.name} first", [f"groups.0.name={g1.name}",
                                       f"groups.0.temperature={g1.temperature}",
                                       f"groups.1.name={g0.name}",
                                       f"groups.1.temperature={g0.temperature}"]),
        ("filling: shuffled", ["packing.arrangement=mixed"]),
    ]


def load(overrides, duration):
    """The base scene with ``run.duration`` and then the candidate's overrides applied."""
    return dh.load_scene(SCENE, overrides=[f"run.duration={duration:g}", *overrides])


def measure(scene):
    t0 = time.perf_counter()
    res = dh.run(scene, progress=False)
    wall = time.perf_counter() - t0
    traj = res.trajectory
    eq = equalisation_times(traj.t, traj.T, traj.group, traj.mass, threshold=1.0)
    t = np.asarray(traj.t)
    spread = np.asarray(traj.T).max(axis=1) - np.asarray(traj.T).min(axis=1)
    k = int(np.argmin(np.abs(t - T_SPREAD)))
    return dict(spread_time=eq["spread"], fraction_means_time=eq["fraction_means"],
                spread_120=float(spread[k]), t_spread=float(t[k]),
                output_interval=float(np.median(np.diff(t))), duration=float(t[-1]),
                contacts_per_particle=2.0 * float(res.summary["n_contacts"]) / scene.n_particles,
                wall=wall)


def fmt_time(x):
    return "never" if x is None else f"{x:.1f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=DURATION,
                    help="run.duration of every row but the fully coupled one (s)")
    ap.add_argument("--only", nargs="+", default=None,
                    help="run only the rows whose label contains one of these words")
    ap.add_argument("--list", action="store_true", help="print the candidates, run nothing")
    ap.add_argument("--json", type=Path, default=None, help="also write the rows to this file")
    args = ap.parse_args(argv)

    base = dh.load_scene(SCENE)
    rows = candidates(base)
    if args.only:
        rows = [r for r in rows if any(w.lower() in r[0].lower() for w in args.only)]
    print(f"{SCENE}: base run.duration {args.duration:g} s (the coupled row "
          f"{COUPLED_DURATION:g} s), output_interval {base.run.output_interval:g} s, "
          f"stiffness {base.dem.stiffness:g} N/m, gravity {base.dem.gravity:g} m/s2, "
          f"gap tolerance {base.heat.contact.gap_tolerance:g}, replay after "
          f"{base.dem.replay_after} s", flush=True)
    for label, why in SKIPPED:
        print(f"skipped: {label}: {why}", flush=True)
    if args.list:
        for label, ov in rows:
            load(ov, args.duration)  # the overrides are accepted
            print(f"{label}: {' '.join(ov)}")
        return 0

    out, t_all = [], time.perf_counter()
    for label, ov in rows:
        scene = load(ov, args.duration)
        m = measure(scene)
        m.update(label=label, overrides=ov)
        out.append(m)
        print(f"  {label}: spread <= 1 K from {fmt_time(m['spread_time'])} s, spread at "
              f"{m['t_spread']:g} s {m['spread_120']:.2f} K, {m['wall']:.0f} s wall",
              flush=True)
    total = time.perf_counter() - t_all

    print()
    print(f"| candidate | override(s) | spread <= 1 K (s) | spread at {T_SPREAD:g} s (K) | "
          "fraction means within 1 K (s) | conducting contacts per particle | run (s) | "
          "wall time (s) |")
    print("|---" * 8 + "|")
    for m in out:
        print(f"| {m['label']} | `{' '.join(m['overrides'])}` | {fmt_time(m['spread_time'])} | "
              f"{m['spread_120']:.2f} | {fmt_time(m['fraction_means_time'])} | "
              f"{m['contacts_per_particle']:.2f} | {m['duration']:g} | {m['wall']:.0f} |")
    seeds = [m["spread_time"] for m in out if m["label"].startswith("base, seed")]
    if seeds and None not in seeds:
        print(f"\nseed spread (three packings): {min(seeds):g}-{max(seeds):g} s")
    print(f"total wall time: {total:.0f} s")
    if args.json is not None:
        args.json.write_text(json.dumps(dict(rows=out, total_wall_s=total), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
