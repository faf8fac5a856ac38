"""Motion model ``dem``: soft-sphere DEM in a rotating drum with heat transfer in the same scan.

The mechanics come from :mod:`drumheat.mechanics` (jax-md neighbour lists, spring-dashpot
contacts with tangential history, rotation, rotating drum shell); the heat model is the same
composed :class:`~drumheat.thermal.composer.ThermalModel` as for resting beds. Every
``[dem] thermal_substeps`` mechanical steps the particle temperatures take one explicit step
(weigler-thermal-dem.md eq. [2.7]) on the contacts that existed during those steps, each
contact's conductance weighted by the fraction of the thermal step it existed (its contact
time is accumulated per neighbour pair, carried across neighbour-list rebuilds like the
tangential springs). With one substep this is the coupled scheme of the thesis (PFC, Δt_th =
Δt_mech, section 6.1). The thermal step limit m c / sum(alpha A) (eq. [2.2], about 10 s) is
far above any mechanical step, so the explicit update is always stable here.

Temperatures are float64; the mechanics may run in float32 (``[dem] precision``).

With ``[dem] record_interval`` the run also records its contact network: for every recording
interval the touching pairs and wall contacts with their contact durations (``contacts.npz``),
which motion model ``replay`` integrates without mechanics (Weigler's decoupled method,
section 6.1, without its dense-matrix size limit).
"""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.assemble import (group_index, group_property, initial_packing, initial_temperatures,
                          make_particles, output_times, scene_values)
from drumheat.geometry.walls import DrumShell, InnerCylinder, RadialPlate
from drumheat.materials import material
from drumheat.mechanics import DEMError, contact_params, make_dem
from drumheat.mechanics import make_particles as mechanical_particles
from drumheat.mechanics.contact_forces import normal_stiffness_from_youngs
from drumheat.runner.progress import SimProgress
from drumheat.scene import Scene, SceneError
from drumheat.thermal.composer import ThermalModel, make_thermal_model
from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.wall import WallConduction
from drumheat.motion.trajectory import Trajectory


def _steps(interval: float, dt: float) -> int:
    return max(1, int(round(interval / dt)))


def drum_walls(scene: Scene) -> list:
    """The walls of the scene's drum: the shell, then the inner cylinder, then the plates.

    All rotate with ``drum.rpm`` about the axis. Plate ``j`` lies at the polar angle
    ``plate_phase - j 360/sections`` (degrees, counter-clockwise from +x) at t = 0, from the
    inner cylinder (or the axis) to the shell. Section ``j`` lies between plates ``j`` and
    ``j + 1``: with the drum turning clockwise (rpm < 0) plate ``j`` is the section's plate 1
    (``B1C1``) and plate ``j + 1`` its plate 2 of herz-sectional-drum.md section 1, and the
    section's rotation angle is ``delta_j = 180 - plate angle of j`` (eq. 17).

    Every surface that carries a temperature gets the wall id of its place in
    ``drum.heated_surfaces()``, so the wall effect books its heat separately; a surface without
    a temperature exchanges no heat (its wall id is irrelevant and set to 0).
    """
    d = scene.drum
    R = 0.5 * d.diameter
    ids = {name: k for k, (name, _) in enumerate(d.heated_surfaces())}
    shell_id = ids.get("shell", ids.get("wall", 0))
    walls = [DrumShell(R, rpm=d.rpm, temperature=d.wall_temperature, wall_id=shell_id)]
    R2 = 0.5 * (d.inner_diameter or 0.0)
    if R2 > 0:
        walls.append(InnerCylinder(R2, rpm=d.rpm, temperature=d.inner_temperature,
                                   wall_id=ids.get("inner", 0)))
    n_sec = d.sections or 0
    phase0 = 180.0 if d.plate_phase is None else d.plate_phase
    for j in range(n_sec):
        walls.append(RadialPlate(R2, R, phase=math.radians(phase0 - j * 360.0 / n_sec),
                                 rpm=d.rpm, thickness=d.plate_thickness or 0.0,
                                 temperature=d.plate_temperature, wall_id=ids.get("plates", 0)))
    return walls


def thermal_network(idx, n, pair_time, wall_time, wall_heated, n_walls, h,
                    wall_ids=None) -> ContactNetwork:
    """Contact network of one thermal step from accumulated contact times.

    Parameters
    ----------
    idx : int array (2, M)
        Neighbour pairs (padding index ``n``).
    pair_time : array (M,)
        Time each pair touched during the thermal step, s.
    wall_time : array (n * n_walls,)
        Time each (particle, wall primitive) touched, s, row-major.
    wall_heated : bool array (n_walls,)
        Primitives that exchange heat (they carry a temperature).
    h : float
        Thermal step, s; weights are contact-time fractions ``time / h``.
    wall_ids : int array (n_walls,), optional
        Wall id (index into the wall effect's temperatures) of each primitive; default 0 for
        all (a drum whose only heated wall is the shell).
    """
    valid = idx[0] < n
    i = jnp.where(valid, idx[0], 0)
    j = jnp.where(valid, idx[1], 0)
    w_pair = jnp.where(valid, pair_time / h, 0.0)
    wp = jnp.repeat(jnp.arange(n), n_walls)
    wk = jnp.tile(jnp.arange(n_walls), n)
    w_wall = wall_time / h * wall_heated[wk]
    wid = jnp.zeros_like(wp) if wall_ids is None else jnp.asarray(wall_ids, wp.dtype)[wk]
    return ContactNetwork(i, j, w_pair, wp, wid, w_wall)


def make_thermal_update(model: ThermalModel, n: int, n_walls: int, wall_heated, substeps: int,
                        dt: float, batch_axis: str | None = None, wall_ids=None,
                        per_wall: bool = False):
    """``extra_update`` for :func:`drumheat.mechanics.make_dem`: coupled heat transfer.

    The ``extra`` state is a dict with ``T`` (N,) K, ``Q`` {account: J}, ``k`` (steps since the
    last thermal step), ``wall_time`` and ``rec_wall_time`` (N * n_walls,) s, and
    ``pair_data`` = {"time", "rec_time"} (M,) s aligned with the neighbour pairs (the
    integrator carries ``extra["pair_data"]`` across rebuilds like the tangential springs).

    If ``extra`` also holds ``"model"`` (the array leaves of a thermal model with the same
    structure as ``model``, ``eqx.partition(m, eqx.is_array)[0]``), that model is used instead
    of ``model``: the thermal parameters are then part of the state, and a ``vmap`` over states
    runs variants with different parameters (:func:`drumheat.run_ensemble`). ``batch_axis``
    names that vmap axis: the thermal sub-step then stays a real ``lax.cond`` (all members
    count the same steps).

    ``wall_ids`` (n_walls,) gives each wall primitive's wall id (see :func:`thermal_network`).
    ``per_wall``: every primitive is its own wall (``wall_ids = 0..n_walls-1``) and ``extra``
    also carries ``Q_walls`` (n_walls,) J, the heat each wall primitive gave to the particles
    (see :func:`initial_extra`).
    """
    import equinox as eqx

    h = substeps * dt
    heated = jnp.asarray(wall_heated, bool)
    skeleton = eqx.partition(model, eqx.is_array)[1]
    if per_wall and wall_ids is None:
        wall_ids = np.arange(n_walls, dtype=np.int32)

    def model_of(extra):
        return eqx.combine(extra["model"], skeleton) if "model" in extra else model

    def thermal_step(extra, idx):
        net = thermal_network(idx, n, extra["pair_data"]["time"], extra["wall_time"], heated,
                              n_walls, h, wall_ids)
        m = model_of(extra)
        q, ext = m.heat_flows(extra["T"], net)
        out = {}
        if per_wall:
            wall_effect = [e for e in m.effects if isinstance(e, WallConduction)]
            qw = (wall_effect[0].heat_flow_by_wall(extra["T"], m.particles, net, n_walls)
                  if wall_effect else jnp.zeros(n_walls))
            out["Q_walls"] = extra["Q_walls"] + h * qw
        T = extra["T"] + h * q / m.particles.capacity
        Q = {a: extra["Q"][a] + h * ext[a] if a in ext else extra["Q"][a] for a in extra["Q"]}
        pair = dict(extra["pair_data"], time=jnp.zeros_like(extra["pair_data"]["time"]))
        return dict(extra, T=T, Q=Q, k=jnp.zeros_like(extra["k"]), pair_data=pair,
                    wall_time=jnp.zeros_like(extra["wall_time"]), **out)

    def update(extra, state, contacts, dt_):
        pm = contacts.pair_mask.astype(jnp.float64) * dt
        wm = contacts.wall_mask.astype(jnp.float64) * dt
        pair = {"time": extra["pair_data"]["time"] + pm,
                "rec_time": extra["pair_data"]["rec_time"] + pm}
        extra = dict(extra, pair_data=pair, wall_time=extra["wall_time"] + wm,
                     rec_wall_time=extra["rec_wall_time"] + wm, k=extra["k"] + 1)
        if substeps == 1:
            return thermal_step(extra, state.nbrs.idx)
        go = extra["k"] >= substeps
        if batch_axis is not None:
            go = jax.lax.psum(go.astype(jnp.int32), batch_axis) > 0
        return jax.lax.cond(go, thermal_step, lambda e, _: e, extra,
                            state.nbrs.idx)

    return update


def initial_extra(model: ThermalModel, T0, capacity: int, n: int, n_walls: int,
                  per_wall: bool = False, accounts=()) -> dict:
    """The thermal part of the DEM state at t = 0.

    ``per_wall`` adds the per-primitive heat ``Q_walls`` (n_walls,) J; ``accounts`` adds
    further heat accounts (J, zero at t = 0) that an open boundary books into ``Q`` (e.g. the
    enthalpy carried in by recycled particles).
    """
    z = jnp.zeros(n * n_walls)
    Q = {a: jnp.zeros(()) for a in tuple(model.accounts) + tuple(accounts)}
    out = {"T": jnp.asarray(T0, float), "Q": Q,
           "k": jnp.asarray(0, jnp.int32), "wall_time": z, "rec_wall_time": z,
           "pair_data": {"time": jnp.zeros(capacity), "rec_time": jnp.zeros(capacity)}}
    if per_wall:
        out["Q_walls"] = jnp.zeros(n_walls)
    return out


def scene_contact_params(scene: Scene, diameter):
    """Contact parameters of the ``[dem]`` table (stiffness default ``E A_p / d_p`` of the
    smallest particle with the softest material, weigler eq. [2.3]); returns ``(params, k_n)``.
    """
    cfg = scene.dem
    value = scene_values(scene)
    k_n = cfg.stiffness
    if k_n is None:
        E = min(float(group_property(scene, value, k, "youngs_modulus"))
                for k in range(len(scene.groups)))
        k_n = float(normal_stiffness_from_youngs(E, float(np.min(diameter))))
    damping = {}
    if cfg.restitution is not None:
        damping = dict(restitution=cfg.restitution)
    elif cfg.damping_ratio is not None:
        damping = dict(damping_ratio=cfg.damping_ratio)
    params = contact_params(k_n, kn_wall=cfg.wall_stiffness, friction=cfg.friction,
                            wall_friction=cfg.wall_friction,
                            rolling_friction=cfg.rolling_friction, **damping)
    return params, k_n


class DEMBed:
    """A bed moved by DEM in a rotating drum, with heat transfer coupled in the same scan.

    Parameters
    ----------
    scene : Scene
        Needs ``[drum]`` and ``[dem]``; 2D (monolayer) or 3D (slice of axial length
        ``drum.depth``, periodic along the axis).
    """

    #: ``drumheat.run(..., devices=)`` may split the particle axis of the DEM state
    supports_particle_sharding = True
    #: device mesh over which the particle arrays are split (set by the runner), or None
    mesh = None

    def __init__(self, scene: Scene):
        if scene.dem is None:
            raise SceneError("dem", None, "motion model 'dem' needs the [dem] table", scene.name)
        for eff in ("internal",):
            if getattr(scene.heat, eff, None) is not None:
                raise SceneError(f"heat.{eff}", "a table", "motion model 'dem' supports lumped "
                                 "particles only so far", scene.name)
        self.scene = scene
        cfg = scene.dem
        value = scene_values(scene)
        self.group = group_index(scene)
        n_groups = len(scene.groups)
        self.diameter = np.concatenate([np.full(g.count, g.diameter) for g in scene.groups])
        density = np.array([float(group_property(scene, value, k, "density"))
                            for k in range(n_groups)])[self.group]
        self.n = len(self.diameter)
        self.walls = drum_walls(scene)
        self.wall_heated = np.array([w.temperature is not None for w in self.walls])
        self.wall_ids = np.array([w.wall_id for w in self.walls], np.int32)
        self.params, self.k_n = scene_contact_params(scene, self.diameter)
        self.mech = mechanical_particles(0.5 * self.diameter, density, group=self.group)
        self.dim = scene.dim
        self.periodic = scene.drum.depth if scene.dim == 3 else None
        gravity = np.zeros(self.dim)
        gravity[1] = -cfg.gravity
        self.gravity = gravity
        self.dtype = jnp.float32 if cfg.precision == "float32" else jnp.float64
        self.t_out = output_times(scene)
        # the mechanical step: at most the requested (or default) one, dividing the output
        # interval into a whole number of thermal steps
        probe = make_dem(self.mech, self.walls, self.params, dim=self.dim, dt=cfg.dt,
                         safety_factor=cfg.safety_factor, gravity=gravity,
                         periodic_length=self.periodic, skin=cfg.skin, dtype=self.dtype)
        self.t_crit = probe.t_crit
        # the mechanical step: at most the requested (or default) one, such that the recording
        # interval (else the output interval) is a whole number of thermal steps
        out_iv = scene.run.output_interval
        unit = cfg.record_interval if cfg.record_interval is not None else out_iv
        ratio = out_iv / unit
        if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
            raise SceneError("dem.record_interval", cfg.record_interval,
                             f"must divide run.output_interval = {out_iv:g} s into a whole "
                             "number of recording intervals", scene.name)
        # dt does not depend on the thermal sub-cycling, so that variants with different
        # thermal steps see the same mechanics; thermal steps run on across output times (an
        # output shows the state after the last completed thermal step)
        steps_per_unit = math.ceil(unit / probe.dt - 1e-9)
        self.dt = unit / steps_per_unit
        self.substeps = cfg.thermal_substeps
        self.steps_per_output = steps_per_unit * int(round(ratio))
        self.steps_per_record = steps_per_unit if cfg.record_interval is not None else None
        self._packing = None

    # -- set-up ---------------------------------------------------------------------------------
    def packing_positions(self) -> np.ndarray:
        """Initial positions: deposition (2D), pouring (DEM settling) or a file."""
        if self._packing is not None:
            return self._packing
        scene = self.scene
        if scene.packing.method == "pour" and scene.drum.sections:
            from drumheat.mechanics.pour import pour_sections

            d, cfg_dem = scene.drum, scene.dem
            pk = pour_sections(
                0.5 * self.diameter, np.asarray(self.mech.mass) / (
                    4 / 3 * np.pi * (0.5 * self.diameter) ** 3), self.walls, self.params,
                n_sections=d.sections,
                phase=math.radians(180.0 if d.plate_phase is None else d.plate_phase),
                dim=self.dim, group=self.group,
                layered=scene.packing.arrangement == "layers", periodic_length=self.periodic,
                gravity=self.gravity, seed=scene.run.seed, dtype=self.dtype,
                safety_factor=cfg_dem.safety_factor,
                surface_angle=scene.packing.surface_angle or 0.0)
            pos = pk.position
        elif scene.packing.method == "pour":
            from drumheat.mechanics.pour import pour

            pk = pour(0.5 * self.diameter, np.asarray(self.mech.mass) / (
                4 / 3 * np.pi * (0.5 * self.diameter) ** 3), self.walls, self.params,
                dim=self.dim, group=self.group, layered=scene.packing.arrangement == "layers",
                periodic_length=self.periodic, gravity=self.gravity, seed=scene.run.seed,
                dtype=self.dtype)
            pos = pk.position
        else:
            pos = initial_packing(scene).position
        self._packing = np.asarray(pos, float)
        return self._packing

    def make_dem(self, model: ThermalModel, batch_axis: str | None = None):
        """The DEM system with the coupled thermal update of ``model``.

        ``batch_axis``: the name of a vmap axis over states (ensembles), see
        :func:`drumheat.mechanics.make_dem` and :func:`make_thermal_update`.
        """
        update = make_thermal_update(model, self.n, len(self.walls), self.wall_heated,
                                     self.substeps, self.dt, batch_axis=batch_axis,
                                     wall_ids=self.wall_ids)
        return make_dem(self.mech, self.walls, self.params, dim=self.dim, dt=self.dt,
                        gravity=self.gravity, periodic_length=self.periodic,
                        skin=self.scene.dem.skin, dtype=self.dtype, extra_update=update,
                        chunk=self.steps_per_record or self.steps_per_output,
                        batch_axis=batch_axis)

    def model(self, params=None):
        """Thermal model and initial temperatures (as :class:`StaticBed`)."""
        value = scene_values(self.scene, params)
        model = make_thermal_model(self.scene, make_particles(self.scene, value), value)
        return model, initial_temperatures(self.scene, value)

    # -- running --------------------------------------------------------------------------------
    def trajectory(self, params=None, progress: bool | None = True) -> Trajectory:
        """Run mechanics and heat together; collect outputs (and the contact recording)."""
        model, T0 = self.model(params)
        dem = self.make_dem(model)
        pos0 = self.packing_positions()
        if self.scene.dem.settle_time > 0:
            pos0 = self._settle(pos0)
        state = dem.init(pos0)
        cap = state.nbrs.idx.shape[1]
        state = state._replace(extra=initial_extra(model, T0, cap, self.n, len(self.walls)))
        if self.mesh is not None:  # positions, velocities, temperatures, springs split by particle
            from drumheat.runner.sharding import shard_particles

            state = shard_particles(state, self.mesh, self.n)
        n_w = len(self.walls)
        out = dict(T=[np.asarray(T0)], pos=[np.asarray(pos0)], Q={a: [0.0] for a in model.accounts},
                   n_pairs=[], n_wall=[], rebuilds=[])
        rec = _Recorder(self.n, n_w, self.dt * (self.steps_per_record or 1)) \
            if self.steps_per_record else None
        if rec is not None:
            rec.positions.append(np.asarray(pos0))
        wall_count_time = 0.0
        chunk = self.steps_per_record or self.steps_per_output
        replay_after = self.scene.dem.replay_after
        n_coupled = len(self.t_out) - 1 if replay_after is None else min(
            len(self.t_out) - 1, int(round(replay_after / self.scene.run.output_interval)))
        with SimProgress(self.scene.run.duration, progress) as bar:
            for t_end in self.t_out[1:n_coupled + 1]:
                pair_acc = wall_acc = 0.0
                done = 0
                while done < self.steps_per_output:
                    state = state._replace(extra=_reset_record(state.extra))
                    try:
                        state = dem.run(state, chunk, chunk=chunk)
                    except DEMError as err:
                        raise DEMError(self._save_last_good(err), err.state) from None
                    done += chunk
                    ex = jax.device_get(state.extra)
                    pair_acc += float(np.sum(ex["pair_data"]["rec_time"]))
                    wall_acc += float(np.sum(ex["rec_wall_time"] * np.tile(self.wall_heated,
                                                                           self.n)))
                    if rec is not None:
                        rec.add(np.asarray(state.nbrs.idx), ex, np.asarray(state.position))
                span = self.steps_per_output * self.dt
                out["T"].append(np.asarray(state.extra["T"]))
                out["pos"].append(np.asarray(state.position))
                for a in model.accounts:
                    out["Q"][a].append(float(state.extra["Q"][a]))
                out["n_pairs"].append(pair_acc / span)
                out["n_wall"].append(wall_acc / span)
                bar.update_to(t_end)
            n_rest = len(self.t_out) - 1 - n_coupled
            if n_rest > 0:  # cyclic replay of what was recorded
                from drumheat.motion.replay import Recording

                cfg = self.scene.dem
                cycle = cfg.replay_cycle if cfg.replay_cycle is not None else 0.5 * replay_after
                n_rec = len(rec.pair_ptr) - 1
                recording = Recording(rec.arrays(self),
                                      first=n_rec - int(round(cycle / cfg.record_interval)))
                per_out = self.steps_per_output // self.steps_per_record
                g0 = recording.n_intervals  # the first step restarts the cycle
                Ts, Qs, _ = recording.integrate(model, state.extra["T"], state.extra["Q"], g0,
                                                per_out, n_rest, bar, float(self.t_out[n_coupled]))
                for m, (T, Q) in enumerate(zip(Ts, Qs)):
                    out["T"].append(np.asarray(T))
                    out["pos"].append(recording.position_at(g0 + (m + 1) * per_out))
                    for a in model.accounts:
                        out["Q"][a].append(float(Q[a]))
                    out["n_pairs"].append(recording.mean_pairs)
                    out["n_wall"].append(recording.mean_wall)
        self.recording = rec
        return self.make_trajectory(model, out, n_coupled, rec)

    def make_trajectory(self, model: ThermalModel, out: dict, n_coupled: int,
                        rec=None) -> Trajectory:
        """The :class:`Trajectory` from the outputs collected during a run.

        ``out`` holds lists over the output times: ``T`` (N,), ``pos`` (N, dim), ``Q``
        {account: [J]}, and per output interval ``n_pairs``, ``n_wall`` (mean contacts);
        ``n_coupled`` output intervals were simulated with mechanics (the rest replayed);
        ``rec`` is the contact recorder or None.
        """
        n_pairs = np.array([out["n_pairs"][0]] + out["n_pairs"])
        n_wall = np.array([out["n_wall"][0]] + out["n_wall"])
        # eq. [1.10] area: d^2 x wall contacts, averaged from the start (thesis App. A9 uses the
        # mean number of wall contacts of the run)
        cum_wall = np.concatenate([[n_wall[0]], np.cumsum(n_wall[1:]) / np.arange(1, len(n_wall))])
        d2 = float(np.mean(self.diameter**2))
        positions = np.stack(out["pos"])
        return Trajectory(
            t=self.t_out, T=np.stack(out["T"]), Q={a: np.array(v) for a, v in out["Q"].items()},
            position=positions, diameter=self.diameter, mass=np.asarray(model.particles.mass),
            capacity=np.asarray(model.particles.capacity), group=self.group,
            n_contacts=n_pairs, n_wall_contacts=n_wall, wall_area=d2 * cum_wall,
            extra={"interfraction_contacts": np.concatenate([
                self._interfraction(positions[:n_coupled + 1]),
                np.full(len(positions) - n_coupled - 1, np.nan)])}  # not moving in a replay
            if len(self.scene.groups) == 2 else {},
            files={"contacts.npz": lambda path: rec.save(path, self)} if rec is not None else {})

    def _interfraction(self, positions) -> np.ndarray:
        """Contacts between the two groups at each output time (mixing observable)."""
        from drumheat.analysis.observe import count_interfraction_contacts
        from scipy.spatial import cKDTree

        counts = []
        d = self.diameter
        for p in positions:
            box = None
            if self.periodic is not None:
                p = p.copy()
                p[:, -1] = np.mod(p[:, -1], self.periodic)
                box = np.array([np.inf] * (self.dim - 1) + [self.periodic])
                box[:-1] = 1e9
            tree = cKDTree(p, boxsize=box)
            pairs = np.array(sorted(tree.query_pairs(d.max() * 1.001)), int).reshape(-1, 2)
            if len(pairs):
                dist = np.linalg.norm(p[pairs[:, 0]] - p[pairs[:, 1]], axis=1)
                if self.periodic is not None:
                    dz = np.abs(p[pairs[:, 0], -1] - p[pairs[:, 1], -1])
                    dz = np.minimum(dz, self.periodic - dz)
                    dist = np.sqrt(np.sum((p[pairs[:, 0], :-1] - p[pairs[:, 1], :-1]) ** 2, 1)
                                   + dz**2)
                pairs = pairs[dist < 0.5 * (d[pairs[:, 0]] + d[pairs[:, 1]])]
            c = count_interfraction_contacts(pairs[:, 0], pairs[:, 1], np.ones(len(pairs), bool),
                                             self.group)
            counts.append(float(np.asarray(c)))
        return np.array(counts)

    def _settle(self, pos0):
        from drumheat.geometry.walls import walls_at_rest

        dem = make_dem(self.mech, walls_at_rest(self.walls), self.params, dim=self.dim,
                       dt=self.dt, gravity=self.gravity, periodic_length=self.periodic,
                       skin=self.scene.dem.skin, dtype=self.dtype)
        state = dem.run(dem.init(pos0), _steps(self.scene.dem.settle_time, self.dt))
        return np.asarray(state.position, float)

    def _save_last_good(self, err) -> str:
        path = Path(f"{self.scene.name}.last_good_state.npz").resolve()
        st = err.state
        if st is not None:
            arrays = dict(position=np.asarray(st.position), velocity=np.asarray(st.velocity),
                          time=float(st.time), diameter=self.diameter, group=self.group)
            if isinstance(st.extra, dict) and "T" in st.extra:
                arrays["T"] = np.asarray(st.extra["T"])
            np.savez(path, **arrays)
            return f"{err} The last good state is saved in {path}."
        return str(err)


def _reset_record(extra):
    pair = dict(extra["pair_data"], rec_time=jnp.zeros_like(extra["pair_data"]["rec_time"]))
    return dict(extra, pair_data=pair, rec_wall_time=jnp.zeros_like(extra["rec_wall_time"]))


class _Recorder:
    """Collects the contact network per recording interval in compact (CSR-like) form."""

    def __init__(self, n, n_walls, interval):
        self.n, self.n_walls, self.interval = n, n_walls, interval
        self.pair_i, self.pair_j, self.pair_dur, self.pair_ptr = [], [], [], [0]
        self.wall_p, self.wall_k, self.wall_dur, self.wall_ptr = [], [], [], [0]
        self.positions = []

    def add(self, idx, extra, position):
        pt = np.asarray(extra["pair_data"]["rec_time"])
        keep = (idx[0] < self.n) & (pt > 0)
        self.pair_i.append(idx[0][keep])
        self.pair_j.append(idx[1][keep])
        self.pair_dur.append(pt[keep])
        self.pair_ptr.append(self.pair_ptr[-1] + int(keep.sum()))
        wt = np.asarray(extra["rec_wall_time"])
        nz = np.nonzero(wt > 0)[0]
        self.wall_p.append(nz // self.n_walls)
        self.wall_k.append(nz % self.n_walls)
        self.wall_dur.append(wt[nz])
        self.wall_ptr.append(self.wall_ptr[-1] + len(nz))
        self.positions.append(position)

    def arrays(self, bed: DEMBed) -> dict:
        """The recording as arrays (the content of ``contacts.npz``)."""
        cat = lambda xs, dt: np.concatenate(xs).astype(dt) if xs else np.zeros(0, dt)  # noqa
        return dict(
            interval=self.interval, n_particles=self.n, n_walls=self.n_walls,
            pair_i=cat(self.pair_i, np.int32), pair_j=cat(self.pair_j, np.int32),
            pair_duration=cat(self.pair_dur, np.float64),
            pair_ptr=np.asarray(self.pair_ptr, np.int64),
            wall_particle=cat(self.wall_p, np.int32), wall_index=cat(self.wall_k, np.int32),
            wall_duration=cat(self.wall_dur, np.float64),
            wall_ptr=np.asarray(self.wall_ptr, np.int64),
            wall_heated=bed.wall_heated, wall_ids=bed.wall_ids, diameter=bed.diameter,
            group=bed.group,
            positions=np.stack(self.positions).astype(np.float32), scene=bed.scene.to_toml())

    def save(self, path, bed: DEMBed):
        np.savez_compressed(path, **self.arrays(bed))
