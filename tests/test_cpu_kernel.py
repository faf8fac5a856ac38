"""The opt-in C++ contact kernel (make_dem(..., pair_kernel="cpu")) against the JAX kernel, and
its build and fallback (drumheat.mechanics.cpu_kernel)."""

import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import drumheat  # noqa: F401  (x64)
from drumheat.geometry import DrumShell, InnerCylinder
from drumheat.mechanics import (Contacts, DEMState, contact_params, cpu_kernel, make_dem,
                                make_particles)
from drumheat.mechanics.conduction import PairConduction, heat_flow

# the beds are stiff for their dt (0.25 t_crit): fine for comparing kernels, not for drum flow
pytestmark = pytest.mark.filterwarnings("ignore::drumheat.mechanics.DEMAccuracyWarning")
needs_kernel = pytest.mark.skipif(not cpu_kernel.available()[0],
                                  reason=f"C++ contact kernel unavailable: "
                                         f"{cpu_kernel.available()[1]}")

R_P = 0.002  # particle radius (m)


def _bed(dim, dtype, kernel, law="projected", gap_tolerance=0.0, seed=0, rolling=True,
         rotation=True, calm=False, friction_heat=None, shuffle=False, layers=4,
         position_dtype=None, contact_details=True, one_material=False, conduction_gap=None,
         shell_only=False):
    """A small moving bed of two materials with rolling resistance in the lower half of an
    annulus between a rotating drum shell and a counter-rotating inner cylinder (2D, or a 3D
    slice with periodic z): spheres of 0.97-1 r on a 1.97 r lattice, jittered, so that many
    neighbours overlap, some by a hair and some with a gap of a few percent of d, and the bed
    presses on both walls; random velocities, spins and tangential springs (some at their
    Coulomb limit, most not), a temperature gradient. ``calm``: for runs, a 2 r lattice that
    touches nothing yet (gaps up to 1e-4 d), moving slowly, no springs, set in motion by
    gravity (50 g) and the walls. Returns the DEM and a state (None for kernel "cpu": the
    state of the "jax" twin serves both). ``one_material``: equal spheres (0.985 r) of one
    material instead (the rest as above). ``friction_heat``: make_dem's (a FrictionHeat, or a
    function of the particles that gives one). ``shuffle``: the particles numbered at random
    (else along the lattice, so that neighbours lie near each other in the numbering).
    ``layers``: lattice layers along the periodic z (3D); ``position_dtype``: make_dem's (the
    state's positions in it); ``contact_details``, ``conduction_gap``: make_dem's;
    ``shell_only``: without the inner cylinder (the bed lies on the shell alone)."""
    rng = np.random.default_rng(seed)
    R, r_in = 0.03, 0.008
    a = (2.0 if calm else 1.97) * R_P
    g = np.arange(-R, R, a) + 0.3 * a
    zs = (np.arange(layers) + 0.5) * a if dim == 3 else None
    grids = np.meshgrid(g, g, zs, indexing="ij") if dim == 3 else np.meshgrid(g, g, indexing="ij")
    pts = np.stack([x.ravel() for x in grids], 1)
    rho = np.hypot(pts[:, 0], pts[:, 1])
    pts = pts[(rho < R - 0.95 * R_P) & (rho > r_in + 0.95 * R_P) & (pts[:, 1] < 0.0)]
    pts[:, :2] += rng.uniform(-0.01, 0.01, (len(pts), 2)) * R_P * (not calm)
    # the outermost and innermost rings moved radially onto the walls (overlap up to 0.1 r)
    rho = np.hypot(pts[:, 0], pts[:, 1])[:, None]
    out, inn = rho[:, 0] > R - 1.9 * R_P, rho[:, 0] < r_in + 1.9 * R_P
    lo, hi = (1.0, 1.0001) if calm else (0.9, 1.05)
    pts[out, :2] *= (R - rng.uniform(lo, hi, (out.sum(), 1)) * R_P) / rho[out]
    pts[inn, :2] *= (r_in + rng.uniform(lo, hi, (inn.sum(), 1)) * R_P) / rho[inn]
    keep = np.ones(len(pts), bool)  # and those that came too close to another one dropped
    for k in range(len(pts)):
        near = np.linalg.norm(pts[:k][keep[:k]] - pts[k], axis=1) < (1.9999 if calm else 1.9) * R_P
        keep[k] = not np.any(near)
    pts = pts[keep]
    n = len(pts)
    if shuffle:
        pts = pts[rng.permutation(n)]
    radius = R_P * rng.uniform(0.9999 if calm else 0.97, 1.0, n)
    ptype = rng.integers(0, 2, n)
    if one_material:
        radius, ptype = np.full(n, 0.985 * R_P), np.zeros(n, int)
    part = make_particles(radius, np.where(ptype == 0, 2500.0, 2700.0), ptype=ptype)
    two = lambda a, b, c: np.array([[a, b], [b, c]])  # noqa: E731  symmetric (T, T)
    walls = [DrumShell(R, rpm=30.0), InnerCylinder(r_in, rpm=-20.0)][:1 if shell_only else 2]
    w = 1 if shell_only else 2  # the wall tables' columns
    params = contact_params(
        two(1e5, 1.4e5, 2e5), kt=two(0.9e5, 1.2e5, 1.7e5),
        kn_wall=np.array([[1.2e5, 0.8e5], [1.5e5, 1e5]])[:, :w],
        kt_wall=np.array([[1e5, 0.7e5], [1.3e5, 0.9e5]])[:, :w],
        damping_ratio=two(0.3, 0.25, 0.2),
        wall_damping_ratio=np.array([[0.3, 0.2], [0.1, 0.4]])[:, :w],
        tangential_damping_ratio=two(0.2, 0.3, 0.25), friction=two(0.5, 0.4, 0.6),
        wall_friction=np.array([[0.6, 0.3], [0.4, 0.5]])[:, :w],
        rolling_friction=two(0.05, 0.1, 0.02) * rolling,
        wall_rolling_friction=np.array([[0.08, 0.03], [0.0, 0.1]])[:, :w] * rolling, n_types=2)
    if one_material:
        params = contact_params(1e5, kt=0.9e5, kn_wall=1.2e5, kt_wall=1e5, damping_ratio=0.3,
                                wall_damping_ratio=0.2, tangential_damping_ratio=0.25,
                                friction=0.5, wall_friction=0.4, rolling_friction=0.05 * rolling,
                                wall_rolling_friction=0.08 * rolling)
    cond = PairConduction(law, 1e3 if law == "projected" else 2.0,
                          np.asarray(part.mass) * 836.0, gap_tolerance)
    # calm: dt = 0.05 t_crit, where the round-off differences of the two kernels stay
    # round-off over hundreds of steps (at 0.25 t_crit the dense frictional bed amplifies them
    # by e every two steps, the same in either kernel); a thin skin for frequent rebuilds
    kw = dict(dim=dim, dt=2e-6 if calm else 1e-5, skin=0.00005 if calm else 0.0008,
              dtype=dtype, position_dtype=position_dtype, pair_kernel=kernel,
              conduction=cond, rotation=rotation, contact_details=contact_details,
              friction_heat=friction_heat(part) if callable(friction_heat) else friction_heat)
    if dim == 3:
        kw["periodic_length"] = layers * a
    if conduction_gap is not None:
        kw["conduction_gap"] = conduction_gap
    if calm:  # 50 g: the bed forms within the few hundred steps of a test
        kw["gravity"] = np.array([0.0, -500.0, 0.0][:dim])
    dem = make_dem(part, walls, params, **kw)
    if kernel == "cpu":  # the state comes from the JAX twin
        return dem, None
    # the state as DEM.init makes it, without its force evaluation (one compilation less)
    pos = jnp.asarray(pts, position_dtype or dtype)
    nbrs = dem.neighbor.allocate(pos, (4 if dim == 2 else 8) * n, dem.cell_capacity)
    xi = lambda *shape: jnp.asarray(rng.uniform(-1, 1, shape) * 1e-5 * (not calm), dtype)  # noqa
    wshape = (n, 3) if dim == 3 else (n,)
    st = DEMState(
        position=pos, velocity=jnp.asarray(rng.normal(0.0, 0.002 if calm else 0.05, (n, dim)),
                                           dtype),
        angular_velocity=jnp.asarray(rng.normal(0.0, 2.0 if calm else 20.0, wshape), dtype),
        force=jnp.zeros(pos.shape, dtype), torque=jnp.zeros(wshape, dtype),
        time=jnp.asarray(0.0, jnp.float64), step=jnp.asarray(0, jnp.int32), nbrs=nbrs,
        pair_spring=xi(nbrs.idx.shape[1], dim), wall_spring=xi(n, len(walls), dim),
        n_rebuilds=jnp.asarray(0, jnp.int32), max_overlap=jnp.asarray(0.0, dtype),
        extra=jnp.asarray(300.0 + 50.0 * (pts[:, 0] + R) / (2 * R)))
    return dem, st


def _in_cell_order(st, dem):
    """``st`` with its neighbour list in the cell order of ``dem``'s grid, the pairs' springs
    carried (a bed as small as these does not get that order from ``layout_order``)."""
    import dataclasses

    from drumheat.mechanics.integrator import _carry_pairs
    from drumheat.mechanics.neighbors import sort_pairs

    n = st.position.shape[0]
    cells = dem.neighbor.grid.order(st.nbrs.reference_position)
    return _carry_pairs(st, sort_pairs(dataclasses.replace(st.nbrs, order=cells), n, cells), n)


def _forces(dem, st):
    """Force, torque, pair springs, wall springs, Contacts, max overlap, heat flows."""
    return dem._forces(st.position, st.velocity, st.angular_velocity, st.time, st.nbrs,
                       st.pair_spring, st.wall_spring, temperature=st.extra)


@pytest.mark.parametrize("kernel", ["jax", pytest.param("cpu", marks=needs_kernel)])
def test_steps_without_contact_details(kernel):
    """make_dem(contact_details=False): the step's contacts leave out the per-pair mask,
    overlap, distance and normal force (None; the C++ loop does not write them) and the steps
    are the same, the pairs that conduct included (3D, float64, conduction gap, friction
    heat): bit for bit with the C++ loop, to round-off with the JAX kernel (XLA fuses the
    program without the unused arrays otherwise); DEM.contacts still has them."""
    from drumheat.mechanics.dissipation import FrictionHeat

    st = _bed(3, jnp.float64, "jax", "projected", 0.05)[1]
    dems = [_bed(3, jnp.float64, kernel, "projected", 0.05, contact_details=d,
                 friction_heat=FrictionHeat())[0] for d in (True, False)]
    out = []
    for dem in dems:
        s, c = st, None
        for _ in range(3):
            s, c = dem.step(s)
        out.append((s, c))
    (a, ca), (b, cb) = out
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        if kernel == "cpu" or not jnp.issubdtype(x.dtype, jnp.floating):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
        else:  # to round-off of the largest entry (sums over contacts)
            scale = float(jnp.max(jnp.abs(x), initial=0.0))
            np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=0,
                                       atol=REL[jnp.float64] * scale)
    for f in ("pair_mask", "pair_overlap", "pair_distance", "pair_normal_force"):
        assert getattr(cb, f) is None and getattr(ca, f) is not None, f
    assert int(jnp.sum(ca.pair_conducts)) >= int(jnp.sum(ca.pair_mask)) > 10
    for f in ("pair_conducts", "wall_conducts", "wall_mask", "wall_overlap"):
        np.testing.assert_array_equal(np.asarray(getattr(ca, f)), np.asarray(getattr(cb, f)), f)
    np.testing.assert_allclose(np.asarray(ca.dissipation.particle),
                               np.asarray(cb.dissipation.particle), rtol=1e-12,
                               atol=1e-12 * float(jnp.max(jnp.abs(ca.dissipation.particle))))
    full = dems[1].contacts(b)
    np.testing.assert_allclose(np.asarray(full.pair_overlap),
                               np.asarray(dems[0].contacts(a).pair_overlap), rtol=1e-12,
                               atol=1e-12 * R_P)


@pytest.mark.parametrize("kernel", ["jax", pytest.param("cpu", marks=needs_kernel)])
def test_init_evaluates_the_contacts_forces(kernel):
    """DEM.init takes the forces, torques and largest overlap of its state from a program that
    returns those alone (the contact call's per-slot outputs its temporaries, no per-pair
    details): the numbers of the full contact evaluation, bit for bit with the C++ loop, to
    round-off with the JAX kernel (XLA fuses the smaller program otherwise)."""
    dem = _bed(3, jnp.float64, kernel, "projected", 0.05)[0]
    twin = _bed(3, jnp.float64, "jax", "projected", 0.05)[1]
    st = dem.init(twin.position, twin.velocity, twin.angular_velocity, extra=twin.extra)
    full = dem._forces(st.position, st.velocity, st.angular_velocity, st.time, st.nbrs,
                       st.pair_spring, st.wall_spring)
    assert float(full.max_overlap) > 0
    for got, want, what in ((st.force, full.force, "force"), (st.torque, full.torque, "torque"),
                            (st.max_overlap, full.max_overlap, "max_overlap")):
        if kernel == "cpu":
            np.testing.assert_array_equal(np.asarray(got), np.asarray(want), what)
        else:
            _close(got, want, REL[jnp.float64], what)


def _close(x, y, rel, what):
    """x == y to ``rel`` of the largest |x| (round-off of the sums over contacts)."""
    x, y = np.asarray(x), np.asarray(y)
    assert x.shape == y.shape, what
    scale = np.max(np.abs(x), initial=0.0)
    assert scale > 0, f"{what}: all zero, nothing compared"
    assert np.max(np.abs(x - y)) <= rel * scale, (what, np.max(np.abs(x - y)) / scale)


# round-off: float32 1e-7, float64 1e-16, times the growth of the sums and of the cancelling
# subtractions (overlap = r_i + r_j - distance loses log2(2r / overlap) ~ 6 bits here)
REL = {jnp.float32: 1e-4, jnp.float64: 1e-11}

# each law with and without a gap tolerance, once in each dimension and once in each dtype
CASES = [(2, jnp.float32, "projected", 0.0), (2, jnp.float64, "overlap", 0.05),
         (3, jnp.float32, "overlap", 0.0), (3, jnp.float64, "projected", 0.05)]


@needs_kernel
@pytest.mark.parametrize("dim,dtype,law,tol", CASES,
                         ids=[f"{d}d-{jnp.dtype(t).name}-{c}-tol{g}" for d, t, c, g in CASES])
def test_one_step_equals_the_jax_kernel(dim, dtype, law, tol):
    """Forces, torques (contact + rolling), pair and wall springs, contact outputs and heat
    flows of one force evaluation: two materials, rolling resistance, two rotating walls."""
    jdem, st = _bed(dim, dtype, "jax", law, tol)
    cdem, _ = _bed(dim, dtype, "cpu", law, tol)
    a, b = _forces(jdem, st), _forces(cdem, st)
    rel = REL[dtype]
    ca, cb = a[4], b[4]
    n_pairs, n_walls = int(jnp.sum(ca.pair_mask)), int(jnp.sum(ca.wall_mask))
    assert n_pairs > (40 if dim == 2 else 150) and n_walls > 5  # a dense bed on both walls
    # both materials and both walls in contact
    types = np.asarray(jdem.particles.ptype)
    pi, pj = (np.asarray(x)[np.asarray(ca.pair_mask)] for x in (ca.pair_i, ca.pair_j))
    assert len({(min(types[i], types[j]), max(types[i], types[j])) for i, j in zip(pi, pj)}) == 3
    assert len(set(np.asarray(ca.wall_index)[np.asarray(ca.wall_mask)])) == 2
    for what, x, y in [("force", a[0], b[0]), ("torque", a[1], b[1]),
                       ("pair springs", a[2], b[2]), ("wall springs", a[3], b[3])]:
        _close(x, y, rel, what)
        assert x.dtype == y.dtype == dtype, what
    np.testing.assert_array_equal(np.asarray(ca.pair_mask), np.asarray(cb.pair_mask))
    np.testing.assert_array_equal(np.asarray(ca.wall_mask), np.asarray(cb.wall_mask))
    for f in ("pair_overlap", "pair_distance", "pair_normal_force", "wall_overlap",
              "wall_normal_force"):
        _close(getattr(ca, f), getattr(cb, f), rel, f)
    _close(a[5], b[5], rel, "max overlap")
    _close(a[6], b[6], rel, "heat flow")
    # some contacts slide (the new spring at the Coulomb limit k_t |xi| = mu F_n), most stick
    ti, tj = types[pi], types[pj]
    kt = np.asarray(jdem.params.kt_pp)[ti, tj]
    mu = np.asarray(jdem.params.mu_pp)[ti, tj]
    xi = np.linalg.norm(np.asarray(b[2])[np.asarray(ca.pair_mask)], axis=1)
    sliding = np.isclose(kt * xi, mu * np.asarray(cb.pair_normal_force)[np.asarray(ca.pair_mask)],
                         rtol=1e-4)
    assert 0 < np.sum(sliding) < 0.8 * len(sliding)
    # the gap tolerance lets more pairs conduct ("projected"; "overlap" has no circle there)
    q0 = heat_flow(st.extra, ca, jdem.particles.radius, law, jdem.conduction.coefficient)
    more = np.sum(~np.isclose(np.asarray(q0), np.asarray(a[6]), rtol=1e-6, atol=0))
    assert more > 5 if (law == "projected" and tol > 0) else more == 0


@needs_kernel
@pytest.mark.parametrize("dim", [2, 3])
def test_equal_spheres_of_one_material_pass_one_value(monkeypatch, dim):
    """Radii, masses and moments of inertia that all particles share go to the C++ loop as one
    value each (``cpu_kernel.uniform_or_all``; gravity as one row), the types not at all with
    one material: the
    same forces, torques, springs and heat flows as with the per-particle arrays, bit for bit,
    and the JAX kernel's to round-off."""
    jdem, st = _bed(dim, jnp.float64, "jax", "projected", 0.05, one_material=True)
    cdem, _ = _bed(dim, jnp.float64, "cpu", "projected", 0.05, one_material=True)
    assert [a.shape for a in cdem._forces.__wrapped__.func._kernel_particles] == [(1,)] * 4
    assert cdem._forces.__wrapped__.func._body_force.shape == (1, dim)  # gravity, one row
    monkeypatch.setattr(cpu_kernel, "uniform_or_all", lambda values: values)
    fdem, _ = _bed(dim, jnp.float64, "cpu", "projected", 0.05, one_material=True)
    n = jdem.particles.n
    assert [a.shape for a in fdem._forces.__wrapped__.func._kernel_particles] == [(n,)] * 3 + [(1,)]
    assert fdem._forces.__wrapped__.func._body_force.shape == (n, dim)
    a, b, c = _forces(jdem, st), _forces(cdem, st), _forces(fdem, st)
    assert int(jnp.sum(b[4].pair_mask)) > (40 if dim == 2 else 150)
    assert float(jnp.max(jnp.abs(b[1]))) > 0.0  # rolling resistance and spins: inertia read
    for k, what in enumerate(["force", "torque", "pair springs", "wall springs"]):
        np.testing.assert_array_equal(np.asarray(b[k]), np.asarray(c[k]), err_msg=what)
        _close(a[k], b[k], REL[jnp.float64], what)
    np.testing.assert_array_equal(np.asarray(b[6]), np.asarray(c[6]))
    _close(a[6], b[6], REL[jnp.float64], "heat flow")


@needs_kernel
def test_mixed_precision_equals_the_jax_kernel():
    """Mixed precision (float64 positions, float32 mechanics): both kernels read the positions
    folded along the periodic axis (ContactForces.pair_positions) and agree to float32's
    round-off, pairs across a fold included; 17 lattice layers make the slice long enough to
    fold (twice its cross-section)."""
    jdem, st = _bed(3, jnp.float32, "jax", "projected", 0.05, layers=17,
                    position_dtype=jnp.float64)
    cdem, _ = _bed(3, jnp.float32, "cpu", "projected", 0.05, layers=17,
                   position_dtype=jnp.float64)
    assert st.position.dtype == jnp.float64 and jdem.fold_length is not None
    length = float(jdem.neighbor.periodic_length)
    assert length / jdem.fold_length == pytest.approx(round(length / jdem.fold_length))
    a, b = _forces(jdem, st), _forces(cdem, st)
    ca, cb = a[4], b[4]
    np.testing.assert_array_equal(np.asarray(ca.pair_mask), np.asarray(cb.pair_mask))
    for what, x, y in [("force", a[0], b[0]), ("torque", a[1], b[1]),
                       ("pair springs", a[2], b[2]), ("wall springs", a[3], b[3])]:
        _close(x, y, REL[jnp.float32], what)
        assert x.dtype == y.dtype == jnp.float32, what
    for f in ("pair_overlap", "pair_distance", "pair_normal_force"):
        _close(getattr(ca, f), getattr(cb, f), REL[jnp.float32], f)
    _close(a[6], b[6], REL[jnp.float32], "heat flow")
    # touching pairs whose folded coordinates lie on either side of a fold
    z = np.mod(np.asarray(st.position[:, 2]), jdem.fold_length)
    i, j = (np.asarray(x)[np.asarray(ca.pair_mask)] for x in (ca.pair_i, ca.pair_j))
    assert np.sum(np.abs(z[i] - z[j]) > 0.5 * jdem.fold_length) > 5


@needs_kernel
def test_rolling_resistance_and_rotation_off_in_the_kernel():
    """Rolling resistance changes the kernel's torques (and the JAX kernel's, equal in
    test_one_step_equals_the_jax_kernel); without rotation neither kernel gives torques and
    the forces stay equal."""
    jdem, st = _bed(3, jnp.float64, "jax")
    b = _forces(_bed(3, jnp.float64, "cpu")[0], st)
    c = _forces(_bed(3, jnp.float64, "cpu", rolling=False)[0], st)
    assert np.max(np.abs(np.asarray(b[1] - c[1]))) > 1e-2 * np.max(np.abs(np.asarray(b[1])))
    a = _forces(_bed(3, jnp.float64, "jax", rotation=False)[0], st)
    d = _forces(_bed(3, jnp.float64, "cpu", rotation=False)[0], st)
    assert not np.any(np.asarray(a[1])) and not np.any(np.asarray(d[1]))
    _close(a[0], d[0], REL[jnp.float64], "force without rotation")


def _run_both(dim, dtype, steps):
    """The calm bed poured for 5000 steps (C++ kernel, the faster), then ``steps`` more steps
    with each kernel."""
    jdem, st = _bed(dim, dtype, "jax", "projected", 0.05, calm=True)
    cdem, _ = _bed(dim, dtype, "cpu", "projected", 0.05, calm=True)
    st = cdem.run(st, 5000, chunk=5000)
    a = jdem.run(st, steps, chunk=steps)
    b = cdem.run(st, steps, chunk=steps)
    assert b.nbrs.order is not None and a.nbrs.order is None  # the C++ loop's lists: cell order
    b = jdem.adopt(b)  # its pairs in canonical order, the springs with them: slot for slot
    assert int(a.n_rebuilds) > int(st.n_rebuilds)  # history carried through neighbour rebuilds
    # touching pairs and wall contacts: those with a spring (zero where nothing touches)
    assert int(jnp.sum(jnp.any(a.pair_spring != 0, -1))) > (50 if dim == 2 else 200)  # a bed
    assert int(jnp.sum(jnp.any(a.wall_spring != 0, -1))) > 10
    assert np.max(np.linalg.norm(np.asarray(a.velocity), axis=1)) > 0.05  # that moves
    return jdem, st, a, b


@needs_kernel
@pytest.mark.parametrize("dim", [2, 3])
def test_moving_bed_over_300_steps_equals_the_jax_kernel(dim):
    """300 steps (float64) of the bed between the rotating walls with conduction (gap tolerance
    0.05): positions, velocities, spins, forces, springs and temperatures."""
    jdem, st, a, b = _run_both(dim, jnp.float64, 300)
    assert float(jnp.max(jnp.abs(a.position - b.position))) < 1e-9 * R_P
    for f in ("velocity", "angular_velocity", "force", "torque", "pair_spring", "wall_spring"):
        _close(getattr(a, f), getattr(b, f), 1e-7, f)
    _close(a.extra - st.extra, b.extra - st.extra, 1e-9, "temperature change")
    cap = np.asarray(jdem.conduction.heat_capacity)
    assert abs(np.sum(cap * np.asarray(b.extra - st.extra))) < 1e-12 * np.sum(cap * st.extra)


@needs_kernel
@pytest.mark.slow
@pytest.mark.parametrize("dim", [2, 3])
def test_moving_bed_over_300_steps_float32(dim):
    """The same in float32, where the kernels' round-off differences grow faster."""
    jdem, st, a, b = _run_both(dim, jnp.float32, 300)
    assert float(jnp.max(jnp.abs(a.position - b.position))) < 1e-4 * R_P
    _close(a.velocity, b.velocity, 1e-2, "velocity")
    _close(a.extra - st.extra, b.extra - st.extra, 1e-3, "temperature change")


@needs_kernel
def test_threaded_kernel_equals_one_thread(monkeypatch):
    # chunks accumulate in their own buffers, summed in chunk order: the thread count changes
    # the force sums by round-off only
    cs = _bed(3, jnp.float32, "jax", "overlap", 0.05)[1]
    cdem = _bed(3, jnp.float32, "cpu", "overlap", 0.05)[0]
    monkeypatch.setenv("DRUMHEAT_KERNEL_THREADS", "1")
    a = _forces(cdem, cs)
    monkeypatch.setenv("DRUMHEAT_KERNEL_THREADS", "3")
    b = _forces(cdem, cs)
    np.testing.assert_array_equal(np.asarray(a[4].pair_mask), np.asarray(b[4].pair_mask))
    np.testing.assert_array_equal(np.asarray(a[2]), np.asarray(b[2]))  # springs bit for bit
    np.testing.assert_array_equal(np.asarray(a[3]), np.asarray(b[3]))
    _close(a[0], b[0], 1e-5, "force")
    _close(a[1], b[1], 1e-5, "torque")
    _close(a[6], b[6], 1e-9, "heat flow")


@needs_kernel
@pytest.mark.parametrize("dim,dtype,shuffle", [(3, jnp.float64, False), (2, jnp.float32, True)])
def test_the_body_force_is_added_last(monkeypatch, dim, dtype, shuffle):
    """The loop adds the body force (gravity, one row for all particles or one per particle)
    to each particle's sum of contact forces last: the forces are the loop's without it plus
    the body force, bit for bit, in one chunk and in three, in the particles' own numbering and
    in the cell order; nothing else changes."""
    st = _bed(dim, dtype, "jax", "overlap", 0.05, shuffle=shuffle)[1]
    cdem = _bed(dim, dtype, "cpu", "overlap", 0.05, shuffle=shuffle)[0]
    f = cdem._forces.__wrapped__.func  # the CpuContactForces of the DEM
    n = st.position.shape[0]
    if shuffle:  # the cell order (test_the_cell_order)
        st = _in_cell_order(st, cdem)
    geometry = f.wall_geometry(st.position, st.time)
    rows = jnp.asarray(np.random.default_rng(5).normal(0.0, 1e-3, (n, dim)), dtype)

    def call(body):
        return cpu_kernel.contacts(
            st.position, st.velocity, st.angular_velocity, *f._kernel_particles, st.nbrs.idx,
            st.pair_spring, *geometry, st.wall_spring, **f._kernel_params,
            temperature=st.extra, conduction_law="overlap", conduction_h=2.0,
            gap_tolerance=0.05, pair_gap=0.05, order=st.nbrs.order, body_force=body)

    assert f._body_force.shape == (n, dim)  # gravity of two materials: a row per particle
    for threads in ("1", "3"):
        monkeypatch.setenv("DRUMHEAT_KERNEL_THREADS", threads)
        plain = call(None)
        for body in (f._body_force, rows[:1], rows):
            out = call(body)
            np.testing.assert_array_equal(np.asarray(out[0]),
                                          np.asarray(plain[0] + body))  # as JAX adds it
            for x, y in zip(out[1:], plain[1:]):
                np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@needs_kernel
@pytest.mark.parametrize("dim,dtype,shuffle", [(3, jnp.float64, False), (2, jnp.float32, True),
                                               (3, jnp.float32, True), (2, jnp.float64, False)])
def test_the_drum_shells_geometry_in_the_call(dim, dtype, shuffle):
    """With a drum shell as the first wall (``CpuContactForces.shell``) the C++ loop computes
    the shell's distance, normal and velocity at the particles itself: every output of the
    jitted step's forces (forces, torques, springs, overlaps, heat, the wall slots' conduction
    flags) is that of the call given XLA's geometry of all walls, bit for bit (the loop takes
    XLA's roundings of DrumShell.evaluate, contact_kernel.cc), beside an inner cylinder whose
    geometry XLA gives, without and with a wall gap tolerance; the flags are wall_gap_mask's."""
    for gap in (None, (0.05, 0.1)):
        st = _bed(dim, dtype, "jax", "overlap", 0.05, shuffle=shuffle, conduction_gap=gap)[1]
        f = _bed(dim, dtype, "cpu", "overlap", 0.05, shuffle=shuffle,
                 conduction_gap=gap)[0]._forces.__wrapped__.func
        assert f.shell == (0.03, 2 * np.pi * 30.0 / 60.0)

        @jax.jit
        def call(s):
            return f(s.position, s.velocity, s.angular_velocity, s.time, s.nbrs, s.pair_spring,
                     s.wall_spring, temperature=s.extra)

        looped = call(st)
        f.shell = None  # the instance's: XLA's geometry for every wall
        given = call(st)
        wd = jax.jit(f.wall_geometry)(st.position, st.time)[0]
        del f.shell
        for x, y in zip(jax.tree_util.tree_leaves(looped), jax.tree_util.tree_leaves(given)):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
        c = looped.contacts
        np.testing.assert_array_equal(np.asarray(c.wall_conducts),
                                      np.asarray(f.wall_gap_mask(wd, c.wall_mask)))
        touching = np.asarray(c.wall_mask).reshape(-1, 2)
        assert touching[:, 0].sum() >= 5 and touching[:, 1].sum() >= 1  # both walls pressed
        conducting = int(np.sum(np.asarray(c.wall_conducts)))
        assert (conducting > touching.sum()) == (gap is not None)  # gaps within the tolerance


@needs_kernel
@pytest.mark.parametrize("dim,dtype,shuffle", [(3, jnp.float64, False), (2, jnp.float32, True)])
def test_the_coming_steps_skin_test_in_the_call(monkeypatch, dim, dtype, shuffle):
    """For particles of one mass the C++ loop also makes the skin test of the integrator's
    coming step (``ahead``): the largest squared displacement from the list's reference
    positions after the coming step's two half-kicks and drift, from the call's own forces.
    It equals XLA's loop condition, the same kicks, drift and ``max_displacement_sq`` in JAX,
    to an ulp (XLA's generated code may fuse the squares' sum into multiply-adds, the loop
    does not; the kicks, the drift and the displacements themselves are the same bits), in
    one chunk and in three, in the particles' own numbering and in the cell order; asking for
    it changes no other output; a class that cannot make it refuses."""
    import dataclasses

    from drumheat.mechanics.integrator import wrap_periodic_axis

    st = _bed(dim, dtype, "jax", "overlap", 0.05, shuffle=shuffle, one_material=True)[1]
    jdem = _bed(dim, dtype, "jax", "overlap", 0.05, shuffle=shuffle, one_material=True)[0]
    cdem = _bed(dim, dtype, "cpu", "overlap", 0.05, shuffle=shuffle, one_material=True)[0]
    f, nb, n = cdem._forces.__wrapped__.func, cdem.neighbor, st.position.shape[0]
    assert f.looks_ahead and not jdem._forces.__wrapped__.func.looks_ahead
    if shuffle:  # the cell order
        st = _in_cell_order(st, cdem)
    # the reference positions a few half-skins behind, so that the test has a spread to find
    rng = np.random.default_rng(7)
    ref = st.nbrs.reference_position + jnp.asarray(rng.normal(0.0, 0.3 * nb.skin, (n, dim)), dtype)
    st = st._replace(nbrs=dataclasses.replace(st.nbrs, reference_position=ref))
    dt = cdem.dt
    L = cdem.neighbor.periodic_length
    inv_m = 1.0 / cpu_kernel.shared_value(f.mass)
    consts = cpu_kernel.skin_test_constants(dt, inv_m, L, nb.lo, dtype)

    @jax.jit
    def xla_test(x, v, force, nbrs):  # the loop's condition (integrator.run_segments)
        half = 0.5 * dt
        v = v + half * force * inv_m
        v = v + half * force * inv_m
        return nb.max_displacement_sq(wrap_periodic_axis(x + dt * v, L, near=True), nbrs)

    call = jax.jit(lambda s, ahead: f(s.position, s.velocity, s.angular_velocity, s.time,
                                      s.nbrs, s.pair_spring, s.wall_spring,
                                      temperature=s.extra, ahead=ahead))
    for threads in ("1", "3"):
        monkeypatch.setenv("DRUMHEAT_KERNEL_THREADS", threads)
        plain, looked = call(st, None), call(st, consts)
        assert plain.ahead is None
        moved = float(looked.ahead)
        np.testing.assert_allclose(
            moved, float(xla_test(st.position, st.velocity, looked.force, st.nbrs)),
            rtol=2 * float(jnp.finfo(dtype).eps), atol=0)
        assert moved > (0.5 * nb.skin) ** 2  # a particle past the skin: the test finds it
        for x, y in zip(jax.tree_util.tree_leaves(plain), jax.tree_util.tree_leaves(looked[:8])):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    with pytest.raises(ValueError, match="no skin test"):
        jdem._forces.__wrapped__.func(st.position, st.velocity, st.angular_velocity, st.time,
                                      st.nbrs, st.pair_spring, st.wall_spring, ahead=consts)


@needs_kernel
@pytest.mark.parametrize("dim,dtype,shuffle", [(3, jnp.float64, False), (2, jnp.float32, True),
                                               (3, jnp.float32, True), (2, jnp.float64, False)])
def test_the_steps_kicks_and_drift_in_the_call(dim, dtype, shuffle):
    """For particles of one mass and moment of inertia in a drum shell alone
    (``CpuContactForces.drifts``) the C++ loop makes the step's two half-kicks and drift itself
    (``drift``): given the step before's positions, velocities and spins (its last half-kick
    pending, or not: ``aux`` 1 or 0) and its forces and torques, the call's outputs and the
    drifted state equal XLA's kicks and drift (integrator.run_segments' arithmetic, jitted)
    followed by the call at their result, bit for bit, in the particles' own numbering and in
    the cell order; a kernel or a bed that cannot make them refuses."""
    from drumheat.mechanics.integrator import wrap_periodic_axis

    kw = dict(shuffle=shuffle, one_material=True, shell_only=True)
    st = _bed(dim, dtype, "jax", "overlap", 0.05, **kw)[1]
    cdem = _bed(dim, dtype, "cpu", "overlap", 0.05, **kw)[0]
    f, n = cdem._forces.__wrapped__.func, st.position.shape[0]
    assert f.drifts
    if shuffle:  # the cell order
        st = _in_cell_order(st, cdem)
    rng = np.random.default_rng(3)
    st = st._replace(force=jnp.asarray(rng.normal(0.0, 0.05, st.force.shape), dtype),
                     torque=jnp.asarray(rng.normal(0.0, 1e-5, st.torque.shape), dtype))
    dt, L = cdem.dt, cdem.neighbor.periodic_length
    half = 0.5 * dt
    inv_m = 1.0 / cpu_kernel.shared_value(f.mass)
    inv_i = 1.0 / cpu_kernel.shared_value(f.inertia)

    def forces(s, x, v, w, drift=None):
        return f(x, v, w, s.time + dt, s.nbrs, s.pair_spring, s.wall_spring,
                 temperature=s.extra, drift=drift)

    @jax.jit
    def in_xla(s, aux):  # run_segments' kicked(st, aux), drift(...), then the call
        v = s.velocity + half * (aux * s.force) * inv_m
        w = s.angular_velocity + half * (aux * s.torque) * inv_i
        v = v + half * s.force * inv_m
        w = w + half * s.torque * inv_i
        x = wrap_periodic_axis(s.position + dt * v, L, near=True)
        return forces(s, x, v, w), (x, v, w)

    @jax.jit
    def in_call(s, aux):
        consts = cpu_kernel.drift_constants(aux, dt, inv_m, inv_i, L, dtype)
        res = forces(s, s.position, s.velocity, s.angular_velocity, (consts, s.force, s.torque))
        return res._replace(drifted=None), res.drifted

    for aux in (0.0, 1.0):
        a = jnp.asarray(aux, dtype)
        (want, drifted), (got, made) = in_xla(st, a), in_call(st, a)
        for x, y in zip(jax.tree_util.tree_leaves((want, drifted)),
                        jax.tree_util.tree_leaves((got, made))):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
        assert int(np.sum(np.asarray(got.contacts.wall_mask))) >= 5  # the shell carries the bed
    consts = cpu_kernel.drift_constants(1.0, dt, inv_m, inv_i, L, dtype)
    two = _bed(dim, dtype, "cpu", "overlap", 0.05, one_material=True)[0]._forces.__wrapped__.func
    jax_f = _bed(dim, dtype, "jax", "overlap", 0.05, **kw)[0]._forces.__wrapped__.func
    assert not two.drifts and not jax_f.drifts  # the inner cylinder's geometry is XLA's
    for g in (two, jax_f):
        with pytest.raises(ValueError, match="no kicks and drift"):
            g(st.position, st.velocity, st.angular_velocity, st.time, st.nbrs, st.pair_spring,
              st.wall_spring, drift=(consts, st.force, st.torque))


@needs_kernel
@pytest.mark.parametrize("dim,dtype,shuffle", [(3, jnp.float64, True), (2, jnp.float32, True),
                                               (3, jnp.float32, False)])
def test_a_run_of_steps_in_the_call_is_its_steps_one_by_one(monkeypatch, dim, dtype, shuffle):
    """A run of steps in one call (``steps``; the coming step's kicks, drift and records made
    in the pass that sums the step's forces) gives what its steps give called one by one, each
    from the outputs of the one before (the first with its half-kick pending or not, the
    later ones with it pending), bit for bit: forces, torques, pair and wall springs, the
    drifted state, the heat flows, the largest overlap of all steps and each slot's count of
    the steps it conducted; in the particles' own numbering and in the cell order, in one
    chunk and in three; a run whose skin test fails ends after the step that failed it, as
    the steps called one by one tell."""
    import dataclasses

    kw = dict(shuffle=shuffle, one_material=True, shell_only=True)
    st = _bed(dim, dtype, "jax", "overlap", 0.05, **kw)[1]
    cdem = _bed(dim, dtype, "cpu", "overlap", 0.05, **kw)[0]
    f, nb, n = cdem._forces.__wrapped__.func, cdem.neighbor, st.position.shape[0]
    assert f.drifts
    if shuffle:  # the cell order
        st = _in_cell_order(st, cdem)
        assert not np.array_equal(np.asarray(st.nbrs.order), np.arange(n))
    # the reference positions some way behind, so that the skin test's displacements grow
    rng = np.random.default_rng(5)
    ref = st.nbrs.reference_position + jnp.asarray(rng.normal(0.0, 0.2 * nb.skin, (n, dim)), dtype)
    st = st._replace(nbrs=dataclasses.replace(st.nbrs, reference_position=ref),
                     force=jnp.asarray(rng.normal(0.0, 0.05, st.force.shape), dtype),
                     torque=jnp.asarray(rng.normal(0.0, 1e-5, st.torque.shape), dtype))
    dt, L = cdem.dt, nb.periodic_length
    inv_m = 1.0 / cpu_kernel.shared_value(f.mass)
    inv_i = 1.0 / cpu_kernel.shared_value(f.inertia)
    ahead = cpu_kernel.skin_test_constants(dt, inv_m, L, nb.lo, dtype)

    @jax.jit
    def call(x, v, w, force, torque, ps, ws, aux, steps=None):
        drift = (cpu_kernel.drift_constants(aux, dt, inv_m, inv_i, L, dtype), force, torque)
        return f(x, v, w, st.time + dt, st.nbrs, ps, ws, temperature=st.extra, ahead=ahead,
                 drift=drift, steps=steps)

    def one_by_one(k):
        """k steps called one by one: the last result, its drifted state, the largest
        overlap, the counts and each step's skin test"""
        x, v, w, F, M, ps, ws = (st.position, st.velocity, st.angular_velocity, st.force,
                                 st.torque, st.pair_spring, st.wall_spring)
        pc = wc = 0
        most, tests = -np.inf, []
        for s in range(k):
            r = call(x, v, w, F, M, ps, ws, jnp.asarray(0.0 if s == 0 else 1.0, dtype))
            x, v, w = r.drifted
            F, M, ps, ws = r.force, r.torque, r.pair_spring, r.wall_spring
            pc = pc + np.asarray(r.contacts.pair_conducts, np.int32)
            wc = wc + np.asarray(r.contacts.wall_conducts, np.int32)
            most = max(most, float(r.max_overlap))
            tests.append(float(r.ahead))
        return r, most, (pc, wc), np.array(tests)

    K = 12
    for threads in ("1", "3"):
        monkeypatch.setenv("DRUMHEAT_KERNEL_THREADS", threads)
        want, most, counts, tests = one_by_one(K)
        # the whole run (the test always passes), and one that the skin test ends: half the
        # skin squared the largest displacement of the first six steps
        h = tests[:6].max()
        stop = 1 + 6 + int(np.argmax(tests[6:] > h))
        assert tests[stop - 1] > h and stop < K  # the displacements grow: the run is ended
        for half_skin2, made in ((np.inf, K), (h, stop)):
            got = call(st.position, st.velocity, st.angular_velocity, st.force, st.torque,
                       st.pair_spring, st.wall_spring, jnp.asarray(0.0, dtype),
                       steps=jnp.asarray([K, min(half_skin2, 1e30)], dtype))
            assert int(got.counted[2][0]) == made
            if made < K:
                want, most, counts, _ = one_by_one(made)
            for x, y in zip(jax.tree_util.tree_leaves((want.force, want.torque, want.pair_spring,
                                                       want.wall_spring, want.drifted, want.heat,
                                                       want.ahead)),
                            jax.tree_util.tree_leaves((got.force, got.torque, got.pair_spring,
                                                       got.wall_spring, got.drifted, got.heat,
                                                       got.ahead))):
                np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
            assert float(got.max_overlap) == most
            np.testing.assert_array_equal(np.asarray(got.counted[0]), counts[0])
            np.testing.assert_array_equal(np.asarray(got.counted[1]), counts[1])
            assert counts[0].max() > 0 and counts[1].max() > 0


@needs_kernel
@pytest.mark.parametrize("dim,dtype,switch", [(2, jnp.float64, "looks_ahead"),
                                              (3, jnp.float64, "looks_ahead"),
                                              (2, jnp.float64, "drifts"),
                                              (3, jnp.float32, "drifts")])
def test_the_loop_with_the_steps_work_in_the_call(monkeypatch, dim, dtype, switch):
    """The integrator's loop between rebuilds with the C++ call doing part of the step's work
    gives the run of the loop that does it in XLA bit for bit, through several neighbour
    rebuilds, and of the step called one by one: ``looks_ahead``, the coming step's skin test
    (particles of one mass), and ``drifts``, the step's kicks and drift too (one mass and moment
    of inertia, the drum shell alone)."""
    from drumheat.mechanics import forces as forces_mod

    def run(on, steps=400):
        init = forces_mod.CpuContactForces.__init__

        def patched(self, *a, **kw):
            init(self, *a, **kw)
            setattr(self, switch, getattr(self, switch) and on)

        monkeypatch.setattr(forces_mod.CpuContactForces, "__init__", patched)
        kw = dict(calm=True, one_material=True, shell_only=switch == "drifts")
        _, st = _bed(dim, dtype, "jax", "projected", 0.05, **kw)
        dem = _bed(dim, dtype, "cpu", "projected", 0.05, **kw)[0]
        f = dem._forces.__wrapped__.func
        assert getattr(f, switch) == on and f.looks_ahead == (on or switch == "drifts")
        return dem, st, dem.run_steps(st, steps)

    dem, st, a = run(True)
    b = run(False)[2]
    assert int(a.n_rebuilds) - int(st.n_rebuilds) >= 3
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    c = dem.adopt(st)
    for _ in range(400):
        c = dem.step(c)[0]
    for field in ("position", "velocity", "angular_velocity", "pair_spring", "n_rebuilds"):
        np.testing.assert_array_equal(np.asarray(getattr(a, field)), np.asarray(getattr(c, field)))


@needs_kernel
def test_the_loop_with_the_kicks_and_drift_without_walls(monkeypatch):
    """Without walls (a periodic box, no gravity: the loop's geometry has nothing to evaluate)
    the call makes the kicks and drift too, and the loop gives the run of the loop that makes
    them in XLA bit for bit, through many rebuilds (a thin skin)."""
    from drumheat.mechanics import forces as forces_mod

    rng = np.random.default_rng(0)
    a = 2.1 * R_P
    g = (np.arange(6) + 0.5) * a
    pts = np.stack([x.ravel() for x in np.meshgrid(g, g, g, indexing="ij")], 1)
    pts += rng.uniform(-0.05, 0.05, pts.shape) * a
    part = make_particles(np.full(len(pts), R_P), np.full(len(pts), 2500.0))
    params = contact_params(1e5, kt=0.9e5, damping_ratio=0.3, tangential_damping_ratio=0.25,
                            friction=0.5, rolling_friction=0.05)
    vel = jnp.asarray(rng.normal(0.0, 0.3, pts.shape))

    def run(drifts):
        init = forces_mod.CpuContactForces.__init__

        def patched(self, *args, **kw):
            init(self, *args, **kw)
            self.drifts = self.drifts and drifts

        monkeypatch.setattr(forces_mod.CpuContactForces, "__init__", patched)
        dem = make_dem(part, [], params, dim=3, dt=1e-5, skin=0.25 * R_P, pair_kernel="cpu",
                       bounds=(np.zeros(3), np.full(3, 6 * a)), periodic_length=6 * a,
                       gravity=np.zeros(3))
        assert dem._forces.__wrapped__.func.drifts == drifts
        st = dem.init(jnp.asarray(pts))._replace(velocity=vel)
        return st, dem.run_steps(st, 400)

    st, a_ = run(True)
    b_ = run(False)[1]
    assert int(a_.n_rebuilds) - int(st.n_rebuilds) >= 10
    for x, y in zip(jax.tree_util.tree_leaves(a_), jax.tree_util.tree_leaves(b_)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@needs_kernel
def test_any_order_of_the_pair_slots(monkeypatch):
    """The loop takes the pairs in any order: a list not sorted by the first particle, its
    padding slots spread among the pairs (the scan finds them one by one instead of at the
    list's end), gives each slot the same outputs as the sorted list, bit for bit, and the same
    forces and heat flows to round-off (the sums run in another order); also in three chunks."""
    import dataclasses

    st = _bed(3, jnp.float64, "jax", "overlap", 0.05)[1]
    cdem = _bed(3, jnp.float64, "cpu", "overlap", 0.05)[0]
    perm = np.random.default_rng(3).permutation(st.nbrs.idx.shape[1])
    assert np.any(np.diff(np.asarray(st.nbrs.idx[0])[perm]) < 0)  # not sorted by i
    shuffled = st._replace(nbrs=dataclasses.replace(st.nbrs, idx=st.nbrs.idx[:, perm]),
                           pair_spring=st.pair_spring[perm])
    for threads in ("1", "3"):
        monkeypatch.setenv("DRUMHEAT_KERNEL_THREADS", threads)
        a, b = _forces(cdem, st), _forces(cdem, shuffled)
        np.testing.assert_array_equal(np.asarray(a[2])[perm], np.asarray(b[2]))  # springs
        for f in ("pair_mask", "pair_overlap", "pair_distance", "pair_normal_force",
                  "pair_conducts"):
            np.testing.assert_array_equal(np.asarray(getattr(a[4], f))[perm],
                                          np.asarray(getattr(b[4], f)), f)
        np.testing.assert_array_equal(np.asarray(a[3]), np.asarray(b[3]))  # wall springs
        _close(a[0], b[0], REL[jnp.float64], "force")
        _close(a[1], b[1], REL[jnp.float64], "torque")
        _close(a[6], b[6], REL[jnp.float64], "heat flow")


@needs_kernel
@pytest.mark.parametrize("dim,dtype", [(3, jnp.float64), (2, jnp.float32)])
def test_the_cell_order(monkeypatch, dim, dtype):
    """The C++ loop's lists are in the cell order (``NeighborList.order``; the pairs grouped by
    their first particle in it) and the loop lays the particles' data out in that order. Given
    the same list without the order (the particles' own numbering), every output is the same
    bit for bit in one chunk (each sum takes the same terms in the same order) and to round-off
    in three; against the canonical list of the same pairs the per-pair outputs are the same
    pair for pair and the sums agree to round-off. An order that is not a permutation is
    refused."""
    import dataclasses

    # numbered along the lattice, the numbering will do (canonical list, order 0 .. N-1)
    st = _bed(dim, dtype, "jax", "overlap", 0.05)[1]
    cs = _bed(dim, dtype, "cpu", "overlap", 0.05)[0].adopt(st)
    np.testing.assert_array_equal(np.asarray(cs.nbrs.order), np.arange(st.position.shape[0]))
    np.testing.assert_array_equal(np.asarray(cs.nbrs.idx), np.asarray(st.nbrs.idx))
    # numbered at random: the same pairs and springs in the cell order (which a bed this small,
    # whose data all fit in the cache, does not get from layout_order: made here)
    jdem, st = _bed(dim, dtype, "jax", "overlap", 0.05, shuffle=True)
    cdem = _bed(dim, dtype, "cpu", "overlap", 0.05, shuffle=True)[0]
    n = st.position.shape[0]
    cs = _in_cell_order(st, cdem)
    assert st.nbrs.order is None
    order = np.asarray(cs.nbrs.order)
    assert not np.array_equal(order, np.arange(n))  # the bed's numbering is not its cells
    rank = np.empty(n, int)
    rank[order] = np.arange(n)
    i = np.asarray(cs.nbrs.idx[0])
    assert np.all(np.diff(np.where(i < n, rank[np.minimum(i, n - 1)], n)) >= 0)  # grouped
    plain = cs._replace(nbrs=dataclasses.replace(cs.nbrs, order=None))
    ref = _forces(cdem, st)
    for threads in ("1", "3"):
        monkeypatch.setenv("DRUMHEAT_KERNEL_THREADS", threads)
        a, b = _forces(cdem, cs), _forces(cdem, plain)
        sums = (0, 1, 6) if threads == "3" else ()  # force, torque, heat: round-off in chunks
        for k in sums:
            _close(a[k], b[k], REL[jnp.float64 if k == 6 else dtype], "sums in three chunks")
        rest = lambda r: [x for k, x in enumerate(r) if k not in sums]  # noqa: E731
        for x, y in zip(jax.tree_util.tree_leaves(rest(a)), jax.tree_util.tree_leaves(rest(b))):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
        # against the canonical list: the same pairs' springs and overlaps, pair for pair
        back = jdem.adopt(cs._replace(pair_spring=a[2]))
        np.testing.assert_array_equal(np.asarray(back.nbrs.idx), np.asarray(st.nbrs.idx))
        np.testing.assert_array_equal(np.asarray(back.pair_spring), np.asarray(ref[2]))
        np.testing.assert_array_equal(np.asarray(a[3]), np.asarray(ref[3]))  # wall springs
        _close(a[0], ref[0], REL[dtype], "force")
        _close(a[1], ref[1], REL[dtype], "torque")
        _close(a[6], ref[6], REL[jnp.float64], "heat flow")
    bad = order.copy()
    bad[0] = bad[1]
    with pytest.raises(Exception, match="not a permutation"):
        bad_state = cs._replace(nbrs=dataclasses.replace(cs.nbrs, order=jnp.asarray(bad)))
        jax.block_until_ready(_forces(cdem, bad_state))


def test_gap_tolerance_of_the_jax_heat_flow():
    """Three spheres in a row: 0-1 overlap, 1-2 have a gap of 3 % of d, 0-2 are far apart.
    With tolerance 0 only 0-1 conducts; with 0.05 also 1-2 ("projected"); the "overlap" law
    has no contact circle across a gap."""
    r = 0.001
    i, j = jnp.array([0, 1, 0, 3]), jnp.array([1, 2, 2, 3])  # the last one padding (N = 3)
    dist = jnp.array([1.99 * r, 2.06 * r, 4.05 * r, 0.0])
    touching = dist < 2 * r
    contacts = Contacts(i, j, touching & (i < 3), None, jnp.where(touching, dist, 0.0), None,
                        *[None] * 8)
    T = jnp.asarray([300.0, 320.0, 350.0])
    radius = jnp.full(3, r)

    def flows(law, tol):
        return np.asarray(heat_flow(T, contacts, radius, law, 10.0, tol, dist))

    g = 10.0 * np.pi * r * r
    np.testing.assert_allclose(flows("projected", 0.0), [20 * g, -20 * g, 0.0], rtol=1e-12)
    np.testing.assert_allclose(flows("projected", 0.05), [20 * g, 10 * g, -30 * g], rtol=1e-12)
    np.testing.assert_allclose(flows("projected", 0.02), flows("projected", 0.0), rtol=1e-12)
    np.testing.assert_allclose(flows("overlap", 0.05), flows("overlap", 0.0), rtol=1e-12)
    assert flows("overlap", 0.0)[0] > 0
    with pytest.raises(ValueError, match="gap tolerance"):
        PairConduction("projected", 1.0, 1.0, -0.1).checked(3)
    with pytest.raises(ValueError, match="distances"):
        heat_flow(T, contacts, radius, "projected", 1.0, 0.1)


@needs_kernel
def test_cpu_kernel_refuses_what_it_does_not_cover():
    part = make_particles(np.full(4, 0.002), 2500.0)
    params = contact_params(1e5, damping_ratio=0.3)
    with pytest.raises(ValueError, match="vmap"):
        make_dem(part, [DrumShell(0.05)], params, dim=2, pair_kernel="cpu", batch_axis="b")
    with pytest.raises(ValueError, match="float16"):
        make_dem(part, [DrumShell(0.05)], params, dim=2, dtype=jnp.float16, pair_kernel="cpu")
    with pytest.raises(ValueError, match="pair_kernel"):
        make_dem(part, [DrumShell(0.05)], params, dim=3, periodic_length=0.03,
                 pair_kernel="fast")


# ---- build and fallback ------------------------------------------------------------------------


@pytest.fixture
def fresh_kernel_state(monkeypatch, tmp_path):
    """cpu_kernel as if in a new process, with an empty kernel cache (restored afterwards)."""
    monkeypatch.setattr(cpu_kernel, "_STATE", None)
    monkeypatch.setattr(cpu_kernel, "_REGISTERED", None)
    monkeypatch.setenv("DRUMHEAT_CACHE_DIR", str(tmp_path))
    return tmp_path


def test_no_compiler_gives_a_clear_reason_and_raises_nothing(fresh_kernel_state, monkeypatch,
                                                             tmp_path):
    empty = tmp_path / "bin"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty))
    monkeypatch.delenv("CXX", raising=False)
    ok, why = cpu_kernel.available()
    assert not ok
    assert why.startswith("no C++ compiler found") and "g++" in why and "\n" not in why
    assert cpu_kernel.available() == (ok, why)  # kept: the second call costs nothing
    monkeypatch.setattr(cpu_kernel, "_STATE", None)
    monkeypatch.setenv("CXX", "no-such-compiler-xyz")
    ok, why = cpu_kernel.available()
    assert not ok and "no-such-compiler-xyz" in why and "not on the PATH" in why
    # make_dem names the reason; ok as long as nothing else in the configuration is wrong
    part = make_particles(np.full(4, 0.002), 2500.0)
    with pytest.raises(ValueError, match="no-such-compiler-xyz.*Use pair_kernel='jax'"):
        make_dem(part, [DrumShell(0.05)], contact_params(1e5), dim=2, pair_kernel="cpu")
    with pytest.raises(RuntimeError, match="not available: the C\\+\\+ compiler"):
        cpu_kernel.load()


def test_failing_compiler_gives_a_clear_reason_and_raises_nothing(fresh_kernel_state,
                                                                  monkeypatch, tmp_path):
    fake = tmp_path / "bad-cxx"
    fake.write_text("#!/bin/sh\necho 'contact_kernel.cc:1:1: error: simulated failure' >&2\n"
                    "exit 3\n")
    fake.chmod(0o755)
    monkeypatch.setenv("CXX", str(fake))
    ok, why = cpu_kernel.available()
    assert not ok
    assert "failed (exit 3: contact_kernel.cc:1:1: error: simulated failure" in why
    log = cpu_kernel._library_path().with_suffix(".log")
    assert str(log) in why and "simulated failure" in log.read_text()
    assert not list(tmp_path.glob("kernels/*.so")) and not list(tmp_path.glob("kernels/*.tmp"))


@needs_kernel
def test_a_cached_kernel_needs_no_compiler(monkeypatch, tmp_path):
    """A kernel built once serves later processes without a compiler (the cache is keyed by
    the source, flags and jaxlib); simulated here by copying the built library."""
    import shutil

    built = cpu_kernel._library_path()
    monkeypatch.setattr(cpu_kernel, "_STATE", None)
    monkeypatch.setattr(cpu_kernel, "_REGISTERED", None)
    monkeypatch.setenv("DRUMHEAT_CACHE_DIR", str(tmp_path))
    (tmp_path / "kernels").mkdir()
    shutil.copy(built, cpu_kernel._library_path())
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.delenv("CXX", raising=False)
    monkeypatch.setattr(jax.ffi, "register_ffi_target", lambda *a, **k: None)  # once/process
    assert cpu_kernel.available() == (True, "")


@pytest.mark.slow
def test_two_processes_build_the_kernel_once(tmp_path):
    """Two processes that need the kernel at once with an empty cache: one compiles under the
    file lock, the other waits and loads the same library."""
    code = textwrap.dedent("""
        from drumheat.mechanics import cpu_kernel
        print(cpu_kernel.available())
    """)
    env = dict(os.environ, DRUMHEAT_CACHE_DIR=str(tmp_path), JAX_PLATFORMS="cpu")
    procs = [subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=900) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode == 0, err
        assert out.strip() == "(True, '')", (out, err)
    assert len(list((tmp_path / "kernels").glob("*.so"))) == 1
    logs = list((tmp_path / "kernels").glob("*.log"))
    assert len(logs) <= 1  # one compilation at most left its log


@needs_kernel
@pytest.mark.parametrize("substeps", [1, 7])
def test_runs_of_steps_in_the_call_give_the_coupled_run(monkeypatch, substeps):
    """With the coupled heat, whose hook only counts the conducting contacts between thermal
    steps (``CountingUpdate``), the loop between rebuilds makes its steps in runs inside one
    C++ call, up to the next thermal step, rebuild or the chunk's end; the run is that of the
    loop that returns to XLA after each step, bit for bit: positions, velocities, springs,
    temperatures, heat accounts, contact-time accumulators and counts, the recording's too,
    through neighbour rebuilds and thermal steps."""
    import drumheat.mechanics.integrator as integrator
    from drumheat.motion import make_motion
    from drumheat.motion.coupling import ThermalUpdate
    from drumheat.scene import load_scene, scene_from_dict
    from drumheat.scene.rules import dem_critical_time_step

    raw = load_scene("weigler-static").to_dict()
    raw["groups"][0]["count"] = raw["groups"][1]["count"] = 15
    raw["run"].update(duration=0.2, output_interval=0.05, solver="explicit")
    raw["drum"]["rpm"] = 12.0
    raw["motion"] = {"model": "dem"}
    raw["dem"] = {"stiffness": 2.0e4, "thermal_substeps": substeps, "contact_backend": "cpu"}
    raw["dem"]["dt"] = 0.2 * dem_critical_time_step(scene_from_dict(raw))
    raw["dem"]["record_interval"] = 0.01

    traced = []  # the runs of steps the loop traced (ThermalUpdate.counted)
    counted = ThermalUpdate.counted
    monkeypatch.setattr(ThermalUpdate, "counted",
                        lambda self, *a: traced.append(1) or counted(self, *a))

    def run(runs):
        if not runs:  # the hook no longer a CountingUpdate: one return to XLA per step
            monkeypatch.setattr(integrator, "CountingUpdate", type("Plain", (), {}))
        bed = make_motion(scene_from_dict(raw))
        assert bed.dem._forces.__wrapped__.func.drifts
        start = bed.initial_state()
        return start, bed.dem.run(start, 1500)

    start, a = run(True)
    assert traced
    traced.clear()
    b = run(False)[1]
    assert not traced
    assert int(a.n_rebuilds) - int(start.n_rebuilds) >= 2
    assert float(jnp.max(a.extra.T - start.extra.T)) > 0  # heat went in
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
