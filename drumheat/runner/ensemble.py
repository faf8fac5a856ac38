"""Ensembles: many variants of one scene as one ``vmap``-ped program.

``drumheat.run_ensemble(scene, overrides)`` runs every variant of a scene (a parameter sweep,
packings with different seeds, the several experiments of a calibration) and returns one
:class:`drumheat.Result` per variant, equal to what ``drumheat.run`` gives for that variant::

    import drumheat as dh

    ens = dh.run_ensemble("weigler-static", {"heat.contact.alpha": [80.0, 105.0, 130.0],
                                             "run.duration": 600.0})
    ens[1].timeseries                 # the Result of variant 1
    ens.throughput                    # variants per second of wall time

How the variants run: an ensemble is the run loop of :func:`drumheat.runner.simulate` over
``jax.vmap`` of the motion model's ``advance`` (:meth:`AbstractMotion.advance_batch`), for every
motion model whose ``advance`` is pure (``vmappable``): ``static``, ``random``, ``replay``,
``fluidized`` and ``dem`` (without contact recording). Every variant's motion model is set up
from its own scene (packings with different seeds differ), the states of all variants are made
stackable (networks padded with zero-weight slots, one neighbour-list capacity) and stacked,
and every chunk runs for all variants at once; the results are those of ``drumheat.run`` for
each variant. What may differ between variants: every value that ends up in the state (thermal
parameters, temperatures, material properties, the packing and its seed); what must be the
same is what the motion model compiles into its program (:meth:`AbstractMotion.shared`: the
output times, the thermal solver and its step, the DEM's contact parameters, particle sizes,
walls and time step, ...); a variant that breaks this is refused with a
:class:`~drumheat.scene.SceneError` naming the overridden keys that vary.

Not vmapped (one variant after the other, with an :class:`EnsembleWarning`): ``granulator``
(its phases end at times found on the host), ``moving_bed`` and ``pneumatic`` (their open
boundaries are not batched yet) and ``dem`` with ``dem.record_interval`` / ``dem.replay_after``
(the recording is host-side work between chunks).

A DEM ensemble has one neighbour-list capacity for all variants; an overflow in any variant
reallocates all and redoes the chunk; a rebuild (and a thermal sub-step) happens for all
variants when any needs it (``psum`` over the variant axis, so the ``lax.cond`` stays a
branch), which leaves every trajectory unchanged because pairs are kept in canonical order.

With ``devices=`` the variant axis is split over several devices
(:mod:`drumheat.runner.sharding`): the variant count is padded to a multiple of the device count and
the padding dropped afterwards; the results are those of one device to round-off.
"""

from __future__ import annotations

import itertools
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from drumheat.motion import AbstractMotion, make_motion
from drumheat.results.result import make_result
from drumheat.runner.compile_cache import enable_compilation_cache
from drumheat.runner.host_memory import free_heap_after_compiles, return_large_buffers
from drumheat.runner.loop import MAX_REDO, output_flags, run
from drumheat.runner.progress import SimProgress
from drumheat.runner.sharding import (make_mesh, pad_to_multiple, resolve_devices, shard_batch,
                                      to_host)
from drumheat.scene import Scene, SceneError, load_scene

__all__ = ["EnsembleResult", "EnsembleWarning", "expand_overrides", "run_ensemble"]

class EnsembleWarning(UserWarning):
    """An ensemble runs its variants one after the other instead of as one vmapped program."""


@dataclass
class EnsembleResult:
    """The variants of an ensemble run.

    Attributes
    ----------
    results : list of Result
        One :class:`drumheat.Result` per variant, in the order of the overrides; each with the
        same time-series columns as ``drumheat.run`` gives.
    overrides : list of dict
        The overrides of each variant (dotted keys).
    wall_time_s : float
        Wall-clock time of the whole ensemble (set-up, compilation and solve), s.
    vmapped : bool
        True where the variants ran as one vmapped program, False where one by one.
    n_devices : int
        Devices the variant axis was split over (1: not sharded).
    sequential_wall_time_s : float or None
        Wall time of the same variants run one by one with ``drumheat.run``, s; filled in by
        :meth:`compare_sequential`.
    """

    results: list
    overrides: list
    wall_time_s: float
    vmapped: bool
    n_devices: int = 1
    sequential_wall_time_s: float | None = None
    _scene: Any = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.results)

    def __getitem__(self, k):
        return self.results[k]

    def __iter__(self):
        return iter(self.results)

    @property
    def throughput(self) -> float:
        """Variants per second of wall time."""
        return len(self.results) / self.wall_time_s if self.wall_time_s > 0 else float("inf")

    @property
    def speedup(self) -> float | None:
        """One-by-one wall time over ensemble wall time (after :meth:`compare_sequential`)."""
        if self.sequential_wall_time_s is None:
            return None
        return self.sequential_wall_time_s / self.wall_time_s

    def timeseries(self) -> pd.DataFrame:
        """All time series in one table, with a ``variant`` column and one column per
        overridden key."""
        frames = []
        for k, (r, ov) in enumerate(zip(self.results, self.overrides)):
            df = r.timeseries.copy()
            df.insert(0, "variant", k)
            for i, (key, v) in enumerate(ov.items()):
                df.insert(1 + i, key, v if np.isscalar(v) else str(v))
            frames.append(df)
        return pd.concat(frames, ignore_index=True)

    def compare_sequential(self, progress: bool = False) -> float:
        """Run the variants one by one with ``drumheat.run``; return the speed-up.

        Sets :attr:`sequential_wall_time_s`. Each ``drumheat.run`` call is timed as a user
        would see it (including compilation where the jit cache cannot be reused).
        """
        from drumheat.runner.loop import run

        start = time.perf_counter()
        for r in self.results:
            run(r.scene, progress=progress)
        self.sequential_wall_time_s = time.perf_counter() - start
        return self.speedup

    def summary(self) -> str:
        """One line: variants, wall time, throughput and (if measured) the speed-up."""
        s = (f"{len(self)} variants in {self.wall_time_s:.2f} s "
             f"({self.throughput:.2f} variants/s, {'vmapped' if self.vmapped else 'one by one'}"
             f", {self.n_devices} device(s))")
        if self.sequential_wall_time_s is not None:
            s += (f"; one by one {self.sequential_wall_time_s:.2f} s, speed-up "
                  f"{self.speedup:.2f}x")
        return s

    def save(self, out_dir: str | Path, figures: bool = False) -> Path:
        """Write each variant's result files to ``out_dir/variant_<k>`` and the combined
        time series to ``out_dir/ensemble_timeseries.csv``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        for k, r in enumerate(self.results):
            r.save(out / f"variant_{k:03d}", figures=figures)
        self.timeseries().to_csv(out / "ensemble_timeseries.csv", index=False)
        return out


def expand_overrides(overrides) -> list[dict]:
    """The list of per-variant override dicts meant by ``overrides``.

    Parameters
    ----------
    overrides : list of dict, or dict
        A list: one dict of dotted keys per variant (``[{"run.seed": 1}, {"run.seed": 2}]``).
        A dict: a sweep; keys with a list value are combined as a grid (Cartesian product, in
        the order given, the last key varying fastest), keys with a scalar value apply to
        every variant (``{"heat.contact.alpha": [80, 105], "run.duration": 600.0}`` gives two
        variants). An int ``n``: ``n`` copies of the scene.

    Raises
    ------
    SceneError
        If the overrides are empty or not of these forms.
    """
    if isinstance(overrides, (int, np.integer)) and not isinstance(overrides, bool):
        if overrides < 1:
            raise SceneError("overrides", overrides, "an ensemble needs at least one variant")
        return [{} for _ in range(int(overrides))]
    if isinstance(overrides, dict):
        sweep = {k: list(v) for k, v in overrides.items() if isinstance(v, (list, tuple))}
        fixed = {k: v for k, v in overrides.items() if k not in sweep}
        for k, v in sweep.items():
            if not v:
                raise SceneError(k, [], "a swept key needs at least one value")
        combos = itertools.product(*sweep.values()) if sweep else [()]
        return [dict(fixed, **dict(zip(sweep, c))) for c in combos]
    if isinstance(overrides, (list, tuple)):
        if not overrides:
            raise SceneError("overrides", [], "an ensemble needs at least one variant")
        for k, o in enumerate(overrides):
            if not isinstance(o, dict):
                raise SceneError(f"overrides[{k}]", o, "each variant is a dict of dotted keys "
                                 "to values, e.g. {'heat.contact.alpha': 120.0}")
        return [dict(o) for o in overrides]
    raise SceneError("overrides", overrides, "a list of dicts (one per variant), a dict of "
                     "key -> list of values (a sweep) or a number of copies")


def _varying_keys(variants: list[dict]) -> list[str]:
    keys = sorted(set().union(*variants)) if variants else []
    out = []
    for key in keys:
        vals = [repr(v.get(key, "<scene value>")) for v in variants]
        if len(set(vals)) > 1:
            out.append(key)
    return out


def _refuse(what: str, detail: str, variants: list[dict], scene_name: str):
    keys = _varying_keys(variants)
    key = ", ".join(keys) if keys else "overrides"
    raise SceneError(
        key, "values that differ between variants",
        f"they change {what} ({detail}), which all variants of an ensemble share because they "
        "run as one program; keep these keys the same for all variants or run the variants "
        "separately with drumheat.run", scene_name)


@free_heap_after_compiles()
def run_ensemble(scene: Scene | str, overrides, *, devices=None, progress: bool | None = True
                 ) -> EnsembleResult:
    """Run many variants of a scene; vmapped into one program where the motion model allows.

    Parameters
    ----------
    scene : Scene or str
        The base scene, or a built-in scene name or path (:func:`drumheat.load_scene`).
    overrides : list of dict, dict or int
        The variants as dotted-key overrides of the base scene, the same keys as ``--set``
        (see :func:`expand_overrides`): a list of dicts, a dict of key -> list of values (a
        grid sweep; scalar values apply to all variants) or a number of identical copies.
    devices : None, "all", int or list of jax.Device, optional
        Split the variant axis over these devices (:mod:`drumheat.runner.sharding`). Default: one
        device.
    progress : bool
        Show a progress bar over the simulated time (vmapped) or per run (one by one).

    Returns
    -------
    EnsembleResult
        One :class:`drumheat.Result` per variant plus wall time and throughput.

    Raises
    ------
    SceneError
        For a bad value in any variant (naming the key), and for variants that differ in
        something the shared program cannot vary (particle count, motion model, effects,
        output times, solver settings), naming the overridden keys that vary.

    Warns
    -----
    EnsembleWarning
        If the motion model cannot be vmapped: the variants then run one by one.

    Notes
    -----
    The ``static``, ``random``, ``replay``, ``fluidized`` and ``dem`` motion models are
    vmapped (see the module docstring for what may vary and why the others are not);
    ``docs/scaling.md`` has the measured speed-ups.
    DEM trajectories are chaotic, so a vmapped DEM variant agrees with its single run to
    round-off only over the first steps, statistically afterwards. The batched programs are
    kept in JAX's persistent compilation cache (:mod:`drumheat.runner.compile_cache`): a second
    ensemble of the same structure does not compile again.
    """
    enable_compilation_cache()
    return_large_buffers()
    variants = expand_overrides(overrides)
    start = time.perf_counter()
    if isinstance(scene, Scene):
        base = scene
        scenes = [scene.with_overrides(ov) if ov else scene for ov in variants]
    else:
        base = load_scene(scene)
        scenes = [load_scene(scene, ov) for ov in variants]
    name = base.name
    for what, get in (("the motion model", lambda s: s.motion.model),
                      ("the dimension", lambda s: s.dim),
                      ("the particle count", lambda s: s.n_parcels),
                      ("the particle groups", lambda s: tuple(g.name for g in s.groups)),
                      ("the heat-transfer effects", lambda s: s.heat.effects())):
        vals = [get(s) for s in scenes]
        if any(v != vals[0] for v in vals):
            _refuse(what, f"{vals[0]!r} vs {next(v for v in vals if v != vals[0])!r}", variants,
                    name)
    devs = resolve_devices(devices)
    first = make_motion(scenes[0])
    reason = first.not_vmappable()
    if reason is None:
        motions = [first] + [make_motion(s) for s in scenes[1:]]
        shared = [m.shared() for m in motions]
        for what in shared[0]:
            vals = [repr(sh[what]) for sh in shared]
            if any(v != vals[0] for v in vals):
                _refuse(what, "vary between variants", variants, name)
        results = _run_vmapped(motions, variants, devs, progress)
        vmapped = True
    else:
        warnings.warn(f"motion model {base.motion.model!r}: {reason}; the {len(scenes)} "
                      "variants run one after the other", EnsembleWarning, stacklevel=2)
        results = [run(s, progress=progress) for s in scenes]
        vmapped = False
        devs = None
    wall = time.perf_counter() - start
    return EnsembleResult(results, variants, wall, vmapped,
                          n_devices=len(devs) if devs else 1, _scene=base)


def _stack_states(states, variants, scene_name):
    """The variants' states stacked leaf by leaf (the non-array parts must be equal)."""
    parts = [eqx.partition(s, eqx.is_array) for s in states]
    static0 = parts[0][1]
    treedef = jax.tree_util.tree_structure(parts[0][0])
    for k, (dyn, static) in enumerate(parts[1:], 1):
        same = jax.tree_util.tree_structure(dyn) == treedef
        if same:
            try:
                same = jax.tree_util.tree_structure(static) == jax.tree_util.tree_structure(
                    static0) and all(_same_leaf(a, b) for a, b in zip(
                        jax.tree_util.tree_leaves(static), jax.tree_util.tree_leaves(static0)))
            except Exception:  # noqa: BLE001 - uncomparable static parts differ
                same = False
        if not same:
            _refuse("the state's structure", f"variant {k} differs from variant 0", variants,
                    scene_name)
    shapes = [[np.shape(a) for a in jax.tree_util.tree_leaves(d)] for d, _ in parts]
    if any(sh != shapes[0] for sh in shapes[1:]):
        _refuse("the array shapes of the state", "they differ between variants", variants,
                scene_name)
    batch = jax.tree_util.tree_map(lambda *a: jnp.stack([jnp.asarray(x) for x in a]),
                                   *[d for d, _ in parts])
    return batch, static0


def _run_vmapped(motions: list[AbstractMotion], variants, devs, progress):
    """The run loop over the stacked states of all variants (module docstring)."""
    m0 = motions[0]
    name = m0.scene.name
    t0_wall = time.perf_counter()
    n_var = len(motions)
    states = m0.align([m.initial_state() for m in motions])
    logs = [m.start_log(s) for m, s in zip(motions, states)]
    batch, static = _stack_states(states, variants, name)
    mesh = make_mesh(devs) if devs is not None and len(devs) > 1 else None

    def stack(sts):
        b = jax.tree_util.tree_map(lambda *a: jnp.stack(a),
                                   *[eqx.partition(s, eqx.is_array)[0] for s in sts])
        if mesh is not None:
            b = shard_batch(pad_to_multiple(b, n_var, len(devs))[0], mesh)
        return eqx.combine(b, static)

    def unstack(b):
        dyn = eqx.partition(b, eqx.is_array)[0]
        return [eqx.combine(jax.tree_util.tree_map(lambda a: a[v], dyn), static)
                for v in range(n_var)]

    if mesh is not None:
        batch = shard_batch(pad_to_multiple(batch, n_var, len(devs))[0], mesh)
    batch = eqx.combine(batch, static)
    axes = jax.tree_util.tree_map(lambda _: 0, eqx.partition(batch, eqx.is_array)[0])
    observe = jax.vmap(m0.observe)
    rows = [[] for _ in range(n_var)]

    def record(b):
        obs = to_host(observe(b))
        for v in range(n_var):
            rows[v].append(jax.tree_util.tree_map(lambda a: a[v], obs))

    record(batch)
    is_output = output_flags(m0)
    times = m0.times
    with SimProgress(float(times[-1] - times[0]), progress) as bar:
        for i, (ta, tb) in enumerate(zip(times[:-1], times[1:])):
            start = batch
            for attempt in range(MAX_REDO):
                end = m0.advance_batch(start, axes, float(ta), float(tb))
                redo = m0.check_batch(start, end, n_var, unstack, stack, attempt)
                if redo is None:
                    break
                start = redo
            else:
                raise RuntimeError("the neighbour lists of a DEM ensemble overflowed "
                                   f"{MAX_REDO} times in a row; the packing may be exploding")
            batch = end
            if is_output[i + 1]:
                record(batch)
            bar.update_to(float(tb - times[0]))
    wall = time.perf_counter() - t0_wall
    finals = unstack(batch)
    return [make_result(m.scene, m.finish(rows[v], logs[v], finals[v]), wall / n_var)
            for v, m in enumerate(motions)]


def _same_leaf(a, b) -> bool:
    if isinstance(a, (jax.Array, np.ndarray)) or isinstance(b, (jax.Array, np.ndarray)):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and a.dtype == b.dtype and bool(np.array_equal(a, b))
    try:
        return bool(a == b)
    except Exception:  # noqa: BLE001
        return a is b


