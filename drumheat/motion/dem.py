"""Motion model ``dem``: soft-sphere DEM in a rotating drum with heat transfer in the same scan.

The mechanics come from :mod:`drumheat.mechanics` (cell-list neighbour lists, spring-dashpot
contacts with tangential history, rotation, rotating drum shell); the heat model is the same
composed :class:`~drumheat.thermal.model.ThermalModel` as for resting beds. Every
``[dem] thermal_substeps`` mechanical steps the particle temperatures take one explicit step
(weigler-thermal-dem.md eq. [2.7]) on the contacts that existed during those steps, each
contact's conductance weighted by the fraction of the thermal step it existed
(:mod:`drumheat.motion.coupling`). With one substep this is the coupled scheme of the thesis
(PFC, Δt_th = Δt_mech, section 6.1). The thermal step limit m c / sum(alpha A) (eq. [2.2], about
10 s) is far above any mechanical step, so the explicit update is always stable here.

Temperatures are float64; the mechanics may run in float32 (``[dem] precision``).

With ``[dem] record_interval`` the run also records its contact network: for every recording
interval the touching pairs and wall contacts with their contact durations (``contacts.npz``),
which motion model ``replay`` integrates without mechanics (Weigler's decoupled method,
section 6.1, without its dense-matrix size limit). With ``[dem] replay_after`` the run switches
from mechanics to the cyclic replay of its own recording after that time; the state is then
``{"model", "T", "Q", "g", "recording"}``, the :class:`~drumheat.motion.replay.Recording` staying
on the host (the result folder's files, or memory) and each chunk putting the networks of its
intervals on the device (:meth:`~drumheat.motion.replay.Recording.replay`).

The run loop's chunks are the recording intervals while the mechanics run (the recording is
taken between them, on the host) and the output intervals otherwise; the neighbour lists are
checked after every chunk (an overflow redoes it with larger buffers).
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from drumheat import assemble
from drumheat.devices import to_device, to_host
from drumheat.mechanics import DEMError, DEMState, make_dem
from drumheat.mechanics.analysis import count_interfraction_contacts
from drumheat.mechanics.dissipation import SOURCES
from drumheat.mechanics.integrator import JIT_OPTIONS
from drumheat.motion.base import register
from drumheat.motion.coupling import (initial_extra, mean_contacts, make_thermal_update,
                                      recorded_times, reset_count, reset_record)
from drumheat.motion.dem_common import DEMMotion
from drumheat.motion.npz_files import save_npz
from drumheat.motion.replay import Recording
from drumheat.motion.rows import stack_arrays, stack_rows
from drumheat.motion.spooled_array import SpooledArray
from drumheat.motion.static import drum_wall_arrays
from drumheat.motion.trajectory import Trajectory
from drumheat.scene import Scene

__all__ = ["DEMBed", "ContactRecorder"]

#: name of the vmap axis of a DEM ensemble
BATCH_AXIS = "variants"


def friction_columns(rows) -> dict:
    """Time-series columns of friction heat from the observed rows (J since t = 0):
    ``Q_friction_walls`` (the walls' share) and ``dissipated:<source>`` (particles and walls,
    :data:`drumheat.mechanics.dissipation.SOURCES`)."""
    fr = stack_rows([r["friction"] for r in rows])
    out = {"Q_friction_walls": np.asarray(fr["walls"], float)}
    for k, name in enumerate(SOURCES):
        out[f"dissipated:{name}"] = np.asarray(fr["sources"][:, k], float)
    return out


class ContactRecorder:
    """Collects the contact network per recording interval in compact (CSR-like) form.

    ``wall_heated``, ``wall_ids`` (per wall primitive), ``diameter``, ``group`` and the scene's
    TOML text go into the recording unchanged (``contacts.npz``). With ``directory`` (a run
    with a result folder: ``<out>/.log``) the recorded intervals go to files there as they
    come (:class:`~drumheat.motion.spooled_array.SpooledArray`) and are read back
    memory-mapped; without, they stay in memory.
    """

    #: the growing arrays of the recording: dtype and the shape of one row (``"positions"``:
    #: one row per interval end, float32 as ``contacts.npz`` stores them)
    COLUMNS = {"pair_i": (np.int32, ()), "pair_j": (np.int32, ()),
               "pair_duration": (np.float64, ()), "wall_particle": (np.int32, ()),
               "wall_index": (np.int32, ()), "wall_duration": (np.float64, ()),
               "positions": (np.float32, None)}

    def __init__(self, n, n_walls, interval, *, wall_heated, wall_ids, diameter, group,
                 scene_toml: str, directory=None, lengths: dict | None = None, dim=None):
        self.n, self.n_walls, self.interval = n, n_walls, interval
        self.static = dict(wall_heated=wall_heated, wall_ids=wall_ids, diameter=diameter,
                           group=group, scene=scene_toml)
        self.pair_ptr, self.wall_ptr = [0], [0]
        self.directory = None if directory is None else Path(directory)
        if self.directory is not None:
            self.directory.mkdir(parents=True, exist_ok=True)
        # lengths, dim: the rows of files a stopped run wrote and its positions' dimension
        lengths = lengths or {}
        self.columns = {key: SpooledArray(
            dtype, (int(n), int(dim)) if key == "positions" and dim is not None else row,
            None if self.directory is None else self.directory / f"contacts.{key}.bin",
            lengths.get(key, 0)) for key, (dtype, row) in self.COLUMNS.items()}

    def add(self, idx, extra, position):
        """Record one interval: the neighbour pairs ``idx`` with their contact times
        (:func:`~drumheat.motion.coupling.recorded_times` of ``extra``), the wall contacts
        and the positions at its end."""
        pt, wt = (np.asarray(a) for a in _recorded_times(extra))
        keep = (idx[0] < self.n) & (pt > 0)
        c = self.columns
        c["pair_i"].append(idx[0][keep])
        c["pair_j"].append(idx[1][keep])
        c["pair_duration"].append(pt[keep])
        self.pair_ptr.append(self.pair_ptr[-1] + int(keep.sum()))
        nz = np.nonzero(wt > 0)[0]
        c["wall_particle"].append(nz // self.n_walls)
        c["wall_index"].append(nz % self.n_walls)
        c["wall_duration"].append(wt[nz])
        self.wall_ptr.append(self.wall_ptr[-1] + len(nz))
        self.add_positions(position)

    def add_positions(self, position):
        """Keep the positions at the end of an interval (or the recording's start) in float32,
        as ``contacts.npz`` stores them: the recording grows by 12 bytes per particle and
        interval for them instead of 24."""
        self.columns["positions"].append(np.asarray(position, np.float32)[None])

    @classmethod
    def from_arrays(cls, a: dict, directory=None) -> "ContactRecorder":
        """A recorder holding the recording ``a``: what :meth:`arrays` gave, or what
        :meth:`checkpoint_arrays` gave of a recorder whose intervals are in the files of
        ``directory`` (which are adopted, cut to the recorded lengths at the next interval)."""
        pp, wp = (np.asarray(a[k], np.int64) for k in ("pair_ptr", "wall_ptr"))
        spooled = bool(a.get("spooled", False))
        if spooled and directory is None:
            raise ValueError("the recording is in files of a result folder; give its directory")
        lengths = {k: (int(pp[-1]) if k.startswith("pair") else int(wp[-1])) for k in
                   cls.COLUMNS if k != "positions"}
        lengths["positions"] = len(pp)
        rec = cls(int(a["n_particles"]), int(a["n_walls"]), float(a["interval"]),
                  wall_heated=a["wall_heated"], wall_ids=a["wall_ids"], diameter=a["diameter"],
                  group=a["group"], scene_toml=str(a["scene"]), directory=directory,
                  lengths=lengths if spooled else None, dim=a["dim"] if spooled else None)
        rec.pair_ptr, rec.wall_ptr = [int(x) for x in pp], [int(x) for x in wp]
        if not spooled:
            # checkpoints of earlier versions kept the positions in float64 as "positions_full"
            blocks = dict(a, positions=a.get("positions_full", a["positions"]))
            for key, column in rec.columns.items():
                column.append(blocks[key])
        return rec

    def arrays(self, first: int = 0) -> dict:
        """The recording as arrays (the content of ``contacts.npz``); with ``first``, only
        intervals ``first`` to the last, as :class:`~drumheat.motion.replay.Recording` keeps
        them (pointers and positions from that interval on). The recorded intervals come as
        read-only memory maps of the files of a recorder with a ``directory``, else from memory."""
        pp, wp = (np.asarray(ptr[first:], np.int64) for ptr in (self.pair_ptr, self.wall_ptr))
        start = {k: (pp[0] if k.startswith("pair") else wp[0]) for k in self.COLUMNS}
        start["positions"] = first
        out = {k: self.columns[k].read(int(start[k])) for k in self.COLUMNS}
        return dict(interval=self.interval, n_particles=self.n, n_walls=self.n_walls,
                    pair_ptr=pp - pp[0], wall_ptr=wp - wp[0], **out, **self.static)

    def checkpoint_arrays(self) -> dict:
        """What a checkpoint keeps of the recording: all of it in memory (:meth:`arrays`), or,
        with a ``directory``, the pointers and the constants only (``spooled``), the intervals
        staying in the files (:meth:`from_arrays` adopts them)."""
        if self.directory is None:
            return self.arrays()
        return dict(interval=self.interval, n_particles=self.n, n_walls=self.n_walls,
                    pair_ptr=np.asarray(self.pair_ptr, np.int64),
                    wall_ptr=np.asarray(self.wall_ptr, np.int64), spooled=True,
                    dim=self.columns["positions"].row_shape[-1], **self.static)

    def save(self, path):
        """Write ``contacts.npz`` (memory-mapped intervals are read in blocks as they are
        compressed, their pages given back after each block: :func:`save_npz`)."""
        save_npz(path, self.arrays())

    def saver(self):
        """:meth:`save` for a run's result (``Trajectory.files``). With a ``directory`` it
        writes the intervals mapped now: a mapping outlives its file, which goes when the
        complete result replaces the running folder."""
        if self.directory is None:
            return self.save
        arrays = self.arrays()
        return lambda path: save_npz(path, arrays)


@register
class DEMBed(DEMMotion):
    """A bed moved by DEM in a rotating drum, with heat transfer coupled in the same scan.

    Parameters
    ----------
    scene : Scene
        Needs ``[drum]`` and ``[dem]``; 2D (monolayer) or 3D (slice of axial length
        ``drum.depth``, periodic along the axis).

    Attributes
    ----------
    dt : float
        Mechanical step, s: at most the requested (or default) one, such that the recording
        interval (else the output interval) is a whole number of thermal steps. It does not
        depend on the thermal sub-cycling, so that variants with different thermal steps see
        the same mechanics; thermal steps run on across output times (an output shows the
        state after the last completed thermal step).
    t_crit : float
        Critical step, s (weigler eq. [2.1]).
    times : ndarray
        Chunk ends of the run loop (recording intervals while the mechanics run, output
        intervals after ``replay_after``); ``output_index`` says which are output times.
    """

    name = "dem"
    vmappable = True
    particle_shardable = True

    def __init__(self, scene: Scene):
        super().__init__(scene)
        cfg = scene.dem
        self.setup = setup = assemble.dem_setup(scene)
        self.group = assemble.group_index(scene)
        self.diameter = assemble.diameters(scene)
        self.n = len(self.diameter)
        self.walls = assemble.drum_walls(scene)
        self.wall_heated = np.array([w.temperature is not None for w in self.walls])
        self.wall_ids = np.array([w.wall_id for w in self.walls], np.int32)
        self.params, self.k_n, self.mech = setup.params, setup.k_n, setup.particles
        self.dim = scene.dim
        self.periodic = scene.drum.depth if scene.dim == 3 else None
        self.gravity, self.dtype, self.t_crit = setup.gravity, setup.dtype, setup.t_crit
        self.position_dtype = setup.position_dtype
        self.t_out = assemble.output_times(scene)
        out_iv = scene.run.output_interval
        unit = cfg.record_interval if cfg.record_interval is not None else out_iv
        ratio = int(round(out_iv / unit))
        self.dt, steps_per_unit = assemble.fit_time_step(setup.dt, unit)
        self.substeps = cfg.thermal_substeps
        self.steps_per_output = steps_per_unit * ratio
        self.steps_per_record = steps_per_unit if cfg.record_interval is not None else None
        n_out = len(self.t_out) - 1
        self.n_coupled = n_out if cfg.replay_after is None else min(
            n_out, int(round(cfg.replay_after / out_iv)))
        # chunk ends: the recording intervals of the coupled outputs, then the output times
        sub = ratio if self.steps_per_record else 1
        coupled = [self.t_out[m + 1] if k == sub else
                   self.t_out[m] + (self.t_out[m + 1] - self.t_out[m]) * k / sub
                   for m in range(self.n_coupled) for k in range(1, sub + 1)]
        self.times = np.concatenate([[self.t_out[0]], coupled, self.t_out[self.n_coupled + 1:]])
        self.output_index = np.concatenate([np.arange(0, self.n_coupled * sub + 1, sub),
                                            self.n_coupled * sub
                                            + np.arange(1, n_out - self.n_coupled + 1)])
        model, _ = self.model()
        self.check_thermal_step(model, int(np.sum(self.wall_heated)))
        self._skeleton = eqx.partition(model, eqx.is_array)[1]
        self.dem = self.make_dem(model)
        self._packing = None
        self._batched = None
        self._start_in_place = None  # chunk_start, jitted with the state donated

    # -- set-up ---------------------------------------------------------------------------------
    def model(self, params=None):
        """Thermal model and initial temperatures (:func:`drumheat.assemble.thermal_model`)."""
        return assemble.thermal_model(self.scene, params)

    def make_dem(self, model, batch_axis: str | None = None):
        """The DEM system with the coupled thermal update of ``model``'s structure.

        ``batch_axis``: the name of a vmap axis over states (ensembles), see
        :func:`drumheat.mechanics.make_dem` and :func:`~drumheat.motion.coupling.make_thermal_update`.
        """
        friction = assemble.friction_heat(self.scene)
        backend = self.contact_backend(batch_axis is not None).backend
        update = make_thermal_update(model, self.n, len(self.walls), self.wall_heated,
                                     self.substeps, self.dt, batch_axis=batch_axis,
                                     wall_ids=self.wall_ids, friction=friction is not None,
                                     pair_kernel=backend)
        return make_dem(self.mech, self.walls, self.params, dim=self.dim, dt=self.dt,
                        gravity=self.gravity, periodic_length=self.periodic,
                        skin=self.scene.dem.skin, dtype=self.dtype,
                        position_dtype=self.position_dtype, extra_update=update,
                        chunk=self.steps_per_record or self.steps_per_output,
                        batch_axis=batch_axis, conduction_gap=self.setup.conduction_gap,
                        pair_kernel=backend, friction_heat=friction,
                        contact_details=False)  # the coupled heat reads pair_conducts only

    def packing_positions(self) -> np.ndarray:
        """Initial positions (pouring, deposition or a file), settled with the drum at rest
        for ``dem.settle_time``; computed once."""
        if self._packing is None:
            pos = assemble.drum_packing(self.scene, self.setup, self.walls, self.periodic)
            if self.scene.dem.settle_time > 0:
                pos = self._settle(pos)
            self._packing = pos
        return self._packing

    def _settle(self, pos0):
        from drumheat.geometry.walls import walls_at_rest

        dem = make_dem(self.mech, walls_at_rest(self.walls), self.params, dim=self.dim,
                       dt=self.dt, gravity=self.gravity, periodic_length=self.periodic,
                       skin=self.scene.dem.skin, dtype=self.dtype,
                       position_dtype=self.position_dtype)
        steps = max(1, int(round(self.scene.dem.settle_time / self.dt)))
        state = dem.run(dem.init(pos0), steps)
        return np.asarray(state.position, float)

    # -- the loop -------------------------------------------------------------------------------
    def initial_state(self, params=None):
        model, T0 = self.model(params)
        state = self.dem.init(self.packing_positions())
        cap = state.nbrs.idx.shape[1]
        return state._replace(extra=initial_extra(
            model, T0, cap, self.n, len(self.walls), self.dt,
            friction=self.scene.heat.friction is not None,
            record=self.steps_per_record is not None))

    def _steps(self, t0, t1, unit) -> int:
        return int(round((t1 - t0) / unit))

    def _start(self, state, t0):
        """The state a chunk starts from (:func:`chunk_start`)."""
        return _chunk_start(state, self._at_output(t0), self.wall_heated)

    def _at_output(self, t0) -> bool:
        """Whether ``t0`` is an output time (where the contact-time count starts anew)."""
        return bool(np.any(np.isclose(self.t_out, t0, rtol=0, atol=1e-9 * self.dt)))

    def advance(self, state, t0, t1):
        if isinstance(state, dict):  # the cyclic replay after dem.replay_after
            rec = state["recording"]
            T, Q, g = rec.replay(state["model"], state["T"], state["Q"], state["g"],
                                 self._steps(t0, t1, rec.tau))
            return dict(state, T=T, Q=Q, g=g)
        return self.dem.run_steps(self._start(state, t0), self._steps(t0, t1, self.dt))

    def advances_in_place(self, state) -> bool:
        # the coupled DEM's chunks (not the replay's, whose state is host data)
        return isinstance(state, DEMState)

    def advance_in_place(self, state, t0, t1):
        if not self.advances_in_place(state):
            return self.advance(state, t0, t1)
        # the start made in the buffers of `state` too: its cleared accumulators would
        # otherwise be new arrays, and the caller's old ones (one int32 per pair slot and per
        # wall slot) would stay alive through the chunk. keep_unused: the old accumulators,
        # which the start does not read, are donated too (XLA would drop them as unused
        # inputs, and JAX donates only the inputs it passes)
        if self._start_in_place is None:
            self._start_in_place = jax.jit(partial(chunk_start, wall_heated=self.wall_heated),
                                           static_argnums=1, donate_argnums=0,
                                           keep_unused=True)
        start = self._start_in_place(state, self._at_output(t0))
        return self.dem.run_steps_in_place(start, self._steps(t0, t1, self.dt))

    def start_log(self, state, params=None, spool=None):
        rec = None
        if self.steps_per_record:
            rec = ContactRecorder(self.n, len(self.walls), self.dt * self.steps_per_record,
                                  wall_heated=self.wall_heated, wall_ids=self.wall_ids,
                                  diameter=self.diameter, group=self.group,
                                  scene_toml=self.scene.to_toml(), directory=spool)
            rec.add_positions(state.position)
        return {"recorder": rec, "recording": None, "g0": 0}

    def between(self, state, log, t):
        if isinstance(state, dict):
            return state, log
        if log["recorder"] is not None:
            ex = jax.device_get(state.extra)
            log["recorder"].add(np.asarray(state.nbrs.idx), ex, np.asarray(state.position))
        if self._switches_at(t):
            state, log = self._switch_to_replay(state, log, release=True)
        return state, log

    def _switches_at(self, t) -> bool:
        """Whether the run goes over to the cyclic replay at ``t`` (``dem.replay_after``)."""
        return self.n_coupled < len(self.t_out) - 1 and abs(t - self.t_out[self.n_coupled]) < 1e-9

    def between_note(self, t):
        if not self._switches_at(t):
            return None
        return f"switching to the cyclic replay: the restart assignment of {self.n} particles"

    def save_log(self, log) -> dict:
        rec = log["recorder"]
        if rec is None:
            return {}
        return {"recorder": rec.checkpoint_arrays()}

    def load_log(self, arrays, log, spool=None):
        if "recorder" in arrays:
            log = dict(log, recorder=ContactRecorder.from_arrays(arrays["recorder"], spool))
        return log

    def restore_state(self, template, leaves, meta, log):
        if meta.get("phase") == "replay":  # after dem.replay_after: rebuild the replay state
            template, log = self._switch_to_replay(template, log)
        return super().restore_state(template, leaves, meta, log)

    def checkpoint_meta(self, state) -> dict:
        return dict(super().checkpoint_meta(state),
                    phase="replay" if isinstance(state, dict) else "dem")

    def _switch_to_replay(self, state, log, release: bool = False):
        """Continue by cyclic replay of the last ``replay_cycle`` of the recording.

        ``release``: free the buffers of the coupled DEM's ``state`` that the replay does not
        take over (:func:`release_mechanics`) before the replay is assembled (the run loop,
        which calls this from :meth:`between`, still holds ``state``)."""
        cfg = self.scene.dem
        cycle = cfg.replayed_cycle
        rec = log["recorder"]
        n_rec = len(rec.pair_ptr) - 1
        model = eqx.combine(state.extra.model, self._skeleton)
        T, Q = state.extra.T, state.extra.Q
        if release:
            release_mechanics(state)
        recording = Recording(rec.arrays(first=n_rec - int(round(cycle / cfg.record_interval))))
        g0 = recording.n_intervals  # the first step restarts the cycle
        log = dict(log, recording=recording, g0=g0)
        # the recording travels in the state as host data (no array leaves: a checkpoint holds
        # T, Q and g only); each chunk puts its own intervals on the device
        return {"model": model, "T": T, "Q": Q, "g": to_device(g0, jnp.int64),
                "recording": recording}, log

    def observe(self, state) -> dict:
        if isinstance(state, dict):
            return {"T": state["T"], "Q": state["Q"], "g": state["g"]}
        ex = state.extra
        n_pairs, n_wall = mean_contacts(ex, self.wall_heated, self.steps_per_output * self.dt,
                                        self.substeps)
        row = {"T": ex.T, "Q": ex.Q, "position": state.position,
               "n_pairs": n_pairs, "n_wall": n_wall,
               "mechanics": self.mechanics(state)}
        if ex.wall is not None:  # [heat.drum_wall]
            row["wall"] = ex.wall
        if ex.friction is not None:
            row["friction"] = {"walls": ex.friction.walls, "sources": ex.friction.sources}
        return row

    def finish(self, rows, log, state) -> Trajectory:
        n_c = self.n_coupled
        recording = log["recording"]
        T = stack_arrays(rows, "T", (r["T"] for r in rows))
        Q = {a: np.array([float(r["Q"][a]) for r in rows]) for a in rows[0]["Q"]}
        positions = stack_arrays(rows, "position", (
            r["position"] if k <= n_c else recording.position_at(int(r["g"]))
            for k, r in enumerate(rows)))
        n_pairs = [float(r["n_pairs"]) for r in rows[1:n_c + 1]]
        n_wall = [float(r["n_wall"]) for r in rows[1:n_c + 1]]
        if recording is not None:  # not moving in a replay: the recording's means
            n_pairs += [recording.mean_pairs] * (len(rows) - 1 - n_c)
            n_wall += [recording.mean_wall] * (len(rows) - 1 - n_c)
        n_pairs = np.array(n_pairs[:1] + n_pairs)
        n_wall = np.array(n_wall[:1] + n_wall)
        # eq. [1.10] area: d^2 x wall contacts, averaged from the start (thesis App. A9 uses the
        # mean number of wall contacts of the run)
        cum_wall = np.concatenate([[n_wall[0]], np.cumsum(n_wall[1:]) / np.arange(1, len(n_wall))])
        d2 = float(np.mean(self.diameter**2))
        extra = {}
        if len(self.scene.groups) == 2:
            extra["interfraction_contacts"] = np.concatenate([
                self._interfraction(positions[:n_c + 1]),
                np.full(len(positions) - n_c - 1, np.nan)])
        if "friction" in rows[0]:
            extra.update(friction_columns(rows))
        rec = log["recorder"]
        particles = (state["model"] if isinstance(state, dict)
                     else eqx.combine(state.extra.model, self._skeleton)).particles
        wall = {}
        if "wall" in rows[0]:  # [heat.drum_wall] (no replay phase: scene/rules.py)
            wall = drum_wall_arrays(stack_rows([r["wall"] for r in rows]),
                                    eqx.combine(state.extra.model, self._skeleton).drum_wall)
        return Trajectory(
            t=self.t_out, T=T, Q=Q, position=positions, diameter=self.diameter,
            mass=np.asarray(particles.mass), capacity=particles.host_capacity(),
            group=self.group,
            n_contacts=n_pairs, n_wall_contacts=n_wall, wall_area=d2 * cum_wall, extra=extra,
            files={"contacts.npz": rec.saver()} if rec is not None else {},
            info=self.backend_info(), mechanics=self.stack_mechanics(rows), drum_wall=wall)

    def _interfraction(self, positions) -> np.ndarray:
        """Contacts between the two groups at each output time (mixing observable), with the
        definition of the contacts that conduct (overlap or a gap within
        ``heat.contact.gap_tolerance``, :func:`drumheat.assemble.conduction_gaps`)."""
        from scipy.spatial import cKDTree

        counts = []
        d = self.diameter
        gap = self.setup.conduction_gap[0]
        for p in positions:
            box = None
            if self.periodic is not None:
                p = p.copy()
                p[:, -1] = np.mod(p[:, -1], self.periodic)
                box = np.array([np.inf] * (self.dim - 1) + [self.periodic])
                box[:-1] = 1e9
            tree = cKDTree(p, boxsize=box)
            pairs = np.array(sorted(tree.query_pairs(d.max() * (1.001 + gap))),
                             int).reshape(-1, 2)
            if len(pairs):
                dist = np.linalg.norm(p[pairs[:, 0]] - p[pairs[:, 1]], axis=1)
                if self.periodic is not None:
                    dz = np.abs(p[pairs[:, 0], -1] - p[pairs[:, 1], -1])
                    dz = np.minimum(dz, self.periodic - dz)
                    dist = np.sqrt(np.sum((p[pairs[:, 0], :-1] - p[pairs[:, 1], :-1]) ** 2, 1)
                                   + dz**2)
                di, dj = d[pairs[:, 0]], d[pairs[:, 1]]
                pairs = pairs[(dist < 0.5 * (di + dj)) | (dist - 0.5 * (di + dj)
                                                          <= gap * np.minimum(di, dj))]
            c = count_interfraction_contacts(pairs[:, 0], pairs[:, 1], np.ones(len(pairs), bool),
                                             self.group)
            counts.append(float(np.asarray(c)))
        return np.array(counts)

    def coupled_until(self) -> float:
        return float(self.t_out[self.n_coupled])

    # -- ensembles ------------------------------------------------------------------------------
    def not_vmappable(self) -> str | None:
        if self.scene.dem.record_interval is not None or self.scene.dem.replay_after is not None:
            return ("dem.record_interval / dem.replay_after (contact recording and replay) are "
                    "not batched")
        return None

    def shared(self) -> dict:
        return dict(super().shared(), **{
            "the mechanical time step and thermal sub-steps": (self.dt, self.steps_per_output,
                                                               self.substeps),
            "the DEM contact parameters (compile-time constants of the DEM step)":
                (self.k_n, _values(self.params)),
            "the particles' sizes and masses": _values(self.mech),
            "the walls (drum diameter, speed, heated or not)": (
                [(float(w.radius), float(w.rpm)) for w in self.walls],
                tuple(self.wall_heated)),
            "the DEM set-up (gravity, precision, skin, periodic length)": (
                tuple(self.gravity), (str(self.dtype), str(self.position_dtype)),
                self.scene.dem.skin, self.periodic),
        })

    def align(self, states):
        """One pair and one cell-list capacity for all variants' neighbour lists."""
        dem = self.dem
        cap = max(int(s.nbrs.idx.shape[1]) for s in states)
        cell_cap = max(int(s.nbrs.cell_list_capacity or 0) for s in states)
        return _common_neighbors(dem, states, cap, cell_cap)

    def advance_batch(self, states, axes, t0, t1):
        if self._batched is None:
            dem = self.make_dem(self.model()[0], batch_axis=BATCH_AXIS)
            self._batched = (dem, jax.jit(jax.vmap(dem.run_steps_fn, in_axes=(0, None),
                                                   axis_name=BATCH_AXIS),
                                          compiler_options=JIT_OPTIONS))
        dem, run = self._batched
        # the variants' states come from the single-run DEM, whose C++ loop may keep its lists
        # in the cell order: the batched DEM (the JAX kernel) takes them in canonical order
        start = jax.vmap(lambda s: dem.adopt(self._start(s, t0)))(states)
        return run(start, jnp.asarray(self._steps(t0, t1, self.dt), jnp.int32))

    def check_batch(self, start, end, n: int, unstack, stack, attempt: int = 0):
        """All variants share one neighbour capacity: an overflow in any reallocates all and
        redoes the chunk; every variant is checked (NaN, escape, overlap)."""
        dem = self.dem
        diag = jax.jit(jax.vmap(dem._diag))
        d = to_host(diag(end))
        starts = unstack(start)
        if np.any(d["overflow"][:n]):
            code = int(np.bitwise_or.reduce(np.asarray(to_host(end.nbrs.error.code))[:n]))
            from drumheat.mechanics.neighbors import PEC

            cap = int(starts[0].nbrs.idx.shape[1])
            need = cap
            if code & PEC.NEIGHBOR_LIST_OVERFLOW:
                need = 2 * cap
                for st in unstack(end):
                    if bool(jnp.all(jnp.isfinite(st.position))):
                        est = dem.neighbor.count_pairs(st.position)
                        need = max(need, int(est * dem.neighbor.capacity_multiplier) + 1)
            cc = int(starts[0].nbrs.cell_list_capacity or 0)
            if code & PEC.CELL_LIST_OVERFLOW:
                cc += max(1, cc // 2) * (attempt + 1)
            return stack(_common_neighbors(dem, starts, need, cc, realloc=True))
        for v, (s, e) in enumerate(zip(starts, unstack(end))):
            try:
                dem._check({key: val[v] for key, val in d.items()}, e, s)
            except DEMError as err:
                raise type(err)(f"variant {v}: {err}", err.state) from None
        return None


_recorded_times = jax.jit(recorded_times)  # one compiled program, not one per operation


def chunk_start(state: DEMState, at_output: bool, wall_heated) -> DEMState:
    """The state a chunk starts from: the recording's accumulators
    (:func:`~drumheat.motion.coupling.reset_record`) and the overlap monitor cleared, and at the
    start of an output interval (``at_output``) the contact-time count
    (:func:`~drumheat.motion.coupling.reset_count`; ``wall_heated`` (n_walls,) bool)."""
    extra = reset_record(state.extra)
    if at_output:
        extra = reset_count(extra, wall_heated)
    return state._replace(extra=extra, max_overlap=jnp.zeros_like(state.max_overlap))


#: :func:`chunk_start` as one compiled program (evaluated eagerly, each of its operations
#: compiles one of its own: drumheat.devices.to_device)
_chunk_start = jax.jit(chunk_start, static_argnums=1)


def release_mechanics(state: DEMState) -> None:
    """Free the device buffers of ``state`` but those of its temperatures, heat account and
    thermal parameters (``extra.T``, ``extra.Q``, ``extra.model``), which the cyclic replay
    takes over: the positions, velocities, neighbour list, springs and contact-time
    accumulators, nearly all of the state. ``state`` is unusable afterwards; arrays made from it
    on the host (``jax.device_get``) stay valid."""
    ex = state.extra
    keep = {id(x) for x in jax.tree_util.tree_leaves((ex.T, ex.Q, ex.model))}
    for x in jax.tree_util.tree_leaves(state):
        if isinstance(x, jax.Array) and id(x) not in keep and not x.is_deleted():
            x.delete()


def _values(tree) -> tuple:
    """The numbers of a PyTree's array leaves, for comparing variants."""
    return tuple(np.asarray(a).tolist() for a in jax.tree_util.tree_leaves(tree))


def _common_neighbors(dem, states, cap: int, cell_cap: int, realloc: bool = False):
    """Neighbour lists of all states with one pair capacity and one cell-list capacity."""
    while True:
        new = []
        for st in states:
            if realloc or int(st.nbrs.idx.shape[1]) != cap or int(
                    st.nbrs.cell_list_capacity or 0) != cell_cap:
                old_cc = st.nbrs.cell_list_capacity or 0
                new.append(dem.reallocate(st, pair_capacity=cap,
                                          extra_cell_capacity=max(0, cell_cap - old_cc)))
            else:
                new.append(st)
        caps = {int(s.nbrs.idx.shape[1]) for s in new}
        ccs = {int(s.nbrs.cell_list_capacity or 0) for s in new}
        if len(caps) == 1 and len(ccs) == 1:
            return new
        cap, cell_cap = max(caps), max(ccs)
        states, realloc = new, True

