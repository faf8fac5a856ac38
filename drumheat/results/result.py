"""A finished run: :class:`Result` with its time series, energy balance and summary.

``drumheat.run`` hands back a :class:`Result`; ``Result.save`` writes the result files of
DESIGN.md (:mod:`drumheat.results.files`).
"""

from __future__ import annotations

import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import jax
import numpy as np
import pandas as pd

from drumheat._version import __version__
from drumheat.assemble import temperature_bounds
from drumheat.motion.trajectory import Trajectory
from drumheat.results import observe
from drumheat.results.equalisation import equalisation_times
from drumheat.results.files import write_results
from drumheat.scene import Scene

__all__ = ["Result", "make_result", "build_timeseries", "energy_balance", "drum_wall_accounts"]

#: :func:`drumheat.results.observe.alpha_overall` as one compiled program (evaluated eagerly,
#: each of its operations compiles one of its own: drumheat.devices.to_device)
_alpha_overall = jax.jit(observe.alpha_overall)


@dataclass
class Result:
    """A finished run.

    Attributes
    ----------
    scene : Scene
    trajectory : Trajectory
        Particle temperatures (and positions) at the output times.
    timeseries : pandas.DataFrame
        Columns ``t`` (s), ``T_mean`` (K, mass-weighted), ``T_mean:<group>``, ``T_min``,
        ``T_max`` and, as the scene calls for, ``Q_wall`` (J received from walls since t = 0;
        a drum with internals adds ``Q_wall:shell``, ``Q_wall:inner``, ``Q_wall:plates``),
        ``Q_loss`` (J lost to the gas since t = 0) and, for a drum with a wall temperature, eq.
        [1.10] on three conventions: ``alphaA_overall`` (W/K, no area), ``alpha_overall``
        (W/(m2 K), A = d^2 x the running mean of the wall contacts) and, with
        ``heat.wall.reference_contacts``, ``alpha_overall_A9`` (A = that number x d^2).
    summary : dict
        What ``summary.json`` holds.
    """

    scene: Scene
    trajectory: Trajectory
    timeseries: pd.DataFrame
    summary: dict

    @property
    def t(self) -> np.ndarray:
        return self.trajectory.t

    @property
    def T(self) -> np.ndarray:
        return self.trajectory.T

    def particles(self, every: int = 1) -> pd.DataFrame:
        """One row per particle and output time: ``t``, ``particle``, ``group``, ``diameter``,
        ``T``, ``x``, ``y`` (``z``), ``heat_rate`` and, with a DEM, the particles' mechanics
        (see :func:`drumheat.particle_table`)."""
        from drumheat.results.particles import particle_table

        return particle_table(self, every)

    def save(self, out_dir: str | Path | None = None, figures: bool = True,
             figure_formats=("png",), dpi: int = 120) -> Path:
        """Write the result files (see DESIGN.md) to ``out_dir`` (default results/<scene>);
        figures in ``figure_formats`` (png, pdf, svg) at ``dpi``."""
        return write_results(self, out_dir, figures=figures, figure_formats=figure_formats,
                             dpi=dpi)


def energy_balance(traj: Trajectory) -> tuple[np.ndarray, float]:
    """Energy book-keeping: stored-heat change minus heat received, and its relative error.

    Returns ``(residual_J (n_out,), rel_error)`` where ``residual = sum_i m_i c_i (T_i(t) -
    T_i(0)) - sum_accounts Q(t)`` and ``rel_error = max |residual| / scale`` with
    ``scale = sum_i m_i c_i |T_i(0) - T_mean(0)| + max |Q_account|`` (the heat that moved inside
    the bed plus the heat exchanged with the outside). Where the trajectory carries
    ``stored_heat`` (particles with radial shells) the stored-heat change is taken from it.

    With a drum wall of its own heat capacity (``traj.drum_wall``) the balance is that of bed
    and wall together: the wall -> bed heat cancels, and ``residual = stored(bed) +
    stored(wall) - (Q_outside - Q_wall->gas + the bed's other accounts)``; the scale adds the
    largest of the wall's accounts (:func:`drum_wall_accounts`).
    """
    if traj.stored_heat is not None:  # particles with shells: from the shell enthalpies
        stored = np.asarray(traj.stored_heat, float)
    else:
        stored = (traj.T - traj.T[0]) @ traj.capacity
    received = sum(traj.Q.values()) if traj.Q else np.zeros_like(stored)
    T0 = traj.T[0]
    scale = float(np.sum(traj.capacity * np.abs(T0 - np.average(T0, weights=traj.capacity))))
    scale += sum(float(np.max(np.abs(q))) for q in traj.Q.values())
    if traj.drum_wall:  # bed and wall together
        w = drum_wall_accounts(traj)
        stored = stored + w["stored"]
        received = received - w["bed"] + w["outside"] - w["gas"]
        scale += sum(float(np.max(np.abs(w[a]))) for a in ("outside", "gas", "stored"))
    residual = stored - received
    rel = float(np.max(np.abs(residual)) / scale) if scale > 0 else float(np.max(np.abs(residual)))
    return residual, rel


def drum_wall_accounts(traj: Trajectory) -> dict[str, np.ndarray]:
    """The drum wall's heat accounts since t = 0, J, (n_out,) each: ``outside`` (in from
    outside), ``bed`` (wall -> bed: the bed's ``wall`` account), ``gas`` (wall -> free gas) and
    ``stored`` (change of the wall's stored heat, ``sum_k C_k (T_k(t) - T_k(0))``)."""
    w = traj.drum_wall
    stored = (w["T"] - w["T"][0]) @ w["capacity"]
    return {"outside": w["Q_outside"], "bed": traj.Q.get("wall", np.zeros_like(stored)),
            "gas": w["Q_gas"], "stored": stored}


def build_timeseries(scene: Scene, traj: Trajectory) -> pd.DataFrame:
    """The time-series table of a run (columns as in :class:`Result`)."""
    cols = {"t": traj.t, "T_mean": traj.T @ traj.mass / traj.mass.sum()}
    for k, g in enumerate(scene.groups):
        m = traj.group == k
        cols[f"T_mean:{g.name}"] = traj.T[:, m] @ traj.mass[m] / traj.mass[m].sum()
    cols["T_min"], cols["T_max"] = traj.T.min(axis=1), traj.T.max(axis=1)
    if "wall" in traj.Q:
        cols["Q_wall"] = traj.Q["wall"]
    surfaces = sorted(a for a in traj.Q if a.startswith("wall:"))
    if surfaces:  # a drum with internals: the total here, each surface (Q_wall:<surface>) below
        cols["Q_wall"] = sum(traj.Q[a] for a in surfaces)
    if traj.drum_wall:  # a drum wall with heat capacity: its temperatures and accounts
        cols.update(drum_wall_columns(traj))
    elif ("wall" in traj.Q and scene.drum is not None
          and scene.drum.wall_temperature is not None):
        T_cap = traj.T @ traj.capacity / traj.capacity.sum()
        # eq. [1.10] times A: the bed's conductance, free of any area convention
        alpha_A = np.asarray(_alpha_overall(
            traj.t, T_cap, scene.drum.wall_temperature, T_cap[0], traj.capacity.sum(), 1.0))
        with np.errstate(divide="ignore", invalid="ignore"):  # no wall contact yet: inf, as before
            cols["alpha_overall"] = alpha_A / traj.wall_area
        cols["alphaA_overall"] = alpha_A
        n_ref = scene.heat.wall.reference_contacts if scene.heat.wall is not None else None
        if n_ref is not None:  # the thesis' App. A9 area, A = n d^2 with a fixed n
            cols["alpha_overall_A9"] = alpha_A / (n_ref * float(np.mean(traj.diameter**2)))
    if "gas" in traj.Q:
        cols["Q_loss"] = -traj.Q["gas"]
    for account in sorted(set(traj.Q) - {"wall", "gas"}):
        cols[f"Q_{account}"] = traj.Q[account]  # heat received from it since t = 0, J
    for name, values in traj.extra.items():
        cols[name] = values
    return pd.DataFrame(cols)


def drum_wall_columns(traj: Trajectory) -> dict[str, np.ndarray]:
    """Time-series columns of a drum wall with heat capacity: ``T_wall_mean``, ``T_wall_min``,
    ``T_wall_max`` (K, over the segments; the mean weighted by capacity) and its accounts
    since t = 0 (J): ``Q_outside`` (outside -> wall), ``Q_wall_gas`` (wall -> free gas),
    ``Q_wall_stored`` (change of the wall's stored heat); wall -> bed is ``Q_wall``. The
    segment temperatures themselves are in ``wall.npz``. eq. [1.10]'s alpha_overall needs a
    fixed wall temperature and is not written."""
    w = traj.drum_wall
    acc = drum_wall_accounts(traj)
    return {"T_wall_mean": w["T"] @ w["capacity"] / w["capacity"].sum(),
            "T_wall_min": w["T"].min(axis=1), "T_wall_max": w["T"].max(axis=1),
            "Q_outside": acc["outside"], "Q_wall_gas": acc["gas"],
            "Q_wall_stored": acc["stored"]}


def peak_memory_mb() -> float:
    """Peak resident memory of this process so far, MB (the operating system's high-water
    mark: it includes everything the process did before the run)."""
    import resource

    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return round(rss / 1024.0 if sys.platform != "darwin" else rss / 1024.0**2, 1)


def max_principle(scene: Scene, traj: Trajectory) -> dict:
    """Whether every temperature of the run stayed between the lowest and highest temperature
    it can reach (initial, gas, walls, radiating surfaces: the maximum principle of heat
    conduction); ``{"ok", "lowest", "highest", "bounds"}``. A violation means an unstable or
    wrong step, which an energy balance cannot see. With a heat source in the bed
    (``[heat.friction]``) nothing bounds the temperatures from above: the upper bound is then
    None and only the lower one is checked."""
    lo, hi = temperature_bounds(scene)
    tol = 1e-9 * max(abs(lo), abs(hi))
    if scene.heat.friction is not None:
        hi = None
    T = np.asarray(traj.T)
    lowest, highest = float(np.min(T)), float(np.max(T))
    ok = lowest >= lo - tol and (hi is None or highest <= hi + tol)
    return {"ok": bool(ok), "lowest": lowest, "highest": highest, "bounds": [lo, hi]}


def make_result(scene: Scene, traj: Trajectory, wall_time: float) -> Result:
    """A :class:`Result` from a finished trajectory: time series, energy balance, summary.

    Parameters
    ----------
    scene : Scene
    traj : Trajectory
    wall_time : float
        Wall-clock time of the run, s (goes into the summary).

    Raises
    ------
    FloatingPointError
        If a temperature became NaN or Inf.
    """
    ts = build_timeseries(scene, traj)
    _, rel = energy_balance(traj)
    if not np.all(np.isfinite(traj.T)):
        raise FloatingPointError(f"scene {scene.name!r}: temperatures became NaN/Inf; "
                                 "reduce run.dt or use run.solver = 'implicit'")
    summary = {
        "scene": scene.name,
        "complete": True,
        "drumheat": __version__,
        "n_particles": int(scene.n_parcels),
        "duration_s": float(traj.t[-1] - traj.t[0]),
        "wall_time_s": round(wall_time, 3),
        "energy_balance_rel_error": rel,
        "effects": list(scene.heat.effects()),
        "motion": scene.motion.model,
        "n_contacts": float(np.mean(traj.n_contacts)),
        "n_wall_contacts": float(np.mean(traj.n_wall_contacts)),
    }
    if scene.coarse_grain != 1.0:  # the per-particle arrays hold parcels
        summary.update(coarse_grain=scene.coarse_grain, n_real_particles=scene.n_particles)
    summary.update({k: float(v) for k, v in ts.iloc[-1].items() if k != "t"})
    sources = [k for k in scene.heat.SOURCES if getattr(scene.heat, k) is not None]
    if sources:  # heat generated in the bed (time-series columns Q_<source>)
        summary["heat_sources"] = sources
    summary["max_principle"] = max_principle(scene, traj)
    if len(scene.groups) > 1:  # a bed of fractions: when did it equalise, on each criterion
        gas = scene.gas.temperature if "loss" in scene.heat.effects() else None
        summary["equalisation"] = equalisation_times(traj.t, traj.T, traj.group, traj.mass,
                                                     T_gas=gas)
    if not summary["max_principle"]["ok"]:
        warnings.warn(f"scene {scene.name!r}: temperatures left the bounds of the maximum "
                      f"principle ({summary['max_principle']}): the run is not trustworthy (an "
                      "unstable step?), even though its energy balance may close",
                      RuntimeWarning, stacklevel=2)
    summary["peak_memory_MB"] = peak_memory_mb()
    summary.update(traj.info)  # the motion model's further results (phase table, ...)
    return Result(scene, traj, ts, summary)
