"""JAX's persistent compilation cache for drumheat's programs.

Every :func:`drumheat.run` and :func:`drumheat.run_ensemble` builds its programs anew (the DEM
step closes over the scene's walls and contact tables), so without a persistent cache a second
run of the same scene in a notebook compiles everything again. With it, a repeated DEM ensemble
of two variants took 2.5-3.2 s instead of 12-15 s, and a new process with a filled cache 37 s
instead of 51-54 s for the first call (scripts/bench_ensemble.py's DEM seed ensemble;
docs/performance.md, "Start-up").

The cache folder is ``$DRUMHEAT_CACHE_DIR`` or ``~/.cache/drumheat/jax``. Set
``DRUMHEAT_CACHE_DIR=off`` to leave JAX's cache alone; a cache folder configured in JAX before
drumheat runs (``jax.config.update("jax_compilation_cache_dir", ...)``) is kept.
"""

from __future__ import annotations

import os

from drumheat.environment import cache_dir_setting

__all__ = ["enable_compilation_cache", "cache_dir_setting"]

# programs that compile in less than this (s) are not written to the cache
MIN_COMPILE_TIME_S = 0.2


def enable_compilation_cache() -> str | None:
    """Switch on JAX's persistent compilation cache (idempotent); return its folder.

    Returns None if ``DRUMHEAT_CACHE_DIR`` is ``off`` (nothing is changed). A folder already
    configured in JAX is kept and returned.
    """
    import jax

    env = cache_dir_setting()
    if env is False:
        return None
    current = jax.config.jax_compilation_cache_dir
    if current:
        return current
    cache = env or os.path.join(os.path.expanduser("~"), ".cache", "drumheat", "jax")
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_TIME_S)
    return cache
