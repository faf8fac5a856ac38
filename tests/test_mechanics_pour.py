"""Bed generation (pour and settle, layered groups), packing files, angle of repose."""

import math

import numpy as np
import pytest

from drumheat.geometry import DrumShell
from drumheat.mechanics import contact_params
from drumheat.mechanics.analysis import angle_of_repose, free_surface
from drumheat.mechanics.pour import (
    load_packing,
    particles_for_filling_degree,
    pour,
    save_packing,
)


def test_pour_layered_groups_settle_without_overlap(tmp_path):
    R, r = 0.025, 0.002
    n = particles_for_filling_degree(0.5, R, r, dim=2)
    assert n == 66  # 0.5 * 0.025^2 * 0.85 / 0.002^2
    group = np.repeat([0, 1], [n // 2, n - n // 2])
    p = contact_params(2e4, damping_ratio=0.3)
    pk = pour(np.full(n, r), 2700.0, [DrumShell(R, rpm=12.0)], p, dim=2, group=group,
              layered=True, seed=2, max_time=2.0)
    pos = pk.position
    assert pos.shape == (n, 2)
    assert np.all(np.linalg.norm(pos, axis=1) < R - r + 1e-4)  # inside the shell
    d = np.linalg.norm(pos[:, None] - pos[None], axis=-1) + np.eye(n)
    assert d.min() > 2 * r * (1 - 0.02)  # overlaps below 2 % of a diameter
    assert pos[group == 0, 1].mean() < pos[group == 1, 1].mean() - 2 * r  # first group below
    path = tmp_path / "bed.npz"
    save_packing(path, pk, note="test")
    back = load_packing(path)
    np.testing.assert_array_equal(back.position, pk.position)
    np.testing.assert_array_equal(back.group, group)
    np.testing.assert_array_equal(back.radius, pk.radius)
    assert back.info["dim"] == 2 and back.info["note"] == "test"
    assert back.info["periodic_length"] is None


def test_angle_of_repose_of_a_tilted_surface():
    """A synthetic bed whose top layer lies on a line of known slope (2D and 3D)."""
    rng = np.random.default_rng(0)
    r = 0.002
    for deg in (-20.0, 0.0, 35.0):
        s = math.tan(math.radians(deg))
        x = np.arange(-0.04, 0.04, 2 * r)
        pts = []
        for k in range(4):  # four layers below the surface line
            pts.append(np.stack([x, s * x - 2 * r * k], axis=1))
        pos = np.concatenate(pts) + rng.normal(0, 1e-5, (4 * len(x), 2))
        assert angle_of_repose(pos, r) == pytest.approx(deg, abs=0.2)
        z = np.arange(0, 0.02, 2 * r)
        pos3 = np.concatenate([np.column_stack([pos, np.full(len(pos), zz)]) for zz in z])
        assert angle_of_repose(pos3, r) == pytest.approx(deg, abs=0.2)
    # the wall-near ends are excluded
    surf = free_surface(pos, r, central_fraction=0.5)
    assert np.all(np.abs(surf[:, 0]) <= 0.021)


def test_a_bed_that_does_not_settle_warns_with_advice():
    from drumheat.mechanics.pour import PourWarning

    R, r, n = 0.025, 0.002, 30
    p = contact_params(2e4, restitution=0.5, friction=0.5, wall_friction=0.5)
    with pytest.warns(PourWarning, match="harmless") as rec:
        pour(np.full(n, r), 2700.0, [DrumShell(R, rpm=12.0)], p, dim=2, min_time=0.01,
             max_time=0.01, chunk=100)
    assert "dem.settle_time" in str(rec[0].message)
