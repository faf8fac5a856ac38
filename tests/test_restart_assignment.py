"""The cyclic replay's restart assignment (drumheat.motion.replay.restart_assignment): exact for
a group up to the block size, cut into blocks by median bisection above it."""

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from drumheat.motion.replay import bisection_blocks, restart_assignment, squared_distances


def jittered_lattice(n, seed=0):
    """n points of a unit-spaced cubic lattice, each moved by up to 0.2 spacings."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(n ** (1 / 3)))
    grid = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3)
    return grid[:n] + rng.uniform(-0.2, 0.2, (n, 3))


def test_blocks_cover_both_sets_once_in_equal_parts():
    rng = np.random.default_rng(1)
    start, end = rng.normal(size=(1001, 3)), rng.normal(size=(1001, 3))
    blocks = bisection_blocks(start, end, 100)
    assert all(len(b) == len(a) <= 100 for b, a in blocks)
    assert len(blocks) == 16  # 1001 -> 500 | 501 -> ... four cuts deep
    for k in (0, 1):
        np.testing.assert_array_equal(np.sort(np.concatenate([x[k] for x in blocks])),
                                      np.arange(1001))
    with pytest.raises(ValueError, match="equal sets"):
        bisection_blocks(start, end[:-1], 100)


def test_squared_distances_are_the_direct_sums_bit_for_bit():
    rng = np.random.default_rng(6)
    x, y = rng.normal(size=(70, 3)), rng.normal(size=(50, 3)) * 3
    direct = np.sum((x[:, None, :] - y[None, :, :]) ** 2, axis=-1)
    np.testing.assert_array_equal(squared_distances(x, y), direct)
    for rows in (1, 16, 70, 500):  # row blocks that do and do not divide the 70 rows
        np.testing.assert_array_equal(squared_distances(x, y, rows=rows), direct)


def test_small_group_is_the_optimal_assignment():
    rng = np.random.default_rng(2)
    start, end = jittered_lattice(300), jittered_lattice(300, seed=3) + rng.normal(0, 0.3, 3)
    group = np.zeros(300, int)
    match = restart_assignment(end, start, group)
    cost = np.sum((start[:, None] - end[None]) ** 2, axis=-1)
    rows, cols = linear_sum_assignment(cost)
    assert cost[np.arange(300), match].sum() == pytest.approx(cost[rows, cols].sum(), rel=1e-12)


@pytest.mark.parametrize("block", [64, 2048])
def test_relabelled_bed_is_handed_back_exactly(block):
    """End positions that are the start positions renumbered (and moved by less than the
    points' spacing, as a whole) are matched back to their own particle, blocks or not: both
    sets are cut at the same places."""
    start = jittered_lattice(3000)
    perm = np.random.default_rng(4).permutation(3000)
    end = start[perm] + np.array([0.1, -0.05, 0.02])
    group = np.zeros(3000, int)
    match = restart_assignment(end, start, group, block=block)
    np.testing.assert_array_equal(perm[match], np.arange(3000))


def test_groups_stay_apart():
    """Each particle takes a temperature of its own group, each particle's once."""
    start = jittered_lattice(500)
    group = np.arange(500) % 2
    end = start[np.random.default_rng(5).permutation(500)]
    match = restart_assignment(end, start, group, block=64)
    np.testing.assert_array_equal(group[match], group)
    np.testing.assert_array_equal(np.sort(match), np.arange(500))
