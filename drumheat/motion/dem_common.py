"""What the DEM-based motion models (``dem``, ``moving_bed``, ``pneumatic``) share: the checked
chunk and the checkpoint of a DEM state.

A DEM state's neighbour list carries a few numbers outside its arrays (capacities, the cell
size); a checkpoint keeps them (:meth:`DEMMotion.checkpoint_meta`) so that the state can be
rebuilt on a fresh template of another capacity.
"""

from __future__ import annotations

import dataclasses
import functools
import time

import jax
import numpy as np

from drumheat.mechanics import DEMError, DEMState
from drumheat.mechanics.analysis import PARTICLE_MECHANICS, particle_mechanics
from drumheat.mechanics.backend import BackendChoice, choose_contact_backend
from drumheat.motion.base import AbstractMotion
from drumheat.motion.coupling import thermal_step_limit
from drumheat.motion.rows import stack_arrays
from drumheat.scene import SceneError

__all__ = ["DEMMotion", "WARMUP_STEPS"]

#: mechanical steps of the timed warm-up behind a run's cost estimate
WARMUP_STEPS = 200

#: the static fields of a neighbour list that a checkpoint keeps
_NEIGHBOR_STATICS = ("cell_list_capacity", "max_occupancy", "cell_size")


class DEMMotion(AbstractMotion):
    """Base of the motion models whose state is a :class:`~drumheat.mechanics.DEMState`.

    Subclasses set ``self.dem`` (the DEM system of :func:`drumheat.mechanics.make_dem`).
    """

    dem = None
    _backend = None
    #: (seconds per mechanical step, seconds of host work per chunk), set by :meth:`cost`
    _cost_model = None
    #: the compiled :func:`~drumheat.mechanics.analysis.particle_mechanics` of :meth:`mechanics`
    _mechanics = None

    def contact_backend(self, batched: bool = False) -> BackendChoice:
        """The contact kernel of this scene's DEM (``[dem] contact_backend``,
        :func:`drumheat.mechanics.backend.choose_contact_backend`); chosen once for single
        runs (one warning line at most), always JAX under ``vmap``."""
        if batched:
            return choose_contact_backend(self.scene.dem.contact_backend, dim=self.scene.dim,
                                          params=self.params, dtype=self.dtype, batched=True,
                                          warn=False)
        if self._backend is None:
            self._backend = choose_contact_backend(self.scene.dem.contact_backend,
                                                   dim=self.scene.dim, params=self.params,
                                                   dtype=self.dtype)
        return self._backend

    def backend_info(self) -> dict:
        """What summary.json says about the contact kernel, the time step and what the mechanics'
        float type resolves (:func:`drumheat.mechanics.precision.position_resolution`)."""
        choice = self.contact_backend()
        info = {"contact_backend": choice.backend}
        if choice.reason is not None:
            info["contact_backend_note"] = (f"'{choice.requested}' asked for; "
                                            f"{choice.reason}")
        info["time_step"] = {"dt_s": self.dt, "t_crit_s": self.t_crit,
                             "dt_over_t_crit": self.dt / self.t_crit,
                             "set_by": self.setup.dt_origin}
        info["precision"] = self.dem.position_resolution().summary()
        return info

    # -- per-particle mechanics in the outputs ----------------------------------------------------
    def mechanics(self, state) -> dict:
        """The per-particle mechanics of an output row (velocity, spin, force without weight,
        contact numbers; :func:`drumheat.mechanics.analysis.particle_mechanics`), compiled
        once per motion model."""
        if self._mechanics is None:
            self._mechanics = jax.jit(functools.partial(particle_mechanics, self.dem))
        return self._mechanics(state)

    def stack_mechanics(self, rows) -> dict:
        """The rows' ``"mechanics"`` stacked to ``(n_out, N, ...)`` float32 arrays (disk-backed
        for a spool); NaN at rows without them (outputs of a replay, which has no mechanics).
        Empty if no row has them."""
        first = next((r["mechanics"] for r in rows if "mechanics" in r), None)
        if first is None:
            return {}
        nan = {k: np.full(np.shape(first[k]), np.nan, np.float32) for k in PARTICLE_MECHANICS}
        return {k: stack_arrays(rows, f"mechanics.{k}",
                                (r["mechanics"][k] if "mechanics" in r else nan[k]
                                 for r in rows)) for k in PARTICLE_MECHANICS}

    def check(self, start, end, attempt=0):
        """The DEM's host-side check of a chunk (:meth:`drumheat.mechanics.DEM.check_chunk`):
        a neighbour-buffer overflow redoes it with larger buffers; NaN, escaped particles and
        excessive overlaps stop the run, naming the scene."""
        if not isinstance(end, DEMState):
            return None
        try:
            return self.dem.check_chunk(start, end, attempt)
        except DEMError as err:
            raise type(err)(f"{err} (scene {self.scene.name!r})", err.state) from None

    def passes(self, end) -> bool:
        """:meth:`drumheat.mechanics.DEM.passes` for a DEM state (any other: yes)."""
        return not isinstance(end, DEMState) or self.dem.passes(end)

    def checkpoint_meta(self, state) -> dict:
        if not isinstance(state, DEMState):
            return {}
        def plain(v):  # numpy scalars to JSON numbers
            return None if v is None else (int(v) if float(v).is_integer() and not
                                           isinstance(v, float) else float(v))

        return {"neighbors": {k: plain(getattr(state.nbrs, k)) for k in _NEIGHBOR_STATICS}}

    def restore_state(self, template, leaves, meta, log):
        state, log = super().restore_state(template, leaves, meta, log)
        if "neighbors" in meta:
            statics = {k: meta["neighbors"][k] for k in _NEIGHBOR_STATICS}
            state = state._replace(nbrs=dataclasses.replace(state.nbrs, **statics))
        return state, log

    def check_thermal_step(self, model, n_heated_walls: int) -> None:
        """Refuse a coupled thermal step ``dem.thermal_substeps x dt`` above the explicit limit
        of the densest contact network the bed can form (:func:`drumheat.motion.coupling.
        thermal_step_limit`): above it the temperatures would oscillate and leave the bounds
        of the maximum principle while the energy balance still closed."""
        d = [g.diameter for g in self.scene.groups]
        limit = thermal_step_limit(model, self.scene.n_parcels, self.scene.dim,
                                   max(d) / min(d), min(n_heated_walls, 3))
        substeps = self.scene.dem.thermal_substeps
        h = substeps * self.dt
        cfg = self.scene.dem
        if cfg.replay_after is not None and cfg.record_interval > limit:
            raise SceneError("dem.record_interval", cfg.record_interval,
                             "the replay after dem.replay_after takes one explicit thermal step "
                             f"per recording interval; {cfg.record_interval:g} s exceeds the "
                             f"explicit limit {limit:.3g} s of the densest contact network "
                             "(weigler eq. [2.2]): record more often or check the coefficients",
                             self.scene.name)
        if h <= limit:
            return
        if model.drum_wall is not None:  # [heat.drum_wall]: is it the wall's segments' limit?
            _wall_step_refusal(self.scene, model, h, limit, max(d) / min(d),
                               min(n_heated_walls, 3))
        if substeps > 1 and self.dt <= limit:
            raise SceneError("dem.thermal_substeps", substeps,
                             f"the thermal step {substeps} x {self.dt:.3g} s = {h:.3g} s exceeds "
                             f"the explicit limit {limit:.3g} s of the densest contact network "
                             f"(weigler eq. [2.2]); use at most {int(limit // self.dt)}",
                             self.scene.name)
        key = "heat.wall.alpha" if self.scene.heat.wall is not None else "heat.contact.alpha"
        raise SceneError(key, self.scene.get(key) if self.scene.get(key.rsplit(".", 1)[0])
                         is not None else None,
                         f"the coefficients make the explicit thermal limit of the densest "
                         f"contact network {limit:.3g} s (weigler eq. [2.2]), below the "
                         f"mechanical step {self.dt:.3g} s: no thermal step of this DEM can be "
                         "stable; check the coefficients (units: W/(m2 K))", self.scene.name)

    # -- cost ---------------------------------------------------------------------------------
    def mechanical_steps(self) -> int:
        """Mechanical steps of the whole run (the chunks that run the DEM)."""
        return int(round((self.coupled_until() - self.times[0]) / self.dt))

    def coupled_until(self) -> float:
        """Time (s) up to which the DEM itself runs (a replay follows where the scene asks)."""
        return float(self.times[-1])

    def progress_work(self, t0: float, t1: float) -> float:
        """Estimated seconds from ``t0`` to ``t1``, by the model of :meth:`cost` (mechanical
        steps times the warm-up's time per step, plus the host work of the chunk), so that the
        ETA of a run whose replay follows the DEM is not that of a DEM run throughout. Before
        :meth:`cost` ran: the mechanical steps, one per replayed chunk."""
        tc = self.coupled_until()
        steps = max(0.0, min(t1, tc) - min(t0, tc)) / self.dt
        if self._cost_model is None:
            return steps if steps > 0 else 1.0
        per_step, per_chunk = self._cost_model
        return steps * per_step + per_chunk

    def thermal_steps(self) -> int:
        """Thermal steps of the whole run."""
        return self.mechanical_steps() // max(1, self.scene.dem.thermal_substeps)

    def cost(self, state, in_place: bool = False) -> dict:
        """The run's step counts and its wall time estimated from a timed warm-up of
        :data:`WARMUP_STEPS` steps from ``state`` (after one compiling call), plus the host-side
        work of a chunk (observation and check, also timed after a compiling call) times the
        number of chunks. ``in_place`` (where :meth:`advances_in_place`): both warm-ups run in
        the buffers of ``state``, one after the other (the chunk a run into a result folder
        runs on the CPU, so compiled once for both, and one state in memory instead of two)."""
        n = self.mechanical_steps()
        k = max(1, min(WARMUP_STEPS, n))
        if in_place and self.advances_in_place(state):
            warm = jax.block_until_ready(self.dem.run_steps_in_place(state, k))  # compiles
            del state  # donated
            t0 = time.perf_counter()
            end = jax.block_until_ready(self.dem.run_steps_in_place(warm, k))
        else:
            jax.block_until_ready(self.dem.run_steps(state, k))  # compiles
            t0 = time.perf_counter()
            end = jax.block_until_ready(self.dem.run_steps(state, k))
        per_step = (time.perf_counter() - t0) / k
        jax.device_get(self.observe(end))  # compiles what an output and a check run
        self.dem._diag(end)
        t0 = time.perf_counter()
        jax.device_get(self.observe(end))
        jax.block_until_ready(self.dem._diag(end))
        per_chunk = time.perf_counter() - t0
        self._cost_model = (per_step, per_chunk)
        chunks = len(self.times) - 1
        return dict(mechanical_steps=n, thermal_steps=self.thermal_steps(), dt=self.dt,
                    chunks=chunks, seconds=n * per_step + chunks * per_chunk,
                    seconds_per_step=per_step, warmup_steps=k,
                    text=f"{n:.3g} mechanical steps of {self.dt:.3g} s and "
                         f"{self.thermal_steps():.3g} thermal steps (timed warm-up of {k} "
                         "steps)",
                    cheaper="softer contacts (dem.stiffness: the step grows as 1/sqrt(k); "
                            "docs/accuracy-vs-cost.md says what that costs in accuracy), "
                            "replaying the recorded contacts after a few revolutions "
                            "(dem.record_interval with dem.replay_after), fewer thermal steps "
                            "(dem.thermal_substeps), fewer outputs (run.output_interval), a "
                            "shorter run (run.duration)")


def _wall_step_refusal(scene, model, h: float, limit: float, size_ratio: float,
                       walls_at_once: int) -> None:
    """Raise a :class:`SceneError` naming ``[heat.drum_wall]`` when the drum wall's segments,
    not the particles, make the thermal step ``h`` (s) exceed the explicit ``limit`` (s)."""
    bare = dataclasses.replace(model, drum_wall=None)  # the particles alone
    if h > thermal_step_limit(bare, scene.n_parcels, scene.dim, size_ratio, walls_at_once):
        return  # the particles' own limit binds: the caller says so
    raise SceneError("heat.drum_wall.thickness", scene.heat.drum_wall.thickness,
                     f"the drum wall's segments make the explicit thermal limit {limit:.3g} s "
                     f"(C_k / (A_k (U + h_i) + G), docs/models/drum-wall.md), below the thermal "
                     f"step {h:.3g} s: a thicker wall, fewer heat.drum_wall.segments or fewer "
                     "dem.thermal_substeps", scene.name)
