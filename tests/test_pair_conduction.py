"""Per-step contact conduction in the DEM loop (drumheat.mechanics.conduction) and the
segmented step loop of DEM.run_steps."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import drumheat  # noqa: F401
from drumheat.geometry import DrumShell
from drumheat.mechanics import contact_params, make_dem, make_particles
from drumheat.mechanics.conduction import PairConduction, pair_conductance
from drumheat.mechanics.integrator import wrap_periodic_axis

# the steps given here are above the tangential dashpots' limit on purpose (these tests are about
# heat and the run loop, not about the forces of sticking contacts)
pytestmark = pytest.mark.filterwarnings("ignore::drumheat.mechanics.DEMAccuracyWarning")


def _pair(law, h, r1=0.004, r2=0.003, overlap=1e-4, T=(300.0, 350.0)):
    """Two touching spheres at rest, no gravity, no walls, one step."""
    pos = np.array([[0.0, 0.0, 0.0], [r1 + r2 - overlap, 0.0, 0.0]])
    part = make_particles(np.array([r1, r2]), 2500.0)
    cap = np.asarray(part.mass) * 800.0
    params = contact_params(1e4, damping_ratio=0.3)
    dem = make_dem(part, [], params, dim=3, dt=1e-6, gravity=np.zeros(3),
                   bounds=(np.full(3, -0.02), np.full(3, 0.02)),
                   conduction=PairConduction(law, h, cap))
    st = dem.init(pos, extra=np.array(T))
    return dem, st, cap


def test_projected_law_is_weigler_2_7_on_the_smaller_sphere():
    # g = alpha_pp pi d_min^2 / 4 (weigler-thermal-dem.md eq. [2.7], A_p of the smaller one)
    alpha = 200.0
    # (a linear law: temperatures relative to 0 keep the tiny one-step change exact)
    dem, st, cap = _pair("projected", alpha, T=(0.0, 50.0))
    new, c = dem.step(st)
    g = alpha * math.pi * 0.006**2 / 4
    q = g * 50.0  # into particle 0
    T = np.asarray(new.extra)
    np.testing.assert_allclose(T[0], dem.dt * q / cap[0], rtol=1e-12)
    np.testing.assert_allclose(T[1] - 50.0, -dem.dt * q / cap[1], rtol=1e-6)


def test_overlap_law_uses_the_overlap_circle():
    # a^2 = r1^2 - ((L^2 + r1^2 - r2^2) / 2L)^2 (circle where two spheres intersect)
    r1, r2, ovl = 0.004, 0.003, 2e-4
    L = r1 + r2 - ovl
    a2 = r1**2 - ((L**2 + r1**2 - r2**2) / (2 * L)) ** 2
    g = float(pair_conductance("overlap", 2.0, r1, r2, L))
    np.testing.assert_allclose(g, 2.0 * math.sqrt(math.pi * a2), rtol=1e-12)
    assert float(pair_conductance("overlap", 2.0, r1, r2, r1 + r2 + 1e-6)) == 0.0


def test_conduction_conserves_heat_in_a_moving_bed():
    # a layer of spheres on a square lattice (gap 0.02 r) in the lower half of a turning drum
    r, R = 0.004, 0.05
    g = np.arange(-R, R, 2.02 * r)
    X, Y = np.meshgrid(g, g, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), np.full(X.size, 0.01)], 1)
    pts = pts[(np.hypot(pts[:, 0], pts[:, 1]) < R - 1.5 * r) & (pts[:, 1] < 0.01)]
    n = len(pts)
    part = make_particles(np.full(n, r), 2500.0)
    cap = np.asarray(part.mass) * 836.0
    params = contact_params(1e5, restitution=0.5, friction=0.5, wall_friction=0.5)
    dem = make_dem(part, [DrumShell(R, rpm=30.0)], params, dim=3, periodic_length=0.02,
                   dt=1e-5, conduction=PairConduction("projected", 5e4, cap))
    T0 = 300.0 + 50.0 * np.random.default_rng(1).uniform(size=n)
    st = dem.init(pts, extra=T0)
    out = dem.run(st, 3000, chunk=1000)
    T = np.asarray(out.extra)
    assert np.std(T) < 0.998 * np.std(T0)  # heat flowed from hot to cold (0.4 % here)
    e0, e1 = float(np.sum(cap * T0)), float(np.sum(cap * T))
    assert abs(e1 - e0) < 1e-12 * e0


def test_conduction_input_is_checked():
    part = make_particles(np.full(2, 0.004), 2500.0)
    params = contact_params(1e4, damping_ratio=0.3)
    kw = dict(dim=3, dt=1e-6, bounds=(np.full(3, -0.02), np.full(3, 0.02)))
    with pytest.raises(ValueError, match="law"):
        make_dem(part, [], params, conduction=PairConduction("radiation", 1.0, 1.0), **kw)
    with pytest.raises(ValueError, match="heat capacities"):
        make_dem(part, [], params, conduction=PairConduction("projected", 1.0, 0.0), **kw)
    dem = make_dem(part, [], params, conduction=PairConduction("projected", 1.0, 1.0), **kw)
    with pytest.raises(ValueError, match="temperatures"):
        dem.init(np.array([[0.0, 0, 0], [0.01, 0, 0]]))


def test_near_wrap_equals_mod_within_one_period_either_side():
    L = 0.26
    z = jnp.asarray(np.random.default_rng(0).uniform(-L, 2 * L, (5000, 3)), jnp.float32)
    np.testing.assert_array_equal(np.asarray(wrap_periodic_axis(z, L, near=True)),
                                  np.asarray(wrap_periodic_axis(z, L)))


def test_segmented_run_steps_equals_stepping_one_by_one():
    # DEM.run_steps runs the steps between neighbour rebuilds without a per-step cond; the
    # trajectory and the rebuild count must be those of DEM.step bit for bit
    r, R = 0.004, 0.05
    g = np.arange(-R, R, 2.3 * r)
    X, Y = np.meshgrid(g, g, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), np.full(X.size, 0.01)], 1)
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) < R - 1.5 * r]
    part = make_particles(np.full(len(pts), r), 2500.0)
    params = contact_params(1e5, restitution=0.5, friction=0.5, wall_friction=0.5)
    dem = make_dem(part, [DrumShell(R, rpm=30.0)], params, dim=3, periodic_length=0.02,
                   dt=2e-5, skin=0.0005)
    vel = np.random.default_rng(2).normal(0.0, 0.1, pts.shape)
    st = dem.init(pts, velocity=vel)
    k = 1500
    a = dem.run_steps(st, k)
    b = st
    for _ in range(k):
        b = dem.step(b)[0]
    assert int(a.n_rebuilds) > 5  # the particles moved through several rebuilds
    assert int(a.n_rebuilds) == int(b.n_rebuilds)
    assert int(a.step) == k
    for f in ("position", "velocity", "angular_velocity", "force", "pair_spring",
              "wall_spring"):
        np.testing.assert_array_equal(np.asarray(getattr(a, f)), np.asarray(getattr(b, f)), f)


def test_softening_area_correction_restores_the_real_contact():
    """Two spheres pressed together by the same force F: the overlap law's conductance follows
    the stiffness (overlap F / k) unless the area is corrected by k_sim / k_real (LIGGGHTS
    area_correction, a = 1 for a linear contact); corrected, softening leaves it unchanged."""
    from drumheat.mechanics.conduction import (PairConduction, pair_conductance,
                                               softening_area_correction)

    r, F, k_real, h = 0.004, 0.05, 1.22e9, 2.0
    g = {}
    for k in (1e5, 1e6, k_real):
        pc = PairConduction("overlap", h, np.ones(2),
                            area_correction=softening_area_correction(k, k_real)).checked(2)
        g[k] = float(pair_conductance("overlap", pc.coefficient, r, r, 2 * r - F / k))
    assert g[1e5] == pytest.approx(g[k_real], rel=1e-4)
    assert g[1e6] == pytest.approx(g[k_real], rel=1e-4)
    raw = float(pair_conductance("overlap", h, r, r, 2 * r - F / 1e5))
    assert raw / g[k_real] == pytest.approx((k_real / 1e5) ** 0.5, rel=1e-3)  # uncorrected
    with pytest.raises(ValueError, match="overlap"):
        PairConduction("projected", h, np.ones(2), area_correction=0.5).checked(2)
