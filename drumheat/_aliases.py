"""Old import paths of drumheat 0.1, kept for one release.

The modules moved when the package was laid out in layers (docs/architecture.md). Importing an
old path, e.g. ``import drumheat.mixing.dem`` or ``from drumheat.observe import alpha_overall``,
returns the module at its new place and warns once with a :class:`DeprecationWarning` that
names it. The table below is the only record of the moves. ``drumheat.animate`` is not among
them: the name is now the function :func:`drumheat.animate` (the module is
:mod:`drumheat.results.animate`).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings

#: old module path -> new module path (a package prefix maps every module under it)
MOVED = {
    "drumheat.mixing": "drumheat.motion",
    "drumheat.bed": "drumheat.assemble",
    "drumheat.ensemble": "drumheat.runner.ensemble",
    "drumheat.sharding": "drumheat.runner.sharding",
    "drumheat.compile_cache": "drumheat.runner.compile_cache",
    "drumheat.progress": "drumheat.runner.progress",
    "drumheat.io": "drumheat.results.files",
    "drumheat.vtk_export": "drumheat.results.vtk",
    "drumheat.trajectory": "drumheat.motion.trajectory",
    "drumheat.observe": "drumheat.results.observe",
    "drumheat.advisor": "drumheat.analysis.advisor",
    "drumheat.calibrate": "drumheat.analysis.calibrate",
    "drumheat.thermochromic": "drumheat.experiments.thermochromic",
    "drumheat.thermal.composer": "drumheat.thermal.model",
    "drumheat.thermal.integrate": "drumheat.thermal.solvers",
}


def new_name(fullname: str) -> str | None:
    """The new path of an old module path, or None if it did not move."""
    for old, new in MOVED.items():
        if fullname == old or fullname.startswith(old + "."):
            return new + fullname[len(old):]
    return None


class _Loader(importlib.abc.Loader):
    def __init__(self, old: str, new: str):
        self.old, self.new = old, new

    def create_module(self, spec):
        warnings.warn(f"'{self.old}' moved to '{self.new}'; the old path goes away in the next "
                      "release", DeprecationWarning, stacklevel=3)
        return importlib.import_module(self.new)

    def exec_module(self, module):  # the target module is already executed
        pass


class _Finder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        new = new_name(fullname)
        if new is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _Loader(fullname, new))


def install() -> None:
    """Put the finder of the old paths on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.insert(0, _Finder())  # before the path finder: no second copy
