"""The run loop: one loop for every motion model, ``drumheat.run(scene) -> Result``.

:func:`simulate` drives a motion model (:class:`~drumheat.motion.base.AbstractMotion`) through
its chunks: a pure ``advance`` per chunk, a host-side check that may redo the chunk (e.g. with
larger neighbour buffers), an observation at every output time and the host-side work between
chunks (contact recording, phase switches); then the motion model turns the observations into
a :class:`~drumheat.motion.trajectory.Trajectory`. :func:`run` wraps it: scene in, checked
output folder, :class:`~drumheat.results.result.Result` out. :func:`trace` is the same loop
without host-side work, for differentiating a run (:mod:`drumheat.analysis.calibrate`).
``drumheat.run_ensemble`` (:mod:`drumheat.runner.ensemble`) is this loop over ``vmap``.
"""

from __future__ import annotations

import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.motion import AbstractMotion, make_motion
from drumheat.motion.trajectory import Trajectory
from drumheat.results.files import check_out_dir
from drumheat.results.result import Result, make_result
from drumheat.runner.compile_cache import enable_compilation_cache
from drumheat.runner.progress import SimProgress
from drumheat.runner.sharding import make_mesh, resolve_devices, shard_particles
from drumheat.scene import Scene, load_scene

__all__ = ["run", "simulate", "trace", "advance_checked", "MAX_REDO"]

#: how often a chunk may be redone (each time with larger buffers) before a run stops
MAX_REDO = 9


def advance_checked(motion: AbstractMotion, state, t0: float, t1: float):
    """One chunk of a run: ``motion.advance``, redone from the start state that
    ``motion.check`` hands back (at most :data:`MAX_REDO` times)."""
    start = state
    for attempt in range(MAX_REDO):
        end = motion.advance(start, t0, t1)
        redo = motion.check(start, end, attempt)
        if redo is None:
            return end
        start = redo
    raise RuntimeError(f"the chunk from t = {t0:g} s to {t1:g} s had to be redone "
                       f"{MAX_REDO} times (neighbour buffers kept overflowing); the packing "
                       "may be exploding: reduce the time step or check the inputs")


def output_flags(motion: AbstractMotion) -> np.ndarray:
    """Which chunk ends of ``motion.times`` are output times (bool, one per chunk end)."""
    flags = np.zeros(len(motion.times), bool)
    flags[motion.output_index if motion.output_index is not None else slice(None)] = True
    return flags


def simulate(motion: AbstractMotion, params: dict | None = None,
             progress: bool | None = True, mesh=None, return_state: bool = False):
    """Run a motion model through all its chunks; the :class:`Trajectory` it makes of it.

    Parameters
    ----------
    motion : AbstractMotion
    params : dict, optional
        Dotted scene keys with values replacing the scene's (e.g. in a fit).
    progress : bool
        Show a progress bar over simulated time (for runs longer than ~2 s).
    mesh : jax.sharding.Mesh, optional
        Split the state's per-particle arrays over this device mesh.
    return_state : bool
        Return ``(trajectory, final state)`` instead of the trajectory alone.
    """
    state = motion.initial_state(params)
    if mesh is not None:
        state = shard_particles(state, mesh, motion.scene.n_particles)
    log = motion.start_log(state, params)
    is_output = output_flags(motion)
    rows = [jax.device_get(motion.observe(state))]
    times = motion.times
    with SimProgress(float(times[-1] - times[0]), progress) as bar:
        for i, (t0, t1) in enumerate(zip(times[:-1], times[1:])):
            state = advance_checked(motion, state, float(t0), float(t1))
            if is_output[i + 1]:
                rows.append(jax.device_get(motion.observe(state)))
            state, log = motion.between(state, log, float(t1))
            bar.update_to(float(t1 - times[0]))
    traj = motion.finish(rows, log, state)
    return (traj, state) if return_state else traj


def trace(motion: AbstractMotion, params: dict | None = None) -> tuple:
    """The temperatures ``(n_out, N)`` and heat accounts ``{account: (n_out,)}`` of a run as
    device arrays, differentiable with respect to ``params`` (the motion model must be
    ``differentiable``; no host-side checks or work between chunks)."""
    if not motion.differentiable:
        raise ValueError(f"motion model {motion.name!r} cannot be differentiated (its run has "
                         "host-side control flow)")
    state = motion.initial_state(params)
    is_output = output_flags(motion)
    rows = [motion.observe(state)]
    times = motion.times
    for i, (t0, t1) in enumerate(zip(times[:-1], times[1:])):
        state = motion.advance(state, float(t0), float(t1))
        if is_output[i + 1]:
            rows.append(motion.observe(state))
    T = jnp.stack([r["T"] for r in rows])
    Q = {a: jnp.stack([r["Q"][a] for r in rows]) for a in rows[0]["Q"]}
    return T, Q


def run(scene: Scene | str, out: str | Path | None = None, progress: bool | None = True,
        params: dict | None = None, overrides: dict | None = None, devices=None) -> Result:
    """Run a scene and return its :class:`Result`; write result files if ``out`` is given.

    Compiled programs are kept in JAX's persistent compilation cache
    (:mod:`drumheat.runner.compile_cache`; ``DRUMHEAT_CACHE_DIR=off`` leaves it alone), so
    running the same scene again does not compile again.

    Parameters
    ----------
    scene : Scene or str
        A scene, a built-in scene name or a path to a scene file.
    out : path, optional
        Result folder; checked before the run (:func:`drumheat.results.files.check_out_dir`);
        nothing is written when None (call ``result.save()`` later).
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
    enable_compilation_cache()
    if not isinstance(scene, Scene):
        scene = load_scene(scene, overrides)
    elif overrides:
        scene = scene.replace(overrides)
    if out is not None:
        check_out_dir(out)  # before the run, not after it
    start = time.perf_counter()
    motion = make_motion(scene)
    mesh = None
    devs = resolve_devices(devices)
    if devs is not None and len(devs) > 1:
        if not motion.particle_shardable:
            raise ValueError(f"motion model {scene.motion.model!r} does not support devices= "
                             "(particle-axis sharding); supported: static, dem")
        mesh = make_mesh(devs)
    traj = simulate(motion, params, progress, mesh)
    result = make_result(scene, traj, time.perf_counter() - start)
    if out is not None:
        result.save(out)
    return result
