"""The opt-in C++ pair kernel (make_dem(..., pair_kernel="cpu")) against the JAX kernel."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import drumheat  # noqa: F401
from drumheat.geometry import DrumShell
from drumheat.mechanics import contact_params, make_dem, make_particles
from drumheat.mechanics import cpu_kernel

ok, why = cpu_kernel.available()
pytestmark = pytest.mark.skipif(not ok, reason=f"C++ pair kernel unavailable: {why}")


def _drum(kernel, seed=0):
    """A cubic-lattice bed in the lower half of a rotating 3D drum slice (periodic z) whose
    polydisperse spheres (0.97-1 r on a 1.97 r lattice) partly overlap their neighbours."""
    r, R = 0.004, 0.06
    a = 1.97 * r
    L = 5 * a
    g = np.arange(-R, R, a)
    X, Y, Z = np.meshgrid(g, g, (np.arange(5) + 0.5) * a, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    pts = pts[(np.hypot(pts[:, 0], pts[:, 1]) < R - 1.2 * r) & (pts[:, 1] < 0.0)]
    radius = r * np.random.default_rng(seed).uniform(0.97, 1.0, len(pts))
    part = make_particles(radius, 2500.0)
    params = contact_params(1e5, restitution=0.5, restitution_model="linear", friction=0.5,
                            wall_friction=0.5)
    dem = make_dem(part, [DrumShell(R, rpm=30.0)], params, dim=3, periodic_length=L, dt=1e-5,
                   skin=0.002, dtype=jnp.float32, pair_kernel=kernel)
    return dem, dem.init(pts)


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
