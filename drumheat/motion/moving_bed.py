"""Motion model ``moving_bed``: a moving bed sinking through a staggered tube bundle (DEM + heat).

kraychev-tube-bundle.md sections 1, 2, 5, 7 (cited as *Kraychev digest*): in phase 1 of the
MKKM-02 apparatus the solids sink by gravity as a dense moving bed through a horizontal
staggered bundle of tubes (D_R = 14 mm, s1 = s2 = 25 mm) held at a fixed temperature, and leave
through a bottom slit of adjustable width S. This model simulates a slice of that hopper:

* **Geometry** (:func:`hopper_walls`): x across the bundle (hopper axis x = 0), y up (y = 0 at
  the slit lips), z along the tubes. A 3D slice of length ``hopper.depth``, periodic in z (the
  slit and the tubes are 500 mm long in the rig, many particle diameters: periodic is the
  honest reduction). Side walls at ``x = +-columns s1 / 2`` are symmetry planes of the staggered
  bundle, so tubes centred on them are half tubes. A sloped bottom of two plates ends in the
  slit lips at ``x = +-S/2``. The bottom tube row has its tubes at ``x = +-s1/2`` (no tube right
  above the slit), the next row at ``x = 0, +-s1``, and so on.
* **Mechanics**: the soft-sphere DEM of :mod:`drumheat.mechanics` with the ``[dem]`` table.
* **Heat**: the coupled thermal update of :mod:`drumheat.motion.dem` (contact conduction
  particle-particle ``[heat.contact]`` and particle-tube ``[heat.wall]``, one temperature per
  wall primitive so that the heat of every tube is booked separately).
* **Open boundary** (``boundary_update`` hook of :func:`drumheat.mechanics.make_dem`): a
  particle whose centre falls ``hopper.exit_depth`` below the slit has left; it is put back on
  a free site of an insertion band above the bed (the sites are taken in turn; a site where
  the new particle would touch another is skipped; when none is free the particle waits below
  the slit, at rest, and tries again next step), with velocity zero, no spin,
  its wall springs cleared and its temperature reset to ``hopper.inlet_temperature``. The
  number and mass of recycled particles is the discharge through the slit; the enthalpy they
  carry in (``m c (t_1 - T_exit)``) is booked in the heat account ``inflow`` so that the energy
  balance closes: change of stored heat = heat from the tubes + ``inflow``.

Measurements (accumulated every step inside the scan, reported per output interval as
time-series columns and over a window by :meth:`MovingBed.measure`):

* ``W_p_axis`` (m/s): the digest's W_p, section 7: "mean apparent velocity between the tubes,
  measured on the hopper axis" (dyed particles timed over the bed height, W_p = H_Sch/tau).
  Here: the time average of the downward velocity of the particles whose centres lie in the
  axis column ``|x| < s1/2`` between the lowest and the highest tube row. For a steady flow
  down the column this is H/tau of the particles travelling along the axis.
* ``W_p_slit`` (m/s): the discharge expressed as eq. (8-5) does, ``m_dot = L S W_p beta rho``,
  i.e. ``W_p = m_dot / (rho_p beta L S)`` with beta = 0.59. The digest's measured circulating
  flows (Table 10.3.2) and eq. (5-5) agree in this form, so it is the second reading of W_p.
* ``alpha_1`` (W/(m2 K)) = Q_tubes / (A_tubes dt_ln), eqs. (5-14), (5-15): Q_tubes the heat the
  tubes gave in the window, A_tubes the outer surface of the tubes in the slice, and
  ``dt_ln = LMTD(t_R - t_1, t_R - t_2)`` with t_R the tube temperature, t_1 the inlet and t_2
  the mean temperature of the particles leaving through the slit (eps_dt = 1: the digest gives
  no value). In a steady state Q_tubes = Q_M1 = m_dot c (t_2 - t_1) (5-14a); their ratio is
  reported as the steadiness check.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from drumheat import assemble
from drumheat.geometry.hopper import HopperGeometry, hopper_walls  # noqa: F401 (re-exported)
from drumheat.geometry.walls import Plane
from drumheat.mechanics import make_dem
from drumheat.mechanics.neighbors import minimum_image
from drumheat.models.moving_bed import BETA_HOPPER, lmtd
from drumheat.motion.base import register
from drumheat.motion.dem_common import DEMMotion
from drumheat.motion.coupling import (initial_extra, make_thermal_update, mean_contacts,
                                      reset_count)
from drumheat.motion.trajectory import Trajectory
from drumheat.scene import Scene, SceneError

__all__ = ["HopperGeometry", "hopper_walls", "particles_to_fill", "MovingBed", "measure"]


def _lattice(x_lo, x_hi, y_lo, y_hi, depth, spacing):
    """Cubic lattice sites (M, 3) in a box, z evenly over the periodic length."""
    nz = max(1, int(math.floor(depth / spacing)))
    xs = np.arange(x_lo, x_hi + 1e-12, spacing)
    ys = np.arange(y_lo, y_hi + 1e-12, spacing)
    zs = (np.arange(nz) + 0.5) * depth / nz
    g = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1).reshape(-1, 3)
    return g


@register
class MovingBed(DEMMotion):
    """A moving bed discharging through a slit from a hopper with a tube bundle (module
    docstring); DEM and heat in one scan, particles recycled from the slit to the top.

    The flow counters at the output times travel in the trajectory's ``records`` (``n_out``,
    ``m_out``, ``H_out``, ``C_out``, ``v_axis``, ``n_axis``, ``v_bundle``, ``n_bundle``,
    ``steps``, ``waiting``, ``Q_tubes``, ``max_overlap``, ``passes``); :func:`measure` averages
    them over a window.

    Parameters
    ----------
    scene : Scene
        Needs ``[hopper]`` and ``[dem]``, ``dim = 3``.
    """

    name = "moving_bed"
    INSERT_LAYERS = 5

    def __init__(self, scene: Scene):
        super().__init__(scene)
        h = self.hopper = scene.hopper
        self.setup = setup = assemble.dem_setup(scene)
        self.group = assemble.group_index(scene)
        self.diameter = assemble.diameters(scene)
        self.n = len(self.diameter)
        self.density = setup.density
        self.geometry = assemble.hopper_geometry(scene)
        self.walls = self.geometry.walls
        self.n_walls = len(self.walls)
        self.wall_heated = np.array([w.temperature is not None for w in self.walls])
        self.params, self.k_n, self.mech = setup.params, setup.k_n, setup.particles
        self.gravity, self.dtype, self.t_crit = setup.gravity, setup.dtype, setup.t_crit
        self.position_dtype = setup.position_dtype
        d_max = float(self.diameter.max())
        self.d_max = d_max
        xw = self.geometry.half_width
        # insertion band: INSERT_LAYERS lattice layers above crest + insertion_height
        sp = 1.1 * d_max
        y_ins = self.geometry.crest + h.insertion_height
        self.sites = _lattice(-xw + 0.6 * d_max, xw - 0.6 * d_max, y_ins,
                              y_ins + (self.INSERT_LAYERS - 0.5) * sp, h.depth, sp)
        self.y_exit = -h.exit_depth
        self.bounds = (np.array([-xw, self.y_exit - 0.1, 0.0]),
                       np.array([xw, float(self.sites[:, 1].max()) + 0.05, h.depth]))
        self.dt, self.steps_per_output = assemble.fit_time_step(setup.dt,
                                                                scene.run.output_interval)
        self.substeps = scene.dem.thermal_substeps
        # measurement regions
        self.axis_half = 0.5 * h.pitch
        self.tube_area = (self.geometry.tube_fraction * math.pi * h.tube_diameter * h.depth)
        self._packing = None
        model, _ = self.model()
        self.check_thermal_step(model, int(np.sum(self.wall_heated)))
        self._skeleton = eqx.partition(model, eqx.is_array)[1]
        self.dem = self.make_dem(model)

    # -- set-up ---------------------------------------------------------------------------------
    def model(self, params=None):
        """Thermal model (one wall temperature per primitive, the tube temperature where the
        primitive is heated) and initial temperatures: the particles start at the inlet
        temperature (the bed is filled with fresh solids)."""
        value = assemble.scene_values(self.scene, params)
        Tw = jnp.where(jnp.asarray(self.wall_heated),
                       jnp.asarray(value("hopper.tube_temperature"), float), 0.0)
        model, _ = assemble.thermal_model(self.scene, params, wall_temperatures=Tw)
        T0 = jnp.full(self.n, jnp.asarray(value("hopper.inlet_temperature"), float))
        return model, T0

    def packing_positions(self) -> np.ndarray:
        """Initial bed: particles on a jittered lattice, lowest sites first, settled with the
        slit closed for ``hopper.settle_time``."""
        if self._packing is not None:
            return self._packing
        h = self.hopper
        d = self.d_max
        rng = np.random.default_rng(self.scene.run.seed)
        xw = self.geometry.half_width
        # body-centred layers (solids fraction ~0.65): row j shifted by half a spacing in x
        # and z, so that rows sit 0.7 d apart without touching; little settling needed
        a = 1.03 * d
        nz = max(1, int(math.floor(h.depth / (1.01 * d))))
        c = h.depth / nz
        dy = 1.01 * math.sqrt(max(d * d - (0.5 * a) ** 2 - (0.5 * min(c, 2 * d)) ** 2,
                                  0.25 * d * d))
        rows = []
        for j, y in enumerate(np.arange(0.55 * d, 1.0, dy)):
            xs = np.arange(-xw + 0.55 * d + 0.5 * a * (j % 2), xw - 0.55 * d + 1e-12, a)
            zs = (np.arange(nz) + 0.5 * (j % 2)) * c
            g = np.stack(np.meshgrid(xs, [y], zs, indexing="ij"), -1).reshape(-1, 3)
            rows.append(g)
        grid = np.concatenate(rows)
        sp = a
        # inside the hopper: above the sloped bottom plates (and clear of every wall)
        S2 = 0.5 * h.slit_width
        y_plate = h.bottom_height * np.clip((np.abs(grid[:, 0]) - S2) / (xw - S2), 0.0, 1.0)
        ok = grid[:, 1] > y_plate
        xg = jnp.asarray(grid)
        for w in self.walls:
            ok &= np.asarray(w.distance(xg, 0.0)) > 0.55 * d
        grid = grid[ok]
        grid = grid[np.argsort(grid[:, 1], kind="stable")]
        if len(grid) < self.n:
            raise SceneError("groups", f"{self.n} particles", "too many for the lattice start "
                             "below y = 1 m", self.scene.name)
        pos = grid[:self.n] + rng.uniform(-0.005, 0.005, (self.n, 3)) * sp
        pos[:, 2] %= h.depth
        top = float(pos[:, 1].max())
        if h.settle_time > 0:
            closed = self.walls + (Plane((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), wall_id=99),)
            hi = self.bounds[1].copy()
            hi[1] = max(hi[1], top + 2 * d)
            dem = make_dem(self.mech, closed, self.params, dim=3, dt=self.dt,
                           gravity=self.gravity, periodic_length=h.depth,
                           bounds=(self.bounds[0], hi), skin=self.scene.dem.skin,
                           dtype=self.dtype, position_dtype=self.position_dtype)
            state = dem.run(dem.init(pos), max(1, int(round(h.settle_time / self.dt))))
            pos = np.asarray(state.position, float)
        self._packing = pos
        return pos

    # -- the open boundary ----------------------------------------------------------------------
    def make_boundary(self):
        """``boundary_update`` hook: recycling from the slit to the insertion band, and the
        flow measurements (module docstring). The heat capacities come from the thermal
        model in the state."""
        sites = jnp.asarray(self.sites, self.dtype)
        K = len(self.sites)
        L = self.hopper.depth
        y_exit = self.y_exit
        radius = jnp.asarray(0.5 * self.diameter, self.dtype)
        mass = jnp.asarray(self.mech.mass, float)
        skeleton = self._skeleton
        T_in = jnp.asarray(self.hopper.inlet_temperature, float)
        clear = 0.55 * self.d_max  # centre distance > r_other + 1.1 r_new: no overlap
        ax = self.axis_half
        ylo = self.geometry.bundle_lo
        yhi = self.geometry.bundle_hi

        def recycle(args):
            state, out = args
            pos = state.position
            ex = state.extra
            d = sites[:, None, :] - pos[None, :, :]
            dz = minimum_image(d[..., 2], L)
            dist = jnp.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2 + dz**2) - radius[None, :]
            dist = jnp.where(out[None, :], jnp.inf, dist)
            clearance = jnp.min(dist, axis=1)  # (K,)
            free = clearance > clear
            turn = ex.flow["turn"]
            key = jnp.where(free, (jnp.arange(K) - turn) % K, K + jnp.arange(K))
            order = jnp.argsort(key)
            rank = jnp.cumsum(out) - 1
            ok = out & (rank < jnp.sum(free))
            site = order[jnp.clip(rank, 0, K - 1)]
            new_pos = jnp.where(ok[:, None], sites[site], pos)
            zero = jnp.zeros_like(state.velocity)
            vel = jnp.where(ok[:, None], zero, state.velocity)
            vel = jnp.where((out & ~ok)[:, None], zero, vel)  # waiting below the slit
            w = jnp.where(ok[:, None], 0.0, state.angular_velocity)
            ws = jnp.where(ok[:, None, None], 0.0, state.wall_spring)
            T_old = ex.T
            cap = eqx.combine(ex.model, skeleton).particles.capacity
            T = jnp.where(ok, T_in, T_old)
            okf = ok.astype(float)
            flow = dict(ex.flow)
            flow["n_out"] = flow["n_out"] + jnp.sum(ok).astype(flow["n_out"].dtype)
            flow["m_out"] = flow["m_out"] + jnp.sum(okf * mass)
            flow["H_out"] = flow["H_out"] + jnp.sum(okf * cap * T_old)
            flow["C_out"] = flow["C_out"] + jnp.sum(okf * cap)
            flow["waiting"] = flow["waiting"] + jnp.sum(out & ~ok).astype(flow["waiting"].dtype)
            flow["turn"] = (turn + jnp.sum(ok).astype(turn.dtype)) % K
            flow["passes"] = flow["passes"] + ok.astype(flow["passes"].dtype)
            Q = dict(ex.Q, inflow=ex.Q["inflow"] + jnp.sum(okf * cap * (T_in - T_old)))
            extra = ex.replace(T=T, Q=Q, flow=flow)
            return state._replace(position=new_pos, velocity=vel, angular_velocity=w,
                                  wall_spring=ws, extra=extra)

        def boundary(state):
            pos = state.position
            vy = state.velocity[:, 1].astype(float)
            y = pos[:, 1]
            in_axis = (jnp.abs(pos[:, 0]) < ax) & (y > ylo) & (y < yhi)
            in_bundle = (y > ylo) & (y < yhi)
            ex = state.extra
            flow = dict(ex.flow)
            flow["v_axis"] = flow["v_axis"] - jnp.sum(jnp.where(in_axis, vy, 0.0))
            flow["n_axis"] = flow["n_axis"] + jnp.sum(in_axis).astype(float)
            flow["v_bundle"] = flow["v_bundle"] - jnp.sum(jnp.where(in_bundle, vy, 0.0))
            flow["n_bundle"] = flow["n_bundle"] + jnp.sum(in_bundle).astype(float)
            flow["steps"] = flow["steps"] + 1.0
            state = state._replace(extra=ex.replace(flow=flow))
            out = y < y_exit
            return jax.lax.cond(jnp.any(out), recycle, lambda a: a[0], (state, out))

        return boundary

    def initial_flow(self) -> dict:
        """Flow accumulators at t = 0: discharged count ``n_out``, mass ``m_out`` (kg),
        ``H_out`` = sum m c T and ``C_out`` = sum m c of the discharged particles (J, J/K),
        ``passes`` (N,) per particle, ``waiting`` (particle-steps spent waiting for a free
        site), and the sums of downward velocity (m/s) and counts on the axis column and in
        the bundle over ``steps``."""
        z = jnp.zeros(())
        return {"n_out": jnp.asarray(0, jnp.int32), "waiting": jnp.asarray(0, jnp.int32),
                "passes": jnp.zeros(self.n, jnp.int32),
                "turn": jnp.asarray(0, jnp.int32), "m_out": z, "H_out": z, "C_out": z,
                "v_axis": z, "n_axis": z, "v_bundle": z, "n_bundle": z, "steps": z}

    def make_dem(self, model):
        """The DEM system with the coupled thermal update and the recycling boundary."""
        backend = self.contact_backend().backend
        update = make_thermal_update(model, self.n, self.n_walls, self.wall_heated,
                                     self.substeps, self.dt, per_wall=True, pair_kernel=backend)
        return make_dem(self.mech, self.walls, self.params, dim=3, dt=self.dt,
                        gravity=self.gravity, periodic_length=self.hopper.depth,
                        bounds=self.bounds, skin=self.scene.dem.skin, dtype=self.dtype,
                        position_dtype=self.position_dtype,
                        extra_update=update, boundary_update=self.make_boundary(),
                        chunk=self.steps_per_output, conduction_gap=self.setup.conduction_gap,
                        pair_kernel=backend,
                        contact_details=False)  # the coupled heat reads pair_conducts only

    # -- the loop -------------------------------------------------------------------------------
    def initial_state(self, params=None):
        model, T0 = self.model(params)
        state = self.dem.init(self.packing_positions())
        cap = state.nbrs.idx.shape[1]
        extra = initial_extra(model, T0, cap, self.n, self.n_walls, self.dt, per_wall=True,
                              accounts=("inflow",), record=False)  # records no contacts
        return state._replace(extra=extra.replace(flow=self.initial_flow()))

    def advance(self, state, t0, t1):
        start = state._replace(extra=reset_count(state.extra, self.wall_heated),
                               max_overlap=jnp.zeros_like(state.max_overlap))
        return self.dem.run_steps(start, int(round((t1 - t0) / self.dt)))

    def observe(self, state) -> dict:
        ex = state.extra
        n_pairs, n_wall = mean_contacts(ex, self.wall_heated, self.steps_per_output * self.dt,
                                        self.substeps)
        return {"T": ex.T, "Q": ex.Q, "position": state.position,
                "Q_tubes": ex.Q_walls[self.geometry.tube_index],
                "flow": {k: ex.flow[k] for k in FLOW_RECORDS},
                "max_overlap": state.max_overlap,
                "n_pairs": n_pairs, "n_wall": n_wall,
                "mechanics": self.mechanics(state)}

    def finish(self, rows, log, state) -> Trajectory:
        r = self.stack_rows(rows)
        records = {k: np.asarray(v, float) for k, v in r["flow"].items()}
        records["Q_tubes"] = r["Q_tubes"]
        records["max_overlap"] = r["max_overlap"]
        records["passes"] = np.asarray(state.extra.flow["passes"])
        t = np.asarray(self.times)
        info = self.constants()
        ts = interval_columns(t, records, info)
        for k in range(len(self.geometry.tube_index)):
            ts[f"Q_tube:{k}"] = records["Q_tubes"][:, k]
        particles = eqx.combine(state.extra.model, self._skeleton).particles
        n_pairs, n_wall = r["n_pairs"], r["n_wall"]
        return Trajectory(
            t=t, T=r["T"], Q=r["Q"], position=r["position"], diameter=self.diameter,
            mass=np.asarray(particles.mass), capacity=particles.host_capacity(),
            group=self.group, n_contacts=np.concatenate([n_pairs[1:2], n_pairs[1:]]),
            n_wall_contacts=np.concatenate([n_wall[1:2], n_wall[1:]]),
            wall_area=np.zeros(len(t)), extra=ts, records=records,
            info={"moving_bed": info, **self.backend_info()}, mechanics=r["mechanics"])

    def constants(self) -> dict:
        """What :func:`measure` needs besides the records (JSON-serialisable)."""
        h = self.hopper
        return dict(depth=h.depth, slit_width=h.slit_width, inlet_temperature=h.inlet_temperature,
                    tube_temperature=h.tube_temperature, measure_from=h.measure_from,
                    density=float(np.average(self.density)),
                    tube_area=float(np.sum(self.tube_area)), dt=self.dt,
                    dt_over_tcrit=self.dt / self.t_crit)


#: the flow counters of the boundary hook recorded at every output time
FLOW_RECORDS = ("n_out", "m_out", "H_out", "C_out", "v_axis", "n_axis", "v_bundle", "n_bundle",
                "steps", "waiting")


def rates(t, records: dict, info: dict, i0: int, i1: int) -> dict:
    """Flow and heat measurements between output indices i0 < i1 (module docstring)."""
    r = records
    span = t[i1] - t[i0]
    diff = lambda k: r[k][i1] - r[k][i0]  # noqa: E731
    rho = info["density"]
    m_dot = diff("m_out") / span  # kg/s through the slice's slit
    n_ax = diff("n_axis")
    W_axis = diff("v_axis") / n_ax if n_ax > 0 else float("nan")
    n_b = diff("n_bundle")
    W_bundle = diff("v_bundle") / n_b if n_b > 0 else float("nan")
    W_slit = m_dot / (rho * BETA_HOPPER * info["depth"] * info["slit_width"])
    Q_tubes = float(np.sum(r["Q_tubes"][i1] - r["Q_tubes"][i0])) / span  # W
    A = info["tube_area"]
    C = diff("C_out")
    t1 = info["inlet_temperature"]
    tR = info["tube_temperature"]
    t2 = diff("H_out") / C if C > 0 else float("nan")
    Q_M1 = C * (t2 - t1) / span if C > 0 else float("nan")  # m c (t2 - t1), W
    dt_ln = float(lmtd(tR - t1, tR - t2)) if C > 0 else float("nan")
    return dict(t_start=float(t[i0]), t_end=float(t[i1]), mass_flow=m_dot,
                mass_flow_per_m=m_dot / info["depth"], n_discharged=int(diff("n_out")),
                W_p_axis=W_axis, W_p_bundle=W_bundle, W_p_slit=W_slit, Q_tubes=Q_tubes,
                Q_M1=Q_M1, T_out=t2, dt_ln=dt_ln, tube_area=A,
                alpha_1=Q_tubes / (A * dt_ln) if C > 0 else float("nan"),
                alpha_1_solids=Q_M1 / (A * dt_ln) if C > 0 else float("nan"))


def interval_columns(t, records: dict, info: dict) -> dict:
    """Time-series columns of the flow measurements over each output interval."""
    cols = {k: [np.nan] for k in ("W_p_axis", "W_p_slit", "mass_flow", "T_out", "Q_dot_tubes",
                                  "alpha_1")}
    for i in range(1, len(t)):
        m = rates(t, records, info, i - 1, i)
        cols["W_p_axis"].append(m["W_p_axis"])
        cols["W_p_slit"].append(m["W_p_slit"])
        cols["mass_flow"].append(m["mass_flow"])
        cols["T_out"].append(m["T_out"])
        cols["Q_dot_tubes"].append(m["Q_tubes"])
        cols["alpha_1"].append(m["alpha_1"])
    cols = {k: np.array(v) for k, v in cols.items()}
    cols["n_discharged"] = records["n_out"]
    return cols


def measure(result, t_from: float | None = None) -> dict:
    """Window averages of a moving-bed run from ``t_from`` (default ``hopper.measure_from``) to
    its end, plus a steadiness check: the same quantities over the two halves of the window.

    ``result`` is the :class:`~drumheat.Result` (or :class:`Trajectory`) of a ``moving_bed``
    run.
    """
    traj = getattr(result, "trajectory", result)
    info, r = traj.info["moving_bed"], traj.records
    t = np.asarray(traj.t)
    t_from = info["measure_from"] if t_from is None else t_from
    i0 = int(np.searchsorted(t, t_from - 1e-9))
    i1 = len(t) - 1
    if i0 >= i1:
        raise ValueError(f"measurement window starts at {t_from} s, after the run's end")
    res = rates(t, r, info, i0, i1)
    im = (i0 + i1) // 2
    if im > i0:
        a, b = rates(t, r, info, i0, im), rates(t, r, info, im, i1)
        res["first_half"] = {k: a[k] for k in ("W_p_axis", "W_p_slit", "alpha_1", "Q_tubes")}
        res["second_half"] = {k: b[k] for k in ("W_p_axis", "W_p_slit", "alpha_1", "Q_tubes")}
    res["max_overlap"] = float(np.max(r["max_overlap"]))
    res["waiting_steps"] = int(r["waiting"][-1])
    # mean number of particles waiting below the slit for a free insertion site
    res["mean_waiting"] = float((r["waiting"][i1] - r["waiting"][i0])
                                / max(r["steps"][i1] - r["steps"][i0], 1.0))
    res["dt"] = info["dt"]
    res["dt_over_tcrit"] = info["dt_over_tcrit"]
    return res


def particles_to_fill(h, diameter: float, level: float, solids_fraction: float = BETA_HOPPER
                      ) -> int:
    """Number of spheres of ``diameter`` that fill the hopper slice of ``[hopper]`` table ``h``
    up to ``level`` (m above the top of the highest tubes) at ``solids_fraction``."""
    g = hopper_walls(h)
    xw = g.half_width
    y_top = g.crest + level
    free = 2 * xw * y_top - (xw - 0.5 * h.slit_width) * h.bottom_height
    free -= float(np.sum(g.tube_fraction)) * math.pi * h.tube_diameter**2 / 4
    return int(round(free * h.depth * solids_fraction / (math.pi * diameter**3 / 6)))
