"""Geometric deposition packing and geometric contact detection."""

import numpy as np
import pytest

from drumheat.mechanics.deposition import Packing, deposit_2d
from drumheat.thermal.network import find_contacts_2d_drum


@pytest.mark.parametrize("n,d,D", [(70, 0.004, 0.05), (370, 0.008, 0.25)])
def test_packing_is_valid_and_stable(n, d, D):
    groups = np.repeat([0, 1], [n // 2, n - n // 2])
    pk = deposit_2d(np.full(n, d), groups, D, seed=3)
    p = pk.position
    # no overlaps (pairwise, fine for these sizes in a test), inside the drum
    dist = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.eye(n) * 10
    assert dist.min() >= d * (1 - 1e-9)
    assert np.all(np.hypot(*p.T) <= D / 2 - d / 2 + 1e-12)
    pairs, wall = find_contacts_2d_drum(p, pk.diameter, D, tolerance=1e-6)
    contacts = np.bincount(pairs.ravel(), minlength=n) + np.isin(np.arange(n), wall)
    # every particle rests on something; mean coordination like a poured monolayer (~3.7,
    # weigler-thermal-dem.md Table 5-2 / A4)
    assert contacts.min() >= 1
    assert 3.0 < 2 * len(pairs) / n < 4.5
    # layers: the first group lies below the second
    assert p[groups == 0, 1].mean() < p[groups == 1, 1].mean()


def test_same_seed_same_packing_and_mixed_arrangement():
    d = np.full(40, 0.004)
    g = np.repeat([0, 1], 20)
    a = deposit_2d(d, g, 0.05, seed=5)
    b = deposit_2d(d, g, 0.05, seed=5)
    np.testing.assert_array_equal(a.position, b.position)
    m = deposit_2d(d, g, 0.05, seed=5, arrangement="mixed")
    assert abs(m.position[g == 0, 1].mean() - m.position[g == 1, 1].mean()) < \
        abs(a.position[g == 0, 1].mean() - a.position[g == 1, 1].mean())


def test_contact_tolerance_and_save_load(tmp_path):
    p = np.array([[0.0, -0.02], [0.0041, -0.02], [0.0083, -0.02]])
    d = np.full(3, 0.004)
    # gaps: 0.1 mm between 0-1, 0.2 mm between 1-2
    pairs, wall = find_contacts_2d_drum(p, d, 0.05, tolerance=0.03)  # 0.12 mm
    assert pairs.tolist() == [[0, 1]]
    pairs, wall = find_contacts_2d_drum(p, d, 0.05, tolerance=0.06)  # 0.24 mm
    assert pairs.tolist() == [[0, 1], [1, 2]]
    pairs, _ = find_contacts_2d_drum(p, d, 0.05, tolerance=0.01)
    assert pairs.size == 0
    pk = Packing(p, d, np.array([0, 0, 1]))
    pk.save(tmp_path / "p.npz")
    back = Packing.load(tmp_path / "p.npz")
    np.testing.assert_array_equal(back.position, p)


def test_overfull_drum_is_refused():
    with pytest.raises(ValueError, match="too full"):
        deposit_2d(np.full(200, 0.004), np.zeros(200, int), 0.05, seed=1, max_attempts=3)


def test_a_poured_packing_file_loads_as_a_scene_packing(tmp_path):
    from drumheat.mechanics.pour import Packing as PouredPacking
    from drumheat.mechanics.pour import save_packing

    p = np.array([[0.0, -0.02], [0.0041, -0.02]])
    save_packing(tmp_path / "poured.npz", PouredPacking(p, np.full(2, 0.002), np.array([0, 1]),
                                                        np.full(2, 2700.0), np.zeros(2, int)))
    back = Packing.load(tmp_path / "poured.npz")
    np.testing.assert_array_equal(back.diameter, [0.004, 0.004])
    np.testing.assert_array_equal(back.position, p)
