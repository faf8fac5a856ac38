"""How XLA:CPU runs a loop over an array it cuts into parts for its threads, by the array's length.

XLA:CPU cuts a long element-wise loop (a loop fusion) along its outer axis into equal parts
for the threads of its pool (its ``ParallelTaskAssigner``; ``outer_dimension_partitions`` in
the compiled HLO). This script times two loops of the DEM step at lengths that the parts
divide evenly and at lengths one or a few elements off:

* the contact-time counts of the pair slots (``motion.coupling``: ``where(fresh, 0, time) +
  conducts`` over (M,) int32), at the built-in drum's slot counts at N = 10 000 and 50 000 of
  before and after ``drumheat.devices.LENGTH_MULTIPLE`` (69 315 / 69 376 and 346 573 / 346 624);
* an update of (N, 3) float64 like a kick (``a x + b i``) at N = 30 000 and 30 001.

Each loop runs 1000 times inside one compiled ``fori_loop``; printed: the number of parts the
compiled loop has (1: not cut), the best of ``--repeat`` calls in microseconds per loop, and
the machine's load and CPU steal during the timing (``scripts/machine.py``). Numbers and their
reading: docs/performance.md (lengths that XLA:CPU cuts evenly).

Usage: python scripts/bench_xla_partitions.py [--repeat 9]
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from machine import cpu_ticks, load, print_table, steal_percent  # noqa: E402

jax.config.update("jax_enable_x64", True)

from drumheat.mechanics.integrator import JIT_OPTIONS  # noqa: E402

LOOPS = 1000


def counts(m: int):
    """The contact-time count update over ``m`` pair slots, LOOPS times; and its start."""
    conducts = jnp.asarray(np.random.default_rng(0).random(m) < 0.4)

    def body(i, t):
        return jnp.where(i % 10 == 0, 0, t) + conducts.astype(jnp.int32)
    return (lambda t: jax.lax.fori_loop(0, LOOPS, body, t)), jnp.zeros(m, jnp.int32)


def kick(n: int):
    """A kick-like update of (n, 3) float64 values (``a x + b i``), LOOPS times; its start."""
    return (lambda x: jax.lax.fori_loop(0, LOOPS, lambda i, x: x * 1.0000001 + 1e-9 * i, x)), \
        jnp.ones((n, 3))


def parts(compiled) -> int:
    """The most parts any loop of ``compiled`` is cut into (1: none is)."""
    found = re.findall(r'outer_dimension_partitions":\["(\d+)"', compiled.as_text())
    return max([int(p) for p in found], default=1)


def time_loop(make, size: int, repeat: int):
    fn, start = make(size)
    compiled = jax.jit(fn, compiler_options=JIT_OPTIONS).lower(start).compile()
    jax.block_until_ready(compiled(start))
    ld, c0 = load(), cpu_ticks()
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(start))
        best = min(best, time.perf_counter() - t0)
    return parts(compiled), 1e6 * best / LOOPS, ld, steal_percent(c0, cpu_ticks())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=9)
    args = ap.parse_args()
    cases = [("contact-time counts, (M,) int32", counts, m)
             for m in (69315, 69376, 346573, 346624)]
    cases += [("a kick's update, (N, 3) float64", kick, n) for n in (30000, 30001)]
    rows = []
    for name, make, size in cases:
        p, us, ld, st = time_loop(make, size, args.repeat)
        rows.append((name, f"{size:,}".replace(",", " "), p, us, ld, st))
    print(f"XLA:CPU loops by length, {jax.devices()[0].device_kind}, {LOOPS} loops per call, "
          f"best of {args.repeat} calls:")
    print_table(("loop", "length", "parts", "us per loop", "load", "steal %"), rows,
                ("s", "s", "d", ".1f", ".2f", ".0f"))


if __name__ == "__main__":
    main()
