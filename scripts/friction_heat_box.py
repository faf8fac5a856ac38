"""Figure of the adiabatic box of docs/models/friction-heat.md: particles thrown into a closed
box come to rest; the mechanical energy they lose reappears as heat, to round-off.

    python scripts/friction_heat_box.py --figure docs/img/friction_heat_box.png

36 spheres (d = 2-2.4 mm, 2500 kg/m3) with random velocities (0.3 m/s) and spins in a 2D box
under gravity, damping ratio 0.3, friction 0.5 / 0.4, rolling resistance 0.05, the default time
step. Prints the energy book at the end and draws the mechanical energy (kinetic + rotational +
potential + elastic + the velocity-Verlet boundary term, from its start value), the heat by
source and their sum.
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.geometry import Box
from drumheat.mechanics import contact_params, make_dem, make_particles
from drumheat.mechanics.dissipation import SOURCES, FrictionHeat

jax.config.update("jax_enable_x64", True)


def gather(extra, state, contacts, dt):
    """Sum each step's heat (particles and walls) and its sources."""
    d = contacts.dissipation
    return dict(E=extra["E"] + jnp.sum(d.particle) + d.walls, S=extra["S"] + d.by_source)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=0.3, help="simulated time, s")
    ap.add_argument("--frames", type=int, default=60, help="points of the curves")
    ap.add_argument("--figure", help="write the figure here (png)")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    n_side = 6
    n = n_side**2
    r = 1e-3 * (1.0 + 0.2 * rng.random(n))
    g = np.linspace(0.003, 0.017, n_side)
    x = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    params = contact_params(1e4, damping_ratio=0.3, friction=0.5, wall_friction=0.4,
                            rolling_friction=0.05)
    dem = make_dem(make_particles(r, 2500.0), [Box((0.0, 0.0), (0.02, 0.03))], params, dim=2,
                   extra_update=gather, friction_heat=FrictionHeat())
    state = dem.init(x, velocity=rng.normal(0.0, 0.3, x.shape),
                     angular_velocity=rng.normal(0.0, 50.0, n),
                     extra=dict(E=jnp.zeros(()), S=jnp.zeros(len(SOURCES))))
    steps = int(round(args.duration / dem.dt))
    per = max(1, steps // args.frames)
    e = dem.energies(state)
    e0 = e["total"] + e["boundary"]
    t, lost, heat, src = [0.0], [0.0], [0.0], [np.zeros(len(SOURCES))]
    done = 0
    while done < steps:
        k = min(per, steps - done)
        state = dem.run(state, k)
        done += k
        e = dem.energies(state)
        t.append(done * dem.dt)
        lost.append(e0 - e["total"] - e["boundary"])
        heat.append(float(state.extra["E"]))
        src.append(np.asarray(state.extra["S"]))
    lost, heat, src = np.array(lost), np.array(heat), np.array(src)
    print(f"dt = {dem.dt:.3g} s ({dem.dt / dem.t_crit:.3f} t_crit), {steps} steps")
    print(f"mechanical energy lost {lost[-1]:.6e} J, heat {heat[-1]:.6e} J, relative difference "
          f"{(heat[-1] - lost[-1]) / lost[-1]:.2e}")
    for name, v in zip(SOURCES, src[-1]):
        print(f"  {name:12s} {v:.4e} J ({v / heat[-1]:+.1%})")
    if args.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
        t_ms = 1e3 * np.array(t)
        ax[0].plot(t_ms, 1e6 * lost, lw=2.5, label="mechanical energy lost")
        ax[0].plot(t_ms, 1e6 * heat, "--", lw=1.5, label="heat generated")
        ax[0].set(xlabel="t (ms)", ylabel="energy (uJ)",
                  title=f"adiabatic box: |heat - lost| / lost = "
                        f"{abs(heat[-1] - lost[-1]) / lost[-1]:.0e}")
        ax[0].legend()
        for k, name in enumerate(SOURCES):
            ax[1].plot(t_ms, 1e6 * src[:, k], label=name)
        ax[1].axhline(0.0, color="0.6", lw=0.8)
        ax[1].set(xlabel="t (ms)", ylabel="heat (uJ)", title="by source")
        ax[1].legend()
        fig.tight_layout()
        fig.savefig(args.figure, dpi=120)
        print(f"figure: {args.figure}")


if __name__ == "__main__":
    main()
