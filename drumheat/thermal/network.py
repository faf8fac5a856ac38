"""Sparse contact networks: the pipes through which heat flows.

Contacts are stored as pair lists, never as a dense N x N matrix (the thesis' contact matrix CM
of weigler-thermal-dem.md eq. [2.13] is the graph Laplacian of these pairs). Arrays have a fixed
capacity so that a changing network keeps the shapes of a jitted program; unused slots carry
weight 0.

The weight of a contact is the fraction of the thermal step during which it existed (1 for a
resting bed; between 0 and 1 when the thermal step spans several mechanical steps).
"""

from __future__ import annotations

from typing import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from drumheat.devices import round_length

#: :meth:`ContactNetwork.pair_sum` takes the pair slots in blocks of at least this many
PAIR_BLOCK = 1 << 16
#: ... and in at most this many blocks
PAIR_BLOCKS_MAX = 8


class ContactNetwork(eqx.Module):
    """Particle-particle and particle-wall contacts.

    Attributes
    ----------
    pair_i, pair_j : int array, shape (P,)
        Particle indices of each particle-particle contact, each contact once. An index N
        (one past the last particle) marks an unused slot as well as a weight 0 does: the
        effects' scatters drop it and their gathers clamp it (JAX's default modes). Padding
        of many slots should use it rather than a real particle: a GPU serialises the atomic
        adds of many slots into one particle.
    pair_weight : float array, shape (P,)
        Contact-time fraction in [0, 1]; 0 marks an unused slot. With ``pair_unit`` the
        contact time in whole steps instead (:meth:`pair_weights` gives the fractions).
    wall_particle : int array, shape (W,)
        Particle index of each particle-wall contact.
    wall_id : int array, shape (W,)
        Index of the wall touched (into the wall-temperature array of the wall effect).
    wall_weight : float array, shape (W,)
        Contact-time fraction in [0, 1]; 0 marks an unused slot.
    wall_angle : float array, shape (W,), or None
        Polar angle of each particle-wall contact in the lab frame, rad (counter-clockwise
        from +x); set only for a drum wall with segments (``[heat.drum_wall]``,
        :mod:`drumheat.thermal.drum_wall`), which finds each contact's segment from it.
    pair_unit : (dt, h) or None
        ``pair_weight`` counts steps of ``dt`` s and a slot's weight is the fraction
        ``(steps dt) / h`` of the thermal step ``h`` s (the coupled DEM's network,
        :func:`drumheat.motion.coupling.thermal_network`); :meth:`pair_sum` forms the
        fractions one block of slots at a time, so that no per-slot float array of the whole
        list exists beside the counts. Unused slots (index N) weigh 0 in both whatever they
        count (:attr:`n_pairs`, which does not know N, needs them to count 0).
    native_conduction : callable or None
        ``fn(T, diameter, alpha, net) -> (N,)``: the pair sum of
        :class:`drumheat.thermal.contact.ContactConduction` over this network in native code,
        for a network with ``pair_unit`` (the coupled DEM's on the C++ contact backend sets
        it: :func:`drumheat.motion.coupling.thermal_network`); the effect gives it the
        derivatives of its JAX sum (:func:`native_pair_sum`). None: the sum in JAX
        (:meth:`pair_sum`).
    """

    pair_i: Array
    pair_j: Array
    pair_weight: Array
    wall_particle: Array
    wall_id: Array
    wall_weight: Array
    wall_angle: Array | None = None
    pair_unit: tuple[float, float] | None = eqx.field(static=True, default=None)
    native_conduction: Callable | None = eqx.field(static=True, default=None)

    def weights_of(self, raw: Array, i: Array, n: int) -> Array:
        """The contact-time fractions of slots with ``pair_weight`` values ``raw`` and first
        particles ``i`` in a bed of ``n`` particles (``raw`` itself without ``pair_unit``)."""
        if self.pair_unit is None:
            return raw
        dt, h = self.pair_unit
        return jnp.where(i < n, (raw * dt) / h, 0.0)

    def pair_weights(self, n: int) -> Array:
        """The contact-time fraction of every slot (P,) in a bed of ``n`` particles."""
        return self.weights_of(self.pair_weight, self.pair_i, n)

    def pair_sum(self, fn, total: Array, sign: float = -1.0) -> Array:
        """``total`` (N,) plus, for every pair slot, ``q = fn(i, j, w)`` added at its particle
        ``i`` and ``sign * q`` at its particle ``j`` (``sign = -1``: the heat q flows from j to
        i; ``+1``: a conductance counts at both ends).

        ``fn`` maps the slots' indices and weights (arrays of one block of slots) to their
        values, and must give 0 where ``w = 0`` (as every unused slot does). Beyond
        :data:`PAIR_BLOCK` slots the slots go in up to :data:`PAIR_BLOCKS_MAX` blocks of equal
        length (a whole multiple of :data:`drumheat.devices.LENGTH_MULTIPLE`), one after the
        other, so that the per-slot temporaries of ``fn`` (the gathers of both partners'
        temperatures and sizes) exist for one block at a time instead of for every slot at
        once: in a coupled DEM run they set the peak of XLA's working memory
        (docs/performance.md, memory). The last block is shifted back to end at the last slot;
        the slots it shares with the block before it count there only (weight 0 here). The
        terms of a particle's sum are added block by block, so the sums differ from those of
        one pass by round-off.
        """
        def add(acc, i, j, w):
            q = fn(i, j, w)
            return acc.at[i].add(q).at[j].add(sign * q)

        m, n = self.pair_i.shape[0], total.shape[0]
        blocks = min(PAIR_BLOCKS_MAX, -(-m // PAIR_BLOCK))
        if blocks <= 1:
            return add(total, self.pair_i, self.pair_j, self.pair_weights(n))
        size = min(round_length(-(-m // blocks)), m)
        blocks = -(-m // size)
        # the two index rows as one (2, M) array: where they are the rows of a neighbour list
        # (the coupled DEM's network), XLA takes the list itself instead of writing each row
        # out as an array of its own for the loop
        ij = jnp.stack([self.pair_i, self.pair_j])

        def block(b, acc):
            start = jnp.minimum(b * size, m - size)
            cut = lambda a: jax.lax.dynamic_slice_in_dim(a, start, size, axis=-1)  # noqa: E731
            own = start + jnp.arange(size) >= b * size
            i, j = cut(ij)
            w = jnp.where(own, self.weights_of(cut(self.pair_weight), i, n), 0.0)
            return add(acc, i, j, w)

        return jax.lax.fori_loop(0, blocks, block, total)

    @property
    def n_pairs(self) -> Array:
        """Number of particle-particle contacts (weights summed)."""
        n = jnp.iinfo(jnp.int32).max  # with pair_unit: unused slots count 0 (class docstring)
        return jnp.sum(self.pair_weights(n))

    @property
    def n_wall(self) -> Array:
        """Number of particle-wall contacts (weights summed)."""
        return jnp.sum(self.wall_weight)

    @classmethod
    def from_arrays(cls, pairs, wall_particles, wall_ids=None) -> "ContactNetwork":
        """Build a network of permanent contacts (weight 1) from host arrays.

        Parameters
        ----------
        pairs : array_like, shape (P, 2)
        wall_particles : array_like, shape (W,)
        wall_ids : array_like, shape (W,), optional
            Defaults to wall 0 for every wall contact.
        """
        pairs = np.asarray(pairs, dtype=np.int32).reshape(-1, 2)
        wp = np.asarray(wall_particles, dtype=np.int32).reshape(-1)
        wid = np.zeros_like(wp) if wall_ids is None else np.asarray(wall_ids, np.int32)
        return cls(jnp.asarray(pairs[:, 0]), jnp.asarray(pairs[:, 1]),
                   jnp.ones(len(pairs)), jnp.asarray(wp), jnp.asarray(wid), jnp.ones(len(wp)))


def find_contacts_2d_drum(position, diameter, drum_diameter, tolerance=0.01,
                          wall_tolerance=None):
    """Contacts of a resting packing in a drum, from geometry.

    Two particles touch when the gap between their surfaces is at most ``tolerance`` times the
    smaller diameter (weigler-thermal-dem.md eq. [2.4] with a gap tolerance, as needed for
    packings from measured coordinates); a particle touches the drum shell when its gap to the
    shell is at most ``wall_tolerance`` (default ``tolerance``) times its diameter. Uses a
    k-d tree (no N x N array).

    Parameters
    ----------
    position : array_like, shape (N, dim)
        Centres, m (only x and y matter for the shell).
    diameter : array_like, shape (N,)
    drum_diameter : float
    tolerance : float
        Particle-particle gap tolerance as a fraction of the smaller diameter.
    wall_tolerance : float, optional
        Particle-shell gap tolerance as a fraction of the particle diameter.

    Returns
    -------
    pairs : ndarray, shape (P, 2)
    wall_particles : ndarray, shape (W,)
    """
    from scipy.spatial import cKDTree

    position = np.asarray(position, float)
    diameter = np.asarray(diameter, float)
    tree = cKDTree(position)
    pairs = np.array(sorted(tree.query_pairs(diameter.max() * (1 + tolerance))), dtype=int)
    if len(pairs):
        i, j = pairs.T
        gap = np.linalg.norm(position[i] - position[j], axis=1) - 0.5 * (diameter[i] + diameter[j])
        pairs = pairs[gap <= tolerance * np.minimum(diameter[i], diameter[j])]
    pairs = pairs.reshape(-1, 2)
    r_xy = np.hypot(position[:, 0], position[:, 1])
    wall_gap = 0.5 * drum_diameter - r_xy - 0.5 * diameter
    wall_tol = tolerance if wall_tolerance is None else wall_tolerance
    wall_particles = np.nonzero(wall_gap <= wall_tol * diameter)[0]
    return pairs, wall_particles


def native_pair_sum(native, reference, *args):
    """``native(*args)``, with the derivatives of ``reference(*args)``.

    ``native`` computes the values of the JAX function ``reference`` in native code, which JAX
    cannot differentiate (:attr:`ContactNetwork.native_conduction`); wrapped in a
    ``jax.custom_jvp`` whose tangents are those of ``reference``, ``jax.jvp`` and ``jax.grad``
    differentiate the JAX sum. Both take the same positional arrays.
    """
    @jax.custom_jvp
    def values(*a):
        return native(*a)

    @values.defjvp
    def values_jvp(primals, tangents):
        return native(*primals), jax.jvp(reference, primals, tangents)[1]

    return values(*args)
