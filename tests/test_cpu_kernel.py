"""The opt-in C++ contact kernel (make_dem(..., pair_kernel="cpu")) against the JAX kernel."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import drumheat  # noqa: F401
from drumheat.geometry import DrumShell
from drumheat.mechanics import contact_params, make_dem, make_particles
from drumheat.mechanics import cpu_kernel
from drumheat.mechanics.conduction import PairConduction

ok, why = cpu_kernel.available()
pytestmark = pytest.mark.skipif(not ok, reason=f"C++ contact kernel unavailable: {why}")


def _drum(kernel, seed=0, conduction=None, margin=1.2):
    """A cubic-lattice bed in the lower half of a rotating 3D drum slice (periodic z) whose
    polydisperse spheres (0.97-1 r on a 1.97 r lattice) partly overlap their neighbours and
    the drum wall if margin < 1 (bed within R - margin r); with conduction, a temperature
    gradient across the bed."""
    r, R = 0.004, 0.06
    a = 1.97 * r
    L = 5 * a
    g = np.arange(-R, R, a)
    X, Y, Z = np.meshgrid(g, g, (np.arange(5) + 0.5) * a, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    pts = pts[(np.hypot(pts[:, 0], pts[:, 1]) < R - margin * r) & (pts[:, 1] < 0.0)]
    radius = r * np.random.default_rng(seed).uniform(0.97, 1.0, len(pts))
    part = make_particles(radius, 2500.0)
    params = contact_params(1e5, restitution=0.5, restitution_model="linear", friction=0.5,
                            wall_friction=0.5)
    cond = None
    T0 = None
    if conduction is not None:
        cond = PairConduction(conduction, 1e3 if conduction == "projected" else 2.0,
                              np.asarray(part.mass) * 836.0)
        T0 = 300.0 + 50.0 * (pts[:, 0] + R) / (2 * R)
    dem = make_dem(part, [DrumShell(R, rpm=30.0)], params, dim=3, periodic_length=L, dt=1e-5,
                   skin=0.002, dtype=jnp.float32, pair_kernel=kernel, conduction=cond)
    return dem, dem.init(pts, extra=T0)


def test_cpu_kernel_equals_the_jax_kernel_to_round_off():
    jdem, js = _drum("jax")
    cdem, cs = _drum("cpu")
    js = jdem.run(js, 20, chunk=20)  # the overlaps start to push apart, springs build up
    cs = cs._replace(**{k: getattr(js, k) for k in js._fields if k != "extra"})
    # one step from the same state: forces, torques, springs, contacts
    a, ca = jdem.step(js)
    b, cb = cdem.step(cs)
    assert int(jnp.sum(ca.pair_mask)) > 200  # a dense bed: many touching pairs
    np.testing.assert_array_equal(np.asarray(ca.pair_mask), np.asarray(cb.pair_mask))
    scale_f = float(jnp.max(jnp.abs(a.force)))
    assert float(jnp.max(jnp.abs(a.force - b.force))) < 1e-4 * scale_f
    scale_t = float(jnp.max(jnp.abs(a.torque)))
    assert float(jnp.max(jnp.abs(a.torque - b.torque))) < 1e-4 * scale_t
    scale_s = float(jnp.max(jnp.abs(a.pair_spring)))
    assert float(jnp.max(jnp.abs(a.pair_spring - b.pair_spring))) < 1e-4 * scale_s
    # overlap = r_i + r_j - distance cancels: its round-off is that of lengths ~2r in float32
    # (ulp 5e-10 m at 8 mm); 1e-6 x 2r is about 16 ulp, and the normal force k_n times that
    tol = {"pair_overlap": 1e-6 * 0.008, "pair_distance": 1e-6 * 0.008,
           "pair_normal_force": 1e5 * 1e-6 * 0.008}
    for f, atol in tol.items():
        x, y = np.asarray(getattr(ca, f)), np.asarray(getattr(cb, f))
        assert np.max(np.abs(x - y)) <= atol, f
    # and over 200 steps the two stay together to round-off growth (the bed is nearly at rest)
    a2 = jdem.run(js, 200, chunk=200)
    b2 = cdem.run(cs, 200, chunk=200)
    assert float(jnp.max(jnp.abs(a2.position - b2.position))) < 1e-3 * 0.004


def test_cpu_kernel_refuses_what_it_does_not_cover():
    part = make_particles(np.full(4, 0.002), 2500.0)
    params = contact_params(1e5, damping_ratio=0.3)
    with pytest.raises(ValueError, match="3D"):
        make_dem(part, [DrumShell(0.05)], params, dim=2, dtype=jnp.float32, pair_kernel="cpu")
    with pytest.raises(ValueError, match="float32"):
        make_dem(part, [DrumShell(0.05)], params, dim=3, periodic_length=0.03,
                 pair_kernel="cpu")
    rolling = contact_params(1e5, damping_ratio=0.3, rolling_friction=0.1)
    with pytest.raises(ValueError, match="rolling"):
        make_dem(part, [DrumShell(0.05)], rolling, dim=3, periodic_length=0.03,
                 dtype=jnp.float32, pair_kernel="cpu")
    with pytest.raises(ValueError, match="pair_kernel"):
        make_dem(part, [DrumShell(0.05)], params, dim=3, periodic_length=0.03,
                 pair_kernel="fast")


def test_wall_contacts_in_the_kernel_equal_the_jax_walls():
    jdem, js = _drum("jax", margin=0.95)
    cdem, cs = _drum("cpu", margin=0.95)
    js = jdem.run(js, 20, chunk=20)
    cs = cs._replace(**{k: getattr(js, k) for k in js._fields if k != "extra"})
    a, ca = jdem.step(js)
    b, cb = cdem.step(cs)
    assert int(jnp.sum(ca.wall_mask)) > 10  # the bed presses on the drum wall
    np.testing.assert_array_equal(np.asarray(ca.wall_mask), np.asarray(cb.wall_mask))
    scale = float(jnp.max(jnp.abs(a.wall_spring)))
    assert scale > 0
    assert float(jnp.max(jnp.abs(a.wall_spring - b.wall_spring))) < 1e-4 * scale
    fn = np.asarray(ca.wall_normal_force)
    assert np.max(np.abs(fn - np.asarray(cb.wall_normal_force))) < 1e-4 * np.max(fn)
    assert np.max(np.abs(np.asarray(ca.wall_overlap) - np.asarray(cb.wall_overlap))) < 1e-6 * 0.008


@pytest.mark.parametrize("law", ["projected", "overlap"])
def test_conduction_in_the_kernel_equals_the_jax_heat_flow(law):
    jdem, js = _drum("jax", conduction=law)
    cdem, cs = _drum("cpu", conduction=law)
    js = jdem.run(js, 20, chunk=20)
    cs = cs._replace(**{k: getattr(js, k) for k in js._fields})
    a, _ = jdem.step(js)
    b, _ = cdem.step(cs)
    dTa = np.asarray(a.extra - js.extra)
    dTb = np.asarray(b.extra - cs.extra)
    assert np.max(np.abs(dTa)) > 0
    # the pair distances come from float32 positions in both kernels (round-off ~1e-7)
    assert np.max(np.abs(dTa - dTb)) < 1e-4 * np.max(np.abs(dTa))
    cap = np.asarray(cdem.conduction.heat_capacity)
    assert abs(np.sum(cap * dTb)) < 1e-12 * np.sum(cap * np.asarray(cs.extra))


def test_threaded_kernel_equals_one_thread(monkeypatch):
    # chunks accumulate in their own buffers, summed in chunk order: the thread count changes
    # the force sums by round-off only
    cdem, cs = _drum("cpu", conduction="projected")
    cs = cdem.run(cs, 20, chunk=20)
    monkeypatch.setenv("DRUMHEAT_KERNEL_THREADS", "1")
    a, ca = cdem.step(cs)
    monkeypatch.setenv("DRUMHEAT_KERNEL_THREADS", "3")
    b, cb = cdem.step(cs)
    np.testing.assert_array_equal(np.asarray(ca.pair_mask), np.asarray(cb.pair_mask))
    np.testing.assert_array_equal(np.asarray(a.pair_spring), np.asarray(b.pair_spring))
    np.testing.assert_array_equal(np.asarray(a.wall_spring), np.asarray(b.wall_spring))
    for f in ("force", "torque"):
        x, y = np.asarray(getattr(a, f)), np.asarray(getattr(b, f))
        assert np.max(np.abs(x - y)) <= 1e-5 * np.max(np.abs(x)), f
    dT = np.asarray(a.extra - cs.extra)
    assert np.max(np.abs(np.asarray(b.extra - cs.extra) - dT)) <= 1e-9 * np.max(np.abs(dT))
