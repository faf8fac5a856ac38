"""Checks of the drum wall with heat capacity ([heat.drum_wall], docs/models/drum-wall.md).

1. The analytic limit: a thin wall heated by a hot gas around a lumped bed (the weigler-static
   packing without contact conduction, all particles at one temperature: the particles that
   touch the wall follow one ODE) against the closed-form two-capacity solution
   (:func:`drumheat.models.drum_wall.two_capacity_solution`).
2. The energy balance of a re-mixed bed (weigler-glass-random) in a turning drum heated by a
   prescribed flux, with losses of wall and particles to the gas.

Prints a table (deviation, energy residual, wall time) and writes the figures
``docs/img/drum_wall_analytic.png`` and ``docs/img/drum_wall_segments.png``::

    PYTHONPATH=. python scripts/drum_wall_check.py
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import drumheat as dh  # noqa: E402
from drumheat.materials import material  # noqa: E402
from drumheat.models.drum_wall import two_capacity_solution  # noqa: E402
from drumheat.results.plot import plot_drum_wall  # noqa: E402
from drumheat.scene import load_scene  # noqa: E402

IMG = Path(__file__).resolve().parents[1] / "docs" / "img"
WALL = {"thickness": 0.001, "outside": "gas", "outer_temperature": 400.0, "outer_alpha": 20.0,
        "segments": 1, "inner_alpha": 5.0}


def analytic_case():
    """The lumped limit: drumheat against the closed form; returns a table row."""
    s = load_scene("weigler-static").without("heat.contact", "heat.loss")
    s = s.replace({"groups.1.temperature": 299.15, "drum.wall_temperature": 300.0,
                   "heat.wall": {"model": "constant", "alpha": 300.0}, "heat.drum_wall": WALL,
                   "run.duration": 600.0, "run.output_interval": 5.0, "run.rtol": 1e-10,
                   "run.atol": 1e-9})
    start = time.perf_counter()
    res = dh.run(s, progress=False)
    wall_time = time.perf_counter() - start
    traj = res.trajectory
    touching = np.abs(traj.T[-1] - traj.T[0]) > 1e-9
    n_w = int(touching.sum())
    d, R = 0.004, 0.025
    A = 2 * math.pi * R * d
    steel = material("steel")
    s_w = WALL["thickness"]
    U = A / (1 / WALL["outer_alpha"] + s_w / steel.conductivity)
    G = n_w * 300.0 * math.pi / 4 * d**2
    H = WALL["inner_alpha"] * (A - min(A, n_w * d**2))
    C_w = s_w * steel.density * steel.heat_capacity * A
    C_b = float(traj.capacity[touching].sum())
    Tw, Tb = two_capacity_solution(traj.t, C_w, C_b, U, G, T_o=400.0, H=H, T_g=310.65,
                                   T_w0=300.0, T_b0=299.15)
    Tw_sim, Tb_sim = traj.drum_wall["T"][:, 0], traj.T[:, touching][:, 0]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.plot(traj.t, Tw, "C3-", lw=3, alpha=0.4, label="wall, closed form")
    ax.plot(traj.t, Tb, "C0-", lw=3, alpha=0.4, label="bed, closed form")
    ax.plot(traj.t[::4], Tw_sim[::4], "C3o", ms=3, label="wall, drumheat")
    ax.plot(traj.t[::4], Tb_sim[::4], "C0o", ms=3, label="bed (touching particles), drumheat")
    ax.set_xlabel("time / s")
    ax.set_ylabel("temperature / K")
    ax.set_title(f"thin wall, lumped bed: C_w = {C_w:.3g} J/K, C_b = {C_b:.3g} J/K,\n"
                 f"U = {U:.3g}, G = {G:.3g}, H = {H:.3g} W/K", fontsize="medium")
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(IMG / "drum_wall_analytic.png", dpi=110)
    plt.close(fig)
    return {"case": "lumped limit (static, 1 segment, hot gas)",
            "max |T_wall - closed form| / K": float(np.max(np.abs(Tw_sim - Tw))),
            "max |T_bed - closed form| / K": float(np.max(np.abs(Tb_sim - Tb))),
            "energy_balance_rel_error": res.summary["energy_balance_rel_error"],
            "wall time / s": round(wall_time, 2)}


def balance_case():
    """A re-mixed bed in a turning drum heated by a flux: the energy balance; a table row."""
    s = load_scene("weigler-glass-random")
    s = s.replace({"run.duration": 400.0, "drum.rpm": 3.0, "gas": {"temperature": 293.0},
                   "heat.loss": {"alphaA": 1e-4},
                   "heat.drum_wall": {"thickness": 0.003, "outside": "flux",
                                      "outer_flux": 2000.0, "segments": 36,
                                      "inner_alpha": 8.0}})
    start = time.perf_counter()
    res = dh.run(s, progress=False)
    wall_time = time.perf_counter() - start
    fig = plot_drum_wall(res)
    fig.savefig(IMG / "drum_wall_segments.png", dpi=110)
    plt.close(fig)
    ts = res.timeseries.iloc[-1]
    return {"case": "balance (random, 36 segments, flux, losses)",
            "Q_outside / J": float(ts["Q_outside"]), "Q_wall (to bed) / J": float(ts["Q_wall"]),
            "Q_wall_gas / J": float(ts["Q_wall_gas"]),
            "Q_wall_stored / J": float(ts["Q_wall_stored"]),
            "Q_loss (particles) / J": float(ts["Q_loss"]),
            "energy_balance_rel_error": res.summary["energy_balance_rel_error"],
            "wall time / s": round(wall_time, 2)}


def main() -> None:
    """Run both checks, print their rows, write the figures."""
    IMG.mkdir(parents=True, exist_ok=True)
    for row in (analytic_case(), balance_case()):
        print(row.pop("case"))
        for k, v in row.items():
            print(f"  {k:34s} {v:.6g}")


if __name__ == "__main__":
    main()
