"""DEM state, velocity-Verlet step and a chunked runner with checks.

Usage (functional, like jax-md)::

    from drumheat.geometry import DrumShell
    from drumheat.mechanics import make_particles, contact_params, make_dem

    particles = make_particles(radius=np.full(70, 2e-3), density=2700.0)
    params = contact_params(2.18e5, damping_ratio=0.3, friction=0.9, wall_friction=0.6)
    dem = make_dem(particles, [DrumShell(0.025, rpm=12.0)], params, dim=2)
    state = dem.init(positions)
    state, contacts = dem.step(state)          # one step, jittable
    state = dem.run(state, 100_000)            # chunked lax.scan with checks

Integration (velocity Verlet, the "kick-drift-kick" form used by LIGGGHTS ``nve/sphere``):

1. ``v += dt/2 F/m``, ``w += dt/2 M/I`` (I = 2/5 m r^2, solid sphere; also in 2D, where the
   particles are spheres of a monolayer that move in x-y and spin about z, as in PFC2D);
2. ``x += dt v``; the neighbour list is rebuilt if some particle moved more than skin/2;
3. forces and torques at the new positions with the half-step velocities (the dashpots and
   the tangential spring increment use them, as LIGGGHTS does). The dashpot then lags by
   dt/2, a first-order error: the restitution coefficient of a damped collision (e = 0.5)
   comes out 0.42 at dt = 0.2 t_crit, 0.488 at 0.05 and 0.4988 at 0.01 t_crit. (A predicted
   full-step velocity ``v + dt F/m`` for the dashpots was tried and rejected: it made dense
   damped beds unstable at dt = 0.2 t_crit.)
4. ``v += dt/2 F/m``, ``w += dt/2 M/I``.

Time step: ``t_crit = 2 sqrt(m_min / k_max)`` (Weigler digest [2.1], k_max the largest normal
or tangential stiffness); a given ``dt > t_crit`` is refused with a ValueError. The default
step is the smaller of ``safety_factor x t_crit`` (``safety_factor`` 0.2 here, 0.1 in scenes)
and, for spinning particles, the explicit limit of the tangential dashpots
(:meth:`ContactParams.dashpot_time_step`, derived in
:func:`drumheat.models.soft_sphere.dashpot_time_step`): the dashpots use the half-step
velocities, and a spin braked by several sticking contacts at once overshoots above it (0.079
t_crit at damping ratio 0.3). Above that limit the contacts of resting and slowly moving
particles chatter between sticking and sliding at half the step frequency, and a drum bed
flows as if its friction were lower; a given dt above it is warned about
(:class:`DEMAccuracyWarning`). The single-contact modes are far inside Verlet's stability
limit (the tangential-rotational one, ``omega = sqrt(7 k_t/m)``, has ``omega dt = 0.42`` at
0.079 t_crit). The measurements (angle of repose with and without the tangential dashpot,
resting beds) are in docs/models/dem-mechanics.md.
"""

from __future__ import annotations

import abc
import dataclasses
import math
import warnings
from functools import partial
from typing import Any, Callable, NamedTuple, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from drumheat.devices import device_copy, to_device
from drumheat.geometry.walls import expand_walls, wall_bounds
from drumheat.mechanics.contact_forces import ContactParams, critical_time_step
from drumheat.mechanics.cpu_kernel import drift_constants, shared_value, skin_test_constants
from drumheat.mechanics.conduction import PairConduction
from drumheat.mechanics.dissipation import FrictionHeat, boundary_energy
from drumheat.mechanics.errors import (
    NeighborListError,
    NonFiniteError,
    OverlapError,
    ParticleEscapeError,
)
from drumheat.mechanics.forces import ContactForces, Contacts, make_contact_forces
from drumheat.mechanics.neighbors import (PEC, NeighborSetup, dense_bed_pairs,
                                          make_displacement, make_neighbor_setup, pair_sources,
                                          sort_pairs, take_pair_data)
from drumheat.mechanics.precision import PositionResolution, fold_length, position_resolution
from drumheat.models.soft_sphere import STICKING_CONTACTS, default_time_step

__all__ = [
    "DEMAccuracyWarning",
    "Particles",
    "make_particles",
    "DEMState",
    "PairCarried",
    "CountingUpdate",
    "Contacts",
    "DEM",
    "make_dem",
]


class DEMAccuracyWarning(UserWarning):
    """A DEM setting that is stable but known to give wrong bed mechanics."""


class Particles(eqx.Module):
    """Per-particle constants (SI). ``mass`` and ``inertia`` are those of solid spheres.

    radius (m), mass (kg) = rho 4/3 pi r^3 (= rho pi d^3/6, Weigler digest sec. 4),
    inertia (kg m^2) = 2/5 m r^2, ptype (int, material type for the contact tables),
    group (int, particle group for output).
    """

    radius: jax.Array
    mass: jax.Array
    inertia: jax.Array
    ptype: jax.Array
    group: jax.Array

    @property
    def n(self):
        return int(self.radius.shape[0])


def make_particles(radius, density, ptype=None, group=None) -> Particles:
    """Solid spheres from radii (m) and density (kg/m^3, scalar or per particle)."""
    r = np.asarray(radius, dtype=float).reshape(-1)
    rho = np.broadcast_to(np.asarray(density, dtype=float), r.shape)
    m = rho * 4.0 / 3.0 * math.pi * r**3
    n = r.size
    pt = np.zeros(n, int) if ptype is None else np.asarray(ptype, int).reshape(-1)
    gr = np.zeros(n, int) if group is None else np.asarray(group, int).reshape(-1)
    return Particles(to_device(r), to_device(m), to_device(0.4 * m * r * r),
                     to_device(pt, jnp.int32), to_device(gr, jnp.int32))


class DEMState(NamedTuple):
    """Mechanical state (a PyTree; carried through ``lax.scan``).

    position (N, dim) m; velocity (N, dim) m/s; angular_velocity (N,) in 2D (z component) or
    (N, 3) rad/s; force (N, dim) N and torque (N,) / (N, 3) N m at the current positions;
    time (s, float64); step (int); nbrs: the OrderedSparse neighbour list
    (:class:`~drumheat.mechanics.neighbors.NeighborList`); pair_spring (capacity, dim) m:
    tangential spring per neighbour pair (aligned with ``nbrs.idx``);
    wall_spring (N, W, dim) m: tangential spring per particle x wall primitive; n_rebuilds:
    neighbour rebuilds so far; max_overlap: largest overlap / smaller radius seen since the
    last check; extra: user state advanced by ``extra_update`` (e.g. temperatures).
    """

    position: jax.Array
    velocity: jax.Array
    angular_velocity: jax.Array
    force: jax.Array
    torque: jax.Array
    time: jax.Array
    step: jax.Array
    nbrs: Any
    pair_spring: jax.Array
    wall_spring: jax.Array
    n_rebuilds: jax.Array
    max_overlap: jax.Array
    extra: Any = None


# XLA:CPU options for the DEM kernels. Its YNNPACK library fusions (on by default in jaxlib
# 0.10) run the narrow (pairs, 3) element-wise work of the contact law 2-30x slower than XLA's
# own loop fusions: on the N = 2000 3D drum of scripts/bench_vs_liggghts.py they doubled the
# CPU time per step (3.2 vs 1.6 ms). Per-executable, so nothing else in the process changes;
# GPU backends ignore the option.
JIT_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": ""}


@partial(jax.jit, static_argnums=1)
def _wrapped(pos, periodic_length):
    """:func:`wrap_periodic_axis` of a set-up's positions as one compiled program."""
    return wrap_periodic_axis(pos, periodic_length)


def wrap_periodic_axis(pos, periodic_length, near: bool = False):
    """Positions with the last coordinate brought into ``[0, L)`` (L None: unchanged).

    ``near=True`` assumes that coordinate lies in ``[-L, 2L)`` (a step moves a particle far
    less than L) and shifts it by one period at most: the same numbers as ``mod`` there, in an
    element-wise select that XLA:CPU fuses with the drift (``mod`` and a column scatter took
    80 us at N = 1e4, this 30 us).
    """
    if periodic_length is None:
        return pos
    if not near:
        return pos.at[:, -1].set(jnp.mod(pos[:, -1], periodic_length))
    L = periodic_length
    last = jnp.arange(pos.shape[-1]) == pos.shape[-1] - 1
    return jnp.where(last & (pos >= L), pos - L, jnp.where(last & (pos < 0), pos + L, pos))


def _jit(fun, donate: bool = False):
    """``jax.jit`` with :data:`JIT_OPTIONS`; ``donate``: the first argument's buffers are
    donated (the outputs may reuse them in place)."""
    return jax.jit(fun, compiler_options=JIT_OPTIONS, donate_argnums=(0,) if donate else ())


class PairCarried(eqx.Module):
    """Base of user states (``DEMState.extra``) that hold arrays per neighbour pair.

    A state deriving from it names its per-pair arrays (:meth:`pair_arrays`: a PyTree whose
    leaves have a leading axis over the neighbour pairs, aligned with ``nbrs.idx``); the
    integrator remaps them at every neighbour rebuild and reallocation
    (:meth:`remap_pair_arrays`: by default exactly like the tangential springs, pairs matched
    by identity, new pairs start at zero) and puts them back with :meth:`with_pair_arrays`.
    The coupled heat model (:class:`drumheat.motion.coupling.CoupledHeat`) keeps its
    contact-time accumulators so.
    Any other ``extra`` (an array, a dict, None) is carried through the step unchanged.
    """

    @abc.abstractmethod
    def pair_arrays(self):
        """The per-pair arrays (a PyTree, leading axis over the neighbour pairs)."""

    @abc.abstractmethod
    def with_pair_arrays(self, arrays) -> "PairCarried":
        """This state with its per-pair arrays replaced by ``arrays``."""

    @staticmethod
    def remap_pair_arrays(arrays, remap):
        """The per-pair arrays ``arrays`` (:meth:`pair_arrays`) carried to a new neighbour
        list; ``remap`` takes one array over the old pairs to the new pairs. By default every
        leaf goes through ``remap``; a state may also book what the dropped pairs held (its
        ``arrays`` may then hold other leaves too)."""
        return jax.tree_util.tree_map(remap, arrays)


class CountingUpdate(abc.ABC):
    """An ``extra_update`` hook (:func:`make_dem`) that, on most steps, reads of the step's
    contacts only which ones conduct, and counts them: the steps between its own events (the
    coupled heat's thermal steps) then need not return to it one by one.

    Where the C++ contact loop makes the steps' kicks and drift
    (:attr:`~drumheat.mechanics.forces.ContactForces.drifts`), the loop between neighbour
    rebuilds makes runs of up to :meth:`free_steps` steps in one contact call (its skin test
    between them) and hands the hook their counts (:meth:`counted`) instead of calling it after
    each step. The coupled heat (:func:`drumheat.motion.coupling.make_thermal_update`) is one.
    """

    @abc.abstractmethod
    def __call__(self, extra, state, contacts, dt):
        """``extra`` after the step that led to ``state`` with ``contacts`` (as any hook)."""

    @abc.abstractmethod
    def free_steps(self, extra):
        """How many steps from ``extra`` on the hook takes as counts (a traced int32 >= 1):
        :meth:`counted` of that many steps or fewer equals as many calls."""

    @abc.abstractmethod
    def counted(self, extra, state, pair_counts, wall_counts, steps, dt):
        """``extra`` after ``steps`` steps (at most :meth:`free_steps`), in which each pair
        slot (M,) and particle-wall slot (N W,) conducted ``pair_counts`` and ``wall_counts``
        times (int32; the slots of :class:`Contacts`, the list unchanged over the steps);
        ``state``: the state after them, with half-step velocities and spins."""


def pair_extra(extra):
    """The per-pair arrays of a :class:`PairCarried` ``extra`` state, else None."""
    return extra.pair_arrays() if isinstance(extra, PairCarried) else None


def remap_pair_extra(kind, pdata, remap):
    """``pdata`` (:func:`pair_extra` of an ``extra`` of type ``kind``) carried to a new
    neighbour list by ``remap`` (:meth:`PairCarried.remap_pair_arrays`); None stays None."""
    return None if pdata is None else kind.remap_pair_arrays(pdata, remap)


def _carry_pairs(state: DEMState, new, n: int) -> DEMState:
    """``state`` with the neighbour list ``new``: the springs and the per-pair data of
    ``extra`` carried from the state's list to it, pairs matched by identity (the old list is
    in canonical order when it has no cell order, :func:`pair_sources`)."""
    source = pair_sources(state.nbrs.idx, new.idx, n, old_sorted=state.nbrs.order is None)
    remap = lambda a: take_pair_data(a, source)  # noqa: E731
    pdata = pair_extra(state.extra)
    extra = state.extra if pdata is None else state.extra.with_pair_arrays(
        remap_pair_extra(type(state.extra), pdata, remap))
    return state._replace(nbrs=new, pair_spring=remap(state.pair_spring), extra=extra)


def _chunk_diagnostics(state, lo, hi, periodic_axis):
    """Small reductions checked on the host after each chunk."""
    pos = state.position
    finite = (jnp.all(jnp.isfinite(pos)) & jnp.all(jnp.isfinite(state.velocity))
              & jnp.all(jnp.isfinite(state.angular_velocity)) & jnp.all(jnp.isfinite(state.force)))
    lo = jnp.asarray(lo, pos.dtype)
    hi = jnp.asarray(hi, pos.dtype)
    out = (pos < lo) | (pos > hi)
    if periodic_axis is not None:
        out = out.at[:, periodic_axis].set(False)
    out_any = jnp.any(out, axis=-1)
    return dict(
        finite=finite,
        n_out=jnp.sum(out_any),
        first_out=jnp.argmax(out_any),
        max_overlap=state.max_overlap,
        overflow=state.nbrs.did_buffer_overflow,
    )


@dataclasses.dataclass(frozen=True)
class DEM:
    """A composed DEM system. Build with :func:`make_dem`.

    Attributes: dt (s), t_crit (s), m_min (kg), k_max (N/m), dim, walls (tuple of primitives),
    particles, params, neighbor (NeighborSetup), dtype (the mechanics'), position_dtype (the
    stored positions'; wider than dtype: mixed precision), fold_length (the period the contact
    law folds a periodic axis to with mixed precision, or None), gravity (m/s^2 vector),
    max_overlap (fraction of the smaller radius that stops a run).
    Functions: :meth:`init`, :meth:`step`, :meth:`run`, :meth:`run_steps`, :meth:`contacts`,
    :meth:`energies`, :meth:`reallocate`, :meth:`adopt`, :meth:`position_resolution`.

    ``step_fn(state) -> (state, contacts)`` and ``run_steps_fn(state, n_steps) -> state`` are
    the same functions un-jitted, for composing them into a larger program (``vmap`` over an
    ensemble, ``shard_map``): the methods are jitted with :data:`JIT_OPTIONS`, and JAX accepts
    compiler options on the top-level ``jit`` only, so pass ``compiler_options=JIT_OPTIONS``
    to the ``jit`` around your program.
    """

    dt: float
    t_crit: float
    m_min: float
    k_max: float
    dim: int
    walls: tuple
    particles: Particles
    params: ContactParams
    neighbor: NeighborSetup
    dtype: Any
    gravity: np.ndarray
    max_overlap: float
    domain_lo: np.ndarray
    domain_hi: np.ndarray
    _forces: Callable
    _step: Callable
    _run_steps: Callable
    _diag: Callable
    _energies: Callable
    _run_chunk: Optional[Callable] = None
    #: ``(force, torque, max_overlap)`` alone, for :meth:`init` (the other outputs of the
    #: contact call, per pair slot, are then XLA's temporaries, and the details not computed)
    _rest_forces: Optional[Callable] = None
    default_chunk: int = 1000
    cell_capacity: int = 0
    _external: Optional[Callable] = None
    step_fn: Optional[Callable] = None
    run_steps_fn: Optional[Callable] = None
    conduction: Optional[PairConduction] = None
    position_dtype: Any = None
    fold_length: Optional[float] = None

    def position_resolution(self) -> PositionResolution:
        """What the mechanics' float type resolves in this DEM's domain: the position spacing
        at its largest coordinate against the overlap under a particle's own weight
        (:func:`drumheat.mechanics.precision.position_resolution`)."""
        radius = np.asarray(self.particles.radius)
        # the escape box is the walls' box (or the given bounds; [0, L) along a periodic axis)
        # widened by the largest radius; the centres stay the smallest radius inside the walls
        inset = float(np.max(radius)) + np.full(self.dim, float(np.min(radius)))
        if self.neighbor.periodic_length is not None:
            inset[-1] = float(np.max(radius))
        return position_resolution(self.dtype, self.domain_lo + inset, self.domain_hi - inset,
                                   self.dt, self.m_min, self.k_max, self.gravity,
                                   self.position_dtype, self.fold_length)

    # -- construction of states --------------------------------------------------------------

    def init(self, position, velocity=None, angular_velocity=None, time=0.0, extra=None,
             pair_capacity: Optional[int] = None) -> DEMState:
        """Initial state: allocates the neighbour list and evaluates the forces at rest springs.

        position (N, dim) m; velocity (N, dim) m/s (default 0); angular_velocity (N,) in 2D or
        (N, 3) rad/s (default 0); time (s); extra: user state for ``extra_update``;
        pair_capacity: minimum neighbour-pair capacity; default the pairs of a dense bed of
        these particles within the cutoff (:func:`~drumheat.mechanics.neighbors.
        dense_bed_pairs`) with the head room of a fresh allocation
        (``capacity_multiplier``), or that head room on the current pairs if they are more.
        Overflows are handled by :meth:`run` in any case (reallocation and redo).
        """
        # the arrays made on the host and put on the device: eager jnp operations would each
        # compile a program that stays in memory (drumheat.devices.to_device)
        dt_ = self.dtype
        n = self.particles.n
        zeros = lambda shape: to_device(np.zeros(shape, dt_))  # noqa: E731
        pos = to_device(position, self.position_dtype or dt_)
        if pos.shape != (n, self.dim):
            raise ValueError(f"position must have shape ({n}, {self.dim}), got {pos.shape}")
        if self.neighbor.periodic_length is not None:
            pos = _wrapped(pos, self.neighbor.periodic_length)
        vel = zeros(pos.shape) if velocity is None else to_device(velocity, dt_)
        wshape = (n,) if self.dim == 2 else (n, 3)
        w = (zeros(wshape) if angular_velocity is None
             else to_device(np.reshape(angular_velocity, wshape), dt_))
        # floor: the pairs of a dense bed, so that a dilute start (a poured grid) does not size
        # the buffer for itself; a dense start sizes it from its own pairs
        if pair_capacity is None:
            nb = self.neighbor
            pair_capacity = int(math.ceil(nb.capacity_multiplier * n * dense_bed_pairs(
                self.particles.radius, nb.cutoff, self.dim)))
        nbrs = self.neighbor.allocate(pos, int(pair_capacity), self.cell_capacity)
        cap = nbrs.idx.shape[1]
        n_w = len(self.walls)
        state = DEMState(
            position=pos, velocity=vel, angular_velocity=w,
            force=zeros(pos.shape), torque=zeros(wshape),
            time=to_device(time, jnp.float64 if jax.config.jax_enable_x64 else dt_),
            step=to_device(0, jnp.int32), nbrs=nbrs,
            pair_spring=zeros((cap, self.dim)),
            wall_spring=zeros((n, n_w, self.dim)),
            n_rebuilds=to_device(0, jnp.int32), max_overlap=to_device(0.0, dt_),
            extra=self._check_temperature(extra),
        )
        f, m, ovl = self._rest_forces(state.position, state.velocity, state.angular_velocity,
                                      state.time, state.nbrs, state.pair_spring,
                                      state.wall_spring)
        if self._external is not None:
            f = f + jnp.asarray(self._external(state.position, state.velocity, state.time,
                                               state.extra), dt_)
        return state._replace(force=f, torque=m, max_overlap=ovl)

    def _check_temperature(self, extra):
        if self.conduction is None:
            return extra
        n = self.particles.n
        if extra is None or np.shape(extra) != (n,):
            raise ValueError(f"with conduction, extra must be the particle temperatures, shape "
                             f"({n},); got {None if extra is None else np.shape(extra)}")
        return to_device(extra, jnp.float64)

    # -- stepping ------------------------------------------------------------------------------

    def step(self, state: DEMState):
        """One velocity-Verlet step (jittable). Returns ``(new_state, contacts)``."""
        return self._step(self.adopt(state))

    def run_steps(self, state: DEMState, n_steps: int) -> DEMState:
        """``n_steps`` steps in one jitted loop (``lax.fori_loop``), without host-side checks."""
        return self._run_steps(self.adopt(state), to_device(int(n_steps), jnp.int32))

    def run_steps_in_place(self, state: DEMState, n_steps: int) -> DEMState:
        """:meth:`run_steps` reusing the buffers of ``state`` for the result (buffer donation:
        one copy of the state in memory instead of two); ``state`` is unusable afterwards."""
        return self._run_chunk(self.adopt(state), to_device(int(n_steps), jnp.int32))

    def passes(self, new: DEMState) -> bool:
        """Whether :meth:`check_chunk` accepts the chunk that ended in ``new`` (no buffer
        overflowed, and it passes the NaN, escape and overlap checks); it needs no start
        state."""
        d = jax.device_get(self._diag(new))
        return not d["overflow"] and self._passes(d)

    def adopt(self, state: DEMState) -> DEMState:
        """``state`` with its neighbour list in this DEM's pair order (jittable): a state made
        by a DEM of the other contact kernel (whose lists are in the other order, see
        :mod:`drumheat.mechanics.neighbors`) gets the same pairs re-sorted, their springs and
        per-pair data carried with them; a state in this order comes back as it is."""
        if (state.nbrs.order is None) == self.neighbor.index_order:
            return state
        nb, n = self.neighbor, self.particles.n
        order = None if nb.index_order else nb.layout_order(state.nbrs.reference_position,
                                                             state.nbrs.idx)
        new = sort_pairs(dataclasses.replace(state.nbrs, order=order), n, order)
        return _carry_pairs(state, new, n)

    def reallocate(self, state: DEMState, pair_capacity: int = 0, extra_cell_capacity: int = 0):
        """A new neighbour list at the state's positions (larger buffers); springs carried over."""
        nb = self.neighbor
        old_cc = state.nbrs.cell_list_capacity or 0
        new = nb.allocate(state.position, int(pair_capacity),
                          max(self.cell_capacity, old_cc + int(extra_cell_capacity)))
        n = self.particles.n
        count = int(jnp.sum(new.idx[0] < n))
        target = new.idx.shape[1]
        if bool(new.did_buffer_overflow):
            raise NeighborListError(
                f"neighbour list still overflows after reallocation (pairs {count}, capacity "
                f"{target}, cell capacity {new.cell_list_capacity})", state)
        return _carry_pairs(state, new, n)

    def run(self, state: DEMState, n_steps: int, chunk: Optional[int] = None,
            callback: Optional[Callable] = None, max_reallocations: int = 8,
            donate: bool = False) -> DEMState:
        """Advance ``n_steps`` in chunks of ``chunk`` steps, checking after every chunk.

        After each chunk (:meth:`check_chunk`): a neighbour/cell-list overflow discards the
        chunk, reallocates larger buffers at the chunk's start state and redoes it (never
        continues with missing contacts); NaN/Inf raises :class:`NonFiniteError`, a particle
        outside the domain :class:`ParticleEscapeError`, an overlap above ``max_overlap`` x the
        smaller radius :class:`OverlapError`; each carries the last good state
        (``err.state``). ``callback(state)`` is called after each accepted chunk.

        ``donate`` (default off; meant for accelerators): each chunk updates its start state
        in place (buffer donation: one copy of the state on the device instead of two), and the
        start is copied to the host for a redo or an error; ``state`` itself and the states
        given to ``callback`` are never donated (a device copy is made of them). It trades
        speed for memory, because every chunk waits for the copy (the measured trade:
        docs/performance.md, GPU).
        """
        chunk = int(chunk or self.default_chunk)
        state = self.adopt(state)
        donate = bool(donate)
        owned = False  # whether `state`'s buffers are this loop's own (not the caller's)
        done = 0
        while done < n_steps:
            k = min(chunk, n_steps - done)
            # host-made arrays and copies (drumheat.devices: no compiled program each)
            m = state.max_overlap
            start = state._replace(max_overlap=to_device(np.zeros(m.shape, m.dtype)))
            if donate and not owned:
                start = jax.tree_util.tree_map(device_copy, start)
            good = state
            for attempt in range(max_reallocations + 1):
                new, start = self._chunk(start, k, donate)
                if start is None:  # donated, and the chunk passed its checks
                    break
                if donate:  # `state` went into the chunk: the start came back from the host
                    good = start
                redo = self.check_chunk(start, new, attempt)
                if redo is None:
                    break
                start = redo
            else:
                raise NeighborListError(
                    f"neighbour list overflowed {max_reallocations + 1} times in a row at step "
                    f"{int(good.step)}; the packing may be exploding", good)
            state = new
            owned = callback is None
            done += k
            if callback is not None:
                callback(state)
        return state

    def _chunk(self, start: DEMState, k: int, donate: bool):
        """``(new, start)``: ``k`` steps from ``start``. With ``donate`` the chunk updates
        ``start``'s buffers in place; the start comes back (from a host copy) only when the
        chunk fails a check (:meth:`check_chunk` then decides), else None."""
        n = to_device(k, jnp.int32)
        if not donate:
            return self._run_steps(start, n), start
        # the copy to the host must have read the start before the chunk overwrites it
        device = jax.tree_util.tree_leaves(start)[0].sharding
        held = jax.device_put(start, jax.devices("cpu")[0], may_alias=False)
        new = self._run_chunk(start, n)
        if self.passes(new):
            return new, None
        return new, jax.device_put(held, device)

    def _passes(self, d) -> bool:
        """Whether the diagnostics ``d`` of a chunk pass the checks of :meth:`_check`."""
        return bool(d["finite"]) and int(d["n_out"]) == 0 and \
            float(d["max_overlap"]) <= self.max_overlap

    def check_chunk(self, start: DEMState, new: DEMState, attempt: int = 0):
        """Host-side check of a chunk run from ``start`` to ``new``.

        Returns None when the chunk is good; a new start state (larger neighbour or cell-list
        buffers, springs carried over) when a buffer overflowed and the chunk must be redone.
        Raises :class:`NonFiniteError`, :class:`ParticleEscapeError` or :class:`OverlapError`
        (carrying ``start`` as the last good state).
        """
        d = jax.device_get(self._diag(new))
        if not d["overflow"]:
            self._check(d, new, start)
            return None
        return self.grown(start, new, attempt)

    def grown(self, start: DEMState, new: DEMState, attempt: int = 0) -> DEMState:
        """``start`` with the buffers that ``new`` overflowed enlarged (pair capacity doubled
        or sized from the pairs where ``new`` ended; cell capacity grown by half per
        attempt)."""
        code = int(new.nbrs.error.code)
        cap = start.nbrs.idx.shape[1]
        grow_pairs = bool(code & PEC.NEIGHBOR_LIST_OVERFLOW)
        grow_cells = bool(code & PEC.CELL_LIST_OVERFLOW)
        cell_cap = start.nbrs.cell_list_capacity or 0
        need = cap
        if grow_pairs:
            need = 2 * cap
            if bool(jnp.all(jnp.isfinite(new.position))):
                # pairs where the failed chunk ended: a good estimate of what it needs
                est = self.neighbor.count_pairs(new.position)
                need = max(need, int(est * self.neighbor.capacity_multiplier) + 1)
        return self.reallocate(
            start, pair_capacity=need,
            extra_cell_capacity=(max(1, cell_cap // 2) * (attempt + 1) if grow_cells else 0))

    def _check(self, d, new, last_good):
        t = float(last_good.time)
        if not d["finite"]:
            raise NonFiniteError(
                f"NaN/Inf in the DEM state between t = {t:.6g} s and t = {float(new.time):.6g} s "
                f"(dt = {self.dt:.3g} s, t_crit = {self.t_crit:.3g} s). Reduce dt or check "
                "the inputs.", last_good)
        if d["n_out"] > 0:
            i = int(d["first_out"])
            p = np.asarray(new.position[i])
            raise ParticleEscapeError(
                f"{int(d['n_out'])} particle(s) left the domain [{self.domain_lo}, "
                f"{self.domain_hi}] (m) between t = {t:.6g} s and {float(new.time):.6g} s; "
                f"first: particle {i} at {p}. Usually dt too large / walls too soft "
                "(a particle tunnelled through a wall) or a particle inserted outside.",
                last_good)
        if float(d["max_overlap"]) > self.max_overlap:
            raise OverlapError(
                f"overlap reached {float(d['max_overlap']):.3g} x the smaller radius (limit "
                f"{self.max_overlap}) between t = {t:.6g} s and {float(new.time):.6g} s. "
                "Stiffen the contacts, reduce dt or the velocities.", last_good)

    # -- outputs ---------------------------------------------------------------------------------

    def contacts(self, state: DEMState) -> Contacts:
        """Contacts of ``state`` (same content as returned by :meth:`step`)."""
        return self._forces(state.position, state.velocity, state.angular_velocity, state.time,
                            state.nbrs, state.pair_spring, state.wall_spring)[4]

    def energies(self, state: DEMState) -> dict:
        """Energy book (J): kinetic (translation, rotation), gravitational potential
        ``-sum m g.x``, elastic (normal ``k_n delta^2/2`` and tangential ``k_t |xi|^2/2``)
        and their total; with friction heat also ``boundary``, the velocity-Verlet term of
        :func:`~drumheat.mechanics.dissipation.boundary_energy` (``total + boundary`` falls
        by exactly the heat the contacts dissipate)."""
        return {k: float(v) for k, v in self._energies(state).items()}


def _per_row(values):
    """Per-particle ``values`` (N,) as a column that multiplies rows (N, k); a 0-d value as it is."""
    return values if values.ndim == 0 else values[:, None]


def _velocity_verlet(forces: ContactForces, neighbor: NeighborSetup, *, dt, skin,
                     periodic_length, rotation, always_rebuild, batch_axis, external_force,
                     conduction, extra_update, boundary_update):
    """``(step, run_steps, energies)`` of :func:`make_dem`: the velocity-Verlet step over the
    contact forces (module docstring, integration), the loop of steps between neighbour
    rebuilds, and the energy book."""
    n, mass, inertia, dtype = forces.n, forces.mass, forces.inertia, forces.dtype
    half = 0.5 * dt
    # one value where all particles share it (the same quotient either way), divided on the
    # host (one IEEE quotient as XLA's; an eager division would compile a program)
    inv_m = to_device(1.0 / np.asarray(shared_value(mass)))
    inv_i = to_device(1.0 / np.asarray(shared_value(inertia)))
    half_skin_sq = (0.5 * skin) ** 2
    time_dtype = jnp.float64 if jax.config.jax_enable_x64 else dtype

    def _wrap(pos):
        return wrap_periodic_axis(pos, periodic_length, near=True)

    def rebuild(args, kind=None):
        # kind: the type of the state's extra, which remaps pdata
        pos, nbrs, spring, count, pdata = args
        new, source = neighbor.rebuild_with_sources(pos, nbrs)
        remap = lambda a: neighbor.take_pairs(a, source)  # noqa: E731
        return new, remap(spring), count + 1, remap_pair_extra(kind, pdata, remap)

    def keep(args):
        pos, nbrs, spring, count, pdata = args
        return nbrs, spring, count, pdata

    def half_kick(v, w, f, tq):
        """``v + dt/2 F/m``, ``w + dt/2 M/I`` (w unchanged without rotation)."""
        v = v + half * f * _per_row(inv_m)
        if rotation:
            w = w + half * tq * (inv_i if tq.ndim == 1 else _per_row(inv_i))
        return v, w

    def kick(state: DEMState):
        """First half-kick: half-step velocities and spins."""
        return half_kick(state.velocity, state.angular_velocity, state.force, state.torque)

    def drift(state: DEMState, kicked=None):
        """First half-kick (``kicked`` if given) and drift: half-step velocities, spins and
        the new positions."""
        v, w = kick(state) if kicked is None else kicked
        return v, w, _wrap(state.position + dt * v)

    def needs_rebuild(state: DEMState, x):
        return neighbor.max_displacement_sq(x, state.nbrs) > half_skin_sq

    # The coming step's skin test in the contact call (ContactForces.looks_ahead: the C++ loop
    # for particles of one mass): with the step's forces at hand it computes the coming step's
    # kicks and drift and their largest displacement, as `needs_rebuild(st, drift(st,
    # kicked(st, 1)))` of the loop's condition does in XLA (a pass over the particles' positions,
    # velocities, forces and reference positions every step). Only where the step's forces are
    # the call's own (no external force) and the positions are the mechanics' (not mixed
    # precision, whose pair law reads positions rounded to the mechanics' type).
    ahead = None
    if (forces.looks_ahead and external_force is None and boundary_update is None
            and batch_axis is None and not always_rebuild):
        ahead = skin_test_constants(dt, inv_m, periodic_length, neighbor.lo, dtype)
    # With it, the step's kicks and drift in the call too where it can make them
    # (ContactForces.drifts: one mass and moment of inertia, no walls but a drum shell, whose
    # geometry the loop computes at the drifted positions): run_segments' steps that keep the
    # list hand the call the step before's state instead of XLA's three passes over the
    # particles before it (the same numbers).
    drifts = ahead is not None and forces.drifts
    # With the drift in the call and a hook that only counts the conducting contacts between
    # its events (CountingUpdate), run_segments' steps that keep the list run in the call, up
    # to the hook's next event, one call for all (the same numbers: `run_in_call`).
    runs = drifts and isinstance(extra_update, CountingUpdate) and conduction is None
    dt_time = to_device(dt, time_dtype)

    def drift_args(state: DEMState, aux):
        """``drift`` of the contact call: the constants with the pending half-kick's factor
        ``aux``, the step before's forces and torques."""
        return (drift_constants(aux, dt, inv_m, inv_i, periodic_length, dtype), state.force,
                state.torque)

    def step(state: DEMState, pairs: str = "check", drifted=None):
        # pairs: "check" (rebuild the neighbour list if some particle moved more than half the
        # skin: a lax.cond), "keep" (the caller knows it need not) or "rebuild"; drifted:
        # drift(state) if the caller has it already
        return step_ahead(state, pairs, drifted)[:2]

    def step_ahead(state: DEMState, pairs: str = "check", drifted=None, look: bool = False,
                   aux=None):
        # step(), and with `look` (run_segments' `in_call`) the coming step's largest squared
        # displacement from the list's reference positions (else None), and the step's
        # half-step velocities and spins; `aux` (with `drifts`, a step that keeps the list):
        # the kicks and drift in the contact call, the state's last half-kick `aux` times
        # pending (run_segments), instead of `drifted`
        if aux is not None:
            v, w, x = state.velocity, state.angular_velocity, state.position  # the call's
        else:
            v, w, x = drift(state) if drifted is None else drifted
        t = state.time + dt_time
        extra = state.extra
        args = (x, state.nbrs, state.pair_spring, state.n_rebuilds, pair_extra(extra))
        if always_rebuild or pairs == "rebuild":
            nbrs, spring, count, pdata = rebuild(args, type(extra))
        elif pairs == "keep":
            nbrs, spring, count, pdata = keep(args)
        else:
            need = needs_rebuild(state, x)
            if batch_axis is not None:
                need = jax.lax.psum(need.astype(jnp.int32), batch_axis) > 0
            nbrs, spring, count, pdata = jax.lax.cond(need, partial(rebuild, kind=type(extra)),
                                                      keep, args)
        if pdata is not None:
            extra = extra.with_pair_arrays(pdata)
        res = forces(x, v, w, t, nbrs, spring, state.wall_spring,
                     temperature=extra if conduction is not None else None,
                     ahead=ahead if look else None,
                     drift=None if aux is None else drift_args(state, aux))
        if aux is not None:
            x, v, w = res.drifted
        vh, wh = v, w  # the half-step velocities and spins
        f, tq, spring, wspring, contacts, ovl, heat, work = res[:8]
        if external_force is not None:
            f = f + external_force(x, v, t, extra).astype(dtype)
        v, w = half_kick(v, w, f, tq)
        if work is not None:  # friction heat: the contacts' losses at the full-step velocities
            contacts = contacts._replace(dissipation=forces.dissipation(work, v, w))
        new = DEMState(position=x, velocity=v, angular_velocity=w, force=f, torque=tq, time=t,
                       step=state.step + 1, nbrs=nbrs, pair_spring=spring, wall_spring=wspring,
                       n_rebuilds=count, max_overlap=jnp.maximum(state.max_overlap, ovl),
                       extra=extra)
        if conduction is not None:
            new = new._replace(extra=extra + dt * heat / conduction.heat_capacity)
        if extra_update is not None:
            new = new._replace(extra=extra_update(new.extra, new, contacts, dt))
        if boundary_update is not None:
            new = boundary_update(new)
        return new, contacts, res.ahead, (vh, wh)

    run_in_call = (_run_in_call(forces, extra_update, ahead, drift_args, dt, dt_time,
                                half_skin_sq) if runs else None)

    energies = _energy_book(forces, rotation, dt)

    def run_steps(state, n_steps):
        # a loop with a traced trip count: one compilation serves every chunk length
        if batch_axis is not None or always_rebuild:
            return jax.lax.fori_loop(0, n_steps, lambda k, st: step(st)[0], state)
        return run_segments(state, n_steps)

    def run_segments(state, n_steps):
        """The same steps as ``fori_loop(step)``, as runs of steps between neighbour rebuilds.

        Inside a run the neighbour list is known to stay valid (the loop condition tests the
        coming step's drift against the skin), so the step carries it unchanged; each run ends
        with one step that rebuilds. Without the per-step ``lax.cond`` XLA updates the pair
        arrays in place instead of copying the neighbour indices and springs every step
        (~0.3 ms per step at N = 1e4 on XLA:CPU, docs/performance.md). The decisions, and so
        the trajectory, are those of :func:`step` (with the skin test in the C++ call, whose
        squared displacement may differ from XLA's by an ulp, unless one falls within an ulp
        of half the skin squared).
        """
        # The loop carries each step's state with its last half-kick pending: velocities and
        # spins at the half step, which the next step kicks twice (the last half-kick of its
        # predecessor, then its own first one) before its drift, and the loop's end once. The
        # same additions in the same order as `step`'s, so the same numbers; but the full-step
        # velocities, which nothing in the loop reads, are no longer written every step (two
        # passes over (N, 3) less). The carry's `aux` says whether a half-kick is pending: 0
        # for the chunk's start state, whose velocities are full-step (adding 0 x the kick
        # leaves them as they are), 1 after a step.
        # A `boundary_update` may change the full-step velocities: then the carry holds the
        # coming step's half-kick instead, computed once from them.
        # The coming step's kick and positions are computed twice (the same values), in the
        # loop condition, which tests them against the skin, and in the step: carried, they
        # made XLA copy them every step (from the carry's drift into the state).
        # With the skin test in the contact call (`ahead`), the carry's `moved` holds the
        # coming step's largest squared displacement from each step's call (the loop's first
        # test, before any call, from XLA); the loop's condition then only compares it. Where
        # the call also makes the kicks and drift (`drifts`), a step that keeps the list hands
        # it the carried state and its `aux`, and neither the condition nor the step computes
        # them in XLA; the step that rebuilds drifts in XLA, since the rebuild needs the new
        # positions before the call. Where the hook only counts the conducting contacts
        # between its events (`runs`: CountingUpdate, the coupled heat), such steps run in the
        # call, as many as the hook lets pass before its next event (`run_in_call`): XLA then
        # returns to the loop once per run, not once per step.
        pending = boundary_update is None
        in_call = pending and ahead is not None and state.position.dtype == dtype

        def kicked(st, aux):
            if not pending:
                return aux
            v, w = half_kick(st.velocity, st.angular_velocity, aux * st.force, aux * st.torque)
            return half_kick(v, w, st.force, st.torque)

        def moved_by(st, aux):
            return neighbor.max_displacement_sq(drift(st, kicked(st, aux))[2], st.nbrs)

        def advance(c, pairs):
            st, k, aux, moved = c
            if in_call and runs and pairs == "keep":  # a run of steps in the call
                new, done, ahead_moved = run_in_call(st, aux, n_steps - k)
                return new, k + done.astype(k.dtype), jnp.ones_like(aux), ahead_moved
            if in_call and drifts and pairs == "keep":  # the kicks and drift in the call
                new, _, ahead_moved, (v, w) = step_ahead(st, pairs, look=True, aux=aux)
            else:
                v, w, x = drift(st, kicked(st, aux))
                new, _, ahead_moved, _ = step_ahead(st, pairs, (v, w, x), look=in_call)
            if not pending:
                return new, k + 1, kick(new), moved
            new = new._replace(velocity=v, angular_velocity=w)
            return new, k + 1, jnp.ones_like(aux), ahead_moved if in_call else moved

        def go_on(c):
            st, k, aux, moved = c
            return (k < n_steps) & ~((moved if in_call else moved_by(st, aux)) > half_skin_sq)

        def segment(c):
            c = jax.lax.while_loop(go_on, lambda c: advance(c, "keep"), c)
            return jax.lax.cond(c[1] < n_steps, lambda c: advance(c, "rebuild"), lambda c: c, c)

        k0 = jnp.zeros_like(jnp.asarray(n_steps))
        aux = jnp.zeros((), state.force.dtype) if pending else kick(state)
        moved = moved_by(state, aux) if in_call else jnp.zeros((), dtype)
        st, _, aux, _ = jax.lax.while_loop(lambda c: c[1] < n_steps, segment,
                                           (state, k0, aux, moved))
        if not pending:
            return st
        v, w = half_kick(st.velocity, st.angular_velocity, aux * st.force, aux * st.torque)
        return st._replace(velocity=v, angular_velocity=w)

    return step, run_steps, energies


def _run_in_call(forces: ContactForces, extra_update: "CountingUpdate", ahead, drift_args, dt,
                 dt_time, half_skin_sq):
    """``run_in_call(state, aux, left)`` of :func:`_velocity_verlet`'s loop: a run of steps in
    the contact call (``ContactForces.__call__(steps=...)``) with the hook's counts."""

    def run_in_call(state: DEMState, aux, left):
        # run_segments' steps that keep the list, as step_ahead with `aux` makes them one by
        # one, up to `left` steps and the hook's next event, in one contact call (`runs`): it
        # makes each step's kicks, drift and forces, its skin test of the coming step, and
        # stops after a step whose test fails. Returns the state after them (half-step
        # velocities and spins, as run_segments carries them), the steps made and the coming
        # step's largest squared displacement. The time advances by dt per step, as each
        # step adds it; the largest overlap ratio is the steps' largest, the hook's
        # accumulators take the steps' counts (CountingUpdate.counted), the same integers.
        most = jnp.minimum(jnp.minimum(left, extra_update.free_steps(state.extra)), 1 << 20)
        res = forces(state.position, state.velocity, state.angular_velocity,
                     state.time + dt_time, state.nbrs, state.pair_spring, state.wall_spring,
                     ahead=ahead, drift=drift_args(state, aux), steps=(most, half_skin_sq))
        (x, v, w), (pair_counts, wall_counts, done) = res.drifted, res.counted
        done = done[0]
        t = jax.lax.fori_loop(0, done, lambda _, t: t + dt_time, state.time)
        new = state._replace(position=x, velocity=v, angular_velocity=w, force=res.force,
                             torque=res.torque, time=t, step=state.step + done,
                             pair_spring=res.pair_spring, wall_spring=res.wall_spring,
                             max_overlap=jnp.maximum(state.max_overlap, res.max_overlap))
        extra = extra_update.counted(state.extra, new, pair_counts, wall_counts, done, dt)
        return new._replace(extra=extra), done, res.ahead

    return run_in_call


def _energy_book(forces: ContactForces, rotation: bool, dt):
    """``energies(state)`` of :func:`make_dem`: kinetic, rotational, potential and elastic
    energy, J, their total, and with friction heat the work of the boundaries."""
    mass, inertia = forces.mass, forces.inertia

    def energies(state):
        m = mass
        ek = 0.5 * jnp.sum(m[:, None] * state.velocity**2)
        w2 = state.angular_velocity**2
        if w2.ndim == 2:
            w2 = jnp.sum(w2, axis=-1)
        er = 0.5 * jnp.sum(inertia * w2)
        ep = -jnp.sum(m * (state.position @ forces.g_vec))
        c = forces.at(state).contacts
        el = forces.elastic_energy(c, state.pair_spring, state.wall_spring)
        out = dict(kinetic=ek, rotational=er, potential=ep, elastic=el,
                   total=ek + er + ep + el)
        if forces.friction_heat is not None:
            tq = state.torque if rotation else jnp.zeros_like(state.torque)
            out["boundary"] = boundary_energy(state.force, tq, state.velocity,
                                              state.angular_velocity, mass, inertia,
                                              forces.g_vec, dt)
        return out

    return energies


def _checked_time_step(mass, params, dt, safety_factor, rotation):
    """``(dt, t_crit, m_min, k_max)``: the DEM time step, by default the smaller of
    ``safety_factor x t_crit`` (Weigler digest [2.1]) and, with spin, the explicit limit of the
    tangential dashpots (:meth:`ContactParams.dashpot_time_step`). A given dt above ``t_crit``
    is refused; one above the dashpot limit is warned about (:class:`DEMAccuracyWarning`)."""
    m_min = float(np.min(mass))
    k_max = params.k_max()
    t_crit = critical_time_step(m_min, k_max)
    t_dash = params.dashpot_time_step(m_min) if rotation else math.inf
    given = dt is not None
    dt = float(dt if given else default_time_step(t_crit, safety_factor, t_dash)[0])
    if not dt > 0:
        raise ValueError(f"time step must be positive, got dt = {dt}")
    if dt > t_crit:
        raise ValueError(
            f"time step dt = {dt:.4g} s exceeds the critical time step t_crit = 2 sqrt(m_min/k_n)"
            f" = {t_crit:.4g} s (m_min = {m_min:.4g} kg, k_n = {k_max:.4g} N/m; Weigler digest "
            f"[2.1]). Use dt <= {safety_factor * t_crit:.4g} s (safety factor "
            f"{safety_factor}), or soften the contacts (k_n ~ 1/dt^2).")
    if given and dt > t_dash * (1 + 1e-9):
        warnings.warn(
            f"dt = {dt:.4g} s is above the explicit limit of the tangential dashpots, "
            f"{t_dash:.4g} s = {t_dash / t_crit:.3g} t_crit (a particle with "
            f"{STICKING_CONTACTS} sticking contacts): the contacts of resting and slowly "
            "moving particles chatter between sticking and sliding at half the step frequency, "
            "a drum bed flows as if its friction were lower and the contact forces of a resting "
            "bed are wrong (docs/models/dem-mechanics.md, time step). Leave dt to the default "
            "or lower the tangential damping.", DEMAccuracyWarning, stacklevel=3)
    return dt, t_crit, m_min, k_max


def _warn_coarse_positions(res: PositionResolution, periodic: bool) -> None:
    """Warn (:class:`DEMAccuracyWarning`) where the contact law's float type cannot resolve the
    overlap under a particle's own weight in the domain (:mod:`drumheat.mechanics.precision`)."""
    ratio = res.spacing_over_weight_overlap
    if ratio is None or ratio < 1.0:
        return
    axis = int(np.argmax(res.spacing))
    drift = ""
    if res.positions == res.dtype:
        drift = (f", and a particle slower than {res.slowest_speed[axis]:.2g} m/s along that "
                 "axis does not move along it in a step")
    remedy = "float64 ([dem] precision = \"float64\")"
    if periodic and axis == len(res.spacing) - 1 and res.positions == res.dtype:
        remedy += " or mixed precision (\"mixed\": float64 positions, the rest float32)"
    warnings.warn(
        f"The {res.dtype} contact law resolves positions in this domain only to "
        f"{res.spacing[axis]:.2g} m (the spacing of {res.dtype} at the largest coordinate it "
        f"reads, along {'xyz'[axis]}), {ratio:.2g} times the overlap under a particle's own "
        f"weight, m g / k_n = {res.weight_overlap:.2g} m: resting contacts cannot represent "
        f"the force that carries one particle{drift} (drumheat.mechanics.precision; "
        f"docs/performance.md, precision). Run the mechanics in {remedy}, or compare with a "
        "float64 run before using the results.", DEMAccuracyWarning,
        stacklevel=2)  # make_dem's line: a scene builds several DEMs (pour, run), one line shows


def _neighbour_domain(walls, dim, radius, skin, gap_cut, bounds, periodic_length,
                      capacity_multiplier, builder="jax", pair_order="index"):
    """``(neighbour setup, cell-capacity floor, escape box lo, hi)`` of a DEM domain.

    The neighbour cutoff is ``2 r_max + skin`` plus the conduction gap (pairs that conduct
    across a gap must be listed); the search box is the walls' bounding box (or ``bounds``)
    with a margin of two cutoffs; particles count as escaped one radius outside the domain.
    """
    r_max, r_min = float(np.max(radius)), float(np.min(radius))
    cutoff = 2.0 * r_max + skin + gap_cut * 2.0 * r_max
    if bounds is None:
        lo, hi = wall_bounds(walls, dim)
    else:
        lo, hi = (np.asarray(b, dtype=float).copy() for b in bounds)
    if periodic_length is not None:
        if dim != 3:
            raise ValueError("periodic_length requires dim = 3")
        lo[-1], hi[-1] = 0.0, float(periodic_length)
        if periodic_length < 2.0 * cutoff:
            raise ValueError(f"periodic length {periodic_length} m must be at least twice the "
                             f"neighbour cutoff {cutoff:.4g} m")
    if np.any(np.isnan(lo)) or np.any(np.isnan(hi)):
        raise ValueError(f"the walls do not bound the domain in every direction (lo={lo}, "
                         f"hi={hi}); pass bounds=(lo, hi) or periodic_length")
    margin = 2.0 * cutoff
    neighbor = make_neighbor_setup(dim, lo - margin, hi + margin, cutoff, skin, periodic_length,
                                   capacity_multiplier, builder, pair_order)
    # cell-list capacity floor: twice the particles of the smallest size that a cell of side
    # `cutoff` holds at the densest packing (hexagonal 0.907 in 2D, fcc 0.74 in 3D), plus one;
    # an estimate from a dilute start (a poured grid) would overflow at once
    if dim == 2:
        per_cell = 0.907 * cutoff**2 / (math.pi * r_min**2)
    else:
        per_cell = 0.74 * cutoff**3 / (4.0 / 3.0 * math.pi * r_min**3)
    cell_cap = int(math.ceil(2.0 * per_cell)) + 1
    return neighbor, cell_cap, lo - r_max, hi + r_max


def make_dem(
    particles: Particles,
    walls,
    params: ContactParams,
    *,
    dim: int,
    dt: Optional[float] = None,
    safety_factor: float = 0.2,
    gravity=None,
    periodic_length: Optional[float] = None,
    bounds=None,
    skin: Optional[float] = None,
    dtype=jnp.float64,
    position_dtype=None,
    capacity_multiplier: float = 1.5,
    always_rebuild: bool = False,
    max_overlap: float = 0.5,
    rotation: bool = True,
    extra_update: Optional[Callable] = None,
    external_force: Optional[Callable] = None,
    boundary_update: Optional[Callable] = None,
    chunk: int = 1000,
    batch_axis: Optional[str] = None,
    pair_kernel: str = "jax",
    neighbor_builder: Optional[str] = None,
    conduction: Optional[PairConduction] = None,
    conduction_gap: tuple[float, float] = (0.0, 0.0),
    friction_heat: Optional[FrictionHeat] = None,
    contact_details: bool = True,
) -> DEM:
    """Compose a DEM system (static choices are fixed here, before ``jit``).

    Args:
      particles: :class:`Particles` (see :func:`make_particles`).
      walls: wall primitives (``drumheat.geometry``); composites (Box) are expanded. Order =
        wall index of ``wall_spring`` / ``Contacts.wall_index``.
      params: :class:`ContactParams`; wall tables (T, W) must match the expanded walls.
      dim: 2 (monolayer of spheres in x-y, spin about z) or 3.
      dt: time step (s). Default the smaller of ``safety_factor * t_crit`` and the dashpot
        limit (module docstring, time step); a dt above ``t_crit`` is refused.
      gravity: vector (m/s^2); default 9.81 along -y.
      periodic_length: period L (m) of the z axis (3D drum slice without end plates); z is
        kept in [0, L).
      bounds: ``(lo, hi)`` of the domain (m); default from the walls (e.g. the drum shell).
      skin: neighbour-list skin (m); default 0.5 x the largest radius (cutoff 2 r_max + skin).
      dtype: float dtype of the mechanics (float32 or float64); time stays float64. The
        positions are kept in it too (unless ``position_dtype`` says otherwise): where the
        spacing of the coordinates the contact law reads, at their largest,
        reaches the overlap under a particle's own weight (float32 in a long periodic slice),
        a :class:`DEMAccuracyWarning` says so (:mod:`drumheat.mechanics.precision`).
      position_dtype: float dtype of the stored positions; default ``dtype``. float64 with
        float32 mechanics is mixed precision: the drift adds to float64 positions and the
        contact law reads them folded along a periodic axis and rounded to float32
        (:mod:`drumheat.mechanics.precision`), so a long periodic slice keeps the resolution
        of its cross-section. Not narrower than ``dtype``.
      always_rebuild: rebuild the neighbour list every step (for testing the history remap).
      max_overlap: overlap / smaller radius that stops a run (default 0.5, PFC's stated
        assumption, Weigler digest sec. 4 [2.4]).
      rotation: integrate particle spin (False freezes it, like PFC's "fix spin").
      extra_update: ``extra_update(extra, state, contacts, dt) -> extra``, called at the end of
        every step inside the scan (plug a thermal update in here). A
        :class:`CountingUpdate` (the coupled heat's) takes, between its own events, the
        counts of the steps each contact conducted instead; with the C++ loop's drift the
        steps between them then run in one contact call (the same numbers).
      external_force: ``external_force(position, velocity, t, extra) -> (N, dim)`` force (N)
        added to the contact forces and gravity every step (e.g. gas drag); it enters the
        second half-kick of the step, so it acts on the velocity at the new positions.
      boundary_update: ``boundary_update(state) -> state``, called last in every step (after
        ``extra_update``): open boundaries, e.g. particles leaving through an outlet re-entering
        at an inlet. A hook that moves particles must also clear their ``wall_spring`` rows;
        their pair springs lapse at the next neighbour rebuild (pairs are matched by identity).
      chunk: default number of steps per checked chunk in :meth:`DEM.run`.
      batch_axis: name of a ``jax.vmap`` axis over which the step is batched (ensembles of
        states, :func:`drumheat.run_ensemble`). The neighbour list is then rebuilt for every
        member of the batch when any member needs it (a ``psum`` over the axis), so that the
        rebuild stays a real ``lax.cond`` instead of being computed every step; because the
        pairs are kept in canonical order (:func:`~drumheat.mechanics.neighbors.sort_pairs`)
        an extra rebuild does not change the trajectory. Leave None for single runs.
      pair_kernel: ``"jax"`` (default; every backend, vmap, any material table) or ``"cpu"``:
        the particle-particle and particle-wall contacts (and the conduction) in one C++ loop
        on XLA's CPU threads, called through ``jax.ffi`` (:mod:`drumheat.mechanics.cpu_kernel`;
        a faster DEM step on CPU, docs/performance.md; 2D and 3D, float32 and
        float64, any materials, rolling resistance, friction heat; single runs, not under vmap;
        compiled with g++ on first use, ``cpu_kernel.available()`` says whether it can be).
        Same contact law; results agree with ``"jax"`` to round-off. Its neighbour lists go
        over to the cell order once the particles' numbering has mixed
        (:mod:`drumheat.mechanics.neighbors`, pair order), which keeps its memory reads local
        however the particles are numbered; the sums then depend on the rebuild times by
        round-off.
      neighbor_builder: who rebuilds the neighbour list in a run: ``"jax"`` (the cell list in
        XLA) or ``"cpu"`` (one C++ pass, :func:`drumheat.mechanics.cpu_kernel.neighbor_pairs`:
        the same pairs in the same order, quicker on XLA:CPU); default ``"cpu"`` with
        ``pair_kernel="cpu"``, else ``"jax"``.
      conduction: :class:`~drumheat.mechanics.conduction.PairConduction`: heat conduction
        through the touching pairs every step (:mod:`drumheat.mechanics.conduction`); the
        state's ``extra`` is then the particle temperatures (N,), float64, advanced after the
        forces of every step and before ``extra_update``.
      conduction_gap: ``(particle-particle, particle-wall)`` gap tolerances of the contacts that
        conduct heat (``Contacts.pair_conducts`` / ``wall_conducts``, what a coupled thermal
        update counts): a pair conducts while its surface gap is at most the first times the
        smaller diameter, a particle-wall contact while the gap is at most the second times the
        particle diameter; (0, 0): while they overlap (Weigler digest [2.4]). The neighbour
        cutoff grows by the pair gap so that such pairs are listed.
      friction_heat: :class:`~drumheat.mechanics.dissipation.FrictionHeat`: every step's
        contact losses (damping, sliding, rolling) as heat, split between the partners of each
        contact; the step's ``Contacts.dissipation`` carries it to ``extra_update``
        (:mod:`drumheat.mechanics.dissipation`). Both kernels (the C++ loop in a second pass
        after the second half-kick, :func:`~drumheat.mechanics.cpu_kernel.contact_heat`).
      contact_details: False: the contacts a step hands to ``extra_update`` leave out the
        per-pair mask, overlap, centre distance and normal force (None; the C++ loop does not
        write them): three arrays per pair slot less in every step's working memory, for a
        hook that reads only ``pair_conducts`` (the coupled heat). :meth:`DEM.contacts` and
        :meth:`DEM.energies` have them in any case.
    """
    gap_pp, gap_pw = (float(g) for g in conduction_gap)
    if not (0.0 <= gap_pp < 0.5 and 0.0 <= gap_pw < 0.5):
        raise ValueError(f"conduction_gap must be two fractions of the diameter in [0, 0.5), "
                         f"got {conduction_gap}")
    if dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3, got {dim}")
    if conduction is not None:
        conduction = PairConduction(*conduction).checked(particles.n)
    if friction_heat is not None:
        friction_heat = FrictionHeat(*friction_heat).checked(particles.n)
    walls = expand_walls(walls) if walls is not None else ()
    n_w = len(walls)
    if params.kn_pw.shape[1] not in (1, n_w) and n_w > 0:
        raise ValueError(f"wall parameter tables have {params.kn_pw.shape[1]} columns but there "
                         f"are {n_w} wall primitives")
    radius_np = np.asarray(particles.radius)
    mass_np = np.asarray(particles.mass)
    if np.any(radius_np <= 0) or np.any(mass_np <= 0):
        raise ValueError("particle radii and masses must be positive")
    if int(np.max(np.asarray(particles.ptype))) >= params.n_types:
        raise ValueError(f"particle type {int(np.max(np.asarray(particles.ptype)))} has no row "
                         f"in the contact tables ({params.n_types} types)")
    dt, t_crit, m_min, k_max = _checked_time_step(mass_np, params, dt, safety_factor,
                                                  rotation)
    if gravity is None:
        gravity = np.zeros(dim)
        gravity[1] = -9.81
    gravity = np.asarray(gravity, dtype=float)
    if gravity.shape != (dim,):
        raise ValueError(f"gravity must have shape ({dim},), got {gravity.shape}")

    r_max = float(np.max(radius_np))
    skin = 0.5 * r_max if skin is None else float(skin)
    # pairs that conduct across a gap must be in the neighbour list
    gap_cut = max(gap_pp, conduction.gap_tolerance if conduction is not None else 0.0)
    neighbor, cell_cap, dom_lo, dom_hi = _neighbour_domain(
        walls, dim, radius_np, skin, gap_cut, bounds, periodic_length, capacity_multiplier,
        neighbor_builder or ("cpu" if pair_kernel == "cpu" else "jax"),
        "cell" if pair_kernel == "cpu" else "index")
    periodic_axis = dim - 1 if periodic_length is not None else None

    dtype = jnp.dtype(dtype)
    position_dtype = dtype if position_dtype is None else jnp.dtype(position_dtype)
    if (dtype not in (jnp.float32, jnp.float64) or position_dtype not in (jnp.float32, jnp.float64)
            or position_dtype.itemsize < dtype.itemsize):
        raise ValueError(f"dtype and position_dtype must be float32 or float64, the positions "
                         f"not narrower than the mechanics; got {dtype.name} and "
                         f"{position_dtype.name}")
    fold = None  # mixed precision: the period the pair law folds the periodic axis to
    if position_dtype != dtype:
        cross = float(np.max(np.abs([dom_lo[:-1], dom_hi[:-1]])))  # the axes across a slice
        fold = fold_length(periodic_length, cross, neighbor.cutoff)
    forces = make_contact_forces(
        pair_kernel, particles, walls, params, batch_axis=batch_axis, dim=dim, dt=dt,
        dtype=dtype, gravity=gravity, rotation=rotation,
        displacement=neighbor.displacement if fold is None else make_displacement(dim, fold),
        conduction=conduction, conduction_gap=(gap_pp, gap_pw), periodic_length=periodic_length,
        friction_heat=friction_heat, fold_length=fold, pair_details=bool(contact_details))
    step, run_steps, energies = _velocity_verlet(
        forces, neighbor, dt=dt, skin=skin, periodic_length=periodic_length, rotation=rotation,
        always_rebuild=always_rebuild, batch_axis=batch_axis, external_force=external_force,
        conduction=conduction, extra_update=extra_update, boundary_update=boundary_update)
    diag = jax.jit(partial(_chunk_diagnostics, lo=dom_lo, hi=dom_hi, periodic_axis=periodic_axis))

    def rest_forces(*args):
        res = forces(*args, details=False)
        return res.force, res.torque, res.max_overlap

    dem = DEM(
        dt=dt, t_crit=t_crit, m_min=m_min, k_max=k_max, dim=dim, walls=walls,
        particles=particles, params=params, neighbor=neighbor, dtype=dtype, gravity=gravity,
        max_overlap=float(max_overlap), domain_lo=dom_lo, domain_hi=dom_hi,
        _forces=_jit(partial(forces, details=True)), _step=_jit(step),
        _run_steps=_jit(run_steps), _diag=diag,
        _energies=_jit(energies), _run_chunk=_jit(run_steps, donate=True),
        _rest_forces=_jit(rest_forces),
        default_chunk=int(chunk), conduction=conduction,
        cell_capacity=cell_cap, _external=external_force, step_fn=step, run_steps_fn=run_steps,
        position_dtype=position_dtype, fold_length=fold,
    )
    _warn_coarse_positions(dem.position_resolution(), periodic_length is not None)
    return dem
