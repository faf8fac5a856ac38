"""drumheat vs LIGGGHTS side by side: the 3D rotating-drum slice of shared/peers/liggghts.

Scene (peers/liggghts/README.md): glass spheres d = 8 mm, rho = 2500 kg/m^3, drum D = 0.25 m
turning at 9.55 rpm about z, periodic axis (no end walls) of length L = N Vp / (0.35 0.6 pi R^2)
(35 % nominal fill), gravity -y; LIGGGHTS ``hooke`` with tangential history:
k_n = k_t = 1.001e5 N/m (particle-particle), 1.517e5 N/m (particle-wall), e = 0.5
(gamma = sqrt(4 m* k / (1 + (pi/ln e)^2)), i.e. drumheat's ``restitution_model="linear"``),
mu = 0.5, dt = 1e-5 s, skin 0.5 d = 4 mm; contact conduction on (k = 1 W/m/K, c = 836 J/kg/K,
LIGGGHTS ``heat/gran/conduction`` with the default overlap contact area).

Procedure for each N:

1. Packing (not timed, LIGGGHTS is much the quicker code for this): the peers folder's input
   files are copied to a scratch directory (``--workdir``); ``in.prep`` inserts N particles into
   the rotating drum and lets them fall and settle for 0.8 s, ``in.spinup`` rotates 0.7 s more
   and writes a restart and a data file (N = 50000: the N = 10000 state tiled 5x along z,
   ``replicate_z.py``, + 0.2 s). Existing restarts in the work directory are reused.
2. LIGGGHTS: ``in.bench`` reads the restart, runs ``nwarm`` steps, then ``steps`` timed steps
   (its ``Loop time``), on 1 and 2 MPI ranks.
3. drumheat: the same state read from the data file (positions, velocities, spins; the
   tangential springs start at zero, the warm-up rebuilds them), float32 mechanics, float64
   temperatures updated every step in the same jitted loop by the LIGGGHTS conduction law
   ``q_ij = 4 k_i k_j / (k_i + k_j) sqrt(A_c) (T_j - T_i)`` with the overlap-circle area A_c
   (``make_dem(conduction=PairConduction("overlap", ...))``,
   :mod:`drumheat.mechanics.conduction`; the C++ kernel sums it in its contact loop); ``nwarm``
   steps (compilation included) then ``steps`` timed steps via :meth:`DEM.run` (chunked, with
   the overflow / NaN / escape checks). Twice: with the JAX
   kernel (the default, every backend) and with the C++ contact loop
   (``make_dem(pair_kernel="cpu")``, :mod:`drumheat.mechanics.cpu_kernel`) where it can be built.

With ``--rounds R`` steps 2 and 3 take turns R times: drumheat times the next ``steps`` of
its run, then LIGGGHTS its ``steps`` from the restart on each rank count, and so on. This
machine has stretches of seconds to tens of seconds in which the same code on the same state
runs 1.5x slower or more with no CPU steal reported (docs/performance.md, "Slow stretches"):
one timing of each code, one after the other, lets such a stretch fall on the whole of one
code's timing; with rounds it falls on some rounds of either code, and each code's median
over the rounds, which leaves those rounds out while fewer than half are hit, is compared.

Output: a table N x code x ranks with particle-steps/s and the ratio to drumheat, the machine
load seen before each timing and the CPU steal during it (the share of CPU time a hypervisor
gave to other guests: on a shared virtual machine a timing with much steal is slow for reasons
outside both codes; compare rows with little). drumheat runs on whatever JAX device is
default (CPU here: it uses both cores through XLA's intra-op threads, so its fair LIGGGHTS
partner is the 2-rank run).

By default drumheat is timed through the product path, the built-in scene ``glass-drum-3d``
(the same drum with its own poured packing; k = 1e5 N/m for particles and wall, dt = 0.1
t_crit = 1.6e-5 s, the coupled heat of the scene: contact times every step, a thermal step every
10) with ``dem.contact_backend`` = jax and cpu, its mechanics in float64 (``--precision``
adds float32 rows, speed only: float32 positions resolve this drum coarsely, see
scripts/precision_drum.py; and mixed rows: float64 positions, float32 forces); ``--bespoke``
times the DEM built here from the LIGGGHTS packing as before. The step cost per particle is
what is compared; the step sizes differ (LIGGGHTS 1e-5 s).

Usage: python scripts/bench_vs_liggghts.py [--n 2000 10000 50000] [--steps S] [--quick]
       [--ranks 1 2] [--workdir DIR] [--packings DIR] [--no-liggghts] [--thermal on|off]
       [--precision float64 float32 mixed] [--bespoke] [--rounds R]
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import re
import shutil
import subprocess
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import drumheat  # noqa: F401  (x64 for the temperatures)
from machine import cpu_ticks, load, print_table, steal_percent  # noqa: E402  (scripts/machine.py)
from drumheat.geometry import DrumShell
from drumheat.mechanics import contact_params, cpu_kernel, make_dem, make_particles
from drumheat.mechanics.conduction import PairConduction

PEERS = Path(__file__).resolve().parents[1].parent / "shared" / "peers" / "liggghts"
if not PEERS.exists():  # a checkout elsewhere
    PEERS = Path("/work/shared/peers/liggghts")

R_DRUM, D_P, RHO = 0.125, 0.008, 2500.0
RPM, DT, SKIN = 9.55, 1e-5, 0.004
KN_PP, KN_PW, E_REST, MU = 1.001e5, 1.517e5, 0.5, 0.5
K_COND, C_P, T0 = 1.0, 836.0, 293.0
LENGTH = {2000: 0.052, 10000: 0.26, 50000: 1.30}
# timed / warm-up steps (the peers' choice is 50000/2000, 10000/500, 2000/200)
DEFAULT_STEPS = {2000: (20000, 1000), 10000: (5000, 500), 50000: (1000, 200)}
PREP_TIMEOUT = 300  # s per LIGGGHTS call


def mpirun(np_):
    cmd = ["mpirun"]
    if os.geteuid() == 0:
        cmd.append("--allow-run-as-root")
    return cmd + ["-np", str(np_), "liggghts", "-echo", "none", "-nocite"]


def run_liggghts(args, cwd, log, np_=1, timeout=None):
    timeout = timeout or PREP_TIMEOUT
    cmd = mpirun(np_) + args + ["-log", log]
    with open(Path(cwd) / (log + ".screen"), "w") as scr:
        subprocess.run(cmd, cwd=cwd, stdout=scr, stderr=subprocess.STDOUT, check=True,
                       timeout=timeout)


def prepare(n, work, np_prep):
    """Settled, rotating drum of n particles: restart/drum_N{n}.restart and .data."""
    rst = work / f"restart/drum_N{n}.restart"
    dat = work / f"restart/drum_N{n}.data"
    if rst.exists() and dat.exists():
        return rst, dat
    (work / "restart").mkdir(exist_ok=True)
    (work / "logs").mkdir(exist_ok=True)
    t0 = time.perf_counter()
    if n == 50000:
        prepare(10000, work, np_prep)
        subprocess.run(["python3", "replicate_z.py", "restart/drum_N10000.data",
                        "restart/rep_N50000.data", "5", "1e-6", "12345"], cwd=work, check=True)
        run_liggghts(["-in", "in.fromdata", "-var", "data_in", "restart/rep_N50000.data",
                      "-var", "nrun", "10000", "-var", "out", "restart/tmp_N50000.restart",
                      "-var", "data", "restart/tmp_N50000.data"], work,
                     "logs/fromdata_N50000.log", np_prep)
        src = "restart/tmp_N50000.restart"
        nrun = 10000
    else:
        L = LENGTH.get(n) or n * math.pi / 6 * D_P**3 / (0.35 * 0.6 * math.pi * R_DRUM**2)
        # 0.8 s fill/settle in two calls (each LIGGGHTS call stays below ~5 min at N = 1e4)
        run_liggghts(["-in", "in.prep", "-var", "N", str(n), "-var", "L", f"{L:.6g}",
                      "-var", "nprep", "40000", "-var", "out", f"restart/prep0_N{n}.restart"],
                     work, f"logs/prep0_N{n}.log", np_prep)
        run_liggghts(["-in", "in.spinup", "-var", "in", f"restart/prep0_N{n}.restart",
                      "-var", "nrun", "40000", "-var", "out", f"restart/prep_N{n}.restart",
                      "-var", "data", f"restart/prep_N{n}.data"], work,
                     f"logs/prep_N{n}.log", np_prep)
        src = f"restart/prep_N{n}.restart"
        nrun = 70000
    run_liggghts(["-in", "in.spinup", "-var", "in", src, "-var", "nrun", str(nrun),
                  "-var", "out", str(rst.relative_to(work)), "-var", "data",
                  str(dat.relative_to(work))], work, f"logs/spinup_N{n}.log", np_prep)
    print(f"  prepared N = {n} with LIGGGHTS in {time.perf_counter() - t0:.0f} s", flush=True)
    return rst, dat


def read_data(path):
    """Positions, velocities, spins, radii and z period of a LIGGGHTS write_data file."""
    lines = Path(path).read_text().splitlines()
    zlo, zhi = [float(v) for v in [ln for ln in lines if ln.endswith("zlo zhi")][0].split()[:2]]
    ia = next(k for k, ln in enumerate(lines) if ln.startswith("Atoms"))
    iv = next(k for k, ln in enumerate(lines) if ln.startswith("Velocities"))
    A = np.array([[float(v) for v in ln.split()[:7]] for ln in lines[ia + 2:iv] if ln.strip()])
    V = np.array([[float(v) for v in ln.split()[:7]] for ln in lines[iv + 2:] if ln.strip()])
    A = A[np.argsort(A[:, 0])]
    V = V[np.argsort(V[:, 0])]
    pos = A[:, 4:7].copy()
    pos[:, 2] -= zlo
    return pos, V[:, 1:4], V[:, 4:7], 0.5 * A[:, 2], zhi - zlo


class StepTimer:
    """One drumheat run being timed: ``warm`` steps at construction (compilation, tangential
    history), then every call times the next ``steps`` steps of the same run and returns
    ``(state before, state after, timing dict)``: particle-steps/s, wall s, the machine's load
    before and the CPU steal during it, rebuilds. Successive calls continue the run, so rounds
    interleaved with LIGGGHTS sample one long run of the drum, its phases included."""

    def __init__(self, dem, state, steps, warm):
        self.dem, self.steps = dem, steps
        t0 = time.perf_counter()
        self.state = dem.run(state, warm, chunk=warm)
        jax.block_until_ready(self.state.position)
        self.warm_s = time.perf_counter() - t0

    def __call__(self):
        dem, start = self.dem, self.state
        ld = load()
        c0 = cpu_ticks()
        t0 = time.perf_counter()
        out = dem.run(start, self.steps, chunk=self.steps)
        jax.block_until_ready(out.position)
        wall = time.perf_counter() - t0
        steal = steal_percent(c0, cpu_ticks())
        self.state = out
        return start, out, dict(rate=dem.particles.n * self.steps / wall, wall=wall, load=ld,
                                steal=steal,
                                rebuilds=int(out.n_rebuilds) - int(start.n_rebuilds))


def drumheat_setup(dat, thermal, pair_kernel="jax"):
    pos, vel, omega, radius, L = read_data(dat)
    part = make_particles(radius, RHO)
    params = contact_params(KN_PP, kn_wall=KN_PW, restitution=E_REST, restitution_model="linear",
                            friction=MU, wall_friction=MU)
    # LIGGGHTS heat/gran/conduction: h = 4 k_i k_j / (k_i + k_j) on sqrt(overlap circle area)
    cond = (PairConduction("overlap", 4 * K_COND * K_COND / (2 * K_COND),
                           np.asarray(part.mass) * C_P) if thermal else None)
    dem = make_dem(part, [DrumShell(R_DRUM, rpm=RPM)], params, dim=3, periodic_length=L, dt=DT,
                   skin=SKIN, dtype=jnp.float32, conduction=cond, pair_kernel=pair_kernel)
    T = None
    if thermal:  # a temperature gradient across the bed so that heat actually flows
        T = jnp.asarray(T0 + 50.0 * (pos[:, 0] - pos[:, 0].min()) / np.ptp(pos[:, 0]),
                        jnp.float64)
    state = dem.init(pos, velocity=vel, angular_velocity=omega, extra=T)
    return dem, state


def drumheat_timer(dat, steps, warm, thermal, pair_kernel="jax"):
    """The bespoke DEM of ``drumheat_setup`` warmed up: a :class:`StepTimer` and a function of
    the timed steps' first and last state that says what they did to the heat content
    (conduction only: round-off)."""
    dem, state = drumheat_setup(dat, thermal, pair_kernel)

    def note(start, end):
        if not thermal:
            return ""
        e = float(jnp.sum(end.extra * dem.particles.mass * C_P)
                  - jnp.sum(start.extra * dem.particles.mass * C_P))
        return f"change of the heat content {e:.2e} J (conduction only: round-off)"

    return StepTimer(dem, state, steps, warm), note


def scene_for(n, backend="auto", packing=None, precision="float64"):
    """The built-in scene glass-drum-3d at N particles (its documented knob: depth = N x
    2.6e-5 m), on the given contact backend, with the mechanics in ``precision`` (the scene's
    float64, or float32: ``dem.precision``); ``packing``: a packing file (``packing.method =
    "file"``) instead of the scene's pour."""
    from drumheat.scene import load_scene

    over = {"groups.0.count": n, "drum.depth": n * 2.6e-5, "dem.contact_backend": backend,
            "dem.precision": precision}
    if packing is not None:
        over.update({"packing.method": "file", "packing.file": str(packing)})
    return load_scene("glass-drum-3d", over)


def scene_packing(n, folder):
    """The scene's poured bed at N in ``folder`` (``glass-drum-3d_N.npz``), poured and saved
    there the first time (the pour is not what is timed; pouring 50 000 beads takes a while);
    None without a folder."""
    if folder is None:
        return None
    from drumheat.motion import make_motion

    path = Path(folder) / f"glass-drum-3d_{n}.npz"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        pos = np.asarray(make_motion(scene_for(n, "auto")).packing_positions(), float)
        np.savez(path, position=pos, diameter=np.full(n, D_P), group=np.zeros(n, int))
    return path


def scene_timer(n, steps, warm, backend="auto", packing=None, precision="float64"):
    """drumheat through the product path: the scene's motion model (``make_motion``), its
    poured initial state (or the ``packing`` file) and its DEM with the coupled heat update
    (contact times every step, a thermal step every ``dem.thermal_substeps``), the mechanics in
    ``precision``, warmed up: a :class:`StepTimer`, the backend that ran and a function of the
    timed steps' first and last state giving the row's note."""
    from drumheat.motion import make_motion

    t0 = time.perf_counter()
    motion = make_motion(scene_for(n, backend, packing, precision))
    state = motion.initial_state()  # pours the bed unless given a packing (not timed)
    t_setup = time.perf_counter() - t0
    timer = StepTimer(motion.dem, state, steps, warm)
    backend = motion.contact_backend().backend
    note = (f"scene path, backend {backend}, set-up {t_setup:.0f} s, warm-up "
            f"{timer.warm_s:.0f} s")
    return timer, backend, lambda start, end: note


def time_liggghts(rst, work, n, steps, warm, ranks, thermal):
    log = f"logs/bench_N{n}_np{ranks}_{thermal}.log"
    ld = load()
    c0 = cpu_ticks()
    run_liggghts(["-in", "in.bench", "-var", "in", str(rst.relative_to(work)), "-var", "nwarm",
                  str(warm), "-var", "nsteps", str(steps), "-var", "thermal", thermal], work,
                 log, ranks)
    steal = steal_percent(c0, cpu_ticks())  # over the whole call (read, warm-up, timed)
    txt = (work / log).read_text()
    loops = re.findall(r"^Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+)",
                       txt, re.M)
    t, p, s, na = loops[-1]
    t, s, na = float(t), int(s), int(na)
    if na != n:
        print(f"  warning: LIGGGHTS has {na} atoms (expected {n})")
    return dict(rate=na * s / t, wall=t, load=ld, steal=steal, note="")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[2000, 10000])
    ap.add_argument("--steps", type=int, default=None, help="timed steps (both codes)")
    ap.add_argument("--warm", type=int, default=None, help="warm-up steps (both codes)")
    ap.add_argument("--quick", action="store_true", help="N = 2000 only, 3000 timed steps")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--rounds", type=int, default=1,
                    help="time each code this many times, the codes taking turns (drumheat "
                         "continuing its run, LIGGGHTS from its restart each time), and add "
                         "each code's median: a slow stretch of the machine that the steal "
                         "does not show then falls on some rounds of either code, which the "
                         "medians leave out")
    ap.add_argument("--thermal", default="on", choices=["on", "off"])
    ap.add_argument("--workdir", default="/tmp/drumheat_vs_liggghts")
    ap.add_argument("--prep-ranks", type=int, default=2)
    ap.add_argument("--prep-timeout", type=int, default=PREP_TIMEOUT,
                    help="s per LIGGGHTS preparation call (N = 1e4 needs an idle machine "
                         "to stay below the default 300 s)")
    ap.add_argument("--packings", default=None,
                    help="folder of the scene's poured beds (glass-drum-3d_N.npz), reused across "
                         "runs and poured there when missing; default: pour in every run")
    ap.add_argument("--no-liggghts", action="store_true", help="time drumheat only")
    ap.add_argument("--pair-kernel", nargs="+", default=["jax", "cpu"], choices=["jax", "cpu"],
                    help="drumheat pair kernels to time: the JAX kernel and/or the C++ loop "
                         "(make_dem(pair_kernel='cpu'), where it is available)")
    ap.add_argument("--precision", nargs="+", default=["float64"],
                    choices=["float64", "float32", "mixed"],
                    help="the scene's mechanics (dem.precision; temperatures stay float64): "
                         "float32 resolves positions only coarsely (scripts/precision_drum.py, "
                         "docs/performance.md), so its rows are speed, not a like-for-like "
                         "comparison with LIGGGHTS' double precision; mixed keeps the "
                         "positions in float64, the rest in float32")
    ap.add_argument("--bespoke", action="store_true",
                    help="time drumheat's DEM built here from the LIGGGHTS packing (the "
                         "earlier path) instead of the built-in scene glass-drum-3d")
    args = ap.parse_args()
    sizes = [2000] if args.quick else args.n
    have_lig = shutil.which("liggghts") is not None and shutil.which("mpirun") is not None
    if not have_lig:
        print("LIGGGHTS not installed (apt-get install liggghts): drumheat only, and only with "
              "packings already in the work directory")
    work = Path(args.workdir)
    work.mkdir(parents=True, exist_ok=True)
    for f in PEERS.iterdir():
        if f.is_file() and (f.name.startswith("in.") or f.suffix in (".py", ".sh")):
            shutil.copy(f, work / f.name)
    thermal = args.thermal == "on"
    globals()["PREP_TIMEOUT"] = args.prep_timeout
    mech = ("float32 mechanics, float64 temperatures (bespoke DEM)" if args.bespoke else
            f"the scene's mechanics in {' and '.join(args.precision)}, float64 temperatures")
    print(f"jax {jax.__version__} on {jax.devices()[0].platform}; drumheat {mech}; heat "
          f"conduction {args.thermal}; {os.cpu_count()} CPUs")
    rows = []  # (N, code, ranks, timed steps, round, timing dict)
    for n in sizes:
        steps, warm = DEFAULT_STEPS.get(n, (max(1000, 2 * 10**7 // n), 500))
        if args.quick:
            steps, warm = 3000, 500
        steps = args.steps or steps
        warm = args.warm or warm
        timers = []  # (code, StepTimer, note of a timing)
        if not args.bespoke:  # the product path: the built-in scene, each backend
            packing = scene_packing(n, args.packings)
            for kernel, precision in itertools.product(args.pair_kernel, args.precision):
                timer, backend, note = scene_timer(n, steps, warm, kernel, packing, precision)
                timers.append((f"drumheat scene ({backend}, {precision})", timer, note))
        if have_lig:
            rst, dat = prepare(n, work, args.prep_ranks)
        elif not args.bespoke:
            rst = None
        else:
            rst, dat = None, work / f"restart/drum_N{n}.data"
            if not dat.exists():
                print(f"  no packing for N = {n} in {work}; skipped")
                continue
        for kernel in (args.pair_kernel if args.bespoke else ()):
            if kernel == "cpu" and not cpu_kernel.available()[0]:
                print(f"  C++ contact kernel unavailable: {cpu_kernel.available()[1]}")
                continue
            timer, note = drumheat_timer(dat, steps, warm, thermal, kernel)
            timers.append((f"drumheat ({'JAX' if kernel == 'jax' else 'C++'} kernel)", timer,
                           note))
        for rnd in range(args.rounds):
            tag = f" round {rnd + 1}/{args.rounds}" if args.rounds > 1 else ""
            for code, timer, note in timers:
                start, end, r = timer()
                r["note"] = ", ".join(filter(None, (f"rebuilds {r['rebuilds']}",
                                                    note(start, end))))
                rows.append((n, code, "-", steps, rnd, r))
                say(f"N={n}{tag} {code}", r)
            if rst is not None and not args.no_liggghts:
                for k in args.ranks:
                    r = time_liggghts(rst, work, n, steps, warm, k, args.thermal)
                    rows.append((n, "LIGGGHTS", str(k), steps, rnd, r))
                    say(f"N={n}{tag} LIGGGHTS {k} rank(s)", r)
    print_tables(rows, args.rounds)


def say(what, r):
    """One timing as it is made: its rate, wall time, load, steal and note."""
    print(f"  {what}: {r['rate']:.3g} p-steps/s ({r['wall']:.1f} s, load {r['load']:.2f}, "
          f"steal {r['steal']:.0f} %) {r['note']}", flush=True)


def print_tables(rows, rounds):
    """The timings as Markdown: every timing (with its round where there were several), and
    with several rounds the median of each code's rounds with their range, drumheat's median
    (the first drumheat code of each N) over each code's, and the range of that ratio taken
    within each round."""
    def ref_of(n, rnd):
        return next(x[5]["rate"] for x in rows
                    if x[0] == n and x[4] == rnd and x[1].startswith("drumheat"))

    print()
    print_table(["N", "code", "ranks", "round", "timed steps", "wall s", "particle-steps/s",
                 "rate / drumheat", "load before", "CPU steal %"],
                [(n, code, ranks, rnd + 1, steps, r["wall"], r["rate"],
                  r["rate"] / ref_of(n, rnd), r["load"], r["steal"])
                 for n, code, ranks, steps, rnd, r in rows],
                ["d", "s", "s", "d", "d", ".2f", ".3g", ".2f", ".2f", ".0f"])
    if rounds < 2:
        return
    print()
    print(f"Over the {rounds} rounds (each code's median and range; drumheat / it: drumheat's "
          "median over this code's, and the range of the same ratio within one round):")
    print()
    table = []
    for key in dict.fromkeys(x[:3] for x in rows):
        n = key[0]
        mine = [x for x in rows if x[:3] == key]
        ref = next(x[:3] for x in rows if x[0] == n and x[1].startswith("drumheat"))
        ref_med = np.median([x[5]["rate"] for x in rows if x[:3] == ref])
        rates = np.array([x[5]["rate"] for x in mine])
        per_round = [ref_of(n, x[4]) / x[5]["rate"] for x in mine]
        table.append((*key, np.median(rates), f"{rates.min():.3g} - {rates.max():.3g}",
                      ref_med / np.median(rates), f"{min(per_round):.2f} - {max(per_round):.2f}",
                      max(x[5]["steal"] for x in mine)))
    print_table(["N", "code", "ranks", "median particle-steps/s", "min - max", "drumheat / it",
                 "drumheat / it per round, min - max", "CPU steal % max"], table,
                ["d", "s", "s", ".3g", "s", ".2f", "s", ".0f"])

if __name__ == "__main__":
    main()
