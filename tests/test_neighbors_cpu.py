"""The C++ neighbour rebuild (NeighborSetup(builder="cpu"), drumheat.mechanics.cpu_kernel.
neighbor_pairs) against the JAX cell list: the same pairs in the same order, the same sources of
the carried pair data, the same overflow flags, and runs equal bit for bit; and the C++ contact
loop's conduction mask against ContactForces.pair_gap_mask."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import drumheat  # noqa: F401  (x64)
from drumheat.geometry import DrumShell
from drumheat.mechanics import contact_params, cpu_kernel, make_dem, make_particles
from drumheat.mechanics.neighbors import PEC, make_neighbor_setup, remap_pair_data

pytestmark = [pytest.mark.skipif(not cpu_kernel.available()[0],
                                 reason=f"C++ kernel unavailable: {cpu_kernel.available()[1]}"),
              pytest.mark.filterwarnings("ignore::drumheat.mechanics.DEMAccuracyWarning")]


def _setups(dim, periodic, lo, hi, cutoff=0.02, pair_order="index"):
    return [make_neighbor_setup(dim, lo, hi, cutoff, 0.004, periodic, builder=b,
                                pair_order=pair_order) for b in ("jax", "cpu")]


def _both(setups, pos, nbrs):
    return [jax.jit(s.rebuild_with_sources)(pos, nbrs) for s in setups]


@pytest.mark.parametrize("dim,periodic,dtype,spread,pair_order", [
    (2, None, np.float32, 1.0, "index"), (3, None, np.float64, 1.0, "index"),
    (3, 0.12, np.float32, 1.0, "index"), (3, 0.12, np.float64, 1.0, "index"),
    (3, None, np.float64, 1.6, "index"), (2, None, np.float64, 1.6, "index"),
    (2, None, np.float32, 1.0, "cell"), (3, 0.12, np.float64, 1.0, "cell"),
    (3, None, np.float64, 1.6, "cell")])
def test_same_pairs_order_and_sources(dim, periodic, dtype, spread, pair_order):
    """Random particles (``spread`` > 1: some outside the box, clipped into its edge cells),
    rebuilt after a move: pairs, order, the old slot of every pair, flags, all equal; in the
    canonical order (by (i, j)) or the cell order (grouped by i in the order of the particles'
    cells, j ascending)."""
    rng = np.random.default_rng(dim + 10 * (periodic is not None) + int(spread * 10))
    n = 2500
    lo, hi = np.full(dim, -0.15), np.full(dim, 0.15)
    if periodic:
        lo[-1], hi[-1] = 0.0, periodic
    pos = jnp.asarray(rng.uniform(lo, hi, (n, dim)), dtype)
    jx, cp = _setups(dim, periodic, lo, hi, pair_order=pair_order)
    nbrs = jx.allocate(pos, min_cell_capacity=40)
    moved = pos * spread + jnp.asarray(rng.normal(0.0, 0.003, (n, dim)), dtype)
    if periodic:
        moved = moved.at[:, -1].set(jnp.mod(moved[:, -1], periodic))
    (a, sa), (b, sb) = _both((jx, cp), moved, nbrs)
    # (spread out, the clipped edge cells may overflow: flagged alike, the same pairs seen)
    assert int(a.error.code) == int(b.error.code) == (int(a.error.code) if spread > 1 else 0)
    assert int(jnp.sum(b.idx[0] < n)) > 300  # a real list
    np.testing.assert_array_equal(np.asarray(a.idx), np.asarray(b.idx))
    np.testing.assert_array_equal(np.asarray(sa), np.asarray(sb))
    assert int(jnp.sum(sb >= 0)) > 0.3 * int(jnp.sum(b.idx[0] < n))  # pairs carried over
    np.testing.assert_array_equal(np.asarray(a.reference_position),
                                  np.asarray(b.reference_position))
    i, j = np.asarray(b.idx)
    if pair_order == "index":
        assert a.order is None and b.order is None
        key = i.astype(np.int64) * (n + 1) + j
    else:  # the cell order: a permutation, by flat cell and by index within a cell
        np.testing.assert_array_equal(np.asarray(a.order), np.asarray(b.order))
        order = np.asarray(b.order)
        np.testing.assert_array_equal(np.sort(order), np.arange(n))
        cell = np.asarray(jx.grid.flat(jx.grid.cell_index(jx.to_box(moved))))[order]
        assert np.all((np.diff(cell) > 0) | ((np.diff(cell) == 0) & (np.diff(order) > 0)))
        rank = np.full(n + 1, n)
        rank[order] = np.arange(n)
        key = rank[i].astype(np.int64) * (n + 1) + j
    assert np.all(np.diff(key[i < n]) > 0)  # sorted
    assert np.all(i[np.argmax(i == n):] == n) and np.all(i[i < n] < j[i < n])  # padding last
    # an old list in any order of its slots (not made by a build): the same pairs found
    perm = rng.permutation(nbrs.idx.shape[1])
    mixed = dataclasses.replace(nbrs, idx=nbrs.idx[:, perm])
    _, sc = _both((cp,), moved, mixed)[0]
    sc = np.asarray(sc)
    np.testing.assert_array_equal(np.where(sc >= 0, perm[np.maximum(sc, 0)], -1), np.asarray(sb))
    # the data carried as remap_pair_data carries it
    data = jnp.arange(nbrs.idx.shape[1], dtype=jnp.float64) + 1.0
    np.testing.assert_array_equal(np.asarray(remap_pair_data(nbrs.idx, data, b.idx, n)),
                                  np.where(np.asarray(sb) >= 0, np.asarray(sb) + 1.0, 0.0))


@pytest.mark.parametrize("dim,periodic,dtype,spread,pair_order", [
    (2, None, np.float32, 1.0, "index"), (3, 0.12, np.float64, 1.0, "index"),
    (3, None, np.float64, 1.6, "index"), (2, None, np.float64, 1.0, "cell"),
    (3, 0.12, np.float32, 1.0, "cell"), (3, None, np.float64, 1.6, "cell")])
def test_allocate_is_the_jax_allocation(dim, periodic, dtype, spread, pair_order):
    """A list allocated by the C++ build (two passes: the count and the fullest cell, then the
    list) has the capacities, pairs, order and flags of the JAX build's; so does the count."""
    rng = np.random.default_rng(7 + dim + int(spread * 10))
    n = 2500
    lo, hi = np.full(dim, -0.15), np.full(dim, 0.15)
    if periodic:
        lo[-1], hi[-1] = 0.0, periodic
    pos = jnp.asarray(rng.uniform(lo, hi, (n, dim)) * spread, dtype)
    if periodic:
        pos = pos.at[:, -1].set(jnp.mod(pos[:, -1], periodic))
    jx, cp = _setups(dim, periodic, lo, hi, pair_order=pair_order)
    for floor in ({}, {"min_capacity": 9000, "min_cell_capacity": 60}):
        a, b = jx.allocate(pos, **floor), cp.allocate(pos, **floor)
        assert (a.max_occupancy, a.cell_list_capacity) == (b.max_occupancy, b.cell_list_capacity)
        assert int(a.error.code) == int(b.error.code) == 0
        assert int(jnp.sum(b.idx[0] < n)) > 300  # a real list
        for x, y in ((a.idx, b.idx), (a.reference_position, b.reference_position)):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
        if pair_order == "index":
            assert a.order is None and b.order is None
        else:
            np.testing.assert_array_equal(np.asarray(a.order), np.asarray(b.order))
    assert jx.count_pairs(pos) == cp.count_pairs(pos) > 300


@pytest.mark.parametrize("pair_order", ["index", "cell"])
def test_rebuild_and_carry_in_the_old_buffers(pair_order):
    """A rebuild whose old list is donated writes the new list into its buffer, and
    ``NeighborSetup.take_pairs`` carries per-pair data of any dtype in the data's own buffer
    (XLA aliases both; the memory a rebuild needs, docs/performance.md): the same pairs,
    sources and data, bit for bit, as without donation and as ``take_pair_data``."""
    from drumheat.mechanics.neighbors import take_pair_data

    rng = np.random.default_rng(7)
    n, dim, periodic = 2500, 3, 0.12
    lo, hi = np.array([-0.15, -0.15, 0.0]), np.array([0.15, 0.15, periodic])
    pos = jnp.asarray(rng.uniform(lo, hi, (n, dim)))
    _, cp = _setups(dim, periodic, lo, hi, pair_order=pair_order)
    nbrs = cp.allocate(pos, min_cell_capacity=40)
    moved = pos + jnp.asarray(rng.normal(0.0, 0.003, (n, dim)))
    moved = moved.at[:, -1].set(jnp.mod(moved[:, -1], periodic))
    plain = jax.jit(cp.rebuild_with_sources)(moved, nbrs)
    copy = jax.tree_util.tree_map(jnp.copy, nbrs)
    donated = jax.jit(cp.rebuild_with_sources, donate_argnums=1)
    m = nbrs.idx.shape[1]
    aliased = donated.lower(moved, copy).compile().memory_analysis().alias_size_in_bytes
    assert aliased >= 2 * m * 4  # the new list took the old one's buffer
    new, src = donated(moved, copy)
    for x, y in zip(jax.tree_util.tree_leaves(plain), jax.tree_util.tree_leaves((new, src))):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    assert 0 < int(jnp.sum(src >= 0)) < int(jnp.sum(new.idx[0] < n))  # carried and new pairs
    take = jax.jit(cp.take_pairs, donate_argnums=0)
    for dtype, tail in [(np.float64, (3,)), (np.float32, (2,)), (np.int32, ()), (np.int8, (4,))]:
        data = jnp.asarray((rng.normal(0.0, 100.0, (m,) + tail)).astype(dtype))
        want = np.asarray(take_pair_data(data, src))
        ma = take.lower(data, src).compile().memory_analysis()
        assert ma.alias_size_in_bytes == data.nbytes  # in place
        got = take(jnp.copy(data), src)
        assert got.dtype == data.dtype
        np.testing.assert_array_equal(np.asarray(got), want)
        np.testing.assert_array_equal(np.asarray(jax.jit(cp.take_pairs)(data, src)), want)


def test_a_numbering_that_keeps_neighbours_near_is_kept():
    """Pair order "cell": particles numbered along their cells need no layout of their own
    (NeighborSetup.layout_order): both builds keep the canonical list and give the order
    0 .. N-1; the same particles numbered at random get the cell order."""
    rng = np.random.default_rng(7)
    n, lo, hi = 2500, np.full(3, -0.15), np.full(3, 0.15)
    jx, cp = _setups(3, None, lo, hi, pair_order="cell")
    pos = jnp.asarray(rng.uniform(lo, hi, (n, 3)))
    pos = pos[jx.grid.order(jx.to_box(pos))]  # numbered along the cells
    nbrs = jx.allocate(pos, min_cell_capacity=40)
    np.testing.assert_array_equal(np.asarray(nbrs.order), np.arange(n))
    moved = pos + jnp.asarray(rng.normal(0.0, 0.003, (n, 3)))
    (a, _), (b, _) = _both((jx, cp), moved, nbrs)
    for x in (a, b):
        np.testing.assert_array_equal(np.asarray(x.order), np.arange(n))
        i, j = np.asarray(x.idx)
        key = i.astype(np.int64) * (n + 1) + j
        assert np.all(np.diff(key[i < n]) > 0)  # canonical
    np.testing.assert_array_equal(np.asarray(a.idx), np.asarray(b.idx))
    shuffled = moved[rng.permutation(n)]
    (c, _), (d, _) = _both((jx, cp), shuffled, jx.allocate(shuffled, min_cell_capacity=40))
    np.testing.assert_array_equal(np.asarray(c.order), np.asarray(d.order))
    np.testing.assert_array_equal(np.asarray(c.order),
                                  np.asarray(jx.grid.order(jx.to_box(shuffled))))


@pytest.mark.parametrize("dim,periodic,pair_order", [(3, 0.12, "cell"), (2, None, "index"),
                                                     (3, 0.08, "index")])
def test_the_search_on_several_threads_is_the_one_threads(monkeypatch, dim, periodic,
                                                          pair_order):
    """The build's search split between threads (DRUMHEAT_KERNEL_THREADS; the tests' beds are
    below the 2000 particles per thread the build asks for) lists the pairs of one thread and
    of the JAX build, slot for slot, with the same sources. Along the periodic axis the
    slice of 0.12 m has six cells (the minimum image only for the cells that wrap), that of
    0.08 m four (the minimum image for every pair)."""
    rng = np.random.default_rng(11 + dim)
    n = 2500
    lo, hi = np.full(dim, -0.15), np.full(dim, 0.15)
    if periodic:
        lo[-1], hi[-1] = 0.0, periodic
    pos = jnp.asarray(rng.uniform(lo, hi, (n, dim)))
    jx, cp = _setups(dim, periodic, lo, hi, pair_order=pair_order)
    if periodic:
        assert cp.grid.cells[-1] == {0.12: 6, 0.08: 4}[periodic]
    nbrs = jx.allocate(pos, min_cell_capacity=40)
    moved = pos + jnp.asarray(rng.normal(0.0, 0.003, (n, dim)))
    if periodic:
        moved = moved.at[:, -1].set(jnp.mod(moved[:, -1], periodic))
    a, sa = jax.jit(jx.rebuild_with_sources)(moved, nbrs)
    assert int(jnp.sum(a.idx[0] < n)) > 300
    for threads in ("1", "2", "3"):
        monkeypatch.setenv("DRUMHEAT_KERNEL_THREADS", threads)
        b, sb = jax.jit(cp.rebuild_with_sources)(moved, nbrs)
        np.testing.assert_array_equal(np.asarray(a.idx), np.asarray(b.idx))
        np.testing.assert_array_equal(np.asarray(sa), np.asarray(sb))
        assert int(a.error.code) == int(b.error.code) == 0


def test_overflows_are_flagged_alike():
    """A crowded cell and too many pairs: the same flags; the pairs written are genuine."""
    rng = np.random.default_rng(4)
    lo, hi = np.zeros(3), np.full(3, 0.2)
    jx, cp = _setups(3, None, lo, hi, 0.03)
    pos = jnp.asarray(rng.uniform(lo, hi, (800, 3)))
    nbrs = jx.allocate(pos)
    (a, _), (b, _) = _both((jx, cp), pos * 0.2, nbrs)
    code = int(b.error.code)
    assert code == int(a.error.code)
    assert code & PEC.NEIGHBOR_LIST_OVERFLOW and code & PEC.CELL_LIST_OVERFLOW
    p = np.asarray(b.idx)
    assert np.all(p[0] < 800) and np.all(p[0] < p[1])
    x = np.asarray(pos * 0.2)
    assert np.all(np.linalg.norm(x[p[0]] - x[p[1]], axis=1) < cp.cutoff)
    # only the cell capacity exceeded (pair buffer large): the same list as the JAX build,
    # which sees only the first particles of a crowded cell
    big = jx.allocate(pos * 0.2, min_cell_capacity=1)
    few = jax.tree_util.tree_map(lambda v: v, big)
    import dataclasses
    few = dataclasses.replace(few, cell_list_capacity=max(1, big.cell_list_capacity // 3))
    (a, sa), (b, sb) = _both((jx, cp), pos * 0.2, few)
    assert int(a.error.code) == int(b.error.code) == PEC.CELL_LIST_OVERFLOW
    np.testing.assert_array_equal(np.asarray(a.idx), np.asarray(b.idx))
    np.testing.assert_array_equal(np.asarray(sa), np.asarray(sb))


def _drum(builder, dtype, gap=0.0):
    """A periodic slice of a turning drum with 600 spheres dropped in, a thin skin (a rebuild
    every few steps)."""
    rng = np.random.default_rng(7)
    R, L, r = 0.05, 0.02, 0.002
    g = np.arange(-R + 2 * r, R - 2 * r, 2.05 * r)
    pts = np.stack(np.meshgrid(g, g, np.arange(r, L - r, 2.05 * r), indexing="ij"), -1)
    pts = pts.reshape(-1, 3)
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) < R - 1.5 * r][:600]
    radius = r * rng.uniform(0.9, 1.0, len(pts))
    part = make_particles(radius, 2500.0)
    params = contact_params(1e5, restitution=0.5, friction=0.5, wall_friction=0.5)
    dem = make_dem(part, [DrumShell(R, rpm=30.0)], params, dim=3, periodic_length=L,
                   skin=0.0002, dtype=dtype, pair_kernel="cpu", neighbor_builder=builder,
                   conduction_gap=(gap, gap))
    vel = rng.normal(0.0, 0.5, pts.shape)
    return dem, dem.init(jnp.asarray(pts, dtype), velocity=jnp.asarray(vel, dtype))


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_run_is_the_same_bit_for_bit(dtype):
    """300 steps with the C++ contact loop and either neighbour build: the same state, bit for
    bit, through many rebuilds (springs carried by either)."""
    dj, st = _drum("jax", dtype)
    dc, _ = _drum("cpu", dtype)
    assert dj.neighbor.builder == "jax" and dc.neighbor.builder == "cpu"
    a = dj.run(st, 300, chunk=150)
    b = dc.run(st, 300, chunk=150)
    assert int(a.n_rebuilds) == int(b.n_rebuilds) > 5
    assert int(jnp.sum(jnp.any(a.pair_spring != 0, -1))) > 10  # contacts with history
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_kernel_conduction_mask_is_pair_gap_mask():
    """The C++ loop's pairs within the conduction gap are pair_gap_mask's, pair for pair."""
    dem, st = _drum("cpu", jnp.float64, gap=0.05)
    st = dem.run(st, 200, chunk=200)
    forces = dem._forces.__wrapped__.func  # the ContactForces
    r = dem._forces(st.position, st.velocity, st.angular_velocity, st.time, st.nbrs,
                    st.pair_spring, st.wall_spring)
    ref = jax.jit(forces.pair_gap_mask)(st.position, st.nbrs.idx[0], st.nbrs.idx[1])
    got = r[4].pair_conducts
    assert int(jnp.sum(got)) > int(jnp.sum(r[4].pair_mask)) > 10  # gaps conduct too
    np.testing.assert_array_equal(np.asarray(got), np.asarray(ref))
