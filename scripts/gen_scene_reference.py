"""Generate the scene-file reference (Markdown) from the declarations in drumheat/scene.py.

Every key comes from :func:`drumheat.scene.iter_keys` (type, unit, default, allowed values,
documentation) and every table's description from its dataclass docstring, so the reference
cannot drift from the code. The documentation build calls :func:`render` through the mkdocs
hook ``docs/hooks/scene_reference.py`` (the page is generated, never committed); run this
script to get the same page as a file::

    python scripts/gen_scene_reference.py                 # to stdout
    python scripts/gen_scene_reference.py --out ref.md
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
import sys
import typing


def _table_docs() -> dict[str, str]:
    """``{table prefix: first docstring paragraph}`` for every table of a scene."""
    from drumheat import scene as sc
    from drumheat.scene.spec import unwrap_optional

    out: dict[str, str] = {"": inspect.getdoc(sc.Scene).split("\n\n")[0]}

    def walk(cls, prefix):
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            if f.metadata.get("internal"):
                continue
            tp, _ = unwrap_optional(hints[f.name])
            if typing.get_origin(tp) is tuple:
                tp, key = typing.get_args(tp)[0], f"{prefix}{f.name}.*"
            elif dataclasses.is_dataclass(tp):
                key = f"{prefix}{f.name}"
            else:
                continue
            doc = inspect.getdoc(tp) or ""
            out[key] = doc.split("\n\n")[0].replace("\n", " ")
            walk(tp, key + ".")

    walk(sc.Scene, "")
    return out


def _cell(text) -> str:
    """Docstring text as one Markdown table cell (reST roles and literals to code spans)."""
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"`\1`", str(text))
    text = text.replace("``", "`").replace("<", "&lt;").replace(">", "&gt;")
    return text.replace("|", "\\|").replace("\n", " ")


def _table_text(text: str) -> str:
    """A table's description without the leading ``[name]``: of its docstring."""
    text = re.sub(r"^``\[{1,2}[^\]]+\]{1,2}``:\s*", "", text)
    return _cell(text[:1].upper() + text[1:])


def _default(value) -> str:
    if value == "required":
        return "**required**"
    if value is None:
        return "unset"
    if isinstance(value, str):
        return f'`"{value}"`'
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, float):
        return f"`{value:g}`"
    return f"`{value}`"


def _heading(prefix: str) -> str:
    if prefix == "":
        return "Top level"
    if prefix.endswith(".*"):
        return f"`[[{prefix[:-2]}]]`"
    return f"`[{prefix}]`"


def render() -> str:
    """The scene reference page as Markdown."""
    from drumheat.scene import iter_keys

    docs = _table_docs()
    tables: dict[str, list] = {}
    for key, type_name, unit, default, allowed, doc in iter_keys():
        prefix, _, _ = key.rpartition(".")
        tables.setdefault(prefix, []).append((key, type_name, unit, default, allowed, doc))
    lines = [
        "# Scene file reference",
        "",
        "<!-- Generated from drumheat/scene.py by scripts/gen_scene_reference.py "
        "(mkdocs hook docs/hooks/scene_reference.py); do not edit. -->",
        "",
        "A scene is a TOML file in SI units with temperatures in kelvin. This page lists every "
        "key the loader accepts, generated from the declarations in `drumheat/scene.py`. "
        "A table that is absent (for example `[heat.wall]`) is not simulated at all; a wrong "
        "value stops the run before any computation with a message naming the key. Every key "
        "can be overridden by its dotted path: `drumheat run SCENE --set run.duration=600` or "
        '`drumheat.load_scene(name, overrides={"groups.0.temperature": 300.0})`; '
        "`groups.*` stands for every group (`groups.0`, `groups.1`, ...).",
        "",
        "Tables: " + ", ".join(f"[{_heading(p)}](#{_anchor(p)})" for p in tables)
        + ".",
        "",
    ]
    for prefix, rows in tables.items():
        lines += [f"## {_heading(prefix)} {{ #{_anchor(prefix)} }}", ""]
        if docs.get(prefix):
            lines += [_table_text(docs[prefix]), ""]
        lines += ["| key | type | unit | default | allowed | description |",
                  "|---|---|---|---|---|---|"]
        for key, type_name, unit, default, allowed, doc in rows:
            lines.append(f"| `{key}` | {_cell(type_name)} | {_cell(unit) or '-'} | "
                         f"{_default(default)} | {_cell(allowed)} | {_cell(doc)} |")
        lines.append("")
    return "\n".join(lines)


def _anchor(prefix: str) -> str:
    return "top-level" if prefix == "" else prefix.replace(".*", "").replace(".", "-")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", help="write to this file instead of stdout")
    args = parser.parse_args(argv)
    text = render()
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            fh.write(text)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
