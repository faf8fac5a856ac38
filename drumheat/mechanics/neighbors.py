"""Neighbour lists for DEM on top of ``jax_md.partition`` (cell list + Verlet skin).

* Format: ``OrderedSparse``: ``idx`` has shape (2, capacity); column k is the pair
  ``(i, j) = (idx[0, k], idx[1, k])`` with ``i < j``, each pair once; padding is ``N``.
  Per-pair data (tangential springs) live in arrays aligned with these columns.
* Domain: jax-md's cell list bins positions in ``[0, box)``. The drum is centred on the axis,
  so positions are shifted by ``-lo`` (the lower corner of the domain box, which includes a
  margin) before they reach jax-md. In 3D the drum axis may be periodic (length L): then z is
  kept in ``[0, L)`` and the displacement uses the minimum image along z only.
* Rebuilds: jax-md is configured to rebuild whenever asked (``dr_threshold = 0`` with the
  cutoff ``2 r_max + skin`` passed in full); the integrator decides when: as soon as some
  particle has moved more than ``skin / 2`` since the last build (the usual Verlet-list
  criterion), so no pair can come into contact unseen.
* Pair order: after every build the pairs are sorted by ``(i, j)`` (:func:`sort_pairs`), so
  force sums do not depend on when the list was built.
* History across rebuilds: after a rebuild, :func:`remap_pair_data` finds every new pair in the
  old pair list (sort + binary search on the key ``i (N+1) + j``) and carries its data over;
  new pairs start with zero history.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import jax
import jax.numpy as jnp
import numpy as np
from jax_md import partition

__all__ = [
    "make_displacement",
    "NeighborSetup",
    "make_neighbor_setup",
    "remap_pair_data",
    "pair_keys",
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
        dz = dR[..., -1]
        dz = dz - L * jnp.round(dz / L)
        return dR.at[..., -1].set(dz)

    return displacement


def pair_keys(idx, n):
    """Integer key ``i (N+1) + j`` of each column of an OrderedSparse ``idx``; padding is large.

    Uses int64 when x64 is enabled (drumheat enables it), else int32 (N up to 46340).
    """
    use64 = jax.config.jax_enable_x64
    dt = jnp.int64 if use64 else jnp.int32
    if not use64 and (n + 1) * (n + 1) >= 2**31:
        raise ValueError("pair keys need int64 for this N: enable jax_enable_x64")
    i = idx[0].astype(dt)
    j = idx[1].astype(dt)
    return i * (n + 1) + j


def remap_pair_data(old_idx, old_data, new_idx, n):
    """Carry per-pair data from an old pair list to a new one (pairs matched by identity).

    Args:
      old_idx, new_idx: OrderedSparse neighbour indices (2, M_old) and (2, M_new).
      old_data: array (M_old, ...) aligned with ``old_idx``.
      n: number of particles (padding value).
    Returns:
      array (M_new, ...): the old data of pairs present in both lists, zeros for new pairs
      and padding.
    """
    ko = pair_keys(old_idx, n)
    kn = pair_keys(new_idx, n)
    order = jnp.argsort(ko)
    ko_sorted = ko[order]
    pos = jnp.searchsorted(ko_sorted, kn)
    pos = jnp.clip(pos, 0, ko.shape[0] - 1)
    found = (ko_sorted[pos] == kn) & (new_idx[0] < n)
    src = order[pos]
    gathered = old_data[src]
    mask = found.reshape(found.shape + (1,) * (old_data.ndim - 1))
    return jnp.where(mask, gathered, 0)


def sort_pairs(nbrs, n):
    """The neighbour list with its pairs in canonical order (by ``i (N+1) + j``, padding last).

    A canonical order makes the force sums (``segment_sum`` over the pairs) independent of when
    the list was built: a run that rebuilds every step and one that rebuilds rarely add the
    same non-zero contributions in the same order, so their trajectories agree bit for bit.
    It also groups each particle's pairs in memory.
    """
    import dataclasses

    order = jnp.argsort(pair_keys(nbrs.idx, n))
    # two row gathers stacked (not idx[:, order]): XLA:CPU then keeps idx row-major, the
    # layout of the scan carry, instead of converting it back and forth every step
    return dataclasses.replace(nbrs, idx=jnp.stack([nbrs.idx[0][order], nbrs.idx[1][order]]))


@dataclass(frozen=True)
class NeighborSetup:
    """Static description of the neighbour search (built by :func:`make_neighbor_setup`).

    Attributes:
      dim: spatial dimension; lo, box: lower corner and size of the domain box (m);
      periodic_length: drum-axis period L (m) or None; cutoff: ``2 r_max + skin`` (m);
      skin (m); capacity_multiplier: head room of a fresh allocation;
      displacement: minimum-image displacement; neighbor_fns: jax-md allocate/update.
    """

    dim: int
    lo: np.ndarray
    box: np.ndarray
    periodic_length: Optional[float]
    cutoff: float
    skin: float
    capacity_multiplier: float
    displacement: Callable
    neighbor_fns: object

    def to_box(self, position):
        """Positions in jax-md's box frame (shifted by ``-lo``)."""
        return position - jnp.asarray(self.lo, dtype=position.dtype)

    def allocate(self, position, min_capacity: int = 0, min_cell_capacity: int = 0):
        """Allocate a neighbour list at ``position`` (not jittable: it sizes the buffers).

        The pair capacity is ``capacity_multiplier`` times the current number of pairs, and at
        least ``min_capacity`` (and at least 1); the cell-list capacity is jax-md's estimate
        (``capacity_multiplier`` x the fullest cell) and at least ``min_cell_capacity``.
        """
        import dataclasses

        pos = self.to_box(position)
        nbrs = self.neighbor_fns.allocate(pos)
        n = position.shape[0]
        cc = nbrs.cell_list_capacity
        if cc is not None and cc < min_cell_capacity:
            nbrs = self.neighbor_fns.allocate(pos, extra_capacity=int(min_cell_capacity - cc))
        count = int(jnp.sum(nbrs.idx[0] < n))
        target = max(int(min_capacity), int(count * self.capacity_multiplier) + 1, 1)
        if nbrs.max_occupancy != target:
            nbrs = dataclasses.replace(nbrs, max_occupancy=target)
            nbrs = self.neighbor_fns.update(pos, nbrs)
        return sort_pairs(nbrs, n)

    def count_pairs(self, position):
        """Number of pairs within the cutoff at ``position`` (host-side, for sizing buffers)."""
        nbrs = self.neighbor_fns.allocate(self.to_box(position))
        return int(jnp.sum(nbrs.idx[0] < position.shape[0]))

    def rebuild(self, position, nbrs):
        """Rebuild the list at ``position`` with the existing capacities (jittable)."""
        return sort_pairs(self.neighbor_fns.update(self.to_box(position), nbrs), position.shape[0])

    def max_displacement_sq(self, position, nbrs):
        """Largest squared displacement (m^2) of any particle since the last build."""
        d = jax.vmap(self.displacement)(self.to_box(position), nbrs.reference_position)
        return jnp.max(jnp.sum(d * d, axis=-1))


def make_neighbor_setup(dim, lo, hi, cutoff, skin, periodic_length=None,
                        capacity_multiplier=1.5) -> NeighborSetup:
    """Neighbour search for the box ``[lo, hi]`` (m); along a periodic axis ``[0, L)``."""
    lo = np.asarray(lo, dtype=float).copy()
    hi = np.asarray(hi, dtype=float).copy()
    if periodic_length is not None:
        lo[-1], hi[-1] = 0.0, float(periodic_length)
    box = hi - lo
    if np.any(~np.isfinite(box)) or np.any(box <= 0):
        raise ValueError(f"neighbour box must be finite and positive, got lo={lo}, hi={hi}")
    disp = make_displacement(dim, periodic_length)
    fns = partition.neighbor_list(
        disp,
        jnp.asarray(box),
        r_cutoff=float(cutoff),
        dr_threshold=0.0,
        capacity_multiplier=float(capacity_multiplier),
        format=partition.NeighborListFormat.OrderedSparse,
    )
    return NeighborSetup(dim, lo, box, periodic_length, float(cutoff), float(skin),
                         float(capacity_multiplier), disp, fns)
