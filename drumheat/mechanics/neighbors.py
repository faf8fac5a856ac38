"""Neighbour lists for DEM: a cell list with a Verlet skin, built in constant memory per
particle, in jax-md's OrderedSparse layout (:class:`NeighborList`: the fields and overflow
codes of ``jax_md.partition.NeighborList``, so code written for jax-md's lists reads ours).

* Format: ``OrderedSparse``: ``idx`` has shape (2, capacity); column k is the pair
  ``(i, j) = (idx[0, k], idx[1, k])`` with ``i < j``, each pair once; padding is ``N``.
  Per-pair data (tangential springs) live in arrays aligned with these columns.
* Pairs: every pair closer than the cutoff ``2 r_max + skin`` (plus the conduction gap), the
  same set as ``jax_md.partition.neighbor_list`` finds (``tests/test_neighbors.py`` holds the
  two equal). The build (:class:`CellGrid`) bins the particles into cells of side at least the
  cutoff, sorts them by cell, and visits the 3^dim neighbouring cells one after the other
  (``lax.fori_loop``), compacting each visit's hits into the pair buffer: its temporaries are
  ``N x cell capacity`` per visit, some hundred bytes per particle, where jax-md gathers all
  ``N x 3^dim x cell capacity`` candidates at once (about 10 kB per particle in 3D, the bulk
  of a run's memory).
* Domain: positions are shifted by ``-lo`` (the lower corner of the domain box, which includes a
  margin) into ``[0, box)``. In 3D the drum axis may be periodic (length L): then z is
  kept in ``[0, L)``, the cells wrap along it and the displacement uses the minimum image along
  z only.
* Rebuilds: the integrator decides when: as soon as some particle has moved more than
  ``skin / 2`` since the last build (the usual Verlet-list criterion), so no pair can come into
  contact unseen.
* Overflow: a build flags ``NEIGHBOR_LIST_OVERFLOW`` (more pairs than the buffer holds) or
  ``CELL_LIST_OVERFLOW`` (a cell holds more particles than the cell capacity) in the list's
  ``error`` (:class:`PEC`, jax-md's bits); the integrator then reallocates and redoes the chunk.
* Why not jax-md's own build: it gathers all candidates at once (about 10 kB per particle in
  3D, measured in docs/performance.md), and importing ``jax_md`` runs compiled code at import
  time (7-8 s of every drumheat start on the development machine). jax-md stays the reference
  the tests compare with.
* Pair order (:func:`sort_pairs`, ``NeighborSetup.pair_order``): ``"index"``, the canonical
  order, by ``(i, j)``: force sums then do not depend on when the list was built (an extra
  rebuild leaves a trajectory unchanged: ensembles rebuild every member together). ``"cell"``,
  with the C++ contact loop: grouped by the first particle in the order of the particles' cells
  at the build (:meth:`CellGrid.order`, kept in ``NeighborList.order``), ``j`` ascending within
  a group. The loop takes the pairs as listed with the particles' data laid out in that order,
  so it reads memory in the order of the particles' places however they are numbered (a turning
  bed mixes its numbering; docs/performance.md, the particles' order in memory); the sums then
  depend on the cell order of the last build (round-off). While the particles' own numbering
  keeps neighbours near in memory (a poured bed) the list stays canonical and ``order`` is
  ``0 .. N-1`` (:meth:`NeighborSetup.layout_order`): the copies would cost more than they save.
* History across rebuilds: after a rebuild, :func:`remap_pair_data` finds every new pair in the
  old pair list (a binary search on ``(i, j)`` in the old list sorted, int32) and carries its
  data over; new pairs start with zero history (:func:`pair_sources` finds,
  :func:`take_pair_data` carries).
* On CPU with the C++ contact loop the rebuild of a run is one C++ pass
  (``NeighborSetup(builder="cpu")``, :func:`drumheat.mechanics.cpu_kernel.neighbor_pairs`):
  the same pairs in the same order and the same sources, quicker than the XLA build
  (docs/performance.md); allocations stay in XLA.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Callable, Optional

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.devices import round_length

__all__ = [
    "NeighborList",
    "ListError",
    "PEC",
    "CellGrid",
    "make_displacement",
    "minimum_image",
    "NeighborSetup",
    "make_neighbor_setup",
    "DENSE_FRACTION",
    "dense_bed_pairs",
    "remap_pair_data",
    "pair_sources",
    "take_pair_data",
    "sort_pairs",
]


def make_displacement(dim: int, periodic_length: Optional[float] = None) -> Callable:
    """Displacement ``Ra - Rb`` (free space) with the minimum image along z if periodic.

    Built like ``jax_md.space.free()`` / ``space.periodic`` but periodic in the last axis only
    (the drum axis), which jax-md's own spaces cannot express.
    """
    if periodic_length is None:
        def displacement(Ra, Rb, **unused):
            return Ra - Rb
        return displacement
    if dim != 3:
        raise ValueError("a periodic drum axis needs dim = 3")
    L = float(periodic_length)

    def displacement(Ra, Rb, **unused):
        dR = Ra - Rb
        return dR.at[..., -1].set(minimum_image(dR[..., -1], L))

    return displacement


def minimum_image(dz, period: float):
    """The component ``dz`` (m) of a displacement along a periodic axis of length ``period``
    (m), folded to its minimum image ``dz - L round(dz / L)``."""
    return dz - period * jnp.round(dz / period)


def pair_sources(old_idx, new_idx, n, old_sorted: bool = False):
    """For each column of ``new_idx``, the column of ``old_idx`` holding the same pair, or -1
    (a new pair, padding), int32: pairs matched by identity.

    Each new pair is found in the old list by a binary search on ``(i, j)`` in lexicographic
    order, in int32 (no int64 keys ``i (N+1) + j``: the temporaries are a few int32 per pair).
    ``old_sorted=True``: ``old_idx`` is already sorted by ``(i, j)`` (:func:`sort_pairs`), so
    the sort is skipped.
    """
    m_old = old_idx.shape[1]
    order = None
    if not old_sorted:
        oi, oj, order = jax.lax.sort((old_idx[0], old_idx[1],
                                      jnp.arange(m_old, dtype=jnp.int32)), num_keys=2)
        old_idx = jnp.stack([oi, oj])
    ni, nj = new_idx[0], new_idx[1]

    def below(k):
        """Whether old pair k (clipped to the list) comes before (ni, nj)."""
        k = jnp.minimum(k, m_old - 1)
        a, b = old_idx[0, k], old_idx[1, k]
        return (a < ni) | ((a == ni) & (b < nj))

    # branchless lower bound: pos = the number of old pairs before (ni, nj), built bit by bit
    # from the highest power of two down (one int32 per pair carried); the first bit is
    # taken outside the loop so that pos is computed from the pairs (a constant start would
    # be allocated early and held through the neighbour build)
    top = max(int(m_old).bit_length() - 1, 0)

    def narrow(k, pos):
        cand = pos + jnp.left_shift(jnp.int32(1), (top - 1 - k).astype(jnp.int32))
        return jnp.where((cand <= m_old) & below(cand - 1), cand, pos)

    first = jnp.int32(1 << top)
    pos = jnp.where(below(first - 1), first, jnp.int32(0))
    pos = jax.lax.fori_loop(0, top, narrow, pos)
    pos = jnp.minimum(pos, m_old - 1)
    found = (old_idx[0, pos] == ni) & (old_idx[1, pos] == nj) & (ni < n)
    src = pos if order is None else order[pos]
    return jnp.where(found, src, -1).astype(jnp.int32)


def take_pair_data(old_data, source):
    """Per-pair data (M_old, ...) moved to a new list by :func:`pair_sources`' ``source``
    (M_new,): the old data where the pair was listed before, zeros for new pairs and padding."""
    found = source >= 0
    gathered = old_data[jnp.maximum(source, 0)]
    mask = found.reshape(found.shape + (1,) * (old_data.ndim - 1))
    return jnp.where(mask, gathered, 0)


def remap_pair_data(old_idx, old_data, new_idx, n, old_sorted: bool = False):
    """Carry per-pair data from an old pair list to a new one (pairs matched by identity).

    Args:
      old_idx, new_idx: OrderedSparse neighbour indices (2, M_old) and (2, M_new).
      old_data: array (M_old, ...) aligned with ``old_idx``.
      n: number of particles (padding value).
      old_sorted: ``old_idx`` is in canonical order already (:func:`sort_pairs`; every list
        the integrator holds is), which saves sorting it.
    Returns:
      array (M_new, ...): the old data of pairs present in both lists, zeros for new pairs
      and padding.

    :func:`take_pair_data` of :func:`pair_sources` (``old_sorted`` as there).
    """
    return take_pair_data(old_data, pair_sources(old_idx, new_idx, n, old_sorted))


def sort_pairs(nbrs, n, order=None):
    """The neighbour list with its pairs in canonical order (by ``(i, j)``, padding last), or
    with ``order`` (the particles in the order of their cells, :meth:`CellGrid.order`) grouped
    by ``i`` in that order, ``j`` ascending within a group, padding last.

    A canonical order makes the force sums (``segment_sum`` over the pairs) independent of when
    the list was built: a run that rebuilds every step and one that rebuilds rarely add the
    same non-zero contributions in the same order, so their trajectories agree bit for bit.
    It also groups each particle's pairs in memory. The cell order (pair order ``"cell"``, the
    module docstring) puts neighbours' pairs near each other too, for the C++ contact loop.
    """
    import dataclasses

    # a sort on the two int32 rows as keys (lexicographic (i, j), the order of the key
    # i (N+1) + j with padding N last): no int64 keys or permutation; the rows stacked (not
    # one sort of idx): XLA:CPU then keeps idx row-major, the layout of the scan carry
    if order is None:
        i, j = jax.lax.sort((nbrs.idx[0], nbrs.idx[1]), num_keys=2)
    else:  # keys (rank of i, j), the padding's rank N
        rank = jnp.full(n + 1, n, jnp.int32).at[order].set(jnp.arange(n, dtype=jnp.int32))
        _, j, i = jax.lax.sort((rank[nbrs.idx[0]], nbrs.idx[1], nbrs.idx[0]), num_keys=2)
    # the barrier makes every later use read the stacked rows, so the sorted ones die here
    return dataclasses.replace(nbrs, idx=jax.lax.optimization_barrier(jnp.stack([i, j])))


#: places apart in memory within which two partners count as near (:meth:`NeighborSetup.
#: layout_order`): 256 particles' data (positions, velocities, spins, radius, mass, moment of
#: inertia, temperature: about 100 bytes each in float64) fill about a core's 32 kB first-level
#: data cache
NEAR = 256


class PEC:
    """Overflow bits of :attr:`NeighborList.error` (the bits of ``jax_md.partition.PEC``)."""

    NEIGHBOR_LIST_OVERFLOW = 1 << 0  #: more pairs than the pair buffer holds
    CELL_LIST_OVERFLOW = 1 << 1  #: a cell holds more particles than the cell capacity


@partial(jax.tree_util.register_dataclass, data_fields=["code"], meta_fields=[])
@dataclass(frozen=True)
class ListError:
    """Overflow flags of a neighbour list: ``code`` (uint8 array) of :class:`PEC` bits."""

    code: jax.Array

    def update(self, bit: int, pred) -> "ListError":
        """The flags with ``bit`` set where ``pred`` holds (flags only accumulate)."""
        return ListError(jnp.where(pred, self.code | jnp.uint8(bit), self.code))


@partial(jax.tree_util.register_dataclass,
         data_fields=["idx", "reference_position", "error", "order"],
         meta_fields=["cell_list_capacity", "max_occupancy", "cell_size"])
@dataclass(frozen=True)
class NeighborList:
    """A neighbour list (OrderedSparse: see the module docstring).

    Attributes:
      idx: (2, capacity) int32 pairs ``(i, j)``, ``i < j``, padded with N.
      reference_position: box-frame positions at the last build (the skin criterion).
      error: :class:`ListError`, overflows since the last allocation.
      order: None (pair order ``"index"``), or (N,) int32 the layout order of the last build
        (pair order ``"cell"``, :meth:`NeighborSetup.layout_order`: the particles in the order
        of their cells, or ``0 .. N-1`` while their numbering will do): the pairs are grouped
        by their first particle in this order, and the C++ contact loop lays the particles'
        data out in it (``cpu_kernel.contacts``).
      cell_list_capacity: particles one cell may hold (static).
      max_occupancy: pair capacity, ``idx.shape[1]`` (static).
      cell_size: the cutoff the cells are built for, m (static).
    """

    idx: jax.Array
    reference_position: jax.Array
    error: ListError
    order: Optional[jax.Array]
    cell_list_capacity: int
    max_occupancy: int
    cell_size: float

    @property
    def did_buffer_overflow(self):
        """Whether the pair buffer or a cell overflowed since the last allocation."""
        return self.error.code & (PEC.NEIGHBOR_LIST_OVERFLOW | PEC.CELL_LIST_OVERFLOW)


@dataclass(frozen=True)
class CellGrid:
    """The cell grid of a neighbour search and the build that visits it.

    Attributes:
      dim: 2 or 3; cutoff: pair cutoff (m); cells: cells per axis; cell_size: their side (m),
      at least ``cutoff`` (an axis shorter than three cutoffs is one cell, so that no cell is
      visited twice); periodic: whether the last axis wraps (the drum axis); displacement:
      ``Ra - Rb`` with the minimum image along a periodic axis.
    """

    dim: int
    cutoff: float
    cells: tuple
    cell_size: tuple
    periodic: bool
    displacement: Callable

    @property
    def n_cells(self) -> int:
        return int(np.prod(self.cells))

    def shifts(self) -> np.ndarray:
        """Offsets of the neighbouring cells visited, (n, dim) int32: -1, 0, 1 along axes of
        three or more cells, 0 along one-cell axes."""
        axes = [(-1, 0, 1) if c >= 3 else (0,) for c in self.cells]
        return np.array(np.meshgrid(*axes, indexing="ij"), np.int32).reshape(self.dim, -1).T

    def cell_index(self, position):
        """Cell coordinates (N, dim) int32 of box-frame positions (clipped to the grid; along
        a periodic axis wrapped)."""
        size = jnp.asarray(self.cell_size, position.dtype)
        c = jnp.floor(position / size).astype(jnp.int32)
        cells = jnp.asarray(self.cells, jnp.int32)
        wrapped = jnp.mod(c, cells)
        clipped = jnp.clip(c, 0, cells - 1)
        if self.periodic:
            return clipped.at[:, -1].set(wrapped[:, -1])
        return clipped

    def flat(self, coords):
        """Flat cell number of cell coordinates (..., dim)."""
        mult = np.cumprod((1,) + tuple(self.cells[:-1])).astype(np.int32)
        return jnp.sum(coords * jnp.asarray(mult), axis=-1)

    def order(self, position):
        """The particles (N,) int32 in the order of their cells: by flat cell number of the
        box-frame ``position`` (:meth:`cell_index`), by index within a cell (the order of the
        cell list, and of the C++ build's)."""
        return jnp.argsort(self.flat(self.cell_index(position)), stable=True).astype(jnp.int32)

    def occupancy(self, cell):
        """``(flat cell number of each particle (N,), particles per cell (n_cells,))`` of cell
        coordinates :meth:`cell_index`."""
        key = self.flat(cell)
        return key, jax.ops.segment_sum(jnp.ones(cell.shape[0], jnp.int32), key, self.n_cells)

    def visit(self, position, cell_capacity: int, on_hits, carry):
        """Visit every pair closer than the cutoff once, one neighbouring cell at a time.

        ``on_hits(carry, lo, hi, hit)`` receives, per visited cell offset, the candidate
        pairs ``(lo, hi)`` (N, cell_capacity) int32 with ``lo < hi`` and the mask ``hit`` of
        those within the cutoff, and returns the new carry. Returns ``(carry, fullest)``: the
        final carry and the largest number of particles in one cell (above ``cell_capacity``
        some pairs were missed: the caller flags the overflow).
        """
        n = position.shape[0]
        cell = self.cell_index(position)
        key, count = self.occupancy(cell)
        order = jnp.argsort(key, stable=True).astype(jnp.int32)
        start = jnp.searchsorted(key[order], jnp.arange(self.n_cells, dtype=key.dtype),
                                 side="left").astype(jnp.int32)
        sorted_pos = position[order]
        slot = jnp.arange(cell_capacity, dtype=jnp.int32)
        me = jnp.arange(n, dtype=jnp.int32)
        cells = jnp.asarray(self.cells, jnp.int32)
        shifts = jnp.asarray(self.shifts())
        cutoff_sq = self.cutoff**2

        def one_offset(k, carry):
            other = self.flat(jnp.mod(cell + shifts[k], cells))  # (N,)
            s = start[other][:, None] + slot[None, :]  # (N, cap) into the sorted order
            valid = slot[None, :] < count[other][:, None]
            s = jnp.minimum(s, n - 1)
            j = order[s]
            # as jax-md: the squared length of displacement(R_larger, R_smaller) < cutoff^2
            dR = self.displacement(position[:, None, :], sorted_pos[s])
            close = jnp.sum(dR**2, axis=-1) < cutoff_sq
            hit = valid & (j < me[:, None]) & close
            return on_hits(carry, j, jnp.broadcast_to(me[:, None], j.shape), hit)

        carry = jax.lax.fori_loop(0, int(shifts.shape[0]), one_offset, carry)
        return carry, jnp.max(count)

    def count_pairs(self, position, cell_capacity: int):
        """``(pairs within the cutoff, fullest cell)`` (jittable)."""
        def add(total, lo, hi, hit):
            return total + jnp.sum(hit, dtype=jnp.int32)

        return self.visit(position, cell_capacity, add, jnp.zeros((), jnp.int32))

    def build(self, position, capacity: int, cell_capacity: int):
        """``(idx (2, capacity) int32 padded with N, pairs found, fullest cell)``: the pairs in
        the order found (:func:`sort_pairs` makes it canonical); pairs beyond ``capacity`` are
        dropped and counted (jittable)."""
        n = position.shape[0]

        def add(carry, lo, hi, hit):
            idx, total = carry
            hit = hit.reshape(-1)
            at = total + jnp.cumsum(hit, dtype=jnp.int32) - 1
            at = jnp.where(hit, at, capacity)  # misses (and overflow) fall off the end
            idx = idx.at[:, at].set(jnp.stack([lo.reshape(-1), hi.reshape(-1)]), mode="drop")
            return idx, total + jnp.sum(hit, dtype=jnp.int32)

        empty = jnp.full((2, capacity), n, jnp.int32)
        (idx, total), fullest = self.visit(position, cell_capacity, add,
                                           (empty, jnp.zeros((), jnp.int32)))
        return idx, total, fullest


def make_cell_grid(dim, box, cutoff, periodic_length, displacement) -> CellGrid:
    """The grid of cells of side at least ``cutoff`` covering ``[0, box)``."""
    box = np.asarray(box, float)
    n = np.floor(box / cutoff).astype(int)
    n = np.where(n >= 3, n, 1)
    size = box / n
    return CellGrid(int(dim), float(cutoff), tuple(int(c) for c in n),
                    tuple(float(c) for c in size), periodic_length is not None, displacement)


@dataclass(frozen=True, eq=False)
class NeighborSetup:
    """Static description of the neighbour search (built by :func:`make_neighbor_setup`).

    Attributes:
      dim: spatial dimension; lo, box: lower corner and size of the domain box (m);
      periodic_length: drum-axis period L (m) or None; cutoff: ``2 r_max + skin`` (m);
      skin (m); capacity_multiplier: head room of a fresh allocation;
      displacement: minimum-image displacement; grid: the :class:`CellGrid` that builds;
      builder: who rebuilds in a run (:meth:`rebuild_with_sources`): ``"jax"`` (the
      :class:`CellGrid`, every backend) or ``"cpu"`` (the same pairs from one C++ pass,
      :func:`drumheat.mechanics.cpu_kernel.neighbor_pairs`; with the C++ contact loop);
      pair_order: ``"index"`` (canonical) or ``"cell"`` (grouped in the cell order, for the C++
      contact loop; the lists carry ``order``): the module docstring.
    """

    dim: int
    lo: np.ndarray
    box: np.ndarray
    periodic_length: Optional[float]
    cutoff: float
    skin: float
    capacity_multiplier: float
    displacement: Callable
    grid: CellGrid
    builder: str = "jax"
    pair_order: str = "index"

    def to_box(self, position):
        """Positions in the box frame (shifted by ``-lo``)."""
        return position - jnp.asarray(self.lo, dtype=position.dtype)

    def _list(self, pos, built, error, cell_capacity: int):
        """The list of a build ``(idx, pairs found, fullest cell)`` at box-frame ``pos``, its
        overflows added to ``error``, pairs in canonical order."""
        idx, total, fullest = built
        capacity = idx.shape[1]
        error = _flag_overflows(error, total, capacity, fullest, cell_capacity)
        order = self.layout_order(pos, idx) if self.pair_order == "cell" else None
        return sort_pairs(NeighborList(idx, pos, error, order, int(cell_capacity),
                                       int(capacity), self.cutoff), pos.shape[0], order)

    def layout_order(self, pos, idx):
        """The order (N,) int32 in which the C++ contact loop lays out the particles of the
        pairs ``idx`` (2, M; padding N; any order) at box-frame ``pos`` (pair order ``"cell"``):
        the order of their cells (:meth:`CellGrid.order`), unless the particles' own numbering
        keeps the pairs near enough in memory, then ``0 .. N-1`` (no copies; the pairs in
        canonical order). Near: the pairs whose partners lie fewer than :data:`NEAR` places
        apart, about the particles whose data fill a core's first-level cache; the numbering
        will do while it has at least half as many as the cell order (the poured beds of
        glass-drum-3d have 0.7 times as many at N = 10 000 and 50 000, the same beds numbered at
        random 0.08 and 0.02: docs/performance.md). ``neighbor_kernel.cc``
        (``numbering_will_do``) decides alike."""
        near_numbering, near_cells, cells = self.near_pairs(pos, idx)
        n = pos.shape[0]
        return jnp.where(2 * near_numbering >= near_cells, jnp.arange(n, dtype=jnp.int32), cells)

    def near_pairs(self, pos, idx):
        """``(near in the numbering, near in the cell order, cell order)`` of the pairs ``idx``
        (2, M; padding N) at box-frame ``pos`` (jittable): how many pairs have partners fewer
        than :data:`NEAR` places apart in the particles' own numbering and in the order of
        their cells (:meth:`CellGrid.order`, the third item), which :meth:`layout_order`
        compares."""
        n = pos.shape[0]
        cells = self.grid.order(pos)
        rank = jnp.zeros(n, jnp.int32).at[cells].set(jnp.arange(n, dtype=jnp.int32))
        i, j = idx[0], idx[1]
        valid = i < n
        ri, rj = rank[jnp.where(valid, i, 0)], rank[jnp.where(valid, j, 0)]
        return (jnp.sum(valid & (jnp.abs(j - i) < NEAR)),
                jnp.sum(valid & (jnp.abs(rj - ri) < NEAR)), cells)

    @property
    def index_order(self) -> bool:
        """Whether the lists are in canonical order (pair order ``"index"``): the remap of
        per-pair data can then skip sorting the old list (:func:`pair_sources`)."""
        return self.pair_order == "index"

    def allocate(self, position, min_capacity: int = 0, min_cell_capacity: int = 0):
        """Allocate a neighbour list at ``position`` (not jittable: it sizes the buffers).

        The pair capacity is ``capacity_multiplier`` times the current number of pairs, and at
        least ``min_capacity`` (and at least 1), rounded up to a whole multiple of
        :data:`drumheat.devices.LENGTH_MULTIPLE`; the cell capacity ``capacity_multiplier``
        x the fullest cell, and at least ``min_cell_capacity``.
        """
        cells = lambda fullest: max(  # noqa: E731
            int(min_cell_capacity), int(fullest * self.capacity_multiplier), 1)
        slots = lambda count: round_length(  # noqa: E731
            max(int(min_capacity), int(count * self.capacity_multiplier) + 1, 1))
        # each step of it one compiled program: eager jnp operations would compile a program
        # each, which stays in memory (drumheat.devices.to_device)
        if self.builder == "cpu":
            count, fullest = self._cpu_count(position)
            return _cpu_first_list(self._cpu_search, slots(count), cells(fullest),
                                   not self.index_order, self.cutoff, np.asarray(self.lo),
                                   position)
        pos = _to_box(np.asarray(self.lo), position)
        cell_cap = cells(int(_fullest_cell(self.grid, pos)))
        target = slots(int(_count_pairs(self.grid, pos, cell_cap)[0]))
        return _first_list(self, pos, _build(self.grid, pos, target, cell_cap), cell_cap)

    def count_pairs(self, position):
        """Number of pairs within the cutoff at ``position`` (host-side, for sizing buffers)."""
        if self.builder == "cpu":
            return self._cpu_count(position)[0]
        pos = _to_box(np.asarray(self.lo), position)
        return int(_count_pairs(self.grid, pos, max(int(_fullest_cell(self.grid, pos)), 1))[0])

    @property
    def _cpu_search(self) -> tuple:
        """The C++ build's static inputs ``(cells, cell size, cutoff, period)``: values that
        are the same from run to run of a scene (:func:`_cpu_count_program`)."""
        g = self.grid
        return (tuple(int(c) for c in g.cells), tuple(float(c) for c in g.cell_size),
                float(g.cutoff), self.periodic_length)

    def _cpu_count(self, position) -> tuple[int, int]:
        """``(pairs within the cutoff, fullest cell)`` at ``position`` by a C++ build
        without slots (the JAX count gathers the candidates of the surrounding cells at once,
        in XLA temporaries that grow with N: docs/performance.md)."""
        total, fullest = _cpu_count_program(self._cpu_search, np.asarray(self.lo), position)
        return int(total), int(fullest)

    def _cpu_list(self, pos, old_idx, capacity: int, cell_capacity: int, error):
        """``(list, source)``: the list of ``capacity`` slots at box-frame ``pos`` built in C++
        (:func:`drumheat.mechanics.cpu_kernel.neighbor_pairs`; the pairs and their order of
        :meth:`_list`'s, ``tests/test_neighbors_cpu.py``), its overflows added to ``error``,
        and each slot's slot in ``old_idx`` (2, M_old) or -1."""
        from drumheat.mechanics.cpu_kernel import neighbor_pairs

        g = self.grid
        idx, src, total, fullest, order = neighbor_pairs(
            pos, old_idx, capacity, g.cells, g.cell_size, g.cutoff, self.periodic_length,
            cell_capacity, ranked=not self.index_order)
        return NeighborList(idx, pos, _flag_overflows(error, total, capacity, fullest,
                                                      cell_capacity),
                            None if self.index_order else order, int(cell_capacity),
                            int(capacity), self.cutoff), src

    def rebuild(self, position, nbrs):
        """Rebuild the list at ``position`` with the existing capacities (jittable); the
        overflow flags accumulate in ``nbrs.error`` until the next allocation."""
        pos = self.to_box(position)
        built = self.grid.build(pos, nbrs.max_occupancy, nbrs.cell_list_capacity)
        return self._list(pos, built, nbrs.error, nbrs.cell_list_capacity)

    def rebuild_with_sources(self, position, nbrs):
        """``(rebuilt list, source)`` (jittable): :meth:`rebuild`, and for each new pair slot
        the old slot of the same pair or -1 (:func:`pair_sources`; :func:`take_pair_data`
        moves per-pair data with it). With ``builder="cpu"`` one C++ pass finds the same pairs
        in the same order (``tests/test_neighbors_cpu.py`` holds the two equal)."""
        if self.builder != "cpu":
            new = self.rebuild(position, nbrs)
            return new, pair_sources(nbrs.idx, new.idx, position.shape[0],
                                     old_sorted=nbrs.order is None)
        return self._cpu_list(self.to_box(position), nbrs.idx, nbrs.max_occupancy,
                              nbrs.cell_list_capacity, nbrs.error)

    def take_pairs(self, data, source):
        """Per-pair data (M, ...) carried to a list rebuilt by :meth:`rebuild_with_sources`
        (``source`` (M,)): :func:`take_pair_data`, the same bits; with ``builder="cpu"`` in
        the buffer of ``data`` (:func:`drumheat.mechanics.cpu_kernel.take_pair_data_in_place`),
        which holds one column of scratch where the gather held a second array."""
        if self.builder != "cpu" or source.shape != data.shape[:1]:
            return take_pair_data(data, source)
        from drumheat.mechanics.cpu_kernel import take_pair_data_in_place

        return take_pair_data_in_place(data, source)

    def squared_distance(self, Ra, Rb):
        """``|displacement(Ra, Rb)|^2`` (m^2) over the last axis, the components' squares added
        in their order, ``(x^2 + y^2) + z^2``.

        One elementwise expression per component, which XLA fuses with the gathers that make
        ``Ra`` and ``Rb`` (``pos[j]``, ``pos[i]`` over a list's pairs): no ``(M, dim)`` array
        is written out. :attr:`displacement` sets its periodic column into the difference, an
        update that XLA:CPU materialises, and a sum over the last axis is a reduction XLA:CPU
        runs apart from the elementwise code that feeds it. (That reduction adds three
        components as ``(x^2 + z^2) + y^2``, and compiled it may fuse the minimum image's
        multiply and subtract into one multiply-add: either may change the last bit against
        ``jnp.sum(d * d, axis=-1)``.)"""
        d2 = None
        for k in range(self.dim):
            dk = Ra[..., k] - Rb[..., k]
            if k == self.dim - 1 and self.periodic_length is not None:
                dk = minimum_image(dk, self.periodic_length)
            d2 = dk * dk if d2 is None else d2 + dk * dk
        return d2

    def max_displacement_sq(self, position, nbrs):
        """Largest squared displacement (m^2) of any particle since the last build."""
        d = jax.vmap(self.displacement)(self.to_box(position), nbrs.reference_position)
        return jnp.max(jnp.sum(d * d, axis=-1))


#: solid (3D) and area (2D) fractions of a dense bed: random close packing of equal spheres
#: (0.64); hexagonal packing of equal disks (0.907), into which monolayers of them order
DENSE_FRACTION = {2: 0.907, 3: 0.64}


def dense_bed_pairs(radius, cutoff: float, dim: int) -> float:
    """Pairs per particle within ``cutoff`` (m) in a dense bed of these particles, each pair
    counted once (half the neighbours).

    The number density of a bed of solid (area) fraction phi (:data:`DENSE_FRACTION`) is
    ``phi / <V_p>``; a particle then has ``phi c^3 / <r^3>`` centres within c in 3D
    (``phi c^2 / <r^2>`` in 2D), itself included; the pairs per particle are half of the
    others. In 2D at least 3, the first shell of the hexagonal packing (six neighbours at
    contact), which this mean count misses at a thin skin. In 3D beds of spheres stay random
    (the estimate against a poured bed: docs/performance.md, the pair capacity of a dense
    bed).
    """
    r = np.asarray(radius, float).reshape(-1)
    mean = 0.5 * (DENSE_FRACTION[dim] * float(cutoff) ** dim / float(np.mean(r**dim)) - 1.0)
    return max(mean, 3.0) if dim == 2 else mean


@jax.jit
def _to_box(lo, position):
    """:meth:`NeighborSetup.to_box` as one compiled program (``lo`` an argument)."""
    return position - lo.astype(position.dtype)


@partial(jax.jit, static_argnums=0)
def _cpu_count_program(search: tuple, lo, position):
    """``(pairs within the cutoff, fullest cell)`` of :meth:`NeighborSetup._cpu_count` at
    ``position`` (``search``: :attr:`NeighborSetup._cpu_search`)."""
    from drumheat.mechanics.cpu_kernel import neighbor_pairs

    cells, cell_size, cutoff, period = search
    pos = _to_box(lo, position)
    n = pos.shape[0]
    _, _, total, fullest, _ = neighbor_pairs(pos, jnp.full((2, 0), n, jnp.int32), 0, cells,
                                             cell_size, cutoff, period, n)
    return total, fullest


@partial(jax.jit, static_argnums=(0, 1, 2, 3, 4))
def _cpu_first_list(search: tuple, capacity: int, cell_capacity: int, ranked: bool,
                    list_cutoff: float, lo, position):
    """The list of a fresh allocation built in C++ (:meth:`NeighborSetup._cpu_list` from an
    empty list) at ``position``: one compiled program, keyed by values that are the same from
    run to run of a scene."""
    from drumheat.mechanics.cpu_kernel import neighbor_pairs

    cells, cell_size, cutoff, period = search
    pos = _to_box(lo, position)
    n = pos.shape[0]
    idx, _, total, fullest, order = neighbor_pairs(
        pos, jnp.full((2, 0), n, jnp.int32), capacity, cells, cell_size, cutoff, period,
        cell_capacity, ranked=ranked)
    error = _flag_overflows(ListError(jnp.zeros((), jnp.uint8)), total, capacity, fullest,
                            cell_capacity)
    return NeighborList(idx, pos, error, order if ranked else None, int(cell_capacity),
                        int(capacity), list_cutoff)


@partial(jax.jit, static_argnums=(0, 3))
def _first_list(setup: "NeighborSetup", pos, built, cell_capacity: int):
    """The list of a fresh allocation by the JAX build (:meth:`NeighborSetup._list` with no
    overflows yet) as one compiled program (``setup`` static by identity: one program per
    neighbour set-up, as :func:`_build` per grid)."""
    return setup._list(pos, built, ListError(jnp.zeros((), jnp.uint8)), cell_capacity)


def _flag_overflows(error, total, capacity: int, fullest, cell_capacity: int):
    """``error`` with the overflows of a build flagged: more pairs found (``total``) than the
    list has slots, more particles in one cell (``fullest``) than the cell capacity."""
    error = error.update(PEC.NEIGHBOR_LIST_OVERFLOW, total > capacity)
    return error.update(PEC.CELL_LIST_OVERFLOW, fullest > cell_capacity)


@partial(jax.jit, static_argnums=0)
def _fullest_cell(grid: CellGrid, pos):
    return jnp.max(grid.occupancy(grid.cell_index(pos))[1])


@partial(jax.jit, static_argnums=(0, 2))
def _count_pairs(grid: CellGrid, pos, cell_capacity: int):
    return grid.count_pairs(pos, cell_capacity)


@partial(jax.jit, static_argnums=(0, 2, 3))
def _build(grid: CellGrid, pos, capacity: int, cell_capacity: int):
    return grid.build(pos, capacity, cell_capacity)


def make_neighbor_setup(dim, lo, hi, cutoff, skin, periodic_length=None,
                        capacity_multiplier=1.5, builder="jax",
                        pair_order="index") -> NeighborSetup:
    """Neighbour search for the box ``[lo, hi]`` (m); along a periodic axis ``[0, L)``;
    ``builder``, ``pair_order``: see :class:`NeighborSetup`."""
    lo = np.asarray(lo, dtype=float).copy()
    hi = np.asarray(hi, dtype=float).copy()
    if periodic_length is not None:
        lo[-1], hi[-1] = 0.0, float(periodic_length)
    box = hi - lo
    if np.any(~np.isfinite(box)) or np.any(box <= 0):
        raise ValueError(f"neighbour box must be finite and positive, got lo={lo}, hi={hi}")
    disp = make_displacement(dim, periodic_length)
    grid = make_cell_grid(dim, box, float(cutoff), periodic_length, disp)
    if builder not in ("jax", "cpu"):
        raise ValueError(f"neighbour builder must be 'jax' or 'cpu', got {builder!r}")
    if pair_order not in ("index", "cell"):
        raise ValueError(f"pair order must be 'index' or 'cell', got {pair_order!r}")
    return NeighborSetup(dim, lo, box, periodic_length, float(cutoff), float(skin),
                         float(capacity_multiplier), disp, grid, builder, pair_order)
