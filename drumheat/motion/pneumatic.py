"""Motion model ``pneumatic``: particles carried up a vertical channel by gas in plug flow.

The second heat-transfer phase of Kraychev's slot-type spouted bed (kraychev-tube-bundle.md
sections 1, 2, 6): solids are picked up at the bottom of a narrow channel (18 mm x 505 mm x
1.3 m) by the primary gas and carried upward co-currently, exchanging heat with it.

What is simulated
-----------------
* **Mechanics** (:func:`drumheat.mechanics.make_dem`): soft-sphere DEM of the particles in a 3D
  slice of the channel: ``y`` up (gravity along -y), ``x`` across the gap between two walls
  (:class:`~drumheat.geometry.walls.Plane` at ``x = 0`` and ``x = gap``), ``z`` along the
  channel length, periodic over the slice depth. Contacts particle-particle and particle-wall
  from the ``[dem]`` table.
* **Gas drag** (``external_force`` hook): ``F = 1/2 rho_g C_D (pi d^2/4) |u - v| (u - v)``
  with the single-sphere law of ``channel.drag_law`` (default Schiller-Naumann, ``C_D = 24/Re
  (1 + 0.15 Re^0.687)``, 0.44 above Re = 1000; :mod:`drumheat.models.drag`), plus buoyancy
  ``rho_g V_p g``. The gas is in plug flow: ``u = (0, u_k, 0)`` with the gas mass flux
  conserved, ``u_k = rho_g(T_in) u_in / rho_g(T_k)``; density and viscosity at the gas
  temperature ``T_k`` of the particle's axial cell (dry-air fits, :mod:`drumheat.models.air`,
  or the constants of ``[gas]``). The drag acts on the particles only (no momentum coupling
  back to the gas; the interstitial and superficial velocities are taken equal: the solids
  volume fraction of the wheat scene is 1.6 % on average, 9 % in the lowest 25 mm).
* **Entrance jet** (optional, ``[channel.entrance]``): the whole gas flow enters through a slit
  of width ``b0`` (kraychev-tube-bundle.md sections 1, 2: 8 mm, 37 m/s), so at the foot of the
  channel the particles see ``u_k x gap/b0``; above the slit's potential core ``x_c = K^2 b0``
  the velocity decays as the centreline of a plane free jet, ``(x_c/y)^1/2`` (Rajaratnam 1976,
  ``K = 2.47``), until it meets the channel's mean ``u_k`` at the entrance length ``x_c
  (gap/b0)^2`` (:func:`jet_velocity_factor`). Drag and the relative velocity of the convection
  correlation use this velocity; each particle takes it at its own height (not per cell). The
  jet's air is the channel's air: every cross-section carries the same gas mass flow (the jet
  plus the eddies beside it that it entrains and returns), so the gas energy balance below is
  unchanged, the gas of a cell mixed across the gap.
* **Heat** (``extra_update`` hook, every mechanical step, temperatures in float64):
  ``Q_i = alpha_i pi d_i^2 (T_g - T_i)`` with ``alpha_i`` from ``[heat.convection]`` evaluated at
  each particle's own slip speed ``|u_k - v_i|`` (correlation ``"gnielinski-kraychev"``: the
  Gnielinski sphere of kraychev (3-16)-(3-19), exact VDI form, ``L = d_p``,
  :func:`drumheat.models.convection.gnielinski_sphere_nu`). **Gas energy balance** along the
  channel in ``channel.cells`` axial cells, steady at every step (the gas holds no heat: its
  residence time, 0.08 s, is short against the particles' thermal time, seconds): the gas enters
  cell k at ``T_in,k``, sees the conductance-weighted particle temperature ``T_bar,k`` and
  leaves at ``T_out,k = T_bar,k + (T_in,k - T_bar,k) exp(-NTU_k)``, ``NTU_k = sum(alpha A) /
  (mdot_g c_p)``. Particle i in cell k receives ``(alpha A)_i (T_eff,k - T_i)`` with the cell's
  mean gas temperature ``T_eff,k = T_bar,k + (T_in,k - T_bar,k)(1 - exp(-NTU_k))/NTU_k``, so the
  particles take up exactly what the gas gives off, ``mdot_g c_p (T_in,k - T_out,k)`` (the
  scheme of :class:`drumheat.thermal.convection.PlugFlowConvection`). Two-way coupling: the
  particles warm or cool the gas and the gas temperature of each cell feeds back into the
  particles' heat flows, drag and alpha. The cell march is one ``associative_scan`` of the
  affine maps ``T -> exp(-NTU_k) T + (1 - exp(-NTU_k)) T_bar,k``. ``c_p`` of the gas is taken at
  the inlet temperature (it changes by < 0.1 % over tens of kelvin), so enthalpy is ``c_p T``.
* **Internal resistance** (optional): with ``heat.convection.internal_resistance =
  "transient-sphere"`` each particle's alpha is put in series with the transient internal
  coefficient ``alpha_i = Nu_i(Bi, Fo) lambda_p/d`` of fluidized-bed-exercise.md section 5, Fo at
  the residence time of a single-particle ascent (:func:`ascent`). Wheat in the channel has
  ``Bi = alpha d/lambda_p ~ 8`` but ``Fo ~ 0.003``: only a surface layer takes part.
* **Open boundaries** (``boundary_update`` hook): a particle whose centre passes the outlet
  ``y = height`` is counted (mass and enthalpy), reset to the inlet temperature and parked in a
  queue below the channel (its own slot, no contacts, no forces). A feeder releases parked
  particles at the inlet ``y = r`` at the solids mass flow ``channel.solids_mass_flow x
  depth/length`` with velocity ``(u_x, particle_inlet_velocity, u_z)``, ``u_x, u_z`` uniform
  in ``[-inlet_velocity_spread, inlet_velocity_spread]`` (without a spread, identical particles
  in plug flow follow identical paths and never collide); the release point (x, z)
  is the best of 16 random candidates (largest clearance to every particle); a release that
  would overlap a particle waits for the next step. N is constant; the flow reaches a steady
  state after about one residence time.

Energy book-keeping (closed to round-off; :func:`drumheat.runner.energy_balance`): account
``gas`` = heat the particles received from the gas, account ``flow`` = enthalpy of the particles
fed minus that of the particles leaving (``sum c_i (T_in - T_exit)``); stored heat change =
``Q_gas + Q_flow``. On the gas side ``H_gas`` (column) = gas enthalpy in minus out, equal to
``Q_gas`` by construction.

Apparatus-level evaluation (kraychev-tube-bundle.md section 6) per output interval and over the
steady window (``*_steady`` columns, from ``channel.steady_after``):
``Q_2 = mdot_L c_pL (T_L2 - T_L1)``; co-current LMTD from the solids inlet temperature, the
mass-flow-weighted mean temperature of the particles that crossed the outlet, and the gas
inlet/outlet temperatures; ``A_Sch2 = mu_2 V rho_G sigma_M`` with ``mu_2 = mdot_s/mdot_L`` and
``V`` = the channel volume of the slice; ``alpha_2 = Q_2/(A_Sch2 dt_ln)`` (5-20), ``Nu_2 = alpha_2
d_p/lambda_G`` (5-21) (:func:`drumheat.models.moving_bed.channel_alpha2`). ``alpha_2_holdup`` uses
the simulated particle surface in the channel instead (the real hold-up, slip included) and
``alpha_mean`` is the surface-weighted mean of the particles' own alpha.
"""

from __future__ import annotations

import dataclasses
import json
import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from drumheat import assemble
from drumheat.materials import gas as gas_lib
from drumheat.mechanics import make_dem
from drumheat.mechanics.neighbors import minimum_image
from drumheat.models import drag as drag_model
from drumheat.models import moving_bed
from drumheat.motion.base import register
from drumheat.motion.dem_common import DEMMotion
from drumheat.motion.trajectory import Trajectory
from drumheat.scene import Scene
from drumheat.thermal.convection import (_air_clipped, nusselt_alpha,
                                         series_with_transient_sphere)

#: Gas volume per metre of apparatus of the channel part, V_KAM2 (kraychev digest section 2).
V_KAM2 = 0.360
#: Candidate release points per release.
N_CANDIDATES = 16

# ---------------------------------------------------------------------------------------------
# pure pieces
# ---------------------------------------------------------------------------------------------


def march_gas(G, GT, T_in, W):
    """Steady plug-flow gas temperatures through cells with particle conductances.

    Parameters
    ----------
    G, GT : array (n,)
        Per cell: ``sum (alpha A)_i`` (W/K) and ``sum (alpha A)_i T_i`` (W) of its particles.
    T_in : scalar
        Gas inlet temperature, K.
    W : scalar
        Gas capacity rate ``mdot c_p``, W/K.

    Returns
    -------
    T_nodes : array (n + 1,)
        Gas temperature at the cell boundaries (inlet first), K.
    T_eff : array (n,)
        Mean gas temperature over each cell, K: the particles of cell k receive
        ``sum (alpha A)_i (T_eff,k - T_i) = W (T_in,k - T_out,k)`` exactly.
    """
    has = G > 0
    Tbar = jnp.where(has, GT / jnp.where(has, G, 1.0), 0.0)
    ntu = G / W
    a = jnp.exp(-ntu)
    b = (1.0 - a) * Tbar

    def compose(p, q):  # apply p then q: x -> a_q (a_p x + b_p) + b_q
        return p[0] * q[0], q[0] * p[1] + q[1]

    A, B = jax.lax.associative_scan(compose, (a, b))
    T_out = A * T_in + B
    T_nodes = jnp.concatenate([jnp.reshape(jnp.asarray(T_in, T_out.dtype), (1,)), T_out])
    T_cell_in = T_nodes[:-1]
    small = ntu < 1e-12
    frac = jnp.where(small, 1.0, -jnp.expm1(-ntu) / jnp.where(small, 1.0, ntu))
    T_eff = Tbar + (T_cell_in - Tbar) * frac
    return T_nodes, T_eff


def cocurrent_outlet(T_s_in, T_g_in, C_s, C_g, UA):
    """Outlet temperatures of a co-current two-stream exchanger (analytic, NTU form).

    ``T_s_out - T_g_out = (T_s_in - T_g_in) exp(-UA (1/C_s + 1/C_g))`` and ``C_s (T_s_in -
    T_s_out) = C_g (T_g_out - T_g_in)``. C in W/K, UA in W/K. Returns ``(T_s_out, T_g_out)``.
    """
    dT_in = T_s_in - T_g_in
    eff = 1.0 - np.exp(-UA * (1.0 / C_s + 1.0 / C_g))
    T_g_out = T_g_in + dT_in * eff * C_s / (C_s + C_g)
    T_s_out = T_s_in - dT_in * eff * C_g / (C_s + C_g)
    return T_s_out, T_g_out


def jet_velocity_factor(y, gap, slit_width, decay_constant):
    """Gas velocity in the channel's entrance section over the channel's mean velocity (>= 1).

    The whole gas flow enters through a slit of width ``b0 = slit_width`` at ``y = 0``, so its
    velocity there is ``u_slit = u_mean gap/b0`` (mass conservation; kraychev-tube-bundle.md
    section 2: 16.5 m/s x 18/8 = 37.1 m/s, the digest's 37 m/s in the slit). Above the slit the
    particles see the centreline velocity of a plane turbulent free jet (Rajaratnam 1976,
    *Turbulent Jets*, Elsevier, ch. 2: ``u_m/U_0 = 3.50 (x/b)^-1/2`` with ``b`` the slot's
    half-width, i.e. ``K (x/b0)^-1/2`` with ``K = 2.47`` and the full width ``b0``; Albertson,
    Dai, Jensen & Rouse 1950, Trans. ASCE 115: ``K = 2.28``):

    ``u/u_mean = max(1, (gap/b0) min(1, (x_c/y)^1/2))``, ``x_c = K^2 b0`` (the potential core,
    where the decay law meets ``u_slit``).

    It reaches the mean velocity at the entrance length ``x_e = x_c (gap/b0)^2``
    (:func:`entrance_length`) and stays there. ``slit_width = gap`` or ``decay_constant = 0``
    give exactly 1 above the inlet (no entrance). Works on numpy and JAX arrays.
    """
    R = gap / slit_width
    x_c = decay_constant**2 * slit_width
    xp = jnp if isinstance(y, jax.Array) else np
    y = xp.asarray(y)
    inside = y <= x_c
    decay = xp.where(inside, 1.0, xp.sqrt(x_c / xp.where(inside, 1.0, y)))
    return xp.maximum(1.0, R * decay)


def entrance_length(gap, slit_width, decay_constant):
    """Height above the slit where the jet's centreline velocity falls to the channel's mean,
    ``x_e = K^2 b0 (gap/b0)^2`` (m; :func:`jet_velocity_factor`: Rajaratnam 1976, ch. 2)."""
    return decay_constant**2 * slit_width * (gap / slit_width) ** 2


def _cd_numpy(law, Re):
    Re = max(Re, 1e-12)
    if law == "stokes":
        return 24.0 / Re
    if law == "newton":
        return 0.44
    return 24.0 / Re * (1.0 + 0.15 * Re**0.687) if Re <= 1000.0 else 0.44


def ascent(d, rho_p, u_gas, rho_g, mu_g, height, v0=0.0, drag_law="schiller_naumann", g=9.81,
           profile=None):
    """One particle rising in an upward gas stream, no walls or contacts (1D ODE).

    ``m dv/dt = F_drag(u - v) + (rho_g - rho_p) V g`` integrated from ``y = 0`` with ``v0``
    until ``y = height`` (:func:`scipy.integrate.solve_ivp`, rtol 1e-10), ``u = u_gas
    profile(y)`` (``profile``: e.g. the entrance jet, :func:`jet_velocity_factor`; default 1).
    For estimates (the particle count that holds the channel's hold-up) and comparisons.

    Returns
    -------
    dict
        ``t`` (s), ``y`` (m), ``v`` (m/s) along the path, ``residence_time`` (s; inf if the
        particle does not reach the top), ``terminal_velocity`` (m/s, settling in still gas).
    """
    from scipy.integrate import solve_ivp

    V = math.pi * d**3 / 6.0
    m = rho_p * V

    def rhs(t, s):
        v = s[1]
        w = u_gas * (1.0 if profile is None else float(profile(s[0]))) - v
        Re = abs(w) * d * rho_g / mu_g
        F = 0.5 * rho_g * _cd_numpy(drag_law, Re) * math.pi * d**2 / 4.0 * abs(w) * w
        return [v, (F + (rho_g - rho_p) * V * g) / m]

    top = lambda t, s: s[0] - height  # noqa: E731
    top.terminal, top.direction = True, 1
    sol = solve_ivp(rhs, (0.0, 1e3), [0.0, v0], events=top, rtol=1e-10, atol=1e-12,
                    dense_output=True, max_step=0.01)
    t_res = float(sol.t_events[0][0]) if len(sol.t_events[0]) else math.inf
    W_t = float(drag_model.terminal_velocity(d, rho_p, rho_g, mu_g, drag_law, g))
    return dict(t=sol.t, y=sol.y[0], v=sol.y[1], residence_time=t_res, terminal_velocity=W_t)


# ---------------------------------------------------------------------------------------------
# the motion model
# ---------------------------------------------------------------------------------------------


class ChannelState(eqx.Module):
    """The channel's own state in ``DEMState.extra`` (module docstring).

    T: (N,) particle temperatures, K. active: (N,) bool, in the channel (else queued at the
    feeder). park_time: (N,) s, when each queued particle was parked (the feeder releases the
    longest-waiting first). credit: kg of solids the feeder owes. T_gas: (cells + 1,) gas
    temperatures at the cell faces, K. Q: {"gas", "flow"} heat received from the gas and
    carried in by recycled particles, J. H_gas: enthalpy the gas took up, J. acc: the outlet
    and feeder accumulators of the current output interval (:meth:`PneumaticChannel._zero_acc`).
    """

    T: jax.Array
    active: jax.Array
    park_time: jax.Array
    credit: jax.Array
    T_gas: jax.Array
    Q: dict
    H_gas: jax.Array
    acc: dict

    def replace(self, **fields) -> "ChannelState":
        """This state with ``fields`` replaced."""
        return dataclasses.replace(self, **fields)


@register
class PneumaticChannel(DEMMotion):
    """Particles carried up a vertical channel by gas (module docstring).

    The evaluation over the steady window (outlet temperatures, alpha_2, Nu_2, ...) travels in
    the trajectory's ``info["channel"]`` (and so in ``summary.json``), the axial profiles in
    ``records["profiles"]`` and ``channel_profiles.csv``.

    Parameters
    ----------
    scene : Scene
        Needs ``[channel]``, ``[dem]`` and ``[gas]`` (the gas inlet temperature); heat exchange
        with the gas when ``[heat.convection]`` is present.
    """

    name = "pneumatic"

    def __init__(self, scene: Scene):
        super().__init__(scene)
        ch, cfg = scene.channel, scene.dem
        value = assemble.scene_values(scene)
        self.setup = setup = assemble.dem_setup(scene)
        self.group = assemble.group_index(scene)
        self.diameter = assemble.diameters(scene)
        self.n = len(self.diameter)
        self.radius = 0.5 * self.diameter
        self.density = setup.density
        self.thermal = assemble.thermal_particles(scene, value)
        self.mass = np.asarray(self.thermal.mass, float)
        self.capacity = np.asarray(self.thermal.capacity, float)
        self.T_inlet = np.array([float(g.temperature) for g in scene.groups])[self.group]
        self.H, self.gap, self.D = ch.height, ch.gap, ch.depth
        self.cells = ch.cells
        # gas
        self.T_gas_in = float(scene.gas.temperature)
        conv = scene.heat.convection
        self.props_mode = conv.properties if conv is not None else "polynomial"
        rho_in, cp_in, lam_in, nu_in = (float(x) for x in self.gas_props(self.T_gas_in))
        self.rho_gas_in, self.cp_gas, self.lam_gas_in, self.nu_gas_in = rho_in, cp_in, lam_in, nu_in
        self.mass_flux = rho_in * ch.gas_velocity  # kg/(m2 s), conserved along the channel
        self.m_gas = self.mass_flux * self.gap * self.D  # kg/s through the slice
        self.W_gas = self.m_gas * self.cp_gas
        self.m_solids = ch.solids_mass_flow * self.D / ch.length  # kg/s into the slice
        # mechanics
        self.params, self.k_n, self.mech = setup.params, setup.k_n, setup.particles
        self.walls = assemble.channel_walls(scene)
        self.g = cfg.gravity
        self.gravity, self.dtype, self.t_crit = setup.gravity, setup.dtype, setup.t_crit
        self.position_dtype = setup.position_dtype
        r_max = float(self.radius.max())
        self.skin = cfg.skin if cfg.skin is not None else r_max
        cutoff = 2 * r_max + self.skin
        # parking slots below the channel, spaced beyond the neighbour cutoff
        s = 1.05 * cutoff
        nz = max(1, int(math.floor(self.D / s)))
        inset = 1.01 * r_max  # clear of the walls (no zero-force wall contacts)
        nx = max(1, int(math.floor((self.gap - 2 * inset) / s)) + 1)
        xs = (np.linspace(inset, self.gap - inset, nx) if nx > 1
              else np.array([0.5 * self.gap]))
        zs = (np.arange(nz) + 0.5) * self.D / nz
        rows = int(math.ceil(self.n / (nx * nz)))
        self.y_park_top = -max(0.05, 5 * cutoff)
        ys = self.y_park_top - s * np.arange(rows)
        X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
        order = np.lexsort((X.ravel(), Z.ravel(), -Y.ravel()))
        slots = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)[order][: self.n]
        self.park = slots
        lo = np.array([0.0, ys.min() - s, 0.0])
        hi = np.array([self.gap, self.H + 4 * r_max, self.D])
        self.bounds = (lo, hi)
        self.dt, self.steps_per_output = assemble.fit_time_step(setup.dt,
                                                                scene.run.output_interval)
        self.steady_after = ch.steady_after if ch.steady_after is not None else \
            0.5 * scene.run.duration
        ent = ch.entrance
        self.entrance = None if ent is None else (self.gap, ent.slit_width, ent.decay_constant)
        self.dem = self.make_dem()
        if self.entrance is not None:
            self._check_entrance_resolution()

    # -- gas ------------------------------------------------------------------------------------
    def gas_props(self, T):
        """Gas ``(rho, c_p, lambda, nu)`` at temperature(s) T (air fits or [gas] constants)."""
        T = jnp.asarray(T, jnp.float64)
        if self.props_mode == "gas":
            g = self.scene.gas
            lib = gas_lib(g.material)
            cp = g.heat_capacity if g.heat_capacity is not None else lib.heat_capacity
            lam = g.conductivity if g.conductivity is not None else lib.conductivity
            rho = g.density if g.density is not None else g.pressure * lib.molar_mass / (
                8314.0 * float(g.temperature))
            nu = g.kinematic_viscosity
            one = jnp.ones_like(T)
            return rho * one, cp * one, lam * one, nu * one
        return _air_clipped(T)

    def holdup_estimate(self) -> dict:
        """Residence time and hold-up of the slice from a single-particle ascent (no walls)."""
        rho, _, _, nu = (float(x) for x in self.gas_props(self.T_gas_in))
        d, rho_p = float(self.diameter.mean()), float(self.density.mean())
        a = ascent(d, rho_p, self.scene.channel.gas_velocity, rho, nu * rho, self.H,
                   self.scene.channel.particle_inlet_velocity, self.scene.channel.drag_law,
                   self.g, profile=self.velocity_profile())
        m_p = float(self.mass.mean())
        hold = self.m_solids * a["residence_time"]
        return dict(residence_time=a["residence_time"], terminal_velocity=a["terminal_velocity"],
                    holdup_mass=hold, holdup_particles=hold / m_p,
                    exit_velocity=float(a["v"][-1]))

    def velocity_profile(self):
        """``y -> u(y)/u_mean`` of the entrance jet (:func:`jet_velocity_factor`), or None
        without ``[channel.entrance]``."""
        if self.entrance is None:
            return None
        gap, b0, K = self.entrance
        return lambda y: jet_velocity_factor(y, gap, b0, K)

    def entrance_info(self) -> dict:
        """The entrance jet: slit velocity, potential core and entrance length (m), and how
        finely the DEM step resolves a particle's acceleration in it (single-particle ascent
        from the inlet velocity, :func:`ascent`): steps to cross the potential core, steps to
        cross the entrance length, and the drag relaxation time ``m |w| / F_drag`` at the
        inlet over the step. Empty without ``[channel.entrance]``."""
        if self.entrance is None:
            return {}
        gap, b0, K = self.entrance
        ch = self.scene.channel
        rho, _, _, nu = (float(x) for x in self.gas_props(self.T_gas_in))
        d, rho_p = float(self.diameter.mean()), float(self.density.mean())
        u_slit = ch.gas_velocity * gap / b0
        x_c, x_e = K**2 * b0, entrance_length(gap, b0, K)
        a = ascent(d, rho_p, ch.gas_velocity, rho, nu * rho, self.H, ch.particle_inlet_velocity,
                   ch.drag_law, self.g, profile=self.velocity_profile())
        t_at = lambda y: float(np.interp(min(y, self.H), a["y"], a["t"]))  # noqa: E731
        w = u_slit - ch.particle_inlet_velocity
        F = float(drag_model.drag_force(w, d, rho, nu * rho, ch.drag_law))
        tau = float(self.mass.mean()) * w / F
        return dict(slit_velocity=u_slit, core_length=x_c, entrance_length=x_e,
                    steps_in_core=t_at(x_c) / self.dt, steps_in_entrance=t_at(x_e) / self.dt,
                    relaxation_steps=tau / self.dt)

    def _check_entrance_resolution(self):
        gap, b0, K = self.entrance
        if K == 0.0 or b0 == gap:  # no jet: the channel's mean velocity everywhere
            return
        info = self.entrance_info()
        if min(info["steps_in_core"], info["relaxation_steps"]) < 20:
            warnings.warn(f"scene {self.scene.name!r}: the DEM step resolves the particles' "
                          f"acceleration in the entrance jet poorly ({info['steps_in_core']:.0f} "
                          f"steps to cross its core, relaxation time "
                          f"{info['relaxation_steps']:.0f} steps; want >= 20). Lower dem.dt.",
                          UserWarning, stacklevel=3)

    # -- the DEM with hooks ---------------------------------------------------------------------
    def _gas_velocity(self):
        """``(y, rho_g) -> u``: the plug-flow velocity ``G/rho_g`` times the entrance jet's
        factor (:func:`jet_velocity_factor`) where ``[channel.entrance]`` is given. The jet's air
        is the channel's air: the mass flow of the gas energy balance is unchanged."""
        G_flux = self.mass_flux
        if self.entrance is None:
            return lambda y, rho: G_flux / rho
        gap, b0, K = self.entrance
        return lambda y, rho: G_flux / rho * jet_velocity_factor(y, gap, b0, K)

    def _release(self):
        """The feeder's release of parked particle j at the inlet (module docstring)."""
        f64 = jnp.float64
        ch = self.scene.channel
        r = jnp.asarray(self.radius, f64)
        mass = jnp.asarray(self.mass, f64)
        gap, D, v_in = self.gap, self.D, ch.particle_inlet_velocity
        spread = ch.inlet_velocity_spread
        key0 = jax.random.PRNGKey(self.scene.run.seed)

        def release(args):
            pos, vel, w, f, tq, act, credit, acc, step, j = args
            rj = r[j]
            kc, kv = jax.random.split(jax.random.fold_in(key0, step))
            u = jax.random.uniform(kc, (N_CANDIDATES, 2), f64)
            lat = spread * jax.random.uniform(kv, (2,), f64, -1.0, 1.0)
            cand = jnp.stack([rj + u[:, 0] * (gap - 2 * rj), jnp.full(N_CANDIDATES, rj),
                              u[:, 1] * D], axis=1)
            p64 = pos.astype(f64)
            dd = cand[:, None, :] - p64[None, :, :]
            dz = minimum_image(dd[..., 2], D)
            dist = jnp.sqrt(dd[..., 0] ** 2 + dd[..., 1] ** 2 + dz**2) - (r[None, :] + rj)
            clear = jnp.min(jnp.where(act[None, :], dist, jnp.inf), axis=1)
            best = jnp.argmax(clear)
            ok = clear[best] > 0.02 * rj
            pos = jnp.where(ok, pos.at[j].set(cand[best].astype(pos.dtype)), pos)
            v_new = jnp.stack([lat[0], jnp.asarray(v_in, f64), lat[1]]).astype(vel.dtype)
            vel = jnp.where(ok, vel.at[j].set(v_new), vel)
            act = jnp.where(ok, act.at[j].set(True), act)
            credit = jnp.where(ok, credit - mass[j], credit)
            acc = dict(acc, released=acc["released"] + ok.astype(jnp.int32),
                       blocked=acc["blocked"] + (~ok).astype(jnp.int32))
            return pos, vel, w, f, tq, act, credit, acc, step, j

        return release

    def _hooks(self):
        ch = self.scene.channel
        conv = self.scene.heat.convection
        n, n_cells, H = self.n, self.cells, self.H
        dy = H / n_cells
        f64 = jnp.float64
        d = jnp.asarray(self.diameter, f64)
        mass = jnp.asarray(self.mass, f64)
        C = jnp.asarray(self.capacity, f64)
        area = jnp.pi * d**2
        vol = jnp.pi * d**3 / 6.0
        g_vec = jnp.asarray(self.gravity, f64)
        T_in_p = jnp.asarray(self.T_inlet, f64)
        T_g_in = jnp.asarray(self.T_gas_in, f64)
        W = self.W_gas
        law = ch.drag_law
        two_way = ch.gas_coupling == "two-way"
        props = self.gas_props
        park = jnp.asarray(self.park, f64)
        m_dot = self.m_solids
        release = self._release()
        u_gas = self._gas_velocity()
        film = conv is not None and conv.property_temperature == "film"
        internal = conv is not None and conv.internal_resistance == "transient-sphere"
        if internal:
            value = assemble.scene_values(self.scene)
            lam_p = jnp.asarray(assemble.particle_property(self.scene, value, "conductivity"))
            rho_c = C / (jnp.pi * d**3 / 6.0)
            t_E = self.holdup_estimate()["residence_time"]
        if conv is not None and conv.correlation == "constant":
            alpha_const = float(conv.alpha)
        else:
            alpha_const = None

        def cell_of(y):
            return jnp.clip(jnp.floor(y / dy).astype(jnp.int32), 0, n_cells - 1)

        def gas_at(extra, y):
            k = cell_of(y)
            Tn = extra.T_gas
            return k, 0.5 * (Tn[k] + Tn[k + 1])

        def external_force(position, velocity, t, extra):
            pos = position.astype(f64)
            vel = velocity.astype(f64)
            k, Tg = gas_at(extra, pos[:, 1])
            rho, _, _, nu = props(Tg)
            u = u_gas(pos[:, 1], rho)
            u_rel = jnp.stack([-vel[:, 0], u - vel[:, 1], -vel[:, 2]], axis=1)
            F = (drag_model.drag_force(u_rel, d, rho[:, None], (nu * rho)[:, None], law)
                 - (rho * vol)[:, None] * g_vec)
            F_park = -mass[:, None] * g_vec
            return jnp.where(extra.active[:, None], F, F_park)

        def extra_update(extra, state, contacts, dt):
            pos = state.position.astype(f64)
            vel = state.velocity.astype(f64)
            act = extra.active
            T = extra.T
            k, Tg = gas_at(extra, pos[:, 1])
            gas = props(Tg)
            rho, cp, lam, nu = props(0.5 * (T + Tg)) if film else gas
            u = u_gas(pos[:, 1], gas[0])
            u_rel = jnp.stack([-vel[:, 0], u - vel[:, 1], -vel[:, 2]], axis=1)
            slip = jnp.sqrt(jnp.sum(u_rel**2, axis=1))
            actf = act.astype(f64)
            if conv is None:
                alpha = jnp.zeros(n, f64)
            elif alpha_const is not None:
                alpha = jnp.full(n, alpha_const, f64)
            else:
                alpha = nusselt_alpha(conv.correlation, d, slip, rho, cp, lam, nu)
            if internal:  # in series with the transient internal coefficient at Fo(t_res)
                alpha = series_with_transient_sphere(alpha, d, lam_p, rho_c, t_E)
            G = alpha * area * actf
            if two_way:
                Gk, GTk = jax.ops.segment_sum(jnp.stack([G, G * T], axis=1), k, n_cells).T
                T_nodes, T_eff = march_gas(Gk, GTk, T_g_in, W)
                q = G * (T_eff[k] - T)
                dH = dt * W * (T_g_in - T_nodes[-1])
            else:
                Gk = jax.ops.segment_sum(G, k, n_cells)
                T_nodes = jnp.full(n_cells + 1, T_g_in)
                q = G * (T_g_in - T)
                dH = dt * jnp.sum(q)
            acc = extra.acc
            # the per-cell profiles in one scatter (one column per quantity)
            cols = jnp.stack([mass * actf, C * T * actf, C * actf, area * actf,
                              mass * vel[:, 1] * actf, mass * slip * actf, q], axis=1)
            m_k, CT_k, C_k, A_k, mv_k, mslip_k, q_k = jax.ops.segment_sum(cols, k, n_cells).T
            acc = dict(
                acc, t=acc["t"] + dt, m=acc["m"] + dt * m_k, CT=acc["CT"] + dt * CT_k,
                C=acc["C"] + dt * C_k, G=acc["G"] + dt * Gk, A=acc["A"] + dt * A_k,
                mv=acc["mv"] + dt * mv_k, mslip=acc["mslip"] + dt * mslip_k,
                q=acc["q"] + dt * q_k,
                Tg=acc["Tg"] + dt * T_nodes,
                pairs=acc["pairs"] + jnp.sum(contacts.pair_mask, dtype=jnp.int32),
                walls=acc["walls"] + jnp.sum(contacts.wall_mask, dtype=jnp.int32))
            Q = dict(extra.Q, gas=extra.Q["gas"] + dt * jnp.sum(q))
            return extra.replace(T=T + dt * q / C, T_gas=T_nodes, Q=Q, H_gas=extra.H_gas + dH,
                        acc=acc)

        def boundary_update(state):
            ex = state.extra
            act = ex.active
            y = state.position[:, 1].astype(f64)
            out = act & (y > H)
            outf = out.astype(f64)
            T = ex.T
            acc = ex.acc
            acc = dict(acc, n_exit=acc["n_exit"] + jnp.sum(outf),
                       m_exit=acc["m_exit"] + jnp.sum(outf * mass),
                       C_exit=acc["C_exit"] + jnp.sum(outf * C),
                       CT_exit=acc["CT_exit"] + jnp.sum(outf * C * T))
            Q = dict(ex.Q, flow=ex.Q["flow"] + jnp.sum(outf * C * (T_in_p - T)))
            T = jnp.where(out, T_in_p, T)
            o3 = out[:, None]
            pos = jnp.where(o3, park.astype(state.position.dtype), state.position)
            vel = jnp.where(o3, 0.0, state.velocity)
            w = jnp.where(o3, 0.0, state.angular_velocity)
            f = jnp.where(o3, 0.0, state.force)
            tq = jnp.where(o3, 0.0, state.torque)
            act = act & ~out
            park_time = jnp.where(out, state.time, ex.park_time)
            credit = ex.credit + m_dot * self.dt
            waiting = ~act
            j = jnp.argmin(jnp.where(waiting, park_time, jnp.inf))
            has = jnp.any(waiting)
            can = has & (credit >= mass[j])
            acc = dict(acc, starved=acc["starved"] + ((~has) & (credit >= jnp.min(mass))).astype(
                jnp.int32))
            args = (pos, vel, w, f, tq, act, credit, acc, state.step, j)
            pos, vel, w, f, tq, act, credit, acc, _, _ = jax.lax.cond(
                can, release, lambda a: a, args)
            moved = out | (act & ~ex.active)
            ws = jnp.where(moved[:, None, None], 0.0, state.wall_spring)
            extra = ex.replace(T=T, active=act, park_time=park_time, credit=credit, acc=acc, Q=Q)
            return state._replace(position=pos, velocity=vel, angular_velocity=w, force=f,
                                  torque=tq, wall_spring=ws, extra=extra)

        return external_force, extra_update, boundary_update

    def make_dem(self):
        """The DEM system with drag, heat and the inlet/outlet hooks."""
        ext, upd, bnd = self._hooks()
        cfg = self.scene.dem
        return make_dem(self.mech, self.walls, self.params, dim=3, dt=self.dt,
                        gravity=self.gravity, periodic_length=self.D, bounds=self.bounds,
                        skin=self.skin, dtype=self.dtype,
                        position_dtype=self.position_dtype, extra_update=upd,
                        external_force=ext, boundary_update=bnd, chunk=self.steps_per_output,
                        safety_factor=cfg.safety_factor,
                        conduction_gap=self.setup.conduction_gap,
                        pair_kernel=self.contact_backend().backend)

    def _zero_acc(self):
        z = lambda k: jnp.zeros(k, jnp.float64)  # noqa: E731
        c = self.cells
        acc = {name: z(c) for name in ("m", "CT", "C", "G", "A", "mv", "mslip", "q")}
        acc["Tg"] = z(c + 1)
        for name in ("t", "n_exit", "m_exit", "C_exit", "CT_exit"):
            acc[name] = z(())
        for name in ("pairs", "walls", "released", "blocked", "starved"):
            acc[name] = jnp.zeros((), jnp.int32)
        return acc

    def initial_state(self, params=None):
        """All particles parked (queued) at the inlet temperature, the channel empty."""
        if params:
            raise ValueError("motion model 'pneumatic' does not take parameter overrides; use "
                             "scene overrides")
        dem = self.dem
        extra = ChannelState(
            T=jnp.asarray(self.T_inlet, jnp.float64),
            active=jnp.zeros(self.n, bool),
            park_time=jnp.asarray(-1.0 + 1e-6 * np.arange(self.n), jnp.float64),
            credit=jnp.zeros((), jnp.float64),
            T_gas=jnp.full(self.cells + 1, self.T_gas_in, jnp.float64),
            Q={"gas": jnp.zeros((), jnp.float64), "flow": jnp.zeros((), jnp.float64)},
            H_gas=jnp.zeros((), jnp.float64),
            acc=self._zero_acc())
        return dem.init(self.park, extra=extra)

    # -- evaluation -----------------------------------------------------------------------------
    def evaluate(self, acc: dict) -> dict:
        """Outlet temperatures, alpha_2 (kraychev digest section 6) and profiles from sums.

        ``acc`` holds the time integrals of one window (:meth:`_zero_acc` layout, numpy).
        """
        conv = self.scene.heat.convection
        t = float(acc["t"])
        nan = float("nan")
        res = dict(window=t)
        m_out = float(acc["m_exit"])
        T_g_out = float(acc["Tg"][-1]) / t if t > 0 else nan
        m_s = m_out / t if t > 0 else nan
        T_p_out = float(acc["CT_exit"] / acc["C_exit"]) if acc["C_exit"] > 0 else nan
        c_s = float(acc["C_exit"] / acc["m_exit"]) if m_out > 0 else float(self.capacity[0] /
                                                                            self.mass[0])
        T_p_in = float(np.mean(self.T_inlet))
        T_g_in = self.T_gas_in
        A = float(np.sum(acc["A"])) / t if t > 0 else nan
        holdup = float(np.sum(acc["m"])) / t if t > 0 else nan
        T_gm = 0.5 * (T_g_in + T_g_out) if np.isfinite(T_g_out) else T_g_in
        rho_m, cp_m, lam_m, nu_m = (float(x) for x in self.gas_props(T_gm))
        d = float(np.mean(self.diameter))
        rho_p = float(np.mean(self.density))
        res.update(T_particle_out=T_p_out, T_gas_out=T_g_out, solids_mass_flow=m_s,
                   gas_mass_flow=self.m_gas, holdup_mass=holdup, particle_surface=A,
                   residence_time=holdup / m_s if m_s > 0 else nan,
                   Q_gas_side=self.W_gas * (T_g_out - T_g_in),
                   Q_solids_side=m_s * c_s * (T_p_in - T_p_out) if m_s > 0 else nan,
                   loading=m_s / self.m_gas)
        ok = m_s > 0 and np.isfinite(T_p_out) and abs(T_g_out - T_g_in) > 0
        for tag, V in (("", self.H * self.gap * self.D), ("_VKAM2", V_KAM2 * self.D)):
            if ok:
                ev = moving_bed.channel_alpha2(
                    m_L=self.m_gas, c_pL=self.cp_gas, T_L1=T_g_in, T_L2=T_g_out, t_M1=T_p_in,
                    t_M2=T_p_out, m_solids=m_s, V=V, rho_G=self.rho_gas_in, rho_M=rho_p, d_p=d,
                    lambda_G=lam_m)
                res.update({f"alpha_2{tag}": float(ev.alpha_2), f"Nu_2{tag}": float(ev.Nu_2),
                            f"A_Sch2{tag}": float(ev.A_Sch2)})
                if not tag:
                    res.update(Q_2=float(ev.Q_2), dt_ln=float(ev.dt_ln))
            else:
                res.update({f"alpha_2{tag}": nan, f"Nu_2{tag}": nan, f"A_Sch2{tag}": nan})
                if not tag:
                    res.update(Q_2=nan, dt_ln=nan)
        res["alpha_2_holdup"] = res["Q_2"] / (A * res["dt_ln"]) if ok and A > 0 else nan
        sG, sA, sm = float(np.sum(acc["G"])), float(np.sum(acc["A"])), float(np.sum(acc["m"]))
        res["alpha_mean"] = sG / sA if sA > 0 else nan
        res["slip_mean"] = float(np.sum(acc["mslip"])) / sm if sm > 0 else nan
        res["velocity_mean"] = float(np.sum(acc["mv"])) / sm if sm > 0 else nan
        res["UA"] = sG / t if t > 0 else nan
        if conv is not None and conv.correlation != "constant" and np.isfinite(res["slip_mean"]):
            a = lambda w: float(nusselt_alpha(conv.correlation, d, w, rho_m, cp_m, lam_m,  # noqa
                                              nu_m))
            res["alpha_correlation_mean_slip"] = a(res["slip_mean"])
            res["alpha_correlation_gas_velocity"] = a(self.scene.channel.gas_velocity)
        res["lambda_gas"] = lam_m
        res["pair_contacts_mean"] = float(acc["pairs"]) / max(t / self.dt, 1)
        res["wall_contacts_mean"] = float(acc["walls"]) / max(t / self.dt, 1)
        res["released"] = int(acc["released"])
        res["blocked_steps"] = int(acc["blocked"])
        res["starved_steps"] = int(acc["starved"])
        # axial profiles (time means)
        with np.errstate(invalid="ignore", divide="ignore"):
            prof = dict(
                y_nodes=np.linspace(0.0, self.H, self.cells + 1),
                y_cells=(np.arange(self.cells) + 0.5) * self.H / self.cells,
                T_gas=np.asarray(acc["Tg"]) / t,
                T_particles=np.asarray(acc["CT"]) / np.asarray(acc["C"]),
                holdup=np.asarray(acc["m"]) / t,
                velocity=np.asarray(acc["mv"]) / np.asarray(acc["m"]),
                slip=np.asarray(acc["mslip"]) / np.asarray(acc["m"]),
                alpha=np.asarray(acc["G"]) / np.asarray(acc["A"]),
                heat=np.asarray(acc["q"]) / t)
        res["profiles"] = prof
        return res

    def outlet_summary(self, ev: dict, t_end: float) -> dict:
        """The headline of ``summary.json`` (key ``outlet``): outlet temperatures and ``Q_2``
        over the steady window, from the evaluation ``ev`` (:meth:`evaluate`).

        The time series' ``T_mean`` is the mean of all particles, those queued at the feeder
        (at the inlet temperature) included; the outlet temperatures are the ones to quote:
        ``T_particle_out`` (K, heat-capacity-weighted over the particles that crossed the
        outlet), ``T_gas_out`` (K, time mean), ``Q_2`` (W, air side ``mdot_L c_pL (T_L2 -
        T_L1)``, the simulated slice) and ``Q_2_channel`` (W, scaled to the channel length
        ``channel.length``)."""
        ch = self.scene.channel
        return dict(T_particle_out=ev["T_particle_out"], T_gas_out=ev["T_gas_out"],
                    Q_2=ev["Q_2"], Q_2_channel=ev["Q_2"] * ch.length / self.D,
                    solids_mass_flow=ev["solids_mass_flow"],
                    window_s=[t_end - ev["window"], t_end],
                    entrance=self.entrance is not None)

    # -- the loop -------------------------------------------------------------------------------
    def model(self, params=None):
        """No thermal model: the channel couples its gas itself (module docstring); the
        particles start at their groups' (inlet) temperatures."""
        return None, jnp.asarray(self.T_inlet, float)

    def advance(self, state, t0, t1):
        start = state._replace(extra=state.extra.replace(acc=self._zero_acc()),
                               max_overlap=jnp.zeros_like(state.max_overlap))
        return self.dem.run_steps(start, int(round((t1 - t0) / self.dt)))

    def observe(self, state) -> dict:
        ex = state.extra
        return {"T": ex.T, "Q": ex.Q, "position": state.position, "acc": ex.acc,
                "H_gas": ex.H_gas, "n_active": jnp.sum(ex.active),
                "mechanics": self.mechanics(state)}

    def finish(self, rows, log, state) -> Trajectory:
        """Outputs per ``run.output_interval`` plus the evaluation over the steady window."""
        r = self.stack_rows(rows)
        t_out = np.asarray(self.times)
        cols = {k: [np.nan] for k in ("T_gas_out", "T_particle_out", "solids_mass_flow",
                                      "holdup_mass", "alpha_2", "Nu_2", "alpha_2_holdup",
                                      "alpha_mean", "slip_mean")}
        steady_cols = ("T_gas_out", "T_particle_out", "solids_mass_flow", "alpha_2", "Nu_2",
                       "alpha_2_holdup", "alpha_mean", "slip_mean")
        for k in steady_cols:
            cols[f"{k}_steady"] = [np.nan]
        pairs, walls = [0.0], [0.0]
        steady_acc = evs = None
        for m in range(1, len(t_out)):
            acc = {k: np.asarray(v[m]) for k, v in r["acc"].items()}
            ev = self.evaluate(acc)
            if t_out[m] > self.steady_after * (1 + 1e-12):
                steady_acc = acc if steady_acc is None else {
                    k: steady_acc[k] + acc[k] for k in acc}
            evs = self.evaluate(steady_acc) if steady_acc is not None else None
            for k in cols:
                if k.endswith("_steady"):
                    cols[k].append(evs[k[:-7]] if evs is not None else np.nan)
                else:
                    cols[k].append(ev[k])
            pairs.append(ev["pair_contacts_mean"])
            walls.append(ev["wall_contacts_mean"])
        cols["H_gas"] = r["H_gas"]
        cols["n_active"] = r["n_active"]
        if evs is not None and evs["starved_steps"] > 0:
            warnings.warn(f"scene {self.scene.name!r}: the feeder found no queued particle in "
                          f"{evs['starved_steps']} steps of the steady window: the solids flow "
                          "was below channel.solids_mass_flow. Raise the particle count "
                          f"(hold-up estimate: {self.holdup_estimate()['holdup_particles']:.0f} "
                          "particles).", UserWarning, stacklevel=2)
        if evs is not None and evs["solids_mass_flow"] < 0.97 * self.m_solids:
            warnings.warn(f"scene {self.scene.name!r}: the feeder delivered "
                          f"{evs['solids_mass_flow'] / self.m_solids:.0%} of "
                          "channel.solids_mass_flow in the steady window: the inlet is too "
                          "crowded to insert particles without overlap "
                          f"({evs['blocked_steps']} blocked steps). Raise "
                          "channel.particle_inlet_velocity or lower the flow.", UserWarning,
                          stacklevel=2)
        files, info, records = {}, {}, {}
        if evs is not None:
            if self.entrance is not None:
                evs["entrance"] = self.entrance_info()
            files["channel.json"] = lambda path: _write_json(path, evs)
            files["channel_profiles.csv"] = lambda path: _write_profiles(path, evs["profiles"])
            info["channel"] = {k: v for k, v in evs.items() if k != "profiles"}
            info["outlet"] = self.outlet_summary(evs, float(t_out[-1]))
            records["profiles"] = evs["profiles"]
        n_out = len(t_out)
        return Trajectory(
            t=t_out, T=r["T"], Q=r["Q"], position=np.asarray(r["position"], float),
            diameter=self.diameter, mass=self.mass, capacity=self.capacity, group=self.group,
            n_contacts=np.asarray(pairs), n_wall_contacts=np.asarray(walls),
            wall_area=np.zeros(n_out), extra={k: np.asarray(v, float) for k, v in cols.items()},
            files=files, info=dict(info, **self.backend_info()), records=records,
            mechanics=r["mechanics"])


def _write_json(path, ev):
    data = {k: v for k, v in ev.items() if k != "profiles"}
    with open(path, "w") as fh:
        json.dump(data, fh, indent=2)


def _write_profiles(path, prof):
    import pandas as pd

    n = len(prof["y_cells"])
    df = pd.DataFrame({"y": prof["y_cells"], "T_gas_in_cell": prof["T_gas"][:n],
                       "T_gas_out_cell": prof["T_gas"][1:], "T_particles": prof["T_particles"],
                       "holdup_kg": prof["holdup"], "velocity": prof["velocity"],
                       "slip": prof["slip"], "alpha": prof["alpha"], "heat_W": prof["heat"]})
    df.to_csv(path, index=False)
