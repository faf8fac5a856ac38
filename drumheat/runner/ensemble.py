"""Ensembles: many variants of one scene as one ``vmap``-ped program.

``drumheat.run_ensemble(scene, overrides)`` runs every variant of a scene (a parameter sweep,
packings with different seeds, the several experiments of a calibration) and returns one
:class:`drumheat.Result` per variant, equal to what ``drumheat.run`` gives for that variant::

    import drumheat as dh

    ens = dh.run_ensemble("weigler-static", {"heat.contact.alpha": [80.0, 105.0, 130.0],
                                             "run.duration": 600.0})
    ens[1].timeseries                 # the Result of variant 1
    ens.throughput                    # variants per second of wall time

How the variants run depends on the motion model:

* ``static``: **vmapped**. Every variant's packing and contact network are built on the host
  (different seeds give different packings; networks are padded with zero-weight slots to a
  common size); the thermal models (equinox modules), networks and initial temperatures are
  stacked along a leading variant axis, and each output interval is advanced for all variants
  by one ``jax.vmap`` of the same solver call a single run makes (diffrax Tsit5 / Kvaerno5 with
  per-variant step control, the explicit Euler scan or the shell scheme). Leaves equal in all
  variants are not stacked. What may differ between variants: every value that ends up as an
  array leaf of the thermal model (contact, wall and loss coefficients, their model choice when
  the module structure stays the same, gas and wall temperatures, material properties, group
  temperatures) and the packing (``run.seed``, ``packing.*``). What must be the same: particle
  count, effects, output times, solver settings and, for the explicit solvers, the time step;
  a variant that breaks this is refused with a :class:`~drumheat.scene.SceneError` naming the
  overridden keys that vary.
* ``dem``: **vmapped**. The DEM state (positions, velocities, springs, jax-md neighbour list,
  temperatures, and the thermal model's array leaves, which :func:`make_thermal_update
  <drumheat.motion.dem.make_thermal_update>` reads from the state) gets a variant axis and
  every output interval runs as one ``vmap`` of the chunked step loop. Variants may differ in
  packing (``run.seed``), initial temperatures and thermal parameters; the mechanics (contact
  parameters, particle sizes, drum, time step) are compile-time constants of the step and
  must be shared. Neighbour lists have one pair and one cell capacity for all variants; an
  overflow in any variant reallocates all and redoes the chunk; a rebuild (and a thermal
  sub-step) happens for all variants when any needs it (``psum`` over the variant axis, so
  the ``lax.cond`` stays a branch), which leaves every trajectory unchanged because pairs are
  kept in canonical order. Contact recording and replay (``dem.record_interval``,
  ``dem.replay_after``) are not batched: such ensembles run one by one.
* ``random``, ``replay``, ``granulator``, ``fluidized``: **not vmapped**. They run one
  variant after the other (``drumheat.run``) with an :class:`EnsembleWarning`: their
  host-side control flow per interval (re-mixing permutations drawn on the host, recorded
  networks of different sizes, phase schedules) is not batched yet.

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

from drumheat.mechanics.integrator import JIT_OPTIONS
from drumheat.scene import Scene, SceneError, load_scene

__all__ = ["EnsembleResult", "EnsembleWarning", "expand_overrides", "run_ensemble"]

#: motion models whose variants run as one vmapped program
VMAPPED_MODELS = ("static", "dem")


#: diffrax adjoint of the vmapped adaptive solves (the forward values do not depend on it)
AUTODIFF = "reverse"


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
    The ``static`` and ``dem`` motion models are vmapped (see the module docstring for what
    may vary and why the others are not); ``docs/scaling.md`` has the measured speed-ups.
    DEM trajectories are chaotic, so a vmapped DEM variant agrees with its single run to
    round-off only over the first steps, statistically afterwards. The batched programs are
    kept in JAX's persistent compilation cache (:mod:`drumheat.runner.compile_cache`): a second
    ensemble of the same structure does not compile again.
    """
    from drumheat.runner.compile_cache import enable_compilation_cache

    enable_compilation_cache()
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
                      ("the particle count", lambda s: s.n_particles),
                      ("the particle groups", lambda s: tuple(g.name for g in s.groups)),
                      ("the heat-transfer effects", lambda s: s.heat.effects())):
        vals = [get(s) for s in scenes]
        if any(v != vals[0] for v in vals):
            _refuse(what, f"{vals[0]!r} vs {next(v for v in vals if v != vals[0])!r}", variants,
                    name)
    from drumheat.runner.sharding import resolve_devices

    devs = resolve_devices(devices)
    model = scenes[0].motion.model
    reason = None
    if model == "dem":
        reason = _dem_fallback_reason(scenes)
    elif model not in VMAPPED_MODELS:
        reason = f"only {', '.join(VMAPPED_MODELS)} are vmapped so far"
    if reason is None:
        runner = _run_static if model == "static" else _run_dem
        results = runner(scenes, variants, devs, progress)
        vmapped = True
    else:
        warnings.warn(f"motion model {model!r}: {reason}; the {len(scenes)} variants run one "
                      "after the other", EnsembleWarning, stacklevel=2)
        from drumheat.runner.loop import run

        results = [run(s, progress=progress) for s in scenes]
        vmapped = False
        devs = None
    wall = time.perf_counter() - start
    return EnsembleResult(results, variants, wall, vmapped,
                          n_devices=len(devs) if devs else 1, _scene=base)


# ---------------------------------------------------------------------------------------------
# static beds: one vmapped solve
# ---------------------------------------------------------------------------------------------


def _pad_network(net, n_pairs: int, n_wall: int):
    from drumheat.thermal.network import ContactNetwork

    def pad(a, n, fill):
        a = jnp.asarray(a)
        return jnp.concatenate([a, jnp.full((n - a.shape[0],) + a.shape[1:], fill, a.dtype)])

    return ContactNetwork(pad(net.pair_i, n_pairs, 0), pad(net.pair_j, n_pairs, 0),
                          pad(net.pair_weight, n_pairs, 0.0), pad(net.wall_particle, n_wall, 0),
                          pad(net.wall_id, n_wall, 0), pad(net.wall_weight, n_wall, 0.0))


def _same_leaf(a, b) -> bool:
    if isinstance(a, (jax.Array, np.ndarray)) or isinstance(b, (jax.Array, np.ndarray)):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and a.dtype == b.dtype and bool(np.array_equal(a, b))
    try:
        return bool(a == b)
    except Exception:  # noqa: BLE001
        return a is b


def _stack(trees, what: str, variants, scene_name):
    """Stack PyTrees leaf by leaf; leaves equal in all trees stay unbatched.

    Returns ``(stacked, axes)`` with ``axes`` a PyTree of 0 / None for ``jax.vmap``.
    """
    dyn = [eqx.partition(t, eqx.is_array) for t in trees]
    static0 = dyn[0][1]
    def0 = jax.tree_util.tree_structure(dyn[0][0])
    for k, (d, s) in enumerate(dyn[1:], 1):
        same = jax.tree_util.tree_structure(d) == def0
        if same:
            try:
                same = jax.tree_util.tree_structure(s) == jax.tree_util.tree_structure(static0)
                same = same and all(_same_leaf(a, b) for a, b in zip(
                    jax.tree_util.tree_leaves(s), jax.tree_util.tree_leaves(static0)))
            except Exception:  # noqa: BLE001
                same = False
        if not same:
            _refuse(what, f"variant {k} has a different structure from variant 0", variants,
                    scene_name)
    leaves = [jax.tree_util.tree_leaves(d[0]) for d in dyn]
    out, axes = [], []
    for j, l0 in enumerate(leaves[0]):
        col = [lv[j] for lv in leaves]
        if any(np.shape(c) != np.shape(l0) for c in col):
            _refuse(what, f"array shapes {sorted({np.shape(c) for c in col})}", variants,
                    scene_name)
        if all(_same_leaf(c, l0) for c in col[1:]):
            out.append(jnp.asarray(l0))
            axes.append(None)
        else:
            out.append(jnp.stack([jnp.asarray(c) for c in col]))
            axes.append(0)
    return (jax.tree_util.tree_unflatten(def0, out), static0,
            jax.tree_util.tree_unflatten(def0, axes), axes)


def _place(tree, flat_axes, n_var: int, mesh):
    """Pad the batched leaves of ``tree`` to a multiple of the device count and split them
    over ``mesh``; replicate the unbatched ones."""
    from drumheat.runner.sharding import pad_to_multiple, replicate, shard_batch

    leaves, tdef = jax.tree_util.tree_flatten(tree)
    k = mesh.devices.size
    out = [shard_batch(pad_to_multiple(a, n_var, k)[0], mesh) if ax == 0 else replicate(a, mesh)
           for a, ax in zip(leaves, flat_axes)]
    return jax.tree_util.tree_unflatten(tdef, out)


def _static_plan(bed, model, net, T0):
    """Per-variant solver plan: ("adaptive", None) / ("explicit", dt) / ("shells", (scheme, dt))."""
    from drumheat.thermal.integrate import ThermalStabilityError, check_explicit_step

    run = bed.scene.run
    if model.internal is not None:
        from drumheat.thermal.internal import ShellStepError, plan_step

        try:
            return ("shells", plan_step(model, net, T0, float(bed.t_out[-1] - bed.t_out[0])))
        except ShellStepError as err:
            raise SceneError("heat.internal.dt", bed.scene.heat.internal.dt, str(err),
                             bed.scene.name) from None
    if run.solver == "explicit":
        try:
            return ("explicit", float(check_explicit_step(model, net, run.dt)))
        except ThermalStabilityError as err:
            raise SceneError("run.dt", run.dt, str(err), bed.scene.name) from None
    return (run.solver, (run.rtol, run.atol))


_STEPPERS: dict = {}


def _static_stepper(kind, plan, static_parts, axes):
    """A jitted, vmapped function advancing all variants over one output interval.

    Cached by its static inputs, so that a second ensemble of the same structure reuses the
    compiled program (as repeated ``drumheat.run`` calls reuse theirs).
    """
    try:
        key = (kind, plan, jax.tree_util.tree_structure(static_parts),
               tuple(jax.tree_util.tree_leaves(static_parts)), tuple(axes[2]), tuple(axes[3]))
        hash(key)
    except TypeError:
        key = None
    if key is not None and key in _STEPPERS:
        return _STEPPERS[key]
    fn = _make_stepper(kind, plan, static_parts, axes[:2])
    if key is not None:
        if len(_STEPPERS) > 16:
            _STEPPERS.clear()
        _STEPPERS[key] = fn
    return fn


def _make_stepper(kind, plan, static_parts, axes):
    from drumheat.thermal import integrate as integ

    model_static, net_static = static_parts
    model_axes, net_axes = axes

    def combine(md, nd):
        return eqx.combine(md, model_static), eqx.combine(nd, net_static)

    if kind in ("adaptive", "implicit"):
        rtol, atol = plan

        def one(md, nd, y, t0, t1):
            model, net = combine(md, nd)
            return integ.advance_adaptive(model, net, y, t0, t1, rtol, atol,
                                          implicit=kind == "implicit", autodiff=AUTODIFF)
    elif kind == "explicit":
        def one(md, nd, y, h, n_steps):
            model, net = combine(md, nd)
            return integ._euler_scan(model, net, y, h, n_steps)
    else:  # shells
        scheme = plan[0]

        def one(md, nd, y, h, n_steps):
            model, net = combine(md, nd)
            return integ._shell_scan(model, net, y, h, n_steps, scheme)

    if kind in ("adaptive", "implicit"):
        return jax.jit(jax.vmap(one, in_axes=(model_axes, net_axes, 0, None, None)))
    return jax.jit(jax.vmap(one, in_axes=(model_axes, net_axes, 0, None, None)),
                   static_argnums=4)


def _packing_signature(scene: Scene) -> str:
    """What a static bed's packing and contact network depend on (StaticBed.__init__)."""
    import json

    d = scene.to_dict()
    keep = {k: d.get(k) for k in ("dim", "packing")}
    keep["groups"] = [(g.count, g.diameter) for g in scene.groups]
    keep["drum"] = scene.drum.diameter if scene.drum is not None else None
    keep["seed"] = scene.run.seed
    keep["source"] = scene.source_path
    return json.dumps(keep, sort_keys=True, default=str)


def _static_beds(scenes):
    """A StaticBed per scene; variants with the same packing share its construction."""
    import copy

    from drumheat.assemble import output_times
    from drumheat.motion.static import StaticBed

    built: dict = {}
    beds = []
    for s in scenes:
        key = _packing_signature(s)
        if key not in built:
            built[key] = StaticBed(s)
            beds.append(built[key])
            continue
        bed = copy.copy(built[key])  # same packing and network, this variant's scene
        bed.scene = s
        bed.t_out = output_times(s)
        beds.append(bed)
    return beds


def _run_static(scenes: list[Scene], variants, devs, progress):
    from drumheat.motion.static import StaticBed, stack_states
    from drumheat.runner.progress import SimProgress
    from drumheat.runner.loop import make_result
    from drumheat.thermal.integrate import explicit_steps, initial_state

    name = scenes[0].name
    t0_wall = time.perf_counter()
    beds = _static_beds(scenes)
    t_out = beds[0].t_out
    for b in beds[1:]:
        if b.t_out.shape != t_out.shape or not np.allclose(b.t_out, t_out, rtol=0, atol=1e-12):
            _refuse("the output times", "run.duration / run.output_interval", variants, name)
    built = [b.model() for b in beds]
    plans = [_static_plan(b, m, b.net, T0) for b, (m, T0) in zip(beds, built)]
    kinds = [p[0] for p in plans]
    if any(k != kinds[0] for k in kinds):
        _refuse("the thermal solver", f"{sorted(set(kinds))}", variants, name)
    if any(p[1] != plans[0][1] for p in plans):
        what = ("the thermal time step" if kinds[0] in ("explicit", "shells")
                else "the solver tolerances")
        _refuse(what, f"{plans[0][1]} vs {next(p[1] for p in plans if p[1] != plans[0][1])}; "
                "set run.dt / heat.internal.dt explicitly to share one", variants, name)
    kind, plan = plans[0]
    n_pairs = max(int(b.net.pair_i.shape[0]) for b in beds)
    n_wall = max(int(b.net.wall_particle.shape[0]) for b in beds)
    nets = [_pad_network(b.net, n_pairs, n_wall) for b in beds]
    model_b, model_s, model_ax, model_flat = _stack([m for m, _ in built], "the thermal model", variants,
                                        name)
    net_b, net_s, net_ax, net_flat = _stack(nets, "the contact network", variants, name)
    y0 = jax.tree_util.tree_map(lambda *a: jnp.stack(a),
                                *[initial_state(m, T0) for m, T0 in built])
    n_var = len(scenes)
    if devs is not None and len(devs) > 1:
        from drumheat.runner.sharding import make_mesh, pad_to_multiple, shard_batch

        mesh = make_mesh(devs)
        model_b = _place(model_b, model_flat, n_var, mesh)
        net_b = _place(net_b, net_flat, n_var, mesh)
        y0 = shard_batch(pad_to_multiple(y0, n_var, len(devs))[0], mesh)
    step = _static_stepper(kind, plan, (model_s, net_s),
                           (model_ax, net_ax, tuple(model_flat), tuple(net_flat)))
    states = [y0]
    y = y0
    with SimProgress(scenes[0].run.duration, progress) as bar:
        for ta, tb in zip(t_out[:-1], t_out[1:]):
            if kind in ("adaptive", "implicit"):
                y = step(model_b, net_b, y, jnp.asarray(ta, float), jnp.asarray(tb, float))
            else:
                n, h = explicit_steps(float(ta), float(tb), plan if kind == "explicit"
                                      else plan[1])
                y = step(model_b, net_b, y, jnp.asarray(h, float), n)
            states.append(y)
            bar.update_to(float(tb))
    from drumheat.runner.sharding import to_host

    states = to_host(states)
    wall = time.perf_counter() - t0_wall
    results = []
    for v, (bed, (model, _)) in enumerate(zip(beds, built)):
        sv = [jax.tree_util.tree_map(lambda a: a[v], s) for s in states]
        if model.internal is None:  # lumped particles: plain host arrays
            T = np.stack([s["T"] for s in sv])
            Q = {a: np.stack([s["Q"][a] for s in sv]) for a in model.accounts}
        else:
            T, Q = stack_states(sv, model.accounts, model)
        traj = bed.make_trajectory(model, np.asarray(T),
                                   {a: np.asarray(q) for a, q in Q.items()}, sv)
        results.append(make_result(bed.scene, traj, wall / n_var))
    return results


# ---------------------------------------------------------------------------------------------
# DEM: one vmapped scan over a batch of states
# ---------------------------------------------------------------------------------------------

_BATCH_AXIS = "variants"


def _dem_fallback_reason(scenes) -> str | None:
    """Why a DEM ensemble cannot be vmapped (None where it can)."""
    for s in scenes:
        if s.dem.record_interval is not None or s.dem.replay_after is not None:
            return ("dem.record_interval / dem.replay_after (contact recording and replay) are "
                    "not batched")
    return None


def _trees_equal(a, b) -> bool:
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    try:
        if ta != tb:
            return False
    except Exception:  # noqa: BLE001
        return False
    return len(la) == len(lb) and all(_same_leaf(x, y) for x, y in zip(la, lb))


def _common_neighbors(dem, states, cap: int, cell_cap: int, realloc: bool):
    """Neighbour lists of all states with one pair capacity and one cell-list capacity."""
    while True:
        new = []
        for st in states:
            if realloc:
                old_cc = st.nbrs.cell_list_capacity or 0
                new.append(dem.reallocate(st, pair_capacity=cap,
                                          extra_cell_capacity=max(0, cell_cap - old_cc)))
            else:
                nb = dem.neighbor.allocate(st.position, cap, max(cell_cap, dem.cell_capacity))
                new.append(st._replace(nbrs=nb, pair_spring=jnp.zeros(
                    (nb.idx.shape[1],) + st.pair_spring.shape[1:], st.pair_spring.dtype)))
        caps = {int(s.nbrs.idx.shape[1]) for s in new}
        ccs = {int(s.nbrs.cell_list_capacity or 0) for s in new}
        if len(caps) == 1 and len(ccs) == 1:
            # jax-md makes a new (equivalent: same box and cell size) cell-list function at
            # every allocation; one shared function makes the lists stackable
            import dataclasses

            fn = new[0].nbrs.cell_list_fn
            return [s._replace(nbrs=dataclasses.replace(s.nbrs, cell_list_fn=fn)) for s in new]
        cap, cell_cap = max(caps), max(ccs)
        states, realloc = new, True


def _run_dem(scenes: list[Scene], variants, devs, progress):
    from drumheat.mechanics import DEMError
    from drumheat.motion.dem import DEMBed, _reset_record, initial_extra
    from drumheat.runner.progress import SimProgress
    from drumheat.runner.loop import make_result
    from drumheat.runner.sharding import to_host

    name = scenes[0].name
    t0_wall = time.perf_counter()
    beds = [DEMBed(s) for s in scenes]
    b0 = beds[0]
    aspects = {
        "the output times": lambda b: (b.t_out.shape, tuple(np.round(b.t_out, 12))),
        "the mechanical time step and thermal sub-steps": lambda b: (
            b.dt, b.steps_per_output, b.substeps),
        "the DEM contact parameters (compile-time constants of the DEM step)":
            lambda b: (b.k_n, b.params),
        "the particles' sizes and masses": lambda b: b.mech,
        "the walls (drum diameter, speed, heated or not)": lambda b: (
            [(float(w.radius), float(w.rpm)) for w in b.walls], tuple(b.wall_heated)),
        "the DEM set-up (gravity, precision, skin, periodic length)": lambda b: (
            tuple(b.gravity), str(b.dtype), b.scene.dem.skin, b.periodic),
    }
    for what, get in aspects.items():
        ref = get(b0)
        for b in beds[1:]:
            if not _trees_equal(get(b), ref):
                _refuse(what, "vary between variants", variants, name)
    built = [b.model() for b in beds]
    model_b, model_s, _, _ = _stack([m for m, _ in built], "the thermal model", variants, name)
    del model_b, model_s
    dem = b0.make_dem(built[0][0], batch_axis=_BATCH_AXIS)
    pos0 = []
    for b in beds:
        p = b.packing_positions()
        if b.scene.dem.settle_time > 0:
            p = b._settle(p)
        pos0.append(p)
    states = [dem.init(p) for p in pos0]
    states = _common_neighbors(dem, states, max(int(s.nbrs.idx.shape[1]) for s in states),
                               max(int(s.nbrs.cell_list_capacity or 0) for s in states), False)
    n, n_w = b0.n, len(b0.walls)
    cap = int(states[0].nbrs.idx.shape[1])
    states = [st._replace(extra=dict(initial_extra(m, T0, cap, n, n_w),
                                     model=eqx.partition(m, eqx.is_array)[0]))
              for st, (m, T0) in zip(states, built)]
    n_var = len(scenes)
    mesh = None
    if devs is not None and len(devs) > 1:
        from drumheat.runner.sharding import make_mesh

        mesh = make_mesh(devs)

    def stack(sts):
        batch = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *sts)
        if mesh is not None:
            from drumheat.runner.sharding import pad_to_multiple, shard_batch

            batch = shard_batch(pad_to_multiple(batch, n_var, len(devs))[0], mesh)
        return batch

    def unstack(batch):
        return [jax.tree_util.tree_map(lambda a: a[v], batch) for v in range(n_var)]

    run_steps = jax.jit(jax.vmap(dem.run_steps_fn, in_axes=(0, None), axis_name=_BATCH_AXIS),
                        compiler_options=JIT_OPTIONS)
    diag = jax.jit(jax.vmap(dem._diag))
    batch = stack(states)
    heated = np.tile(b0.wall_heated, n)
    out = [dict(T=[np.asarray(T0)], pos=[np.asarray(p)], Q={a: [0.0] for a in m.accounts},
                n_pairs=[], n_wall=[]) for p, (m, T0) in zip(pos0, built)]
    k = b0.steps_per_output
    span = k * b0.dt
    with SimProgress(scenes[0].run.duration, progress) as bar:
        for t_end in b0.t_out[1:]:
            start = jax.vmap(_reset_record)(batch.extra)
            start = batch._replace(extra=start,
                                   max_overlap=jnp.zeros_like(batch.max_overlap))
            for attempt in range(9):
                new = run_steps(start, jnp.asarray(k, jnp.int32))
                d = to_host(diag(new))
                if not np.any(d["overflow"][:n_var]):
                    break
                # reallocate every member with larger buffers and redo the chunk (as DEM.run)
                sts = unstack(start)
                cap = int(sts[0].nbrs.idx.shape[1])
                code = int(np.bitwise_or.reduce(np.asarray(to_host(new.nbrs.error.code))[:n_var]))
                from jax_md import partition as _pt

                need = cap
                if code & _pt.PEC.NEIGHBOR_LIST_OVERFLOW:
                    need = 2 * cap
                    for st in unstack(new):
                        if bool(jnp.all(jnp.isfinite(st.position))):
                            est = dem.neighbor.count_pairs(st.position)
                            need = max(need, int(est * dem.neighbor.capacity_multiplier) + 1)
                cc = int(sts[0].nbrs.cell_list_capacity or 0)
                if code & _pt.PEC.CELL_LIST_OVERFLOW:
                    cc += max(1, cc // 2) * (attempt + 1)
                start = stack(_common_neighbors(dem, sts, need, cc, True))
            else:
                raise DEMError("neighbour list overflowed 9 times in a row in a DEM ensemble; "
                               "the packing may be exploding", None)
            news, olds = unstack(new), unstack(start)
            for v in range(n_var):
                dv = {key: val[v] for key, val in d.items()}
                try:
                    dem._check(dv, news[v], olds[v])
                except DEMError as err:
                    raise type(err)(f"variant {v} ({variants[v]}): {err}", err.state) from None
            batch = new
            ex = to_host(new.extra)
            pos = to_host(new.position)
            for v in range(n_var):
                o = out[v]
                o["T"].append(np.asarray(ex["T"][v]))
                o["pos"].append(pos[v])
                for a in o["Q"]:
                    o["Q"][a].append(float(ex["Q"][a][v]))
                o["n_pairs"].append(float(np.sum(ex["pair_data"]["rec_time"][v])) / span)
                o["n_wall"].append(float(np.sum(ex["rec_wall_time"][v] * heated)) / span)
            bar.update_to(float(t_end))
    wall = time.perf_counter() - t0_wall
    results = []
    for v, (bed, (model, _)) in enumerate(zip(beds, built)):
        traj = bed.make_trajectory(model, out[v], len(bed.t_out) - 1, None)
        results.append(make_result(bed.scene, traj, wall / n_var))
    return results
