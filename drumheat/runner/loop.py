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

import contextlib
import signal
import sys
import threading
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.assemble import group_index, scene_values, thermal_particles
from drumheat.motion import AbstractMotion, make_motion
from drumheat.motion.rows import RowSpool
from drumheat.motion.trajectory import Trajectory
from drumheat.results.files import CHECKPOINT, RunFolder, check_out_dir
from drumheat.results.result import Result, make_result
from drumheat.runner.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from drumheat.runner.compile_cache import enable_compilation_cache
from drumheat.runner.host_memory import free_heap_after_compiles, return_large_buffers
from drumheat.runner.progress import SimProgress
from drumheat.runner.sharding import make_mesh, resolve_devices, shard_particles
from drumheat.runner.spill import StartSpill, copy_leaves
from drumheat.scene import Scene, SceneError, load_scene

__all__ = ["run", "simulate", "trace", "restore", "estimate", "advance_checked", "MAX_REDO",
           "RunStopped", "LongRunError", "FolderMonitor"]

#: how often a chunk may be redone (each time with larger buffers) before a run stops
MAX_REDO = 9


def advance_checked(motion: AbstractMotion, state, t0: float, t1: float,
                    spill: StartSpill | None = None):
    """One chunk of a run: ``motion.advance``, redone from the start state that
    ``motion.check`` hands back (at most :data:`MAX_REDO` times).

    With ``spill`` (which holds ``state``, :meth:`StartSpill.save`) and a motion model that
    advances ``state`` in place, the first attempt runs in place; the start is read back from
    the spill only if the chunk fails :meth:`AbstractMotion.passes`, and any redo runs as
    usual."""
    start, first = state, 0
    if spill is not None and motion.advances_in_place(state):
        end = motion.advance_in_place(state, t0, t1)  # takes the buffers of `state`
        if motion.passes(end):
            spill.adopt(end)
            return end
        redo = motion.check(spill.load(), end, 0)
        if redo is None:
            return end
        start, first = redo, 1
    for attempt in range(first, MAX_REDO):
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
             progress: bool | None = True, mesh=None, return_state: bool = False,
             monitor=None, resume: dict | None = None):
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
    monitor : optional
        Told of every output row and chunk end (:class:`FolderMonitor`: streamed results,
        checkpoints, stop requests) and of a failure.
    resume : dict, optional
        A checkpoint (:func:`drumheat.runner.checkpoint.load_checkpoint`) to continue from.
    """
    spool = monitor.log_dir() if monitor is not None else None
    if resume is None:
        state = motion.initial_state(params)
        log = motion.start_log(state, params, spool)
        rows = monitor.new_rows([]) if monitor is not None else []
        rows.append(jax.device_get(motion.observe(state)))
        i0 = 0
    else:
        state, log, rows, i0 = restore(motion, resume, params, spool)
        if monitor is not None:
            rows = monitor.new_rows(rows)
    if mesh is not None:
        state = shard_particles(state, mesh, motion.scene.n_parcels)
    is_output = output_flags(motion)
    times = motion.times
    # with a result folder, on the CPU (where the start's copy takes the same memory as the run),
    # a chunk that the motion model can advance in place keeps its start on disk instead of in
    # memory (StartSpill); made before the first row lists the folder's entries
    spill = StartSpill(spool) if keeps_start_on_disk(spool is not None, mesh) else None
    if monitor is not None:
        monitor.begin(motion, times[is_output], rows)
    with SimProgress(float(times[-1] - times[0]), progress, work=_work(motion, times)) as bar, \
            _closing(spill):
        bar.update_to(float(times[i0] - times[0]))
        for i in range(i0, len(times) - 1):
            t0, t1 = float(times[i]), float(times[i + 1])
            n_rows = len(rows)
            try:
                if spill is not None and motion.advances_in_place(state):
                    spill.save(state)
                    if not spill.owns(state):  # copied leaf by leaf as the loop lets go of it
                        leaves, treedef = jax.tree_util.tree_flatten(state)
                        state = new = None
                        state = jax.tree_util.tree_unflatten(treedef, copy_leaves(leaves))
                        del leaves
                new = advance_checked(motion, state, t0, t1, spill)
                if is_output[i + 1]:
                    rows.append(jax.device_get(motion.observe(new)))
                note = motion.between_note(t1)
                if note:
                    bar.note(note)
                new, log = motion.between(new, log, t1)
            except BaseException as err:
                if monitor is not None:  # the last good state: before this chunk
                    if isinstance(rows, RowSpool):
                        rows.truncate(n_rows)
                    else:
                        del rows[n_rows:]
                    monitor.failed(motion, i, t0, _last_good(state, spill), log, rows, err)
                raise
            state = new
            if is_output[i + 1] and monitor is not None:
                monitor.row(t1, rows[-1])
            bar.update_to(t1 - float(times[0]))
            if monitor is not None:
                monitor.chunk_done(motion, i + 1, t1, state, log, rows)
    traj = motion.finish(rows, log, state)
    return (traj, state) if return_state else traj


def keeps_start_on_disk(folder: bool, mesh=None) -> bool:
    """Whether :func:`simulate` runs the chunks that a motion model can advance in place so,
    keeping each chunk's start on disk (:class:`StartSpill`): runs with a result folder
    (``folder``) on the CPU, where a copy of the start takes the same memory as the run, not
    sharded over a ``mesh``."""
    return folder and mesh is None and jax.default_backend() == "cpu"


@contextlib.contextmanager
def _closing(spill: StartSpill | None):
    """Remove the spill's files when the loop ends, however it ends."""
    try:
        yield spill
    finally:
        if spill is not None:
            spill.close()


def _last_good(state, spill: StartSpill | None):
    """The chunk's start: ``state``, or where its buffers went into an in-place chunk (or it
    was dropped to be read back), the spill's copy of it."""
    if spill is not None and (state is None or any(
            isinstance(x, jax.Array) and x.is_deleted() for x in jax.tree_util.tree_leaves(state))):
        return spill.load()
    return state


def restore(motion: AbstractMotion, checkpoint: dict, params=None, spool=None):
    """``(state, log, rows, next chunk)`` of a checkpoint, onto a fresh state of ``motion``;
    ``spool``: the folder where the run that wrote it kept its log's large arrays
    (:meth:`AbstractMotion.start_log`)."""
    template = motion.initial_state(params)
    fresh = motion.start_log(template, params)
    try:
        log = motion.load_log(checkpoint["log"], fresh, spool)
    except (ValueError, OSError) as err:  # e.g. the files a run kept in its folder are gone
        raise CheckpointError(f"the checkpoint cannot be continued: {err}; start anew without "
                              "--resume") from None
    state, log = motion.restore_state(template, checkpoint["state"],
                                      checkpoint["meta"]["state"], log)
    return state, log, checkpoint["rows"], int(checkpoint["meta"]["chunk"])


def _work(motion: AbstractMotion, times):
    """Cumulative cost of reaching each simulated time (s from the start), interpolated
    between the chunk boundaries (:meth:`AbstractMotion.progress_work`)."""
    times = np.asarray(times, float)
    w = np.concatenate([[0.0], np.cumsum([motion.progress_work(float(a), float(b))
                                          for a, b in zip(times[:-1], times[1:])])])
    rel = times - times[0]
    return lambda t: float(np.interp(t, rel, w))


class LongRunError(ValueError):
    """A run would take longer than an hour and was not allowed to (``allow_long``)."""


#: a run estimated longer than this (s) needs ``allow_long=True`` (``--yes``)
LONG_RUN_S = 3600.0


def _duration_text(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h" if seconds < 172800 else f"{seconds / 86400:.1f} days"


def estimate(motion: AbstractMotion, params=None, state=None, in_place: bool = False
             ) -> dict | None:
    """The cost of a run before it starts (:meth:`AbstractMotion.cost`) with a one-line
    ``text``; None where the motion model makes no estimate. ``in_place`` (for a run whose
    chunks will run in place, :func:`keeps_start_on_disk`): the warm-up runs in the buffers of
    the initial state made here (never in those of a ``state`` given)."""
    own = state is None
    if own:
        state = motion.initial_state(params)
    in_place = in_place and own and motion.advances_in_place(state)
    if in_place:
        # the warm-up may donate only buffers of its own (arrays the initial state shares with
        # the motion model, e.g. its thermal parameters, stay with it; its own are freed as
        # their copies are made)
        leaves, treedef = jax.tree_util.tree_flatten(state)
        del state
        state = jax.tree_util.tree_unflatten(treedef, copy_leaves(leaves))
        del leaves
    cost = motion.cost(state, in_place=in_place)
    if cost is None:
        return None
    cost = dict(cost)
    cost["text"] = (f"{motion.scene.name}: {motion.scene.n_parcels} particles, {cost['text']}; "
                    f"estimated wall time {_duration_text(cost['seconds'])} on this machine")
    return cost


def check_cost(cost: dict | None, allow_long: bool) -> None:
    """Refuse a run estimated above an hour unless allowed, naming the keys that make it
    cheaper."""
    if cost is None or allow_long or cost["seconds"] <= LONG_RUN_S:
        return
    raise LongRunError(f"{cost['text']}. Runs above an hour need --yes (Python: "
                       f"allow_long=True). Cheaper: {cost['cheaper']}")


class RunStopped(RuntimeError):
    """A run stopped early on request (Ctrl-C): its results so far and a checkpoint are in its
    result folder (``drumheat run ... --resume`` continues it)."""


#: set by Ctrl-C during a run with a result folder: stop at the next chunk end
STOP = threading.Event()


class FolderMonitor:
    """Writes a run into its result folder as it goes (:class:`drumheat.results.files.RunFolder`):
    every output row into ``timeseries.csv``, a checkpoint every ``run.checkpoint_every``
    seconds of wall-clock time (and every ``run.checkpoint_interval`` of simulated time), and
    a checkpoint with what the run has when it stops (Ctrl-C) or fails."""

    def __init__(self, folder: RunFolder, scene: Scene, wall_offset: float = 0.0):
        self.folder, self.scene = folder, scene
        self.wall_start = time.perf_counter() - wall_offset
        self.last_wall = time.perf_counter()
        self.last_sim = None
        self.out_times = None

    def wall_time(self) -> float:
        return time.perf_counter() - self.wall_start

    def log_dir(self) -> Path:
        """The folder where the motion model's log keeps its large arrays
        (:meth:`AbstractMotion.start_log`; the contact recording of a DEM run)."""
        return self.folder.log_dir

    def new_rows(self, rows: list) -> RowSpool:
        """The run's output rows, their particle frames in the folder's spool (a resumed run:
        the checkpoint's ``rows``)."""
        return RowSpool.from_state(self.folder.frames_dir, rows)

    def begin(self, motion, out_times, rows):
        self.out_times = np.asarray(out_times)
        self.folder.rows(self.out_times, rows)

    def row(self, t, row):
        self.folder.row(t, row)

    def checkpoint(self, motion, chunk, t, state, log, rows):
        save_checkpoint(self.folder.checkpoint_path, scene_toml=self.scene.to_toml(),
                        motion_name=motion.name, chunk=chunk, time=t, state=state,
                        state_meta=motion.checkpoint_meta(state),
                        log_arrays=motion.save_log(log), rows=rows,
                        extra_meta={"wall_time_s": self.wall_time()})
        self.last_wall, self.last_sim = time.perf_counter(), t
        self.folder._register()

    def chunk_done(self, motion, chunk, t, state, log, rows):
        run = self.scene.run
        last = len(motion.times) - 1
        if STOP.is_set() and chunk < last:
            self.checkpoint(motion, chunk, t, state, log, rows)
            self._stop("stopped by Ctrl-C", t, rows)
            raise RunStopped(f"stopped at t = {t:g} s of {run.duration:g} s; the results so far "
                             f"and a checkpoint are in '{self.folder.out}': continue with "
                             f"drumheat run ... --out {self.folder.out} --resume")
        due = (run.checkpoint_every > 0
               and time.perf_counter() - self.last_wall >= run.checkpoint_every)
        if run.checkpoint_interval is not None:
            start = self.last_sim if self.last_sim is not None else float(motion.times[0])
            due = due or t - start >= run.checkpoint_interval * (1 - 1e-9)
        if due and chunk < last:
            self.checkpoint(motion, chunk, t, state, log, rows)

    def failed(self, motion, chunk, t, state, log, rows, err):
        if isinstance(err, RunStopped):
            return
        if isinstance(err, SceneError):  # bad input found during the run: nothing to keep
            self.folder.discard()
            return
        reason = f"{type(err).__name__}: {err}"
        try:
            self.checkpoint(motion, chunk, t, state, log, rows)
        except Exception as ckpt_err:  # noqa: BLE001 - the original error matters more
            reason += f" (no checkpoint could be written: {ckpt_err})"
        self._stop(reason, t, rows)

    def _stop(self, reason, t, rows):
        self.folder.stop({"scene": self.scene.name, "complete": False, "status": reason,
                          "t_reached_s": float(t), "duration_s": self.scene.run.duration,
                          "wall_time_s": round(self.wall_time(), 3),
                          "resume": f"drumheat run {self.scene.name} --out {self.folder.out} "
                                    "--resume (with the same scene)"},
                         self.out_times, rows)


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


@free_heap_after_compiles()
def run(scene: Scene | str, out: str | Path | None = None, progress: bool | None = True,
        params: dict | None = None, overrides: dict | None = None, devices=None,
        resume: bool = False, allow_long: bool = False, figure_formats=("png",),
        dpi: int = 120) -> Result:
    """Run a scene and return its :class:`Result`; write result files if ``out`` is given.

    Compiled programs are kept in JAX's persistent compilation cache
    (:mod:`drumheat.runner.compile_cache`; ``DRUMHEAT_CACHE_DIR=off`` leaves it alone), so
    running the same scene again does not compile again. On Linux with glibc, freed buffers of
    1 MiB and more go back to the system from the first run on, and so do the heap's freed pages
    after each compilation during a run (:mod:`drumheat.runner.host_memory`; a
    ``MALLOC_MMAP_THRESHOLD_`` set by the user is kept).

    Parameters
    ----------
    scene : Scene or str
        A scene, a built-in scene name or a path to a scene file.
    out : path, optional
        Result folder, written as the run goes (:class:`~drumheat.results.files.RunFolder`:
        the time series row by row, checkpoints every ``run.checkpoint_every`` seconds, the
        complete result at the end; an earlier result there is kept until the new one is
        complete); checked before the run. Nothing is written when None (call
        ``result.save()`` later). While it runs, Ctrl-C stops the run at the next chunk end
        with a checkpoint (:class:`RunStopped`).
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
    resume : bool
        Continue the run whose checkpoint is in ``out``; the scene must be the one that run
        had (else :class:`~drumheat.runner.checkpoint.CheckpointError`). The results equal
        those of a run that was not interrupted, bit for bit.
    allow_long : bool
        Run even when the estimate made before the run (:func:`estimate`, from a timed
        warm-up of the DEM) is above an hour; otherwise such a run is refused with
        :class:`LongRunError`, which names the keys that make it cheaper. With ``progress``
        the estimate is printed before the run starts.
    figure_formats, dpi :
        Formats (png, pdf, svg) and PNG resolution of the figures written into ``out``.
    """
    enable_compilation_cache()
    return_large_buffers()
    if not isinstance(scene, Scene):
        scene = load_scene(scene, overrides)
    elif overrides:
        scene = scene.replace(overrides)
    checkpoint = None
    if resume:
        if out is None:
            raise ValueError("resume=True needs the result folder (out=) that holds the "
                             "checkpoint")
        checkpoint = load_checkpoint(Path(out) / CHECKPOINT, scene.to_toml())
    elif out is not None:
        check_out_dir(out)  # before the run, not after it
    start = time.perf_counter()
    if progress and scene.motion.model in ("dem", "moving_bed", "pneumatic"):
        print(f"{scene.name}: preparing the run (packing the bed, compiling, timing a warm-up) "
              "...", file=sys.stderr, flush=True)
    motion = make_motion(scene)
    mesh = None
    devs = resolve_devices(devices)
    if devs is not None and len(devs) > 1:
        if not motion.particle_shardable:
            raise ValueError(f"motion model {scene.motion.model!r} does not support devices= "
                             "(particle-axis sharding); supported: static, dem")
        mesh = make_mesh(devs)
    if checkpoint is None:
        cost = estimate(motion, params, in_place=keeps_start_on_disk(out is not None, mesh))
        check_cost(cost, allow_long)
        if cost is not None and progress:
            print(cost["text"], file=sys.stderr, flush=True)
    if out is None:
        traj = simulate(motion, params, progress, mesh)
        return make_result(scene, traj, time.perf_counter() - start)
    # the masses alone, copied to the host (no device array of the thermal particles is kept)
    mass = np.array(thermal_particles(scene, scene_values(scene)).mass, copy=True)
    folder = RunFolder(out, scene, resume=resume, mass=mass, group=group_index(scene))
    offset = float(checkpoint["meta"].get("wall_time_s", 0.0)) if checkpoint else 0.0
    monitor = FolderMonitor(folder, scene, wall_offset=offset)
    with _stop_on_ctrl_c():
        traj = simulate(motion, params, progress, mesh, monitor=monitor, resume=checkpoint)
    result = make_result(scene, traj, monitor.wall_time())
    folder.complete(result, figure_formats=tuple(figure_formats), dpi=dpi)
    return result


@contextlib.contextmanager
def _stop_on_ctrl_c():
    """While a run writes into a result folder, the first Ctrl-C asks it to stop at the next
    chunk end (with a checkpoint); a second one interrupts at once."""
    STOP.clear()
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        STOP.set()
        signal.signal(signal.SIGINT, previous)
        print("\nstopping at the end of this chunk (Ctrl-C again to interrupt at once)",
              file=sys.stderr, flush=True)

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        STOP.clear()
