"""mkdocs hook: generate ``scene-reference.md`` from ``drumheat.scene.iter_keys()`` at build
time (the page is never committed, so it cannot go stale). The Markdown comes from
``scripts/gen_scene_reference.py``."""

from __future__ import annotations

import importlib.util
from pathlib import Path

from mkdocs.structure.files import File

PAGE = "scene-reference.md"


def _render(config) -> str:
    root = Path(config.config_file_path).resolve().parent
    path = root / "scripts" / "gen_scene_reference.py"
    spec = importlib.util.spec_from_file_location("_gen_scene_reference", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.render()


def on_files(files, config):
    existing = files.get_file_from_path(PAGE)
    if existing is not None:
        files.remove(existing)
    files.append(File.generated(config, PAGE, content=_render(config)))
    return files
