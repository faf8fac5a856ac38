"""The runner: run a scene with its motion model, collect observables, write result files.

``drumheat.run(scene) -> Result`` is the Python API the command line is a thin layer over.
"""

from __future__ import annotations

import importlib
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from drumheat.analysis import observe
from drumheat.scene import Scene, load_scene
from drumheat.motion.trajectory import Trajectory


def make_motion(scene: Scene):
    """The motion-model object of a scene (``StaticBed``, ...); it builds packing and contacts.

    Every motion model offers
    ``solve(params) -> (T, Q)`` (differentiable) and ``trajectory(params, progress) ->
    Trajectory``.
    """
    module, cls = _MOTION_CLASSES[scene.motion.model].split(":")
    return getattr(importlib.import_module(module), cls)(scene)


#: Motion models and the class implementing each ("module:Class", imported on use).
_MOTION_CLASSES = {
    "static": "drumheat.motion.static:StaticBed",
    "random": "drumheat.motion.random:RandomBed",
    "granulator": "drumheat.motion.granulator:GranulatorParticle",
    "fluidized": "drumheat.motion.fluidized:FluidizedBed",
    "dem": "drumheat.motion.dem:DEMBed",
    "replay": "drumheat.motion.replay:ReplayBed",
    "pneumatic": "drumheat.motion.pneumatic:PneumaticChannel",
    "moving_bed": "drumheat.motion.moving_bed:MovingBed",
}


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
        ``Q_loss`` (J lost to the gas since t = 0) and ``alpha_overall`` (W/(m2 K), eq. [1.10]).
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

    def save(self, out_dir: str | Path | None = None, figures: bool = True) -> Path:
        """Write the result files (see DESIGN.md) to ``out_dir`` (default results/<scene>)."""
        from drumheat.results.files import write_results

        return write_results(self, out_dir, figures=figures)


def energy_balance(traj: Trajectory) -> tuple[np.ndarray, float]:
    """Energy book-keeping: stored-heat change minus heat received, and its relative error.

    Returns ``(residual_J (n_out,), rel_error)`` where ``residual = sum_i m_i c_i (T_i(t) -
    T_i(0)) - sum_accounts Q(t)`` and ``rel_error = max |residual| / scale`` with
    ``scale = sum_i m_i c_i |T_i(0) - T_mean(0)| + max |Q_account|`` (the heat that moved inside
    the bed plus the heat exchanged with the outside). Where the trajectory carries
    ``stored_heat`` (particles with radial shells) the stored-heat change is taken from it.
    """
    if traj.stored_heat is not None:  # particles with shells: from the shell enthalpies
        stored = np.asarray(traj.stored_heat, float)
    else:
        stored = (traj.T - traj.T[0]) @ traj.capacity
    received = sum(traj.Q.values()) if traj.Q else np.zeros_like(stored)
    residual = stored - received
    T0 = traj.T[0]
    scale = float(np.sum(traj.capacity * np.abs(T0 - np.average(T0, weights=traj.capacity))))
    scale += sum(float(np.max(np.abs(q))) for q in traj.Q.values())
    rel = float(np.max(np.abs(residual)) / scale) if scale > 0 else float(np.max(np.abs(residual)))
    return residual, rel


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
    if "wall" in traj.Q and scene.drum is not None and scene.drum.wall_temperature is not None:
        T_cap = traj.T @ traj.capacity / traj.capacity.sum()
        cols["alpha_overall"] = np.asarray(observe.alpha_overall(
            traj.t, T_cap, scene.drum.wall_temperature, T_cap[0], traj.capacity.sum(),
            traj.wall_area))
    if "gas" in traj.Q:
        cols["Q_loss"] = -traj.Q["gas"]
    for account in sorted(set(traj.Q) - {"wall", "gas"}):
        cols[f"Q_{account}"] = traj.Q[account]  # heat received from it since t = 0, J
    for name, values in traj.extra.items():
        cols[name] = values
    return pd.DataFrame(cols)


def run(scene: Scene | str, out: str | Path | None = None, progress: bool | None = True,
        params: dict | None = None, overrides: dict | None = None, devices=None) -> Result:
    """Run a scene and return its :class:`Result`; write result files if ``out`` is given.

    Compiled programs are kept in JAX's persistent compilation cache
    (:mod:`drumheat.runner.compile_cache`; ``DRUMHEAT_CACHE_DIR=off`` leaves it alone), so running
    the same scene again does not compile again.

    Parameters
    ----------
    scene : Scene or str
        A scene, a built-in scene name or a path to a scene file.
    out : path, optional
        Result folder; nothing is written when None (call ``result.save()`` later).
    progress : bool
        Show a progress bar (it appears only for runs longer than ~2 s).
    params : dict, optional
        Values of dotted scene keys overriding the scene's, without re-validation (used by
        calibration; prefer ``overrides`` otherwise).
    overrides : dict, optional
        Dotted-key overrides applied and validated before the run.
    devices : None, "all", int or list of jax.Device, optional
        Split the particle arrays (temperatures, positions, velocities, particle properties)
        over these devices (:func:`drumheat.runner.sharding.shard_particles`; motion models
        ``static`` and ``dem``). The results equal those of one device to round-off; the
        particle count should be a multiple of the device count. Default: one device. This
        splits memory, not time: a DEM step on 2 simulated CPU devices was 2.1x slower at
        N = 10 000 and over 100x slower at N = 2 000 than on one (docs/scaling.md). For
        many variants of a scene use :func:`drumheat.run_ensemble`, which splits the
        variants over the devices instead.
    """
    from drumheat.runner.compile_cache import enable_compilation_cache

    enable_compilation_cache()
    if not isinstance(scene, Scene):
        scene = load_scene(scene, overrides)
    elif overrides:
        scene = scene.with_overrides(overrides)
    if out is not None:
        from drumheat.results.files import check_out_dir

        check_out_dir(out)  # before the run, not after it
    start = time.perf_counter()
    motion = make_motion(scene)
    mesh = None
    if devices is not None:
        from drumheat.runner.sharding import make_mesh, resolve_devices

        devs = resolve_devices(devices)
        if devs is not None and len(devs) > 1:
            if not getattr(motion, "supports_particle_sharding", False):
                raise ValueError(f"motion model {scene.motion.model!r} does not support "
                                 "devices= (particle-axis sharding); supported: static, dem")
            mesh = make_mesh(devs)
    if mesh is not None:
        motion.mesh = mesh
    traj = motion.trajectory(params, progress=progress)
    wall_time = time.perf_counter() - start
    result = make_result(scene, traj, wall_time)
    if out is not None:
        result.save(out)
    return result


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
        "n_particles": int(scene.n_particles),
        "duration_s": float(traj.t[-1] - traj.t[0]),
        "wall_time_s": round(wall_time, 3),
        "energy_balance_rel_error": rel,
        "effects": list(scene.heat.effects()),
        "motion": scene.motion.model,
        "n_contacts": float(np.mean(traj.n_contacts)),
        "n_wall_contacts": float(np.mean(traj.n_wall_contacts)),
    }
    summary.update({k: float(v) for k, v in ts.iloc[-1].items() if k != "t"})
    return Result(scene, traj, ts, summary)
