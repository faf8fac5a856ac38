"""What the DEM step's building blocks cost on this JAX backend (why the CPU step is as fast
as it is).

The DEM force kernel (``drumheat/mechanics/integrator.py``) is a sequence of XLA operations
over the neighbour-pair slots: gathers of the partners' positions and velocities, element-wise
contact law, one scatter-add of forces and torques onto the particles. This script times each
kind of operation alone, at the sizes of the 3D drum benchmark (``bench_vs_liggghts.py``,
N = 10 000: 99 032 pair slots), with the DEM kernels' compiler options
(:data:`drumheat.mechanics.integrator.JIT_OPTIONS`), and prints a Markdown table: time per call
and per element. Compare the rows with the profile of a whole step (``docs/performance.md``).

Usage::

    python scripts/bench_xla_ops.py [--n 10000] [--pairs 99032] [--repeat 200]
"""

from __future__ import annotations

import argparse
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.mechanics.integrator import JIT_OPTIONS


def timed(fun, *args, repeat=200):
    """Mean wall time (s) of one call of the jitted ``fun`` after a warm-up call."""
    f = jax.jit(fun, compiler_options=JIT_OPTIONS)
    jax.block_until_ready(f(*args))
    t0 = time.perf_counter()
    for _ in range(repeat):
        r = f(*args)
    jax.block_until_ready(r)
    return (time.perf_counter() - t0) / repeat


def cases(n, m, seed=0):
    rng = np.random.default_rng(seed)
    pos = jnp.asarray(rng.random((n, 3)), jnp.float32)
    i = jnp.asarray(np.sort(rng.integers(0, n, m)), jnp.int32)  # sorted like drumheat's pairs
    j = jnp.asarray(rng.integers(0, n, m), jnp.int32)
    j_near = jnp.asarray(np.clip(np.asarray(i) + rng.integers(-200, 200, m), 0, n - 1),
                         jnp.int32)  # partners close in memory (spatially sorted particles)
    a = jnp.asarray(rng.random(m), jnp.float32)
    b = jnp.asarray(rng.random((m, 3)), jnp.float32)
    upd = jnp.asarray(rng.random((2 * m, 6)), jnp.float32)
    seg = jnp.concatenate([i, j])
    dist = lambda p, i, j: jnp.sqrt(jnp.sum((p[j] - p[i]) ** 2, -1))  # noqa: E731
    return [
        ("element-wise a*2+1", "(M,)", m, lambda a: a * 2 + 1, (a,)),
        ("norm sqrt(sum b^2, -1)", "(M, 3)", m, lambda b: jnp.sqrt(jnp.sum(b * b, -1)), (b,)),
        ("pair distance, random partners", "gather 2 x (M, 3)", m, dist, (pos, i, j)),
        ("pair distance, near partners", "gather 2 x (M, 3)", m, dist, (pos, i, j_near)),
        ("pair distance, (3, N) layout", "gather 6 x (M,)", m,
         lambda p, i, j: jnp.sqrt(sum((p[k][j] - p[k][i]) ** 2 for k in range(3))),
         (pos.T, i, j)),
        ("scatter-add forces + torques", "(2M, 6) -> (N, 6)", 2 * m,
         lambda u, s: jax.ops.segment_sum(u, s, n), (upd, seg)),
        ("scatter-add, sorted indices", "(M, 3) -> (N, 3)", m,
         lambda u, s: jax.ops.segment_sum(u, s, n, indices_are_sorted=True), (b, i)),
        ("scatter-add, one column", "(M,) -> (N,)", m,
         lambda u, s: jax.ops.segment_sum(u, s, n), (a, j)),
        ("prefix sum (compaction)", "cumsum (M,) int32", m,
         lambda a: jnp.cumsum((a > 0.8).astype(jnp.int32)), (a,)),
        ("compaction of active pairs", "nonzero(size=M/4)", m,
         lambda a: jnp.nonzero(a > 0.8, size=m // 4, fill_value=m)[0], (a,)),
    ]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=10000, help="particles")
    ap.add_argument("--pairs", type=int, default=99032, help="pair slots (neighbour capacity)")
    ap.add_argument("--repeat", type=int, default=200)
    a = ap.parse_args(argv)
    print(f"backend {jax.default_backend()}, {jax.devices()[0].device_kind}, "
          f"{os.cpu_count()} CPU cores, load {os.getloadavg()[0]:.1f}; N = {a.n}, "
          f"M = {a.pairs} pair slots, float32\n")
    print("| operation | shape | time (us) | ns per element |")
    print("|---|---|---|---|")
    for name, shape, count, fun, args in cases(a.n, a.pairs):
        t = timed(fun, *args, repeat=a.repeat)
        print(f"| {name} | {shape} | {t * 1e6:.0f} | {t / count * 1e9:.2f} |")


if __name__ == "__main__":
    main()
