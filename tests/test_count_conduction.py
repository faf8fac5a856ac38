"""The coupled heat's contact conduction in C++ (``cpu_kernel.count_conduction``, set on the
thermal network of a DEM on the C++ contact backend): the JAX sum of
:class:`~drumheat.thermal.contact.ContactConduction` to round-off, with its derivatives."""

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import drumheat as dh
from drumheat.mechanics import cpu_kernel
from drumheat.motion import coupling
from drumheat.thermal.contact import ContactConduction
from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.particles import ThermalParticles

pytestmark = [
    pytest.mark.skipif(not cpu_kernel.available()[0],
                       reason=f"C++ contact kernel unavailable: {cpu_kernel.available()[1]}"),
    pytest.mark.filterwarnings("ignore::drumheat.mechanics.DEMAccuracyWarning"),
]

N, M, DT, SUBSTEPS = 300, 2048, 2.0e-5, 9


def network(native: bool, seed=0):
    """A coupled DEM's network of N particles of two sizes: M slots, the listed pairs grouped
    by their first particle, padding (index N) last, counts 0 .. SUBSTEPS with about half the
    listed slots 0 (not conducting), the wall part empty."""
    rng = np.random.default_rng(seed)
    listed = 1500
    i = np.sort(rng.integers(0, N - 1, listed))
    j = np.minimum(i + rng.integers(1, 40, listed), N - 1)
    counts = np.where(rng.random(listed) < 0.5, 0, rng.integers(1, SUBSTEPS + 1, listed))
    pad = M - listed
    idx = np.stack([np.r_[i, np.full(pad, N)], np.r_[j, np.full(pad, N)]]).astype(np.int32)
    steps = np.r_[counts, np.zeros(pad)].astype(np.int32)
    return coupling.thermal_network(jnp.asarray(idx), N, jnp.asarray(steps),
                                    jnp.zeros(N), jnp.zeros(1, bool), 1, SUBSTEPS * DT, DT,
                                    pair_kernel="cpu" if native else "jax")


def bed(seed=1):
    rng = np.random.default_rng(seed)
    d = np.where(rng.random(N) < 0.5, 0.004, 0.006)
    particles = ThermalParticles.spheres(d, 2700.0, 900.0)
    T = jnp.asarray(300.0 + 50.0 * rng.random(N))
    return particles, T


def test_the_cpu_sum_is_the_jax_sum_to_round_off():
    particles, T = bed()
    effect = ContactConduction(alpha=jnp.asarray(57.0))
    ref, net = network(False), network(True)
    assert ref.native_conduction is None and net.native_conduction is not None
    q_ref = effect.heat_flow(T, particles, ref)
    q = jax.jit(lambda T, p, n: effect.heat_flow(T, p, n))(T, particles, net)
    scale = float(jnp.max(jnp.abs(q_ref)))
    assert scale > 0 and int(jnp.sum(q_ref != 0)) > 200  # most particles exchange heat
    np.testing.assert_allclose(q, q_ref, rtol=0, atol=1e-13 * scale)
    # each slot moves heat from one particle to the other: the bed's sum is 0 to round-off
    assert abs(float(jnp.sum(q))) < 1e-12 * float(jnp.sum(jnp.abs(q)))


def test_the_cpu_sum_has_the_derivatives_of_the_jax_sum():
    particles, T = bed()
    ref, net = network(False), network(True)

    def flows(net):
        def f(T, alpha, d):
            p = ThermalParticles(d, particles.mass, particles.heat_capacity)
            return ContactConduction(alpha=alpha).heat_flow(T, p, net)
        return f

    args = (T, jnp.asarray(57.0), particles.diameter)
    tangents = (jnp.linspace(-1.0, 1.0, N), jnp.asarray(3.0), 1e-4 * jnp.cos(jnp.arange(N)))
    _, t_ref = jax.jvp(flows(ref), args, tangents)
    _, t = jax.jvp(flows(net), args, tangents)
    np.testing.assert_allclose(t, t_ref, rtol=0, atol=1e-13 * float(jnp.max(jnp.abs(t_ref))))
    w = jnp.sin(jnp.arange(N))  # a weighted sum of the flows, as a fit's loss would be
    g_ref = jax.grad(lambda *a: jnp.sum(w * flows(ref)(*a)), argnums=(0, 1, 2))(*args)
    g = jax.grad(lambda *a: jnp.sum(w * flows(net)(*a)), argnums=(0, 1, 2))(*args)
    for a, b in zip(g, g_ref):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-13 * float(jnp.max(jnp.abs(b))))


def test_a_coupled_run_on_the_cpu_backend_sums_in_cpp_and_keeps_the_jax_temperatures(
        monkeypatch):
    # the same coupled run (cpu contacts, thermal step every 3 steps) with the conduction
    # summed in C++ and in JAX: the same contacts, temperatures to round-off
    sys.path.insert(0, str(Path(__file__).parent))
    from test_coupled import dem_scene

    scene = dem_scene(**{"dem.thermal_substeps": 3, "dem.contact_backend": "cpu",
                         "heat.contact.alpha": 500.0, "run.duration": 0.1})
    calls = []
    native = coupling._cpu_conduction
    monkeypatch.setattr(coupling, "_cpu_conduction",
                        lambda *a: calls.append(1) or native(*a))
    cpp = dh.run(scene, progress=False)
    assert calls  # the thermal step took the C++ sum
    monkeypatch.setattr(coupling, "_cpu_conduction", None)  # the network without it: JAX
    ref = dh.run(scene, progress=False)
    assert cpp.summary["contact_backend"] == ref.summary["contact_backend"] == "cpu"
    np.testing.assert_array_equal(cpp.trajectory.position, ref.trajectory.position)
    rise = float(np.max(np.abs(ref.T - ref.T[0])))
    assert rise > 0.1  # heat moved between the particles
    np.testing.assert_allclose(cpp.T, ref.T, rtol=0, atol=1e-12 * 300)
