"""The heat coupling of a DEM run: contact times accumulated every step, a thermal step every
``[dem] thermal_substeps`` steps (weigler-thermal-dem.md eq. [2.7], section 6.1).

:func:`make_thermal_update` is the ``extra_update`` hook of :func:`drumheat.mechanics.make_dem`
that the DEM-based motion models (``dem``, ``moving_bed``) plug in; its state is the DEM
state's ``extra``, a :class:`CoupledHeat` (:func:`initial_extra`): temperatures, heat accounts,
the thermal model's array leaves (so that parameters travel in the state and an ensemble vmaps
over them), contact-time accumulators aligned with the neighbour pairs (:class:`PairTimes`,
carried across neighbour-list rebuilds like the tangential springs: ``CoupledHeat`` is a
:class:`~drumheat.mechanics.integrator.PairCarried`) and per particle-wall slot, and the
contact time summed over the current output interval (:class:`ContactCount`). A step adds its
contact times to the accumulators of the thermal step only; the thermal step folds them into
the recording's and the output interval's (:func:`recorded_times`, :func:`contact_count` read
them, the time since the last thermal step included). With friction
heat (``make_dem(friction_heat=...)``, :mod:`drumheat.mechanics.dissipation`) each step's heat
of the contacts is gathered in a :class:`FrictionBook` and added to the temperatures with the
thermal step.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, NamedTuple, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from drumheat.devices import to_device
from drumheat.mechanics.cpu_kernel import count_conduction
from drumheat.mechanics.dissipation import SOURCES
from drumheat.mechanics.integrator import CountingUpdate, PairCarried
from drumheat.thermal.model import ThermalModel
from drumheat.thermal.network import ContactNetwork

__all__ = ["CoupledHeat", "PairTimes", "ContactCount", "FrictionBook", "thermal_network",
           "make_thermal_update", "ThermalUpdate", "initial_extra", "reset_record", "reset_count",
           "recorded_times", "contact_count", "mean_contacts",
           "drum_wall_step"]


class PairTimes(NamedTuple):
    """Contact time of each neighbour pair (M,) int32, in DEM steps (``CoupledHeat.dt``
    each), aligned with ``nbrs.idx``: ``time`` since the last thermal step (while ``k = 0``
    still that of the last thermal step, which the next step overwrites); ``rec_time`` from
    the start of the recording interval to the last thermal step (:func:`recorded_times` adds
    ``time`` and gives seconds; negative: the recording started after the last thermal step,
    :func:`reset_record`); None in a run that records no contacts (:func:`initial_extra` with
    ``record=False``). Whole steps: a count is exact and takes half the memory of a float64
    time."""

    time: jax.Array
    rec_time: Optional[jax.Array]


class ContactCount(NamedTuple):
    """Contact time of all particle pairs (``pair``) and of all particle-heated-wall contacts
    (``wall``) from :func:`reset_count` to the last thermal step, in DEM steps (float64
    scalars, whole numbers; :func:`contact_count` adds the time since and gives seconds;
    negative: the count started after the last thermal step)."""

    pair: jax.Array
    wall: jax.Array


class FrictionBook(NamedTuple):
    """Friction heat (:mod:`drumheat.mechanics.dissipation`), J: gathered since the last
    thermal step per particle (``E``), into the walls (``E_walls``) and per source
    (``E_sources``, :data:`~drumheat.mechanics.dissipation.SOURCES`); booked since t = 0 into
    the walls (``walls``) and per source (``sources``)."""

    E: jax.Array
    E_walls: jax.Array
    E_sources: jax.Array
    walls: jax.Array
    sources: jax.Array


class CoupledHeat(PairCarried):
    """The heat state of a coupled DEM run (``DEMState.extra``), made by :func:`initial_extra`.

    T: (N,) K. Q: {account: J} heat received since t = 0. model: the thermal model's array
    leaves (``eqx.partition(m, eqx.is_array)[0]``). k: steps since the last thermal step.
    wall_time, rec_wall_time: (N * n_walls,) int32, contact time per particle-wall slot in DEM
    steps since the last thermal step and from the start of the recording interval to the
    last thermal step (as ``time`` and ``rec_time`` of :class:`PairTimes`; ``rec_wall_time``
    None, as ``rec_time``, in a run that records no contacts). pair: :class:`PairTimes`.
    count: :class:`ContactCount`. dt: the DEM step the counts count, s (static).
    Optional (None when the run has none): Q_walls (n_walls,) J, the
    heat each wall primitive gave (``per_wall``); wall: the drum wall's segments
    (``[heat.drum_wall]``, :meth:`drumheat.thermal.drum_wall.DrumWall.initial`); friction: a
    :class:`FrictionBook`; flow: the motion model's own accumulators (``moving_bed``).
    """

    T: jax.Array
    Q: dict
    model: Any
    k: jax.Array
    wall_time: jax.Array
    rec_wall_time: Optional[jax.Array]
    pair: PairTimes
    count: ContactCount
    dt: float = eqx.field(static=True)
    Q_walls: Optional[jax.Array] = None
    wall: Optional[dict] = None
    friction: Optional[FrictionBook] = None
    flow: Optional[dict] = None

    def pair_arrays(self):
        """``(pair, count, k)``: the pairs' accumulators, the count they fold into and the
        steps since the last thermal step."""
        return self.pair, self.count, self.k

    @staticmethod
    def remap_pair_arrays(arrays, remap):
        """The pairs' accumulators carried to a new neighbour list; the time since the last
        thermal step of the pairs the list drops stays in the count (:func:`contact_count`
        reads the same before and after)."""
        pair, count, k = arrays
        steps = lambda t: jnp.sum(t, dtype=jnp.int32)  # noqa: E731
        # the old steps summed before the remap: it may write the new times into the old
        # ones' buffer (NeighborSetup.take_pairs), and without the barrier's order XLA kept a
        # copy of the old times for a sum it might take later
        before, time = jax.lax.optimization_barrier((steps(pair.time), pair.time))
        new = PairTimes(*(None if a is None else remap(a) for a in pair._replace(time=time)))
        # the dropped pairs' steps as the difference of two int32 sums: each sum may wrap
        # around, their difference is exact while the dropped pairs' steps sum to less than
        # 2^31 (they lie beyond the cutoff, so they touched at most a few of the steps since
        # the last thermal step); summed
        # in float64 instead, XLA wrote a float64 copy of the counts in every rebuild, at the
        # run's memory peak (docs/performance.md)
        dropped = jnp.where(k > 0, (before - steps(new.time)).astype(jnp.float64), 0.0)
        return new, count._replace(pair=count.pair + dropped), k

    def with_pair_arrays(self, arrays) -> "CoupledHeat":
        pair, count, _ = arrays
        return self.replace(pair=pair, count=count)

    def replace(self, **fields) -> "CoupledHeat":
        """This state with ``fields`` replaced."""
        return dataclasses.replace(self, **fields)


def thermal_network(idx, n, pair_steps, wall_time, wall_heated, n_walls, h, dt,
                    wall_ids=None, pair_kernel: str = "jax") -> ContactNetwork:
    """Contact network of one thermal step from accumulated contact times.

    Parameters
    ----------
    idx : int array (2, M)
        Neighbour pairs (padding index ``n``).
    pair_steps : int array (M,)
        DEM steps each pair touched during the thermal step (the padding's are not read).
    wall_time : array (n * n_walls,)
        Time each (particle, wall primitive) touched, s, row-major.
    wall_heated : bool array (n_walls,)
        Primitives that exchange heat (they carry a temperature).
    h : float
        Thermal step, s; weights are contact-time fractions ``time / h``.
    dt : float
        DEM step, s: a pair's time is ``steps dt``, whose fraction the network forms one
        block of slots at a time (``ContactNetwork.pair_unit``).
    wall_ids : int array (n_walls,), optional
        Wall id (index into the wall effect's temperatures) of each primitive; default 0 for
        all (a drum whose only heated wall is the shell).
    pair_kernel : {"jax", "cpu"}
        The DEM's contact backend: with ``"cpu"`` the contact conduction sums over the pairs
        in C++ (:attr:`ContactNetwork.native_conduction`,
        :func:`drumheat.mechanics.cpu_kernel.count_conduction`: the same sum to round-off, at
        a fraction of XLA:CPU's passes over the slots, docs/performance.md); the other
        effects stay in JAX.
    """
    # the padding slots keep their index n (ContactNetwork: dropped by the effects' scatters);
    # pointed at particle 0 instead, each would add its zero into particle 0, and a GPU
    # serialises those atomic adds (docs/performance.md, GPU)
    i, j = idx[0], idx[1]
    wp = jnp.repeat(jnp.arange(n), n_walls)
    wk = jnp.tile(jnp.arange(n_walls), n)
    w_wall = wall_time / h * wall_heated[wk]
    wid = jnp.zeros_like(wp) if wall_ids is None else jnp.asarray(wall_ids, wp.dtype)[wk]
    native = _cpu_conduction if pair_kernel == "cpu" else None
    return ContactNetwork(i, j, pair_steps, wp, wid, w_wall, pair_unit=(dt, h),
                          native_conduction=native)


def _cpu_conduction(T, diameter, alpha, net: ContactNetwork):
    """:attr:`ContactNetwork.native_conduction` of the C++ contact backend."""
    dt, h = net.pair_unit
    # the rows stacked again: of a neighbour list's rows XLA hands the list itself
    ij = jnp.stack([net.pair_i, net.pair_j])
    return count_conduction(T, diameter, alpha, ij, net.pair_weight, dt, h)


def make_thermal_update(model: ThermalModel, n: int, n_walls: int, wall_heated, substeps: int,
                        dt: float, batch_axis: str | None = None, wall_ids=None,
                        per_wall: bool = False, friction: bool = False,
                        pair_kernel: str = "jax"):
    """``extra_update`` for :func:`drumheat.mechanics.make_dem`: coupled heat transfer.

    The ``extra`` state is a :class:`CoupledHeat` (:func:`initial_extra`); the thermal
    parameters are part of it (``model``), so a ``vmap`` over states runs variants with
    different parameters. Every step adds the step's contact times (the contacts that conduct,
    ``Contacts.pair_conducts`` / ``wall_conducts``) to its accumulators; every ``substeps``
    steps the temperatures take one explicit step on them, which then go into the recording's
    and the output interval's accumulators (``fold``). ``batch_axis`` names the vmap axis
    of an ensemble: the thermal sub-step then stays a real ``lax.cond`` (all members count the
    same steps).

    ``wall_ids`` (n_walls,) gives each wall primitive's wall id (see :func:`thermal_network`).
    ``per_wall``: every primitive is its own wall (``wall_ids = 0..n_walls-1``) and the state
    also carries ``Q_walls``.

    ``friction``: the DEM turns its contacts' losses into heat (``Contacts.dissipation``); the
    state's :class:`FrictionBook` gathers each step's heat, and the next thermal step adds it
    to the temperatures and to the account ``Q["friction"]`` (and the walls' share and the
    sources to their totals), so that all of them are booked at the same instants.

    ``pair_kernel``: the DEM's contact backend (``make_dem(pair_kernel=...)``); ``"cpu"`` sums
    the contact conduction of the thermal step in C++ too (:func:`thermal_network`).

    Returns a :class:`ThermalUpdate` (a :class:`~drumheat.mechanics.CountingUpdate`: the DEM
    may hand it the counts of the steps up to the next thermal step at once), or with
    ``friction`` or ``batch_axis`` the plain hook (each step's heat is its own; an ensemble's
    members step jointly).
    """
    h = substeps * dt
    heated = to_device(wall_heated, bool)
    skeleton = eqx.partition(model, eqx.is_array)[1]
    if per_wall and wall_ids is None:
        wall_ids = np.arange(n_walls, dtype=np.int32)

    heated_weights = _heated_weights(heated)

    def model_of(extra):
        return eqx.combine(extra.model, skeleton)

    drum_wall = model.drum_wall is not None  # [heat.drum_wall]: segments with their own state

    def fold(extra):
        """``extra`` with the contact times since the last thermal step added to the
        recording's (if the run records) and the output interval's accumulators."""
        extra = extra.replace(count=_count(extra, heated_weights, substeps))
        if extra.pair.rec_time is None:
            return extra
        pair = extra.pair._replace(rec_time=extra.pair.rec_time + extra.pair.time)
        return extra.replace(pair=pair, rec_wall_time=extra.rec_wall_time + extra.wall_time)

    def thermal_step(extra, ops):
        idx = ops[0] if drum_wall else ops
        net = thermal_network(idx, n, extra.pair.time, extra.wall_time * dt, heated,
                              n_walls, h, dt, wall_ids, pair_kernel)
        m = model_of(extra)
        if drum_wall:
            q, ext, out = drum_wall_step(m, extra, net, ops[1], ops[2], h, n_walls)
        else:
            q, ext = m.heat_flows(extra.T, net)
            out = {}
        if per_wall:
            wall_effect = m.effect("wall")
            qw = (wall_effect.heat_flow_by_wall(extra.T, m.particles, net, n_walls)
                  if wall_effect is not None else jnp.zeros(n_walls))
            out["Q_walls"] = extra.Q_walls + h * qw
        heat = h * q
        if friction:  # the heat gathered since the last thermal step
            fr = extra.friction
            heat = heat + fr.E
            ext = dict(ext, friction=jnp.sum(fr.E) / h)
            out["friction"] = FrictionBook(
                jnp.zeros_like(fr.E), jnp.zeros_like(fr.E_walls), jnp.zeros_like(fr.E_sources),
                fr.walls + fr.E_walls, fr.sources + fr.E_sources)
        T = extra.T + heat / m.particles.capacity
        Q = {a: extra.Q[a] + h * ext[a] if a in ext else extra.Q[a] for a in extra.Q}
        # k = 0 marks the times as folded: the next step starts them afresh (zeroing them here
        # made XLA copy both every step in the other branch of the lax.cond)
        return fold(extra).replace(T=T, Q=Q, k=jnp.zeros_like(extra.k), **out)

    def accumulate(extra, state, pm, wm, steps, fr):
        # the steps' counts of the conducting contacts added, and the thermal step where it
        # falls due (after the last of them)
        fresh = extra.k == 0  # the first step after a thermal step
        pair = extra.pair._replace(time=jnp.where(fresh, 0, extra.pair.time) + pm)
        extra = extra.replace(pair=pair, wall_time=jnp.where(fresh, 0, extra.wall_time) + wm,
                              k=extra.k + steps, friction=fr)
        ops = (state.nbrs.idx, state.position, state.time) if drum_wall else state.nbrs.idx
        if substeps == 1:
            return thermal_step(extra, ops)
        go = extra.k >= substeps
        if batch_axis is not None:
            go = jax.lax.psum(go.astype(jnp.int32), batch_axis) > 0
        return jax.lax.cond(go, thermal_step, lambda e, _: e, extra, ops)

    def update(extra, state, contacts, dt_):
        # the contacts that conduct: overlapping or within the conduction gap tolerance
        # ([heat.contact] / [heat.wall] gap_tolerance, drumheat.mechanics.make_dem)
        # (the recording's and the output interval's accumulators take them at the thermal
        # step: a per-step sum over the pairs cost ~0.1 ms per step at N = 1e4 on XLA:CPU)
        # one step each (PairTimes: whole steps)
        pm = contacts.pair_conducts.astype(jnp.int32)
        wm = contacts.wall_conducts.astype(jnp.int32)
        fr = extra.friction
        if friction:
            d = contacts.dissipation
            fr = fr._replace(E=fr.E + d.particle, E_walls=fr.E_walls + d.walls,
                             E_sources=fr.E_sources + d.by_source)
        return accumulate(extra, state, pm, wm, 1, fr)

    if friction or batch_axis is not None:  # each step's heat, or an ensemble's joint steps
        return update

    def free_steps(extra):
        # up to the next thermal step, which comes after the last of them
        return jnp.maximum(substeps - extra.k, 1).astype(jnp.int32)

    def counted(extra, state, pair_counts, wall_counts, steps, dt_):
        return accumulate(extra, state, pair_counts, wall_counts, steps, extra.friction)

    return ThermalUpdate(update, free_steps, counted)


class ThermalUpdate(CountingUpdate):
    """The coupled heat's ``extra_update`` (:func:`make_thermal_update`) as a
    :class:`~drumheat.mechanics.CountingUpdate`: between two thermal steps it only counts the
    steps each contact conducts, so the DEM may hand it the counts of a run of steps at once
    (``counted``; the same integers as step by step, the thermal step at the same step).

    ``update``, ``free_steps``, ``counted``: the hook's three functions, as
    :func:`make_thermal_update` builds them over one model, wall set and thermal step."""

    def __init__(self, update, free_steps, counted):
        self._update, self._free_steps, self._counted = update, free_steps, counted

    def __call__(self, extra, state, contacts, dt):
        return self._update(extra, state, contacts, dt)

    def free_steps(self, extra):
        return self._free_steps(extra)

    def counted(self, extra, state, pair_counts, wall_counts, steps, dt):
        return self._counted(extra, state, pair_counts, wall_counts, steps, dt)


def drum_wall_step(m: ThermalModel, extra: CoupledHeat, net: ContactNetwork, position, time,
                   h: float,
                   n_walls: int):
    """One explicit thermal step of the particles' heat flows with a drum wall of segments
    (``[heat.drum_wall]``, :meth:`ThermalModel.heat_flows_wall`): each particle-wall slot's
    segment from the particle's polar angle at the step's end (``position``, time ``time``).
    Returns the heat flow into each particle (W), the bed's accounts (W) and ``{"wall":
    the segments' state advanced by h}`` (forward Euler, the step checked against
    :meth:`ThermalModel.stability_limit` when the motion model is built)."""
    pos = jnp.asarray(position, jnp.float64)
    angle = jnp.repeat(jnp.arctan2(pos[:, 1], pos[:, 0]), n_walls)
    net = dataclasses.replace(net, wall_angle=angle)
    q, ext, rate, flows = m.heat_flows_wall(extra.T, extra.wall, net, time)
    w = extra.wall
    wall = {"T": w["T"] + h * rate, "Q": {a: w["Q"][a] + h * flows[a] for a in w["Q"]}}
    return q, ext, {"wall": wall}


def initial_extra(model: ThermalModel, T0, capacity: int, n: int, n_walls: int, dt: float,
                  per_wall: bool = False, accounts=(), friction: bool = False,
                  record: bool = True) -> CoupledHeat:
    """The thermal part of the DEM state at t = 0, for a DEM of step ``dt`` (s; the contact
    times count its steps).

    ``per_wall`` adds the per-primitive heat ``Q_walls`` (n_walls,) J; ``accounts`` adds
    further heat accounts (J, zero at t = 0) that an open boundary books into ``Q`` (e.g. the
    enthalpy carried in by recycled particles); ``friction`` the account ``friction`` and the
    friction-heat accumulators (:func:`make_thermal_update`). ``record=False``: the run
    records no contacts, so the recording's accumulators (:func:`recorded_times`) are left
    out (None): one int32 per pair slot and per particle-wall slot less in the state, in
    every neighbour rebuild's remap and in every thermal step.
    """
    if friction:
        accounts = tuple(accounts) + ("friction",)
    # made on the host (drumheat.devices.to_device: no compiled program each)
    zeros = lambda shape, dtype=np.float64: to_device(np.zeros(shape, dtype))  # noqa: E731
    z = zeros(n * n_walls, np.int32)
    zc = zeros(capacity, np.int32)
    zero = zeros(())
    book = None
    if friction:
        book = FrictionBook(zeros(n), zero, zeros(len(SOURCES)), zero, zeros(len(SOURCES)))
    return CoupledHeat(
        T=to_device(T0, float),
        Q={a: zeros(()) for a in tuple(model.accounts) + tuple(accounts)},
        model=eqx.partition(model, eqx.is_array)[0], k=to_device(0, jnp.int32), wall_time=z,
        rec_wall_time=z if record else None,
        pair=PairTimes(zc, zc if record else None),
        count=ContactCount(zero, zero), dt=float(dt),
        Q_walls=zeros(n_walls) if per_wall else None,
        # [heat.drum_wall]: the segments' temperatures and accounts
        wall=model.drum_wall.initial() if model.drum_wall is not None else None,
        friction=book)


def _heated_weights(wall_heated):
    """(n_walls,) 1.0 for the heated walls, else 0.0: the weights of a particle's wall slots in
    the count of heated-wall contact time (one per wall, not per particle-wall slot: a constant
    array over all slots would stay in memory as an input of every compiled step)."""
    return to_device(wall_heated, jnp.float64)


def _steps(counts, most=None):
    """The sum of step counts as a float64 scalar (exact below 2^53 steps). ``most``: no count
    exceeds it; where the counts then cannot sum past int32, they are summed in it (the same
    number: every partial sum is an integer that float64 holds exactly), so that XLA does not
    write a float64 copy of them first (at the thermal step of a rebuilding step that copy,
    8 bytes per pair slot, was part of the run's memory peak: docs/performance.md)."""
    if most is not None and counts.size * int(most) < 2**31:
        return jnp.sum(counts, dtype=jnp.int32).astype(jnp.float64)
    return jnp.sum(counts, dtype=jnp.float64)


def _since_thermal_step(extra):
    """``(pair (M,), wall (N * n_walls,))``: the contact times since the last thermal step,
    in steps."""
    fresh = extra.k == 0
    return (jnp.where(fresh, 0, extra.pair.time), jnp.where(fresh, 0, extra.wall_time))


def _pending(extra, heated, most=None) -> ContactCount:
    """The contact times since the last thermal step, summed as :class:`ContactCount`
    (steps); ``heated``: :func:`_heated_weights`; ``most``: the most steps between thermal
    steps (:func:`_steps`), if known."""
    # the pairs' times summed before the reset of a fresh state is applied (the same sum):
    # the reset's int32 copy of every slot is not written
    _, wall = _since_thermal_step(extra)
    pair = jnp.where(extra.k == 0, 0.0, _steps(extra.pair.time, most))
    # whole numbers of steps: the float64 sum is exact in any order
    return ContactCount(pair, jnp.sum(wall.reshape(-1, heated.shape[-1]) * heated))


def _count(extra, heated, most=None) -> ContactCount:
    """The count with the contact times since the last thermal step added (steps)."""
    return ContactCount(*(c + p for c, p in zip(extra.count, _pending(extra, heated, most))))


def recorded_times(extra):
    """``(pair (M,), wall (N * n_walls,))``: the contact time of each neighbour pair and of
    each particle-wall slot since :func:`reset_record`, s (a state made with ``record=True``,
    :func:`initial_extra`)."""
    if extra.pair.rec_time is None:
        raise ValueError("this coupled-heat state records no contact times (initial_extra "
                         "with record=False)")
    pair, wall = _since_thermal_step(extra)
    return (extra.pair.rec_time + pair) * extra.dt, (extra.rec_wall_time + wall) * extra.dt


def contact_count(extra, wall_heated, substeps=None) -> ContactCount:
    """The contact time of all particle pairs and of all particle-heated-wall contacts since
    :func:`reset_count`, s (``wall_heated`` (n_walls,) as for :func:`make_thermal_update`;
    ``substeps``, if given: the mechanical steps per thermal step of the update that made
    ``extra``, the most steps a pair's count since the last thermal step can hold, which lets
    the sum run in int32, :func:`_steps`)."""
    return ContactCount(*(c * extra.dt for c in
                          _count(extra, _heated_weights(wall_heated), substeps)))


@functools.partial(jax.jit, static_argnames="substeps")
def mean_contacts(extra, wall_heated, span, substeps=None):
    """``(pairs, wall pairs)``: the mean number of particle pairs and of particle-heated-wall
    pairs in contact over an output interval of ``span`` s (:func:`contact_count` / span), as
    one compiled program (evaluated eagerly, each of its operations compiles one of its own:
    :func:`drumheat.devices.to_device`)."""
    count = contact_count(extra, wall_heated, substeps)
    return count.pair / span, count.wall / span


def reset_record(extra):
    """``extra`` with the contact times of the recording (:func:`recorded_times`) set to zero:
    the accumulators take minus the time since the last thermal step, which the next thermal
    step adds. Unchanged in a state that records nothing."""
    if extra.pair.rec_time is None:
        return extra
    pair, wall = _since_thermal_step(extra)
    return extra.replace(pair=extra.pair._replace(rec_time=-pair), rec_wall_time=-wall)


def reset_count(extra, wall_heated):
    """``extra`` with the contact time summed over the output interval (:func:`contact_count`)
    set to zero, as :func:`reset_record`."""
    pending = _pending(extra, _heated_weights(wall_heated))
    return extra.replace(count=ContactCount(*(-p for p in pending)))


def thermal_step_limit(model: ThermalModel, n: int, dim: int, size_ratio: float,
                       walls_at_once: int) -> float:
    """A lower bound of the explicit thermal step limit ``min m c / sum(alpha A)`` (weigler
    eq. [2.2]) over every contact network a DEM bed can form, s.

    Each particle is given the most contacts it can have at once: the kissing number (6 in a
    monolayer, 12 in 3D) times ``size_ratio^(dim - 1)`` (more, smaller neighbours fit around a
    large particle; the transfer area uses the smaller diameter, so this over-counts) and
    ``walls_at_once`` heated wall primitives, all for the whole step. A thermal step below
    this bound keeps every explicit update a convex combination (the maximum principle).
    """
    z = (6 if dim == 2 else 12) * max(1.0, size_ratio) ** (dim - 1)
    return float(_fullest_network_limit(model, int(n), float(z), float(walls_at_once)))


@eqx.filter_jit
def _fullest_network_limit(model: ThermalModel, n: int, z: float, walls_at_once: float):
    """:func:`thermal_step_limit`'s bound for ``z`` contacts and ``walls_at_once`` heated wall
    primitives per particle, as one compiled program (evaluated eagerly, each operation of the
    model's conductance sum compiled one of its own: drumheat.devices.to_device)."""
    idx = jnp.arange(n, dtype=jnp.int32)
    # a pair (i, i) of weight w adds 2 w g to particle i: weight z / 2 gives z contacts
    net = ContactNetwork(idx, idx, jnp.full(n, 0.5 * z), idx, jnp.zeros(n, jnp.int32),
                         jnp.full(n, walls_at_once))
    return model.stability_limit(net)
