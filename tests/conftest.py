import os

os.environ.setdefault("MPLBACKEND", "Agg")

import drumheat  # noqa: E402,F401  (enables float64)

import jax  # noqa: E402
import pytest  # noqa: E402


def pytest_collection_modifyitems(config, items):
    """Skip the tests marked ``bitwise`` (they compare two runs bit for bit) where runs do not
    repeat bit for bit: on a GPU the scatter-adds add in no fixed order, so two runs of the
    same moving bed part after a few steps (docs/long-runs.md)."""
    if jax.default_backend() == "cpu":
        return
    skip = pytest.mark.skip(reason=f"compares runs bit for bit; on {jax.default_backend()!r} "
                                   "runs do not repeat bit for bit (docs/long-runs.md)")
    for item in items:
        if "bitwise" in item.keywords:
            item.add_marker(skip)
