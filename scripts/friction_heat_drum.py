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

Over a long window that is good to some 1e-5; over a short one two things this route leaves
out are larger (:func:`step_balance` has them): the change of the contacts' elastic energy
(and of the velocity-Verlet boundary term, :func:`drumheat.mechanics.dissipation.boundary_energy`)
and the trapezoid rule's error over the outputs. 300 beads, window 0.3-0.6 s (2026-11-26): the
elastic energy grew by 3.1 uJ (JAX kernel) / 5.3 uJ (C++ loop), 2.2e-4 / 3.9e-4 of the 14 mJ of
heat, and the trapezoid rule at 0.01 s outputs is 1.7e-4 off the per-step sum on either kernel;
at 0.01 s the two happened to cancel on the JAX kernel (9e-6) and not on the C++ loop (-1.7e-4;
at 0.005 s -1.2e-4 and -3.0e-4). :func:`step_balance` (per step, with both terms) closes to
-2.7e-6 and 5.9e-6.

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


def step_balance(scene, window: float) -> dict:
    """The balance of :func:`drum_balance` over ``[window, scene.run.duration]`` of the scene's
    DEM (``drumheat.motion.make_motion``, coupled heat), with the centre of mass, angular
    momentum and mechanical energy at every step instead of at the outputs (the trapezoid rule
    over the steps) and the change of the contacts' elastic energy and of the velocity-Verlet
    boundary term (``DEM.energies``) at the two ends. Returns ``heat`` (J, the contacts' book),
    ``drive`` (``omega M g int x_c dt``), ``transient`` (``omega dL - d(E_kin + E_pot)``),
    ``stored`` (the change of elastic energy and boundary term, J; heat = drive + transient -
    stored), the contact backend and the steps."""
    import jax
    import jax.numpy as jnp

    from drumheat.mechanics.integrator import JIT_OPTIONS
    from drumheat.motion import make_motion

    motion = make_motion(scene)
    dem = motion.dem
    mass = jnp.asarray(dem.particles.mass, jnp.float64)
    inertia = jnp.asarray(dem.particles.inertia, jnp.float64)
    M, g = float(jnp.sum(mass)), float(scene.dem.gravity)
    omega = scene.drum.rpm * 2.0 * np.pi / 60.0
    n0 = int(round(window / dem.dt))
    n1 = int(round(scene.run.duration / dem.dt))

    def observe(s):  # t, x_c, L, E_kin + E_pot, heat booked and gathered so far
        pos, vel, w = (jnp.asarray(a, jnp.float64)
                       for a in (s.position, s.velocity, s.angular_velocity))
        fr = s.extra.friction
        return jnp.stack([
            s.time, pos[:, 0] @ mass / M,
            (pos[:, 0] * vel[:, 1] - pos[:, 1] * vel[:, 0]) @ mass + w[:, 2] @ inertia,
            0.5 * jnp.sum(vel**2, 1) @ mass + 0.5 * jnp.sum(w**2, 1) @ inertia
            + g * (pos[:, 1] @ mass),
            s.extra.Q["friction"] + jnp.sum(fr.E) + fr.walls + fr.E_walls])

    def steps(s, n):
        def body(s, _):
            s = dem.step_fn(s)[0]
            return s, observe(s)
        return jax.lax.scan(body, s, None, length=n)

    steps = jax.jit(steps, static_argnums=1, compiler_options=JIT_OPTIONS)
    state = dem.run(motion.initial_state(), n0)
    e0, rows = dem.energies(state), [np.asarray(observe(state))[None]]
    chunk = int(round(scene.run.output_interval / dem.dt))
    done, retries = n0, 0
    while done < n1:  # in chunks, each checked for a neighbour-list overflow and redone
        n = min(chunk, n1 - done)
        new, obs = steps(state, n)
        if bool(new.nbrs.did_buffer_overflow):
            retries += 1
            if retries > 8:
                raise RuntimeError("the neighbour list keeps overflowing")
            state = dem.reallocate(state, 2 * state.nbrs.idx.shape[1], 2)
            continue
        state, done = new, done + n
        rows.append(np.asarray(obs))
    e1 = dem.energies(state)
    t, x_c, L, E, H = np.concatenate(rows).T
    stored = float(e1["elastic"] + e1["boundary"] - e0["elastic"] - e0["boundary"])
    return dict(heat=H[-1] - H[0], drive=omega * M * g * np.trapezoid(x_c, t),
                transient=omega * (L[-1] - L[0]) - (E[-1] - E[0]), stored=stored,
                backend=motion.contact_backend().backend, steps=len(t) - 1)


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
