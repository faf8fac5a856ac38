"""Wall primitives: signed distance (positive inside the domain), normal, wall velocity."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from drumheat.geometry import (
    Box,
    DrumShell,
    EndPlate,
    FixedCylinder,
    InnerCylinder,
    Plane,
    RadialPlate,
    expand_walls,
    rpm_to_omega,
    wall_bounds,
    walls_at_rest,
)


def test_drum_shell_2d_and_3d():
    w = DrumShell(0.1, rpm=60.0, temperature=343.0, wall_id=3)
    x = jnp.array([[0.03, 0.04], [0.0, -0.09]])
    d, n, v = w.evaluate(x, 0.0)
    np.testing.assert_allclose(d, [0.05, 0.01])
    np.testing.assert_allclose(n[0], [-0.6, -0.8])
    np.testing.assert_allclose(n[1], [0.0, 1.0], atol=1e-15)
    om = 2 * math.pi  # 60 rpm
    # at the bottom the CCW shell moves towards +x with omega R
    np.testing.assert_allclose(v[1], [om * 0.1, 0.0], atol=1e-15)
    x3 = jnp.array([[0.03, 0.04, 0.7]])
    d3, n3, v3 = w.evaluate(x3, 1.0)
    np.testing.assert_allclose(d3, [0.05])
    np.testing.assert_allclose(n3[0], [-0.6, -0.8, 0.0])
    np.testing.assert_allclose(v3[0], om * 0.1 * np.array([-0.8, 0.6, 0.0]))
    assert w.wall_id == 3 and w.temperature == 343.0


def test_rpm_to_omega():
    assert rpm_to_omega(9.55) == pytest.approx(1.0, rel=1e-3)  # peers/liggghts: 9.55 rpm


def test_radial_plate_rotates_and_is_two_sided():
    w = RadialPlate(r_inner=0.02, r_outer=0.1, phase=0.0, rpm=15.0, thickness=0.004)
    # at t = 0 the plate lies along +x; points above and below it
    x = jnp.array([[0.05, 0.01], [0.05, -0.01], [0.12, 0.0], [0.0, 0.0]])
    d, n, v = w.evaluate(x, 0.0)
    np.testing.assert_allclose(d, [0.008, 0.008, 0.018, 0.018])
    np.testing.assert_allclose(n[0], [0, 1], atol=1e-15)
    np.testing.assert_allclose(n[1], [0, -1], atol=1e-15)
    np.testing.assert_allclose(n[2], [1, 0], atol=1e-15)
    om = rpm_to_omega(15.0)
    np.testing.assert_allclose(v[0], [0, om * 0.05], atol=1e-15)
    # a quarter turn later (1 s at 15 rpm) it lies along +y
    t = 1.0
    assert float(w.angle(t)) == pytest.approx(math.pi / 2)
    d, n, v = w.evaluate(jnp.array([[0.01, 0.05]]), t)
    np.testing.assert_allclose(d, [0.008], atol=1e-12)
    np.testing.assert_allclose(n[0], [1, 0], atol=1e-12)


def test_end_plates_inner_and_fixed_cylinders_planes():
    lo = EndPlate(0.0, side=1, rpm=10.0)
    hi = EndPlate(0.2, side=-1)
    x = jnp.array([[0.05, 0.0, 0.03]])
    d, n, v = lo.evaluate(x, 0.0)
    assert float(d[0]) == pytest.approx(0.03)
    np.testing.assert_allclose(n[0], [0, 0, 1])
    np.testing.assert_allclose(v[0], [0, rpm_to_omega(10.0) * 0.05, 0])
    d, n, _ = hi.evaluate(x, 0.0)
    assert float(d[0]) == pytest.approx(0.17)
    np.testing.assert_allclose(n[0], [0, 0, -1])
    ic = InnerCylinder(0.02, rpm=-30.0)
    d, n, v = ic.evaluate(jnp.array([[0.0, 0.05]]), 0.0)
    assert float(d[0]) == pytest.approx(0.03)
    np.testing.assert_allclose(v[0], [-rpm_to_omega(-30.0) * 0.02, 0], atol=1e-15)
    tube = FixedCylinder((0.1, 0.2), 0.0125, wall_id=7)
    d, n, v = tube.evaluate(jnp.array([[0.1, 0.23, 0.5]]), 3.0)
    assert float(d[0]) == pytest.approx(0.0175)
    np.testing.assert_allclose(n[0], [0, 1, 0])
    np.testing.assert_allclose(v, 0)
    pl = Plane((0.0, 0.0), (1.0, 1.0))
    d, n, _ = pl.evaluate(jnp.array([[1.0, 0.0]]), 0.0)
    assert float(d[0]) == pytest.approx(1 / math.sqrt(2))


def test_box_expands_into_faces_and_bounds():
    b = Box((-1.0, 0.0), (1.0, 2.0), temperature=300.0, wall_id=2)
    faces = expand_walls([b, DrumShell(5.0)])
    assert len(faces) == 5 and all(f.wall_id == 2 for f in faces[:4])
    x = jnp.array([[0.9, 1.0]])
    d = jnp.stack([f.distance(x) for f in faces[:4]])[:, 0]
    np.testing.assert_allclose(sorted(np.asarray(d)), [0.1, 1.0, 1.0, 1.9])
    assert float(b.distance(x)[0]) == pytest.approx(0.1)
    lo, hi = wall_bounds(faces, 2)
    np.testing.assert_allclose(lo, [-1, 0])
    np.testing.assert_allclose(hi, [1, 2])
    lo, hi = wall_bounds([DrumShell(0.1), EndPlate(0.0, 1), EndPlate(0.3, -1)], 3)
    np.testing.assert_allclose(lo, [-0.1, -0.1, 0.0])
    np.testing.assert_allclose(hi, [0.1, 0.1, 0.3])


def test_walls_are_pytrees_jit_and_grad():
    w = DrumShell(0.1, rpm=12.0, temperature=343.0)
    leaves = jax.tree_util.tree_leaves(w)
    assert 0.1 in leaves and 12.0 in leaves and 343.0 in leaves
    f = jax.jit(lambda wall, x: wall.distance(x, 0.5))
    assert float(f(w, jnp.array([[0.0, 0.05]]))[0]) == pytest.approx(0.05)
    g = jax.grad(lambda wall: wall.distance(jnp.array([[0.0, 0.05]]), 0.0)[0])(w)
    assert float(g.radius) == pytest.approx(1.0)
    rest = walls_at_rest([w, RadialPlate(0.0, 0.1, rpm=5.0)])
    assert all(float(r.rpm) == 0.0 for r in rest)
    assert eqx.tree_equal(rest[0].radius, w.radius)
