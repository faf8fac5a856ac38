"""The DEM contact loop in C++ on CPU (opt-in: ``make_dem(..., pair_kernel="cpu")``).

On XLA:CPU the JAX force kernel of :mod:`drumheat.mechanics.integrator` runs as some twenty
passes over the pair slots plus scatter-adds, about a third of LIGGGHTS' speed per core
(docs/performance.md). ``contact_kernel.cc`` computes the same contact law
(:func:`drumheat.mechanics.contact_forces.contact_law`) for the particle-particle pairs and
the particle-wall contacts in one loop, called through ``jax.ffi`` (an XLA custom call); the
wall geometry (distance, normal, surface velocity of every wall at every particle) still comes
from the JAX walls, so every wall type works. With ``make_dem(..., conduction=...)`` the same
loop sums the contact heat flows (:mod:`drumheat.mechanics.conduction`). The loop is cut into
as many chunks as XLA's intra-op thread pool has threads (at most one per 8 000 pair slots;
``DRUMHEAT_KERNEL_THREADS`` sets the number) and run on that pool, so no threads are started
per step; each chunk sums into its own buffer and the buffers are added in chunk order, so the
result depends on the chunk count by round-off and on nothing else. The pair and wall springs
are updated in place (aliased buffers). Speed: docs/performance.md
(``scripts/bench_cpu_pair_kernel.py`` kernel against kernel, ``scripts/bench_vs_liggghts.py``
the whole step against LIGGGHTS).

Scope: 3D, one material (single-row contact tables), no rolling resistance, float32 mechanics,
the CPU backend, single runs (not under ``vmap``, not differentiable). :func:`check_supported`
says why a configuration is refused. The JAX kernel stays the reference and the path for GPUs,
ensembles and everything else; ``tests/test_cpu_kernel.py`` holds the two equal to round-off.

The source is compiled with ``g++ -O3 -fno-math-errno`` on first use into
``$DRUMHEAT_CACHE_DIR/kernels`` (default ``~/.cache/drumheat/kernels``), named by the hash of
the source, the flags and the jaxlib version, and registered once per process.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from drumheat.environment import cache_dir_setting

__all__ = ["TARGET", "available", "check_supported", "contacts", "load"]

TARGET = "drumheat_contacts"
SOURCE = Path(__file__).with_name("contact_kernel.cc")
_LOADED = False


def _cache_dir() -> Path:
    env = cache_dir_setting()  # a compiled kernel needs a folder even with the JAX cache off
    return (Path(env) if env else Path.home() / ".cache" / "drumheat") / "kernels"


def available() -> tuple[bool, str]:
    """Whether the kernel can be used here, and why not: ``(ok, reason)``."""
    if jax.default_backend() != "cpu":
        return False, f"the default JAX backend is {jax.default_backend()!r}, not 'cpu'"
    if shutil.which(os.environ.get("CXX", "g++")) is None:
        return False, "no C++ compiler (g++ or $CXX) on the PATH"
    if not (Path(jax.ffi.include_dir()) / "xla" / "ffi" / "api" / "ffi.h").exists():
        return False, "jaxlib ships no XLA FFI headers"
    return True, ""


def load() -> str:
    """Compile (once, cached on disk) and register the kernel; return its FFI target name.

    Raises RuntimeError with the compiler's message if it cannot be built.
    """
    global _LOADED
    if _LOADED:
        return TARGET
    ok, why = available()
    if not ok:
        raise RuntimeError(f"the C++ contact kernel is not available: {why}")
    src = SOURCE.read_text()
    import jaxlib

    flags = ["-O3", "-fno-math-errno", "-shared", "-fPIC", "-std=c++17", "-w"]
    key = hashlib.sha256("\n".join([src, jaxlib.__version__] + flags).encode()).hexdigest()[:16]
    out = _cache_dir() / f"contact_kernel_{key}.so"
    if not out.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(f".{os.getpid()}.tmp")
        cmd = [os.environ.get("CXX", "g++"), *flags, f"-I{jax.ffi.include_dir()}", str(SOURCE),
               "-o", str(tmp)]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError("compiling the C++ contact kernel failed:\n" + proc.stderr[-2000:])
        os.replace(tmp, out)  # atomic: parallel test workers may build at once
    lib = ctypes.cdll.LoadLibrary(str(out))
    jax.ffi.register_ffi_target(TARGET, jax.ffi.pycapsule(lib.Contacts), platform="cpu")
    _LOADED = True
    return TARGET


def check_supported(dim, params, dtype, batch_axis) -> None:
    """Raise ValueError naming every reason why ``pair_kernel="cpu"`` cannot serve."""
    reasons = []
    if dim != 3:
        reasons.append("it is written for 3D (dim = 3)")
    if params.n_types != 1:
        reasons.append("it takes one material (single-row contact tables)")
    if params.uses_rolling():
        reasons.append("it has no rolling resistance")
    if jnp.dtype(dtype) != jnp.float32:
        reasons.append("it runs float32 mechanics (dtype=jnp.float32)")
    if batch_axis is not None:
        reasons.append("it does not batch under vmap (ensembles use the JAX kernel)")
    ok, why = available()
    if not ok:
        reasons.append(why)
    if reasons:
        raise ValueError("pair_kernel='cpu' cannot be used: " + "; ".join(reasons)
                         + ". Use pair_kernel='jax'.")


def contacts(pos, vel, omega, radius, mass, idx, spring, wall_distance, wall_normal,
             wall_velocity, wall_spring, wall_params, *, kn, kt, zeta_n, zeta_t, mu, dt,
             periodic_length=None, temperature=None, conduction_law=None, conduction_h=0.0):
    """Particle-particle and particle-wall contact forces in one C++ loop (float32).

    Args:
      pos, vel, omega: positions, velocities, spins (N, 3).
      radius, mass: (N,).
      idx: (2, M) OrderedSparse neighbour pairs (padding N); spring: (M, 3) tangential springs.
      wall_distance: (N, W) distance of each particle centre from each wall; wall_normal:
        (N, W, 3) unit normal from the wall towards the particle; wall_velocity: (N, W, 3)
        velocity of the wall surface at the particle (the three outputs of each wall's
        ``evaluate``, stacked over the walls); wall_spring: (N, W, 3) tangential springs.
      wall_params: (5, W) per wall ``kn, kt, zeta_n, zeta_t, mu``.
      kn, kt, zeta_n, zeta_t, mu, dt: particle-particle contact parameters as in
        :func:`drumheat.mechanics.contact_forces.contact_law`; periodic_length of z or None.
      temperature, conduction_law, conduction_h: with a law (``"projected"`` or ``"overlap"``,
        :mod:`drumheat.mechanics.conduction`), the heat flow through the touching pairs at the
        temperatures (N,) float64 is summed in the same loop.

    Returns ``(force, torque, spring, overlap, distance, normal_force, wall_spring,
    wall_overlap, wall_normal_force, max_overlap, heat)``: contact forces and torques on the
    particles (N, 3); per pair the new springs (M, 3), overlap, centre distance and normal force
    (M); per wall slot the new springs (N, W, 3), overlap and normal force (N, W); all zero where
    nothing touches; the largest overlap / radius (the smaller radius of a pair) (1,); and the
    heat flow into each particle (N,) float64, W (length 0 without a conduction law).
    """
    target = load()
    n, m = pos.shape[0], idx.shape[1]
    nw = wall_distance.shape[1]
    f32 = jnp.float32
    sd = jax.ShapeDtypeStruct
    outs = [sd((n, 3), f32), sd((n, 3), f32), sd((m, 3), f32), sd((m,), f32), sd((m,), f32),
            sd((m,), f32), sd((n, nw, 3), f32), sd((n, nw), f32), sd((n, nw), f32),
            sd((1,), f32)]
    if conduction_law is None:
        law, temperature = -1, jnp.zeros((0,), jnp.float64)
    else:
        from drumheat.mechanics.conduction import LAWS

        law = LAWS.index(conduction_law)
    outs.append(sd((temperature.shape[0],), jnp.float64))
    c = lambda v: np.float32(v)  # noqa: E731
    # springs updated in place: input 6 -> output 2 (pairs), input 10 -> output 6 (walls)
    return jax.ffi.ffi_call(target, outs, input_output_aliases={6: 2, 10: 6})(
        pos.astype(f32), vel.astype(f32), omega.astype(f32), radius.astype(f32),
        mass.astype(f32), idx.astype(jnp.int32), spring.astype(f32),
        wall_distance.astype(f32), wall_normal.astype(f32), wall_velocity.astype(f32),
        wall_spring.astype(f32), wall_params.astype(f32), temperature.astype(jnp.float64),
        kn=c(kn), kt=c(kt), zn=c(zeta_n), zt=c(zeta_t), mu=c(mu), dt=c(dt),
        L=c(periodic_length or 0.0), law=np.int32(law), h=np.float64(conduction_h))
