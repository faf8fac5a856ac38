"""Scene files: built-in scenes, loading with overrides, TOML in and out.

``load_scene(name_or_path, overrides)`` is the documented entry point: a built-in scene by name
(``drumheat scenes`` lists them) or a TOML file by path, with dotted-key overrides applied
before the scene is checked.
"""

from __future__ import annotations

import importlib.resources
import tomllib
from pathlib import Path
from typing import Any

from drumheat.scene.rules import CHECK_FILES
from drumheat.scene.spec import SceneError, build_table, did_you_mean, parse_override, set_path
from drumheat.scene.tables import Scene

__all__ = ["builtin_scenes", "load_scene", "read_scene_dict", "scene_from_dict"]


def scene_from_dict(raw: dict, source_path: str | None = None) -> Scene:
    """Validate a plain dict (as read from TOML) and build a :class:`Scene`."""
    name = raw.get("name") if isinstance(raw.get("name"), str) else None
    return build_table(Scene, raw, "", name, source_path=source_path)


# ---------------------------------------------------------------------------------------------
# Built-in scenes and files
# ---------------------------------------------------------------------------------------------


def _scene_dir():
    return importlib.resources.files("drumheat.scene") / "builtin"


def builtin_scenes() -> dict[str, str]:
    """Built-in scenes: ``{name: description}``, sorted by name."""
    out = {}
    for entry in sorted(_scene_dir().iterdir(), key=lambda p: p.name):
        if entry.name.endswith(".toml"):
            raw = tomllib.loads(entry.read_text())
            out[raw.get("name", entry.name[:-5])] = raw.get("description", "")
    return out


def read_scene_dict(name_or_path: str | Path) -> tuple[dict, str | None]:
    """Raw dict of a built-in scene (by name) or a scene file (by path), and its path."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.exists():
            raise SceneError("SCENE", str(name_or_path), "no such scene file")
        text, src = path.read_text(), str(path.resolve())
    else:
        entry = _scene_dir() / f"{name_or_path}.toml"
        if not entry.is_file():
            names = builtin_scenes()
            raise SceneError("SCENE", str(name_or_path), "not a scene file"
                             + did_you_mean(name_or_path, names) + "; built-in scenes: "
                             + ", ".join(names))
        text, src = entry.read_text(), str(entry)
    try:
        return tomllib.loads(text), src
    except tomllib.TOMLDecodeError as err:
        raise SceneError("SCENE", str(name_or_path), f"not valid TOML ({err})") from None


def load_scene(name_or_path: str | Path, overrides: dict[str, Any] | list[str] | None = None,
               *, check_files: bool = True) -> Scene:
    """Load and validate a built-in scene (by name) or a TOML scene file (by path).

    Parameters
    ----------
    name_or_path : str or Path
        A built-in scene name (see ``drumheat scenes``) or a path to a ``.toml`` file.
    overrides : dict or list of str, optional
        Dotted-path overrides applied before validation, as a dict
        (``{"groups.0.temperature": 300.0}``) or as ``KEY=VALUE`` strings (as ``--set``).
    check_files : bool
        Check the files the scene names (a packing, a recording); off to read the scene of a
        result folder, whose input files need not be at hand.

    Raises
    ------
    SceneError
        For every bad, unknown or missing value, naming the key.
    """
    raw, src = read_scene_dict(name_or_path)
    if isinstance(overrides, (list, tuple)):
        overrides = dict(parse_override(o) for o in overrides)
    for key, value in (overrides or {}).items():
        set_path(raw, key, value, raw.get("name"))
    token = CHECK_FILES.set(check_files)
    try:
        return scene_from_dict(raw, source_path=src)
    finally:
        CHECK_FILES.reset(token)
