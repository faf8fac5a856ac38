"""The lean cell-list build (drumheat.mechanics.neighbors.CellGrid) finds exactly the pairs of
jax-md's neighbour list, flags overflows, and stays small in memory."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax_md import partition

import drumheat  # noqa: F401  (x64)
from drumheat.mechanics.neighbors import make_neighbor_setup, sort_pairs


def _reference(setup, pos):
    """jax-md's OrderedSparse cell-list neighbour list at the same cutoff, canonical order."""
    fns = partition.neighbor_list(setup.displacement, jnp.asarray(setup.box),
                                  r_cutoff=setup.cutoff, dr_threshold=0.0,
                                  capacity_multiplier=1.5,
                                  format=partition.NeighborListFormat.OrderedSparse)
    return sort_pairs(fns.allocate(setup.to_box(pos)), pos.shape[0])


def _scattered(rng, n, dim, periodic, dtype=np.float64):
    """``(lo, hi, positions)``: n points uniform in a 0.3 m box (along a periodic last axis
    ``[0, periodic)``)."""
    lo, hi = np.full(dim, -0.15), np.full(dim, 0.15)
    if periodic:
        lo[-1], hi[-1] = 0.0, periodic
    return lo, hi, jnp.asarray(rng.uniform(lo, hi, (n, dim)), dtype)


def _pairs(nbrs, n):
    idx = np.asarray(nbrs.idx)
    return idx[:, idx[0] < n]


@pytest.mark.parametrize("dim,periodic,dtype", [(2, None, np.float32), (3, None, np.float64),
                                                (3, 0.12, np.float32)])
def test_same_pairs_as_jax_md(dim, periodic, dtype):
    rng = np.random.default_rng(dim + (periodic is not None))
    n, cutoff = 1500, 0.02
    lo, hi, pos = _scattered(rng, n, dim, periodic, dtype)
    setup = make_neighbor_setup(dim, lo, hi, cutoff, 0.004, periodic)
    ours = setup.allocate(pos)
    ref = _reference(setup, pos)
    assert int(ours.error.code) == 0
    # both canonical: the same pairs in the same order
    np.testing.assert_array_equal(_pairs(ours, n), _pairs(ref, n))
    # the jitted rebuild after a move, with the allocated capacities
    moved = pos + jnp.asarray(rng.normal(0.0, 0.002, (n, dim)), dtype)
    if periodic:
        moved = moved.at[:, -1].set(jnp.mod(moved[:, -1], periodic))
    again = jax.jit(setup.rebuild)(moved, ours)
    assert int(again.error.code) == 0
    np.testing.assert_array_equal(_pairs(again, n), _pairs(_reference(setup, moved), n))
    # every found pair is within the cutoff and listed once, smaller index first
    p = _pairs(again, n)
    assert np.all(p[0] < p[1]) and len({tuple(c) for c in p.T}) == p.shape[1]


@pytest.mark.parametrize("dim,periodic", [(2, None), (3, None), (3, 0.12)])
def test_squared_distance_is_the_displacements(dim, periodic):
    """NeighborSetup.squared_distance (the form XLA fuses with its gathers, for the output
    rows' contact numbers) is the squared length of the displacement, its squares added in
    the order x, y, z, across the periodic boundary too, for the pairs of a list (padding
    index N clamped)."""
    n = 800
    lo, hi, pos = _scattered(np.random.default_rng(7 + dim), n, dim, periodic)
    setup = make_neighbor_setup(dim, lo, hi, 0.03, 0.004, periodic)
    idx = setup.allocate(pos).idx
    i, j = jnp.minimum(idx[0], n - 1), jnp.minimum(idx[1], n - 1)
    d = setup.displacement(pos[j], pos[i])
    squares = np.asarray(d) ** 2
    expected = squares[:, 0] + squares[:, 1]
    if dim == 3:
        expected = expected + squares[:, 2]
    got = np.asarray(jax.jit(setup.squared_distance)(pos[j], pos[i]))
    # eagerly the same operations bit for bit; compiled, XLA may fuse the minimum image's
    # multiply and subtract into one multiply-add (its own rounding of a wrapped component)
    np.testing.assert_array_equal(np.asarray(setup.squared_distance(pos[j], pos[i])), expected)
    if periodic:
        np.testing.assert_array_max_ulp(got, expected, maxulp=2)
    else:
        np.testing.assert_array_equal(got, expected)
    # XLA's reduction adds the three in another order
    np.testing.assert_array_max_ulp(got, np.asarray(jnp.sum(d * d, axis=-1)), maxulp=2)
    if periodic:  # pairs across the boundary are among them, at their minimum image
        dz = np.abs(np.asarray(pos[j, -1] - pos[i, -1]))
        across = dz > periodic / 2
        assert across.any() and np.all(got[across] < 0.03**2)


def test_small_box_is_one_cell_per_short_axis():
    """An axis shorter than three cutoffs is one cell: every pair is still found once."""
    rng = np.random.default_rng(3)
    lo, hi = np.array([0.0, 0.0]), np.array([0.05, 0.3])
    setup = make_neighbor_setup(2, lo, hi, 0.02, 0.004)
    assert setup.grid.cells[0] == 1 and setup.grid.cells[1] >= 3
    pos = jnp.asarray(rng.uniform(lo, hi, (300, 2)))
    np.testing.assert_array_equal(_pairs(setup.allocate(pos), 300),
                                  _pairs(_reference(setup, pos), 300))


def test_overflow_is_flagged():
    rng = np.random.default_rng(4)
    lo, hi = np.zeros(3), np.full(3, 0.2)
    setup = make_neighbor_setup(3, lo, hi, 0.03, 0.004)
    pos = jnp.asarray(rng.uniform(lo, hi, (800, 3)))
    nbrs = setup.allocate(pos)
    n_pairs = _pairs(nbrs, 800).shape[1]
    # all particles into one corner: more pairs than the buffer and a crowded cell
    crowded = jax.jit(setup.rebuild)(pos * 0.2, nbrs)
    code = int(crowded.error.code)
    assert code & partition.PEC.NEIGHBOR_LIST_OVERFLOW
    assert code & partition.PEC.CELL_LIST_OVERFLOW
    # the buffer is full of genuine pairs, never garbage
    p = _pairs(crowded, 800)
    assert p.shape[1] == crowded.idx.shape[1] > n_pairs
    d = np.linalg.norm(np.asarray(pos * 0.2)[p[0]] - np.asarray(pos * 0.2)[p[1]], axis=1)
    assert np.all(d < setup.cutoff)


def test_rebuild_memory_is_linear_and_small():
    """The build's temporaries (XLA's own count) stay at a few hundred bytes per particle: the
    3^dim neighbouring cells are visited one after the other, not gathered at once (jax-md's
    own build needs about 10 kB per particle in 3D at this density)."""
    rng = np.random.default_rng(5)
    n = 20000
    lo, hi = np.zeros(3), np.array([0.25, 0.25, 0.25])
    # a dense bed: spheres of d = 8 mm at about half the volume, cutoff 2.5 r
    pos = jnp.asarray(rng.uniform(lo, hi * np.array([1, 0.5, 1]), (n, 3)), jnp.float32)
    setup = make_neighbor_setup(3, lo, hi, 0.01, 0.002)
    nbrs = setup.allocate(pos)
    mem = jax.jit(setup.rebuild).lower(pos, nbrs).compile().memory_analysis()
    if mem is None:
        pytest.skip("this backend reports no memory analysis")
    per_particle = mem.temp_size_in_bytes / n
    assert per_particle < 1000, per_particle
