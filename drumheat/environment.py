"""The environment variables drumheat reads, parsed in one place.

``DRUMHEAT_CACHE_DIR``: where compiled programs (JAX's persistent cache) and compiled C++
kernels are kept; ``off`` (or ``0``, ``none``, ``false``, empty) switches the JAX cache off.
"""

from __future__ import annotations

import os

__all__ = ["cache_dir_setting"]


def cache_dir_setting() -> str | bool | None:
    """``DRUMHEAT_CACHE_DIR``: a folder (str), False when switched off (``off``, ``0``,
    ``none``, ``false`` or empty), None when not set."""
    env = os.environ.get("DRUMHEAT_CACHE_DIR")
    if env is None:
        return None
    return False if env.strip().lower() in ("off", "0", "none", "false", "") else env
