"""Friction heat in a turning drum against the drum's drive power.

    python scripts/friction_heat_drum.py --duration 4 --window 2

The turning shell is the only wall of the slice; it puts in the power ``omega tau`` with tau
its torque on the bed about the axis (z, counter-clockwise positive like omega). The bed's
angular momentum about the axis, L, changes by that torque plus gravity's, ``-M g x_c`` (x_c the
horizontal position of the bed's centre of mass), so ``tau = dL/dt + M g x_c`` and over a
window [t1, t2]

    heat generated = omega (int M g x_c dt + L(t2) - L(t1)) - (E_kin + E_pot)(t2) + (...)(t1)

(the contacts' elastic energy, micro-joules, is left out). In steady rotation only the first
term is left: the drive power ``omega M g <x_c>`` is all dissipated. The left side is the
contacts' energy book (``Q_friction + Q_friction_walls``), the right side comes from the
particles' positions, velocities and spins at the outputs (trapezoid rule in time): two
independent parts of the run.

The scene is the built-in ``glass-drum-3d`` (2000 glass beads of 8 mm, 9.55 rpm, a periodic
slice without end plates: the shell is the only wall), coupled DEM over the whole run with
``[heat.friction]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import drumheat as dh
from drumheat.scene import load_scene


def drum_balance(scene, res, window: float) -> dict:
    """The two sides of the balance (module docstring) over ``t >= window`` of a finished run:
    ``heat`` (J, the contacts' book), ``drive`` (``omega M g int x_c dt``, J), ``transient``
    (``omega dL - d(E_kin + E_pot)``, J), the window's span (s) and the mean ``x_c`` (m)."""
    ts, traj = res.timeseries, res.trajectory
    t = ts["t"].to_numpy()
    heat = ts["Q_friction"].to_numpy() + ts["Q_friction_walls"].to_numpy()
    m = traj.mass
    M = m.sum()
    g = scene.dem.gravity
    omega = scene.drum.rpm * 2.0 * np.pi / 60.0  # signed, counter-clockwise positive
    pos = traj.position.astype(float)
    vel = traj.mechanics["velocity"].astype(float)
    spin = traj.mechanics["angular_velocity"].astype(float)
    inertia = 0.4 * m * (0.5 * traj.diameter) ** 2
    x_c = pos[:, :, 0] @ m / M
    L = (pos[:, :, 0] * vel[:, :, 1] - pos[:, :, 1] * vel[:, :, 0]) @ m + spin[:, :, 2] @ inertia
    E = (0.5 * np.sum(vel**2, axis=2) @ m + 0.5 * np.sum(spin**2, axis=2) @ inertia
         + g * (pos[:, :, 1] @ m))
    win = t >= window - 1e-9
    tw = t[win]
    return dict(heat=heat[win][-1] - heat[win][0],
                drive=omega * M * g * np.trapezoid(x_c[win], tw),  # gravity's torque: -M g x_c
                transient=omega * (L[win][-1] - L[win][0]) - (E[win][-1] - E[win][0]),
                span=tw[-1] - tw[0], t0=tw[0], t1=tw[-1], x_c=float(np.mean(x_c[win])),
                mass=M, omega=omega)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=4.0, help="simulated time, s")
    ap.add_argument("--window", type=float, default=2.0,
                    help="start of the steady window, s (the bed starts from rest)")
    ap.add_argument("--output-interval", type=float, default=0.05,
                    help="s; the balance integrates x_c over the outputs (trapezoid rule)")
    args = ap.parse_args(argv)
    scene = load_scene("glass-drum-3d", overrides=[
        "heat.friction.partition=conductivity", "dem.replay_after=none",
        "dem.record_interval=none", f"run.duration={args.duration}",
        f"run.output_interval={args.output_interval}"])
    t0 = time.time()
    res = dh.run(scene, progress=True)
    wall = time.time() - t0
    b = drum_balance(scene, res, args.window)
    got, drive, transient, span = b["heat"], b["drive"], b["transient"], b["span"]
    print(f"glass-drum-3d, {res.trajectory.T.shape[1]} beads of {b['mass']:.4f} kg, omega = "
          f"{b['omega']:.4f} rad/s, {args.duration:g} s simulated in {wall:.0f} s")
    print(f"window {b['t0']:g}-{b['t1']:g} s: heat generated {got:.5f} J ({got / span:.4f} W)")
    print(f"  drive omega M g int(x_c) dt    {drive:.5f} J ({drive / span:.4f} W, "
          f"<x_c> = {1e3 * b['x_c']:.2f} mm)")
    print(f"  + omega dL - d(E_kin + E_pot) {transient:+.5f} J")
    print(f"  = {drive + transient:.5f} J; heat / that = {got / (drive + transient):.4f}")
    ts = res.timeseries
    t = ts["t"].to_numpy()
    win = t >= args.window - 1e-9
    sources = {k: ts[f"dissipated:{k}"].to_numpy() for k in
               ("damping", "sliding", "rolling", "integration")}
    for k, v in sources.items():
        print(f"  {k:12s} {(v[win][-1] - v[win][0]) / span:+.4f} W")


if __name__ == "__main__":
    main()
