"""A new scene file from a built-in scene: ``drumheat new FILE --from SCENE --set KEY=VALUE``.

The new file is the template's own text, comments included (they explain why each value is
what it is), with the name changed, each override written into its table (an existing
``key = value`` line is edited in place and marked ``# changed by drumheat new``; a missing key
is added under its table's header; a missing table is appended) and a header saying where the
file came from and how to run it. The result is read back and checked like any scene before
the file is written, so a bad override never leaves a file behind.
"""

from __future__ import annotations

import datetime
import re
import textwrap
from pathlib import Path
from typing import Any

from drumheat.scene.files import load_scene, read_scene_dict
from drumheat.scene.spec import SceneError, parse_override

__all__ = ["new_scene_text", "write_new_scene"]

_HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\-]+)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_\-]+)\s*=")


def _toml_value(value: Any) -> str:
    import tomli_w

    return tomli_w.dumps({"v": value}).split("=", 1)[1].strip()


def _sections(lines: list[str]) -> list[tuple[str, int, int]]:
    """``(table path, first line, end line)`` of each table; array-of-tables entries get their
    index (``groups.0``, ``groups.1``); the top-level keys are the table ``""``."""
    heads, seen = [("", -1)], {}
    for i, line in enumerate(lines):
        m = _HEADER.match(line)
        if m:
            path = m.group(2)
            if m.group(1) == "[[":
                k = seen.get(path, 0)
                seen[path] = k + 1
                path = f"{path}.{k}"
            heads.append((path, i))
    out = []
    for k, (path, start) in enumerate(heads):
        end = heads[k + 1][1] if k + 1 < len(heads) else len(lines)
        out.append((path, start, end))
    return out


def _set_line(lines: list[str], key: str, value: Any) -> list[str]:
    """``lines`` with the dotted ``key`` set to ``value`` (None removes the key or table)."""
    table, _, leaf = key.rpartition(".")
    sections = _sections(lines)
    if value is None:  # remove a whole table (an effect switched off) or one key
        for path, start, end in sections:
            if path == key or path.startswith(key + "."):
                return lines[:max(start, 0)] + lines[end:]
        for path, start, end in sections:
            if path == table:
                return [ln for i, ln in enumerate(lines) if not (
                    start < i < end and (m := _KEY.match(ln)) and m.group(1) == leaf)]
        return lines
    text = f"{leaf} = {_toml_value(value)}"
    for path, start, end in sections:
        if path != table:
            continue
        for i in range(start + 1, end):
            m = _KEY.match(lines[i])
            if m and m.group(1) == leaf:
                return lines[:i] + [f"{text}  # changed by drumheat new"] + lines[i + 1:]
        at = start + 1 if start >= 0 else _first_table(lines)
        return lines[:at] + [f"{text}  # added by drumheat new"] + lines[at:]
    if table.split(".")[-1].isdigit():
        raise SceneError(key, value, "no such entry in the template (its arrays of tables "
                         "have fewer entries)")
    return lines + ["", f"[{table}]", f"{text}  # added by drumheat new"]


def _first_table(lines: list[str]) -> int:
    """Where top-level keys may be added: before the first table header."""
    for i, line in enumerate(lines):
        if _HEADER.match(line):
            while i > 0 and lines[i - 1].lstrip().startswith("#"):
                i -= 1
            return i
    return len(lines)


def new_scene_text(template: str | Path, name: str,
                   overrides: dict[str, Any] | list[str] | None = None) -> str:
    """The text of a new scene file made from ``template`` (a built-in name or a scene file).

    Main arguments:
      template: built-in scene name (``drumheat scenes``) or path to a ``.toml`` file.
      name: the new scene's ``name``.
      overrides: dotted-key values as a dict or as ``KEY=VALUE`` strings (as ``--set``).

    Raises:
      SceneError: a bad override or template, naming the key (checked on the new text).
    """
    _, src = read_scene_dict(template)
    lines = Path(src).read_text().splitlines()
    if isinstance(overrides, (list, tuple)):
        overrides = dict(parse_override(o) for o in overrides)
    overrides = dict(overrides or {})
    overrides["name"] = name
    for key, value in overrides.items():
        lines = _set_line(lines, key, value)
    changed = ", ".join(f"{k}={_toml_value(v) if v is not None else 'none'}"
                        for k, v in overrides.items() if k not in ("name", "description"))
    src_name = Path(src).stem
    if "description" not in overrides:
        raw, _ = read_scene_dict(template)
        desc = f"From {src_name}" + (f" with {changed}" if changed else "") + ": " + \
            raw.get("description", "")
        lines = _set_line(lines, "description", desc)
    made = (f"{name}: made by `drumheat new` from the scene {src_name} on "
            f"{datetime.date.today().isoformat()}" + (f", changed: {changed}." if changed
                                                      else "."))
    head = ["# " + ln for ln in textwrap.wrap(made, 96, break_on_hyphens=False)]
    head += [f"# Run it:             drumheat run {name}.toml",
             f"# Cost before a run:  drumheat estimate {name}.toml (steps, wall time)",
             "# The comments below are the template's: they say why each value was chosen "
             "there; check",
             "# them against your changes. The scene reference (docs) lists every key.", ""]
    return "\n".join(head + lines) + "\n"


def write_new_scene(path: str | Path, template: str | Path,
                    overrides: dict[str, Any] | list[str] | None = None,
                    force: bool = False) -> Path:
    """Write a new scene file at ``path`` made from ``template`` (see :func:`new_scene_text`);
    its name is the file's stem. Checked before it is written; an existing file is kept unless
    ``force``."""
    path = Path(path)
    if path.suffix != ".toml":
        path = path.with_suffix(".toml")
    if path.exists() and not force:
        raise FileExistsError(f"{path} exists; choose another name or pass --force")
    text = new_scene_text(template, path.stem, overrides)
    tmp = path.with_name(f".{path.name}.new")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp.write_text(text)
    try:
        load_scene(tmp)  # the new file must be a valid scene (relative paths as at path)
    except SceneError:
        tmp.unlink()
        raise
    tmp.replace(path)
    return path
