"""The contact forces of a DEM step behind one signature: the JAX kernel and the C++ loop.

:func:`make_contact_forces` returns a :class:`ContactForces` object; calling it with the
positions, the half-step velocities and spins, the time, the neighbour list and the tangential
springs gives a :class:`ForceResult` (forces and torques with gravity, updated springs, the
:class:`Contacts` of the step for the heat model, the largest relative overlap and, with
per-step conduction, the heat flows). Two implementations of the same contact law
(:func:`drumheat.mechanics.contact_forces.contact_law`):

- :class:`JaxContactForces`: JAX operations (every platform, ``vmap``, any material table);
- :class:`CpuContactForces`: pairs and walls in one C++ loop on XLA's CPU threads
  (:mod:`drumheat.mechanics.cpu_kernel`), the wall geometry from JAX.

They are tested equal to round-off (tests/test_cpu_kernel.py; the friction heat in
tests/test_friction_heat.py). The velocity-Verlet step of :func:`drumheat.mechanics.make_dem`
calls one of them once per step and, with friction heat, its :meth:`~ContactForces.dissipation`
after the second half-kick.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.devices import to_device
from drumheat.geometry.walls import DrumShell, rpm_to_omega
from drumheat.mechanics.conduction import PairConduction
from drumheat.mechanics.conduction import heat_flow as pair_heat_flow
from drumheat.mechanics.contact_forces import (
    ContactParams,
    contact_law,
    cross_a_f,
    cross_w_a,
    rolling_loss,
    rolling_torque,
)
from drumheat.mechanics.dissipation import ContactWork, Dissipation, FrictionHeat, step_heat

__all__ = ["Contacts", "ForceResult", "ContactForces", "JaxContactForces", "CpuContactForces",
           "KernelWork", "make_contact_forces"]


class Contacts(NamedTuple):
    """Contacts of the current step as fixed-size padded arrays (for the heat model).

    Particle-particle (length = neighbour capacity M): ``pair_i < pair_j`` (padding = N),
    ``pair_mask`` true for touching pairs, each contact once; ``pair_overlap`` (m),
    ``pair_distance`` centre distance L (m, the thermal-pipe length of Weigler digest [2.5]),
    ``pair_normal_force`` (N).
    Particle-wall (length N*W, row-major over (particle, wall primitive)): ``wall_particle``,
    ``wall_index`` (primitive index into the wall tuple), ``wall_id`` (the walls' labels),
    ``wall_mask``, ``wall_overlap`` (m), ``wall_normal_force`` (N).
    ``pair_conducts`` / ``wall_conducts``: the contacts that conduct heat, those that overlap or
    whose surface gap is within the conduction gap tolerance (``make_dem(conduction_gap=...)``;
    without one they equal the masks).
    ``dissipation``: the heat of the step's friction and damping
    (:class:`~drumheat.mechanics.dissipation.Dissipation`), with ``make_dem(friction_heat=...)``;
    None otherwise.
    Always multiply by the masks: padded entries hold index N (pairs) and zeros.
    ``pair_mask``, ``pair_overlap``, ``pair_distance`` and ``pair_normal_force`` are None in
    the contacts a step hands to ``extra_update`` when the DEM was built with
    ``make_dem(contact_details=False)`` (a hook that reads only ``pair_conducts``, as the coupled
    heat does; :meth:`DEM.contacts <drumheat.mechanics.DEM.contacts>` always has them).
    """

    pair_i: jax.Array
    pair_j: jax.Array
    pair_mask: jax.Array
    pair_overlap: jax.Array
    pair_distance: jax.Array
    pair_normal_force: jax.Array
    wall_particle: jax.Array
    wall_index: jax.Array
    wall_id: jax.Array
    wall_mask: jax.Array
    wall_overlap: jax.Array
    wall_normal_force: jax.Array
    pair_conducts: jax.Array
    wall_conducts: jax.Array
    dissipation: Optional[Dissipation] = None


class KernelWork(NamedTuple):
    """What the C++ loop leaves for the friction heat's second pass
    (:func:`drumheat.mechanics.cpu_kernel.contact_heat`): the neighbour pairs ``idx`` (2, M)
    and their layout order ``order`` (N,) or None (``NeighborList.order``), each contact's row
    (``pair_rows`` (M, K_p), ``wall_rows`` (N W, K_w): force, levers,
    rolling torque, change of spring energy), the wall velocities (N, W, dim) of the step and
    its losses at the continuous rates ``rates`` (3,) float64, J (damping, sliding, rolling)."""

    idx: jax.Array
    order: Optional[jax.Array]
    pair_rows: jax.Array
    wall_rows: jax.Array
    wall_velocity: jax.Array
    rates: jax.Array


class ForceResult(NamedTuple):
    """What :class:`ContactForces` returns for one step.

    force (N, dim) N and torque (N,) / (N, 3) N m: contacts and gravity; pair_spring
    (capacity, dim) and wall_spring (N, W, dim) m: the updated tangential springs; contacts:
    :class:`Contacts`; max_overlap: largest overlap / smaller radius of the step; heat (N,) W:
    the per-step pair conduction (None without it); work: with friction heat, what the
    contacts leave for :meth:`ContactForces.dissipation` (None without it); ahead: the coming
    step's largest squared displacement from the list's reference positions, m^2, where the
    call was asked for it (:attr:`ContactForces.looks_ahead`; else None); drifted: the
    positions, half-step velocities and spins ``(x, v, w)`` of the step's kicks and drift,
    where the call made them (:attr:`ContactForces.drifts`; else None); counted: with a run of
    steps in the call (``steps`` of :meth:`ContactForces.__call__`; else None) each pair slot's
    (M,) and wall slot's (N W,) count of the steps it conducted and the steps made (1,), int32.
    """

    force: jax.Array
    torque: jax.Array
    pair_spring: jax.Array
    wall_spring: jax.Array
    contacts: Contacts
    max_overlap: jax.Array
    heat: Optional[jax.Array]
    work: Optional[ContactWork | KernelWork] = None
    ahead: Optional[jax.Array] = None
    drifted: Optional[tuple] = None
    counted: Optional[tuple] = None


def _materialize(tree, pred):
    """Return ``tree`` unchanged but computed once, before its consumers run.

    XLA:CPU removes ``optimization_barrier`` before fusion, and its fusion heuristics then fuse
    the contact law into the concatenation of the scatter update, recomputing it for each of
    the output columns (measured: half of the force kernel). A conditional on a runtime
    predicate is a fusion boundary that XLA cannot remove; ``pred`` must always be true at
    run time (the other branch, never taken, returns zeros so that the branches differ).
    """
    return jax.lax.cond(pred, lambda t: t,
                        lambda t: jax.tree_util.tree_map(jnp.zeros_like, t), tree)


def _pair_updates(f, tq_i, tq_j):
    """The scatter updates of the two ends of every pair: ``(-f | tq_i, f | tq_j)``, each
    (M, dim + torque components) (2D's scalar torque as one column)."""
    col = (lambda a: a[:, None]) if tq_i.ndim == 1 else (lambda a: a)
    return (jnp.concatenate([-f, col(tq_i)], axis=1), jnp.concatenate([f, col(tq_j)], axis=1))


def _scatter_once(f, tq_i, tq_j, i, j, n):
    """:func:`_scatter_pairs` as one scatter over both ends, its update materialised first
    (the CPU form)."""
    f, tq_i, tq_j = _materialize((f, tq_i, tq_j), i[0] <= n)
    upd = jnp.concatenate(_pair_updates(f, tq_i, tq_j))
    return jax.ops.segment_sum(upd, jnp.concatenate([i, j]), n), f


def _scatter_per_end(f, tq_i, tq_j, i, j, n):
    """:func:`_scatter_pairs` as one scatter per end (the form for GPUs)."""
    upd_i, upd_j = _pair_updates(f, tq_i, tq_j)
    return jax.ops.segment_sum(upd_i, i, n) + jax.ops.segment_sum(upd_j, j, n), f


def _scatter_pairs(f, tq_i, tq_j, i, j, n):
    """``(sums, f)``: forces and torques of the pairs summed into their particles, shape
    (N, dim + torque components): ``-f`` and ``tq_i`` at i, ``f`` and ``tq_j`` at j (padding
    index n dropped); and ``f`` for later use (on the CPU the materialised one).

    The form is chosen per platform when the step is compiled (``platform_dependent``):

    * CPU (:func:`_scatter_once`): one scatter over both ends (the same additions in the same
      order as two scatters), its update materialised first (:func:`_materialize`), else
      XLA:CPU fuses the contact law into the concatenation and recomputes it once per output
      column;
    * other platforms, GPUs (:func:`_scatter_per_end`): one scatter per end, into which XLA
      fuses the contact law; the concatenated (2M, dim + torque) update is never written to
      memory (faster and smaller on an H100: docs/performance.md, GPU).
    """
    return jax.lax.platform_dependent(
        f, tq_i, tq_j, cpu=lambda *a: _scatter_once(*a, i, j, n),
        default=lambda *a: _scatter_per_end(*a, i, j, n))


class ContactForces:
    """Contact forces of particles and walls, one call per step (build with
    :func:`make_contact_forces`).

    Subclasses implement :meth:`_contacts`; this class holds the constants both share (particle
    arrays in the mechanics dtype, contact tables, walls, gravity, the conduction gap) and the
    parts that are JAX in both (wall geometry, the conduction-gap masks, the wall slots of
    :class:`Contacts`, the elastic energy).
    """

    def __init__(self, particles, walls, params: ContactParams, *, dim: int, dt: float, dtype,
                 gravity, displacement, rotation: bool, conduction: PairConduction | None,
                 conduction_gap: tuple[float, float], periodic_length=None,
                 friction_heat: FrictionHeat | None = None, fold_length=None,
                 pair_details: bool = True):
        self.n, self.dim, self.walls, self.n_w = particles.n, dim, tuple(walls), len(walls)
        self.params, self.dtype, self.rotation = params, dtype, rotation
        # mixed precision (positions wider than the mechanics): the pair law reads positions
        # folded along the periodic axis to this period (pair_positions), and ``displacement``
        # takes the minimum image in it
        self.fold_length = fold_length
        # made on the host (drumheat.devices.to_device: no compiled program each)
        self.radius = to_device(particles.radius, dtype)
        self.mass = to_device(particles.mass, dtype)
        self.inertia = to_device(particles.inertia, dtype)
        self.ptype = particles.ptype
        self.radius_thermal = particles.radius  # the conduction's own precision
        self.single_type = params.n_types == 1
        self.use_rolling = params.uses_rolling()
        self.g_vec = to_device(gravity, dtype)
        self.displacement = displacement
        self.wall_ids = np.array([w.wall_id for w in self.walls], dtype=np.int32)
        self.wall_omega = [rpm_to_omega(getattr(w, "rpm", 0.0)) for w in self.walls]
        self.dt, self.dt_c = dt, to_device(dt, dtype)
        self.conduction = conduction
        self.gap_pp, self.gap_pw = conduction_gap
        self.periodic_length = periodic_length
        self.friction_heat = friction_heat
        # whether a call's Contacts carry the per-pair mask, overlap, distance and normal force
        # (unless the call says otherwise)
        self.pair_details = pair_details

    # -- the one signature ---------------------------------------------------------------------
    #: whether :meth:`__call__` takes ``ahead`` (the coming step's skin test in the call)
    looks_ahead: bool = False
    #: whether :meth:`__call__` takes ``drift`` (the step's kicks and drift in the call)
    drifts: bool = False

    def __call__(self, pos, vel, w, t, nbrs, pair_spring, wall_spring,
                 temperature=None, details: bool | None = None, ahead=None,
                 drift=None, steps=None) -> ForceResult:
        """Forces and torques at ``pos`` with the velocities ``vel``, ``w`` (the half-step ones
        in the Verlet step: the dashpots and the spring increment use them, as LIGGGHTS does).
        ``temperature`` (N,) K: for the per-step pair conduction, if the system has one.
        ``details``: whether the :class:`Contacts` carry the per-pair mask, overlap, distance
        and normal force (else None; the C++ loop then does not write them); default
        ``pair_details`` of the constructor. ``ahead``: where :attr:`looks_ahead`, the
        constants of the coming step's skin test
        (:func:`~drumheat.mechanics.cpu_kernel.skin_test_constants`); the result's ``ahead``
        then holds its largest squared displacement from ``nbrs.reference_position``.
        ``drift``: where :attr:`drifts`, ``(constants, force, torque)`` of the step's kicks and
        drift (:func:`~drumheat.mechanics.cpu_kernel.drift_constants`, the forces and torques
        of the step before): ``pos``, ``vel``, ``w`` are then the step before's and the call
        first kicks and drifts them (the result's ``drifted``). ``steps``: where
        :attr:`drifts`, with ``ahead`` and ``drift``, ``(most, half_skin_sq)``: a run of up to
        ``most`` steps while the skin test passes, in one call (the result that of the last
        step, with ``counted``; :func:`~drumheat.mechanics.cpu_kernel.contacts`)."""
        if ahead is not None and not self.looks_ahead:
            raise ValueError(f"{type(self).__name__} makes no skin test of the coming step")
        if drift is not None and not self.drifts:
            raise ValueError(f"{type(self).__name__} makes no kicks and drift")
        if steps is not None and (drift is None or ahead is None):
            raise ValueError("a run of steps in the call takes the kicks and drift and the "
                             "skin test")
        details = self.pair_details if details is None else details
        res = self._contacts(pos, vel, w, t, nbrs, pair_spring, wall_spring, temperature,
                             details, ahead, drift, steps)
        if details:
            return res
        return res._replace(contacts=res.contacts._replace(
            pair_mask=None, pair_overlap=None, pair_distance=None, pair_normal_force=None))

    def pair_positions(self, pos):
        """The positions the pair law reads: ``pos`` itself where it is in the mechanics'
        type; positions kept wider (mixed precision, :mod:`drumheat.mechanics.precision`)
        folded along the periodic axis into ``[0, fold_length)`` and then rounded to the
        mechanics' type. ``fold_length`` divides the period, so the pair separations (minimum
        image in ``fold_length``, :attr:`displacement`) are those of the unfolded positions,
        resolved to the spacing at ``fold_length`` instead of at the whole period."""
        if pos.dtype == self.dtype:
            return pos
        if self.fold_length is not None:
            pos = pos.at[:, -1].set(jnp.mod(pos[:, -1], self.fold_length))
        return pos.astype(self.dtype)

    def at(self, state) -> ForceResult:
        """The forces at a :class:`~drumheat.mechanics.DEMState` with its own velocities
        (a state's contacts, its energy book, the forces of a fresh state)."""
        return self(state.position, state.velocity, state.angular_velocity, state.time,
                    state.nbrs, state.pair_spring, state.wall_spring, details=True)

    def _contacts(self, pos, vel, w, t, nbrs, pair_spring, wall_spring, temperature, details,
                  ahead, drift, steps) -> ForceResult:  # pragma: no cover - abstract
        """The forces (gravity included, :meth:`gravity`) and contacts; ``details`` False: the
        caller drops the per-pair details (a kernel may skip computing them); ``ahead``,
        ``drift``: as :meth:`__call__` (None where the class does not :attr:`looks_ahead`,
        :attr:`drifts`)."""
        raise NotImplementedError

    def gravity(self, mass):
        """The force of gravity ``m g`` on particles of masses ``mass`` (N,), (N, dim)."""
        return mass[:, None] * self.g_vec

    def dissipation(self, work, vel, w) -> Dissipation:  # pragma: no cover - abstract
        """The heat of the step (friction heat) from the ``work`` of :class:`ForceResult` at the
        full-step velocities ``vel`` and spins ``w`` (after the second half-kick)."""
        raise NotImplementedError

    # -- shared parts --------------------------------------------------------------------------
    def table(self, tab, a, b):
        """Particle-particle table entries of the type pairs (a, b)."""
        tab = tab.astype(self.dtype)
        return tab[0, 0] if self.single_type else tab[a, b]

    def wall_table(self, tab):
        """Particle-wall table as (N or 1, W)."""
        tab = jnp.broadcast_to(tab.astype(self.dtype), (self.params.n_types, self.n_w))
        return tab[0][None, :] if self.single_type else tab[self.ptype]

    def wall_geometry(self, pos, t, first: int = 0):
        """Distance (N, W), unit normal towards the particle and wall velocity (N, W, dim);
        of the walls from ``first`` on."""
        n, dim, dtype = self.n, self.dim, self.dtype
        if self.n_w <= first:
            return (jnp.zeros((n, 0), dtype), jnp.zeros((n, 0, dim), dtype),
                    jnp.zeros((n, 0, dim), dtype))
        evs = [wl.evaluate(pos, t) for wl in self.walls[first:]]
        return tuple(jnp.stack([e[k] for e in evs], axis=1).astype(dtype) for k in range(3))

    def pair_gap_mask(self, pos, i, j):
        """Neighbour pairs within the conduction gap (``conduction_gap``), from the positions."""
        valid = i < self.n
        ii, jj = jnp.where(valid, i, 0), jnp.where(valid, j, 0)
        pos = self.pair_positions(pos)
        d = self.displacement(pos[jj], pos[ii])
        dist = jnp.sqrt(jnp.sum(d * d, axis=-1))
        ri, rj = self.radius[ii], self.radius[jj]
        return self.within_gap(valid, ri + rj - dist, ri, rj)

    def within_gap(self, valid, overlap, ri, rj):
        """Pairs whose ``overlap`` (negative: a gap) is at least ``-conduction_gap`` times the
        smaller diameter: the pairs that conduct."""
        return valid & (overlap >= -self.gap_pp * 2.0 * jnp.minimum(ri, rj))

    def wall_gap_mask(self, wd, w_mask):
        """Particle-wall slots within the conduction gap, flattened like ``wall_mask``."""
        if self.n_w == 0 or self.gap_pw == 0:
            return w_mask
        r_ = self.radius[:, None]
        return ((r_ - wd) >= -self.gap_pw * 2.0 * r_).reshape(-1)

    def wall_slots(self, wact, wovl, wfn):
        """The wall fields of :class:`Contacts`, flattened over the (N, W) slots."""
        n, n_w = self.n, self.n_w
        if n_w == 0:
            empty = jnp.zeros((0,), jnp.int32)
            return (empty, empty, empty, jnp.zeros((0,), bool), jnp.zeros((0,), self.dtype),
                    jnp.zeros((0,), self.dtype))
        w_part = jnp.repeat(jnp.arange(n, dtype=jnp.int32), n_w)
        w_idx = jnp.tile(jnp.arange(n_w, dtype=jnp.int32), n)
        w_id = jnp.tile(jnp.asarray(self.wall_ids), n)
        return (w_part, w_idx, w_id, wact.reshape(-1), jnp.where(wact, wovl, 0.0).reshape(-1),
                wfn.reshape(-1))

    def record(self, i, j, active, overlap, distance, normal_force, pair_conducts, slots,
               wall_conducts) -> Contacts:
        """The step's :class:`Contacts` from the pairs ``(i, j)`` and their fields and the wall
        slots' fields (``slots``, :meth:`wall_slots`)."""
        w_part, w_idx, w_id, w_mask, w_ovl, w_fn = slots
        return Contacts(
            pair_i=i, pair_j=j, pair_mask=active, pair_overlap=overlap, pair_distance=distance,
            pair_normal_force=normal_force, wall_particle=w_part, wall_index=w_idx,
            wall_id=w_id, wall_mask=w_mask, wall_overlap=w_ovl, wall_normal_force=w_fn,
            pair_conducts=pair_conducts, wall_conducts=wall_conducts)

    def elastic_energy(self, c: Contacts, pair_spring, wall_spring):
        """Energy in the normal and tangential springs of the touching contacts ``c``, J:
        ``k_n delta^2 / 2 + k_t |xi|^2 / 2`` summed."""
        ptype, n, n_w = self.ptype, self.n, self.n_w
        i = jnp.where(c.pair_mask, c.pair_i, 0)
        j = jnp.where(c.pair_mask, c.pair_j, 0)
        kn = self.table(self.params.kn_pp, ptype[i], ptype[j])
        kt = self.table(self.params.kt_pp, ptype[i], ptype[j])
        el = 0.5 * jnp.sum(jnp.where(c.pair_mask, kn * c.pair_overlap**2
                                     + kt * jnp.sum(pair_spring**2, -1), 0.0))
        if n_w > 0:
            knw = jnp.broadcast_to(self.wall_table(self.params.kn_pw), (n, n_w)).reshape(-1)
            ktw = jnp.broadcast_to(self.wall_table(self.params.kt_pw), (n, n_w)).reshape(-1)
            xi2 = jnp.sum(wall_spring**2, -1).reshape(-1)
            el = el + 0.5 * jnp.sum(jnp.where(c.wall_mask, knw * c.wall_overlap**2 + ktw * xi2,
                                              0.0))
        return el


def _spring_energy_and_rates(kn, kt, overlap_old, spring_old, active, overlap, res, roll_rate):
    """``(U_new - U_old, rates)`` of :class:`~drumheat.mechanics.dissipation.ContactWork`: the
    change of each contact's spring energy ``k_n delta^2/2 + k_t |xi|^2/2`` over the step (a
    normal spring only while it overlaps, as in :meth:`ContactForces.elastic_energy`) and the
    (3, ...) loss rates (damping, sliding, rolling) of the contact law's result ``res``."""
    u_old = (jnp.where(overlap_old > 0, 0.5 * kn * overlap_old**2, 0.0)
             + 0.5 * kt * jnp.sum(spring_old**2, axis=-1))
    u_new = (jnp.where(active, 0.5 * kn * overlap**2, 0.0)
             + 0.5 * kt * jnp.sum(res.spring**2, axis=-1))
    rolling = jnp.zeros_like(overlap) if roll_rate is None else roll_rate
    return u_new - u_old, jnp.stack([res.damping_loss, res.slip_loss, rolling])


class JaxContactForces(ContactForces):
    """The contact law in JAX operations: pairs through the neighbour list (a gather, the law,
    one scatter of forces and torques), walls as an (N, W) block."""

    def _contacts(self, pos, vel, w, t, nbrs, pair_spring, wall_spring, temperature, details,
                  ahead, drift, steps) -> ForceResult:
        n, gap_pp, radius = self.n, self.gap_pp, self.radius
        i, j = nbrs.idx[0], nbrs.idx[1]
        force, torque = self.gravity(self.mass), jnp.zeros_like(w)  # the sums start from them
        force, torque, new_spring, ovl, dist, fn, active, max_ovl, pair_work = self._pairs(
            self.pair_positions(pos), vel, w, nbrs, pair_spring, force, torque, i, j)
        pair_dist = dist  # every pair's, for the conduction gap tolerance (heat_flow)
        p_cond = active
        if gap_pp > 0:
            r_i, r_j = radius[jnp.where(i < n, i, 0)], radius[jnp.where(j < n, j, 0)]
            p_cond = self.within_gap(i < n, ovl, r_i, r_j)
        ovl = jnp.where(active, ovl, 0.0)
        dist = jnp.where(active, dist, 0.0)
        force, torque, new_wall_spring, max_ovl, slots, wd, wall_work = self._walls(
            pos, vel, w, t, wall_spring, force, torque, max_ovl)
        work = None
        if self.friction_heat is not None:
            work = ContactWork(i, j, *pair_work, *wall_work)
        contacts = self.record(i, j, active, ovl, dist, fn, p_cond, slots,
                               self.wall_gap_mask(wd, slots[3]))
        heat = None
        c = self.conduction
        if c is not None and temperature is not None:
            heat = pair_heat_flow(temperature, contacts, self.radius_thermal, c.law,
                                  c.coefficient, c.gap_tolerance, pair_dist)
        # (details: what the caller drops XLA does not compute)
        return ForceResult(force, torque, new_spring, new_wall_spring, contacts, max_ovl, heat,
                           work)

    def dissipation(self, work: ContactWork, vel, w) -> Dissipation:
        """The step's heat (:func:`~drumheat.mechanics.dissipation.step_heat`)."""
        return step_heat(self.friction_heat, work, vel, w, self.dt)

    def _pairs(self, pos, vel, w, nbrs, pair_spring, force, torque, i, j):
        n, dim, params, table = self.n, self.dim, self.params, self.table
        radius, mass, inertia, ptype = self.radius, self.mass, self.inertia, self.ptype
        valid = i < n
        ii = jnp.where(valid, i, 0)
        jj = jnp.where(valid, j, 0)
        d = self.displacement(pos[jj], pos[ii])  # from i to j
        dist = jnp.sqrt(jnp.sum(d * d, axis=-1))
        dist_safe = jnp.where(valid & (dist > 0), dist, 1.0)
        nrm = d / dist_safe[:, None]
        ri = radius[ii]
        rj = radius[jj]
        ovl = ri + rj - dist
        active = valid & (ovl > 0)
        a_i = (ri - 0.5 * ovl)[:, None] * nrm
        a_j = -(rj - 0.5 * ovl)[:, None] * nrm
        wi = w[ii]
        wj = w[jj]
        v_rel = (vel[jj] + cross_w_a(wj, a_j)) - (vel[ii] + cross_w_a(wi, a_i))
        mi = mass[ii]
        mj = mass[jj]
        m_eff = mi * mj / (mi + mj)
        ti = ptype[ii]
        tj = ptype[jj]
        heat = self.friction_heat is not None
        res = contact_law(nrm, ovl, v_rel, m_eff,
                          table(params.kn_pp, ti, tj), table(params.kt_pp, ti, tj),
                          table(params.zeta_n_pp, ti, tj), table(params.zeta_t_pp, ti, tj),
                          table(params.mu_pp, ti, tj), pair_spring, self.dt_c, active,
                          dissipation=heat)
        f = res.force
        m_r = None
        if not self.rotation:
            seg = jnp.concatenate([i, j])  # padding N is dropped by segment_sum
            force = force + jax.ops.segment_sum(jnp.concatenate([-f, f]), seg, n)
        else:
            tq_i = cross_a_f(a_i, -f)
            tq_j = cross_a_f(a_j, f)
            if self.use_rolling:
                r_eff = ri * rj / (ri + rj)
                ii_ = inertia[ii]
                ij_ = inertia[jj]
                m_r = rolling_torque(wj - wi, res.normal_force, r_eff,
                                     table(params.mu_roll_pp, ti, tj), ii_ * ij_ / (ii_ + ij_),
                                     self.dt_c)
                m_r = jnp.where(active[:, None] if m_r.ndim == 2 else active, m_r, 0.0)
                tq_j = tq_j + m_r
                tq_i = tq_i - m_r
                roll_rate = rolling_loss(m_r, wj - wi, ii_ * ij_ / (ii_ + ij_), self.dt_c,
                                         dim == 3) if heat else None
            tot, f = _scatter_pairs(f, tq_i, tq_j, i, j, n)
            force = force + tot[:, :dim]
            torque = torque + (tot[:, dim] if tq_i.ndim == 1 else tot[:, dim:])
        rmin_pair = jnp.minimum(ri, rj)
        max_ovl = jnp.max(jnp.where(active, ovl / rmin_pair, 0.0), initial=0.0)
        work = None
        if heat:
            work = self._pair_work(pos, vel, ii, jj, ri, rj, active, ovl, a_i, a_j, f, m_r,
                                   pair_spring, res, table(params.kn_pp, ti, tj),
                                   table(params.kt_pp, ti, tj),
                                   roll_rate if self.rotation and self.use_rolling else None)
        return force, torque, res.spring, ovl, dist, res.normal_force, active, max_ovl, work

    def _pair_work(self, pos, vel, ii, jj, ri, rj, active, ovl, a_i, a_j, f, m_r, spring_old,
                   res, kn, kt, roll_rate):
        """The pairs' part of :class:`~drumheat.mechanics.dissipation.ContactWork`: force,
        levers, rolling torque, the change of each pair's spring energy over the step (the
        overlap before the step from the positions before the drift, ``x - dt v``) and the
        loss rates."""
        prev = pos - self.dt_c * vel
        d0 = self.displacement(prev[jj], prev[ii])
        ovl0 = ri + rj - jnp.sqrt(jnp.sum(d0 * d0, axis=-1))
        return (f, a_i, a_j, m_r, *_spring_energy_and_rates(kn, kt, ovl0, spring_old, active,
                                                             ovl, res, roll_rate))

    def _walls(self, pos, vel, w, t, wall_spring, force, torque, max_ovl):
        if self.n_w == 0:
            z = jnp.zeros((self.n, 0, self.dim), self.dtype)
            return (force, torque, wall_spring, max_ovl, self.wall_slots(None, None, None),
                    jnp.zeros((self.n, 0), self.dtype),
                    (z, z, z, None, None, z[..., 0], jnp.zeros((3, self.n, 0), self.dtype)))
        dim, dtype, params, wall_table = self.dim, self.dtype, self.params, self.wall_table
        radius, mass, inertia = self.radius, self.mass, self.inertia
        wd, wn, wv = self.wall_geometry(pos, t)
        r_ = radius[:, None]
        wovl = r_ - wd
        wact = wovl > 0
        a = -(r_ - 0.5 * wovl)[..., None] * wn
        v_relw = vel[:, None, :] + cross_w_a(w[:, None], a) - wv
        m_w = jnp.broadcast_to(mass[:, None], wd.shape)
        heat = self.friction_heat is not None
        resw = contact_law(wn, wovl, v_relw, m_w,
                           wall_table(params.kn_pw), wall_table(params.kt_pw),
                           wall_table(params.zeta_n_pw), wall_table(params.zeta_t_pw),
                           wall_table(params.mu_pw), wall_spring, self.dt_c, wact,
                           dissipation=heat)
        m_r = w_wall_rel = roll_rate = None
        force = force + jnp.sum(resw.force, axis=1)
        if self.rotation:
            tq = cross_a_f(a, resw.force)
            if self.use_rolling:
                if dim == 2:
                    w_wall = jnp.asarray(self.wall_omega, dtype)[None, :]
                    w_rel = w[:, None] - w_wall
                else:
                    w_wall = jnp.zeros((self.n_w, 3), dtype).at[:, 2].set(
                        jnp.asarray(self.wall_omega, dtype))
                    w_rel = w[:, None, :] - w_wall[None]
                m_r = rolling_torque(w_rel, resw.normal_force, r_,
                                     wall_table(params.mu_roll_pw), inertia[:, None], self.dt_c)
                m_r = jnp.where(wact[..., None] if m_r.ndim == 3 else wact, m_r, 0.0)
                tq = tq + m_r
                if heat:
                    roll_rate = rolling_loss(m_r, w_rel, inertia[:, None], self.dt_c, dim == 3)
                    w_wall_rel = jnp.broadcast_to(w_wall if dim == 2 else w_wall[None],
                                                  m_r.shape)
            torque = torque + jnp.sum(tq, axis=1)
        max_ovl = jnp.maximum(max_ovl, jnp.max(jnp.where(wact, wovl / r_, 0.0)))
        work = None
        if heat:
            work = self._wall_work(pos, vel, t, r_, wact, wovl, a, wv, resw, m_r, w_wall_rel,
                                   roll_rate, wall_spring)
        return (force, torque, resw.spring, max_ovl,
                self.wall_slots(wact, wovl, resw.normal_force), wd, work)

    def _wall_work(self, pos, vel, t, r_, wact, wovl, lever, wv, resw, m_r, w_wall, roll_rate,
                   spring_old):
        """The walls' part of :class:`~drumheat.mechanics.dissipation.ContactWork` (as
        :meth:`_pair_work`; the overlap before the step from the walls at ``t - dt``)."""
        kn = self.wall_table(self.params.kn_pw)
        kt = self.wall_table(self.params.kt_pw)
        ovl0 = r_ - self.wall_geometry(pos - self.dt_c * vel, t - self.dt)[0]
        return (resw.force, lever, wv, m_r, w_wall,
                *_spring_energy_and_rates(kn, kt, ovl0, spring_old, wact, wovl, resw, roll_rate))


class CpuContactForces(ContactForces):
    """Pairs and walls in one C++ loop (:mod:`drumheat.mechanics.cpu_kernel`), the wall
    geometry from JAX but a drum shell's (:attr:`shell`); the kernel's per-slot outputs are
    already zero where nothing touches."""

    #: ``(R, omega)`` of a drum shell that is the first wall, whose geometry the C++ loop
    #: computes from the positions it reads anyway (``cpu_kernel.contacts(shell=...)``: in XLA,
    #: four passes over the particles per step, written out for the loop to read back); None
    #: where the first wall is none, or with friction heat (whose second pass reads the walls'
    #: velocities from JAX)
    shell: Optional[tuple[float, float]] = None

    def __init__(self, *args, batch_axis=None, **kw):
        super().__init__(*args, **kw)
        import drumheat.mechanics.cpu_kernel as cpu_kernel

        cpu_kernel.check_supported(self.dim, self.params, self.dtype, batch_axis)
        cpu_kernel.load()
        self._kernel = cpu_kernel
        # the C++ kernel's contact tables, wall spins, dt, period and rotation flag
        self._kernel_params = cpu_kernel.kernel_params(
            self.params, self.n_w, self.dtype, self.dt, self.wall_omega,
            self.fold_length or self.periodic_length, self.rotation)
        # the radii, masses and moments of inertia as the loop takes them: one value where all
        # particles share it (XLA turned such a constant into a broadcast that it wrote out
        # anew every step), the types not at all with one type
        self._kernel_particles = (
            *(cpu_kernel.uniform_or_all(a) for a in (self.radius, self.mass, self.inertia)),
            self.ptype if self.params.n_types > 1 else to_device(np.zeros(1, np.int32)))
        # gravity as the loop adds it to each particle's force last, one row where all
        # particles share the mass (:meth:`gravity`, multiplied on the host)
        _, m, inertia, _ = self._kernel_particles
        self._body_force = to_device(np.asarray(m)[:, None] * np.asarray(self.g_vec))
        # the coming step's skin test in the loop: its kick c F takes one mass for all
        self.looks_ahead = m.shape == (1,)
        self.shell = _shell_of(self.walls, self.friction_heat)
        # the step's kicks and drift in the loop: one mass and moment of inertia (its kicks'
        # c F, c_I M), and the walls' geometry the loop's own (none, or the shell alone)
        self.drifts = (self.looks_ahead and inertia.shape == (1,)
                       and (self.n_w == 0 or (self.shell is not None and self.n_w == 1))
                       and self.friction_heat is None)

    def _contacts(self, pos, vel, w, t, nbrs, pair_spring, wall_spring, temperature, details,
                  ahead, drift, steps) -> ForceResult:
        i, j = nbrs.idx[0], nbrs.idx[1]
        # the shell's geometry in the loop where it reads the positions given (not the wider
        # ones of mixed precision, whose walls JAX evaluates before rounding)
        shell = self.shell if pos.dtype == self.dtype else None
        wd, wn, wv = self.wall_geometry(pos, t, first=0 if shell is None else 1)
        heat_args = {}
        c = self.conduction
        if c is not None and temperature is not None:
            heat_args = dict(temperature=temperature, conduction_law=c.law,
                             conduction_h=c.coefficient, gap_tolerance=c.gap_tolerance)
        if self.friction_heat is not None:  # the walls before the step, as JaxContactForces
            heat_args["wall_distance_before"] = self.wall_geometry(pos - self.dt_c * vel,
                                                                   t - self.dt)[0]
        (fk, tk, new_spring, ovl, dist, fn, new_wall_spring, w_ovl, w_fn, mx, heat, p_cond,
         pair_rows, wall_rows, rates, moved, w_cond, drifted, counted) = self._kernel.contacts(
            self.pair_positions(pos), vel, w, *self._kernel_particles, nbrs.idx, pair_spring,
            wd, wn, wv, wall_spring, **self._kernel_params, **heat_args,
            pair_gap=self.gap_pp, order=nbrs.order, details=details, body_force=self._body_force,
            ahead=None if ahead is None else (ahead, nbrs.reference_position), shell=shell,
            wall_gap=self.gap_pw, drift=drift, steps=steps)
        # p_cond, w_cond: the pairs and wall slots within the conduction gap, pair_gap_mask's
        # and wall_gap_mask's tests in the C++ loop
        contacts = self.record(i, j, ovl > 0, ovl, dist, fn, p_cond,
                               self.wall_slots(w_ovl > 0, w_ovl, w_fn), w_cond.reshape(-1))
        if c is None or temperature is None:
            heat = None
        work = None
        if self.friction_heat is not None:
            work = KernelWork(nbrs.idx, nbrs.order, pair_rows, wall_rows, wv, rates)
        # fk includes gravity: the loop's body force, added there last
        return ForceResult(fk, tk, new_spring, new_wall_spring, contacts, mx[0], heat, work,
                           None if ahead is None else moved[0], drifted, counted)

    def dissipation(self, work: KernelWork, vel, w) -> Dissipation:
        """The step's heat from the C++ loop's rows (its second pass,
        :func:`~drumheat.mechanics.cpu_kernel.contact_heat`), as
        :func:`~drumheat.mechanics.dissipation.step_heat` computes it in JAX."""
        fh = self.friction_heat
        particle, sums = self._kernel.contact_heat(
            vel, w, work.idx, work.pair_rows, work.wall_rows, work.wall_velocity,
            self._kernel_params["wall_omega"], self.dt, fh.conductivity, fh.wall_conductivity,
            work.order)
        by_source = jnp.concatenate([work.rates, (sums[1] - jnp.sum(work.rates))[None]])
        return Dissipation(particle, sums[0], by_source)


def _shell_of(walls, friction_heat) -> Optional[tuple[float, float]]:
    """:attr:`CpuContactForces.shell` of these walls: ``(R, omega)`` of a first wall that is a
    :class:`~drumheat.geometry.walls.DrumShell` of fixed radius and speed (numbers, not traced
    values), without friction heat; else None."""
    if not walls or type(walls[0]) is not DrumShell or friction_heat is not None:
        return None
    w = walls[0]
    if not all(isinstance(v, (int, float, np.floating)) for v in (w.radius, w.rpm)):
        return None
    return float(w.radius), rpm_to_omega(float(w.rpm))


def make_contact_forces(backend: str, particles, walls, params: ContactParams, *,
                        batch_axis=None, **kw) -> ContactForces:
    """The :class:`ContactForces` of ``backend`` (``"jax"`` or ``"cpu"``); ``kw`` as
    :class:`ContactForces` takes them. ``"cpu"`` checks that the C++ loop serves (dimension,
    dtype, not under ``vmap``) and compiles it on first use."""
    if backend == "cpu":
        return CpuContactForces(particles, walls, params, batch_axis=batch_axis, **kw)
    if backend == "jax":
        return JaxContactForces(particles, walls, params, **kw)
    raise ValueError(f"pair_kernel must be 'jax' or 'cpu', got {backend!r}")
