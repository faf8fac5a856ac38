"""The DEM pair kernel as one C++ loop on CPU (opt-in: ``make_dem(..., pair_kernel="cpu")``).

On XLA:CPU the JAX pair kernel of :mod:`drumheat.mechanics.integrator` runs as some twenty
passes over the pair slots plus a scatter-add, about a third of LIGGGHTS' speed per core
(docs/performance.md). ``pair_kernel.cc`` computes the same contact law
(:func:`drumheat.mechanics.contact_forces.contact_law`) in one loop over the pairs and is
called through ``jax.ffi`` (an XLA custom call): 2.3-2.4x faster than the JAX kernel on the
3D drum slice at N = 2 000 and 10 000 (``scripts/bench_cpu_pair_kernel.py``), the whole DEM
step with conduction 1.7-2.5x (``scripts/bench_vs_liggghts.py``, docs/performance.md). From
100 000 pair slots up the loop is split over the cores (``DRUMHEAT_KERNEL_THREADS`` caps the
threads); the force sums then depend on the thread count by round-off.

Scope: 3D, one material (single-row contact tables), no rolling resistance, float32 mechanics,
the CPU backend, single runs (not under ``vmap``, not differentiable). :func:`check_supported`
says why a configuration is refused. The JAX kernel stays the reference and the path for GPUs,
ensembles and everything else; ``tests/test_cpu_kernel.py`` holds the two equal to round-off.

The source is compiled with ``g++ -O3`` on first use into
``$DRUMHEAT_CACHE_DIR/kernels`` (default ``~/.cache/drumheat/kernels``), named by the hash of
the source and the jaxlib version, and registered once per process.
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

__all__ = ["TARGET", "available", "check_supported", "load", "pair_forces"]

TARGET = "drumheat_pair_forces"
SOURCE = Path(__file__).with_name("pair_kernel.cc")
_LOADED = False


def _cache_dir() -> Path:
    from drumheat.compile_cache import cache_dir_setting

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
        raise RuntimeError(f"the C++ pair kernel is not available: {why}")
    src = SOURCE.read_text()
    import jaxlib

    key = hashlib.sha256((src + jaxlib.__version__).encode()).hexdigest()[:16]
    out = _cache_dir() / f"pair_kernel_{key}.so"
    if not out.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(f".{os.getpid()}.tmp")
        cmd = [os.environ.get("CXX", "g++"), "-O3", "-shared", "-fPIC", "-std=c++17", "-w",
               f"-I{jax.ffi.include_dir()}", str(SOURCE), "-o", str(tmp)]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError("compiling the C++ pair kernel failed:\n" + proc.stderr[-2000:])
        os.replace(tmp, out)  # atomic: parallel test workers may build at once
    lib = ctypes.cdll.LoadLibrary(str(out))
    jax.ffi.register_ffi_target(TARGET, jax.ffi.pycapsule(lib.PairForces), platform="cpu")
    _LOADED = True
    return TARGET


def check_supported(dim, params, dtype, batch_axis) -> None:
    """Raise ValueError naming the first reason why ``pair_kernel="cpu"`` cannot serve."""
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


def pair_forces(pos, vel, omega, radius, mass, idx, spring, *, kn, kt, zeta_n, zeta_t, mu, dt,
                periodic_length=None):
    """Pair contact forces of all neighbour pairs in one C++ loop (float32).

    Args: positions, velocities, spins (N, 3); radius, mass (N); idx (2, M) OrderedSparse pairs
    (padding N); spring (M, 3) tangential springs; scalar contact parameters as in
    :func:`drumheat.mechanics.contact_forces.contact_law`; periodic_length of z or None.
    Returns ``(force, torque, spring, overlap, distance, normal_force, max_overlap)``: contact
    forces and torques on the particles (N, 3), the new springs (M, 3), per pair the overlap,
    centre distance and normal force (M), zero where the pair does not touch, and the largest
    overlap / smaller radius of the pair (1,).
    """
    target = load()
    n, m = pos.shape[0], idx.shape[1]
    f32 = jnp.float32
    outs = [jax.ShapeDtypeStruct((n, 3), f32), jax.ShapeDtypeStruct((n, 3), f32),
            jax.ShapeDtypeStruct((m, 3), f32), jax.ShapeDtypeStruct((m,), f32),
            jax.ShapeDtypeStruct((m,), f32), jax.ShapeDtypeStruct((m,), f32),
            jax.ShapeDtypeStruct((1,), f32)]
    c = lambda v: np.float32(v)  # noqa: E731
    return jax.ffi.ffi_call(target, outs)(
        pos.astype(f32), vel.astype(f32), omega.astype(f32), radius.astype(f32),
        mass.astype(f32), idx.astype(jnp.int32), spring.astype(f32),
        kn=c(kn), kt=c(kt), zn=c(zeta_n), zt=c(zeta_t), mu=c(mu), dt=c(dt),
        L=c(periodic_length or 0.0))
