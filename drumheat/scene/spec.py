"""How a scene key is declared and checked: ``spec``, :class:`Table`, :class:`SceneError`.

Every key of a scene is a field of a frozen dataclass (a *table*) declared with :func:`spec`:
unit, default, allowed values and documentation in one place. A table checks its own values
when it is constructed, whichever way that happens (from a TOML file, from a dict, or by calling
the class in Python), so a scene that exists is a valid scene::

    >>> GroupConfig(name="glass", count=70, diameter=-0.004, material="glass",
    ...             temperature=300.0)
    Traceback (most recent call last):
    SceneError: key 'groups.*.diameter' = -0.004 is not allowed; must be a number > 0 in m.

A table built inside a scene names the exact key (``groups.0.diameter``) and the scene.
Cross-table rules (a [heat.wall] table needs a wall temperature, ...) are checked by the
:class:`~drumheat.scene.tables.Scene` itself (:mod:`drumheat.scene.rules`).
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import difflib
import math
import tomllib
import types
import typing
from dataclasses import field
from typing import Any

__all__ = ["SceneError", "REQUIRED", "spec", "Table", "build_table", "building", "iter_table_keys", "to_dict",
           "set_path", "parse_override",
           "did_you_mean"]


#: absolute temperatures below this (K) are refused as a likely unit mistake (degC for K)
MIN_TEMPERATURE = 100.0


class _Required:
    def __repr__(self):
        return "REQUIRED"


#: default of a key that must be given
REQUIRED: Any = _Required()


class SceneError(ValueError):
    """A scene value is missing, unknown or not allowed.

    Attributes
    ----------
    key : str
        Dotted path of the offending key, e.g. ``groups.0.diameter``.
    value : Any
        The value given (:data:`REQUIRED` if missing).
    allowed : str
        What would be accepted.
    scene : str or None
        Name of the scene, where known.
    """

    def __init__(self, key: str, value: Any, allowed: str, scene: str | None = None):
        self.key, self.value, self.allowed, self.scene = key, value, allowed, scene
        where = f"scene {scene!r}: " if scene else ""
        if value is REQUIRED:
            msg = f"{where}required key '{key}' is missing; {allowed}."
        else:
            msg = f"{where}key '{key}' = {value!r} is not allowed; {allowed}."
        super().__init__(msg)


def did_you_mean(word: str, choices) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``choices``, or an empty string."""
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.65)
    return f" (did you mean '{close[0]}'?)" if close else ""


def spec(default: Any = REQUIRED, *, unit: str = "", doc: str = "", gt: float | None = None,
         ge: float | None = None, lt: float | None = None, le: float | None = None,
         choices: tuple | None = None, default_factory: Any = None,
         required_when: Any = None):
    """Declare a scene key: a dataclass field with unit, documentation and constraints.

    ``required_when(table) -> bool`` makes an optional key required depending on the table
    being built (e.g. ``[drum]`` for the motion models that need a drum).
    """
    meta = dict(unit=unit, doc=doc, gt=gt, ge=ge, lt=lt, le=le, choices=choices,
                required_when=required_when)
    if default_factory is not None:
        return field(default_factory=default_factory, metadata=meta)
    return field(default=default, metadata=meta)


# ---------------------------------------------------------------------------------------------
# where a table is being built: its dotted prefix and the scene's name
# ---------------------------------------------------------------------------------------------

_WHERE: contextvars.ContextVar = contextvars.ContextVar("drumheat_scene_where", default=None)


@contextlib.contextmanager
def building(prefix: str, scene_name: str | None):
    token = _WHERE.set((prefix, scene_name))
    try:
        yield
    finally:
        _WHERE.reset(token)


def _where(cls) -> tuple[str, str | None]:
    w = _WHERE.get()
    return w if w is not None else (getattr(cls, "TABLE", ""), None)


def _key(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


# ---------------------------------------------------------------------------------------------
# types and conversion
# ---------------------------------------------------------------------------------------------

_HINTS: dict = {}


def _hints(cls) -> dict:
    if cls not in _HINTS:
        _HINTS[cls] = typing.get_type_hints(cls)
    return _HINTS[cls]


def unwrap_optional(tp):
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return args[0], True
    return tp, False


def _type_name(tp) -> str:
    if dataclasses.is_dataclass(tp):
        return "a table"
    if typing.get_origin(tp) is tuple:
        return "an array of tables"
    return {float: "a number", int: "an integer", str: "a string", bool: "true or false"}[tp]


def _allowed_text(meta: dict, tp) -> str:
    parts = []
    if meta.get("choices"):
        parts.append("allowed: " + ", ".join(repr(c) for c in meta["choices"]))
    else:
        parts.append(f"must be {_type_name(tp)}")
    for key, op in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
        if meta.get(key) is not None:
            parts.append(f"{op} {meta[key]:g}")
    if meta.get("unit"):
        parts.append(f"in {meta['unit']}")
    return " ".join(parts)


def _convert(value, tp, meta, key, scene_name):
    """``value`` converted to the declared type ``tp`` and checked against ``meta``."""
    tp, _ = unwrap_optional(tp)
    allowed = _allowed_text(meta, tp)
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if not isinstance(value, dict):
            raise SceneError(key, value, "must be a table", scene_name)
        return build_table(tp, value, key, scene_name)
    if typing.get_origin(tp) is tuple:
        (item_tp, _ellipsis) = typing.get_args(tp)
        if not isinstance(value, (list, tuple)) or not value:
            raise SceneError(key, value, "must be a non-empty array of tables", scene_name)
        return tuple(_convert(v, item_tp, {}, f"{key}.{i}", scene_name)
                     for i, v in enumerate(value))
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(key, value, allowed, scene_name)
        value = float(value)
        if not math.isfinite(value):
            raise SceneError(key, value, allowed + " (finite)", scene_name)
    elif tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                raise SceneError(key, value, allowed, scene_name)
    elif tp is str:
        if not isinstance(value, str):
            raise SceneError(key, value, allowed, scene_name)
    elif tp is bool:
        if not isinstance(value, bool):
            raise SceneError(key, value, allowed, scene_name)
    if (meta.get("unit") == "K" and key.rsplit(".", 1)[-1].endswith("temperature")
            and isinstance(value, float) and 0 < value < MIN_TEMPERATURE):
        raise SceneError(key, value, f"temperatures are in kelvin, and {value:g} K looks like "
                         f"degrees Celsius ({value:g} degC = {value + 273.15:g} K); "
                         f"temperatures below {MIN_TEMPERATURE:g} K are refused", scene_name)
    if meta.get("choices") is not None and value not in meta["choices"]:
        raise SceneError(key, value, allowed + did_you_mean(value, meta["choices"]), scene_name)
    for k, ok in (("gt", lambda v, b: v > b), ("ge", lambda v, b: v >= b),
                  ("lt", lambda v, b: v < b), ("le", lambda v, b: v <= b)):
        if meta.get(k) is not None and not ok(value, meta[k]):
            raise SceneError(key, value, allowed, scene_name)
    return value


# ---------------------------------------------------------------------------------------------
# tables
# ---------------------------------------------------------------------------------------------


class Table:
    """Base of every scene table: checks and converts its fields when constructed.

    Subclasses are frozen dataclasses whose fields are declared with :func:`spec`; the class
    attribute ``TABLE`` is the table's dotted path in a scene file (``"heat.contact"``,
    ``"groups.*"``). A subclass may add cross-field rules of its own in :meth:`check`.
    """

    TABLE = ""

    def __post_init__(self):
        prefix, scene_name = _where(type(self))
        hints = _hints(type(self))
        for f in dataclasses.fields(self):
            if f.metadata.get("internal"):
                continue
            key = _key(prefix, f.name)
            value = getattr(self, f.name)
            tp, optional = unwrap_optional(hints[f.name])
            when = f.metadata.get("required_when")
            if value is REQUIRED or (value is None and when is not None and when(self)):
                raise SceneError(key, REQUIRED, _allowed_text(f.metadata, tp), scene_name)
            if value is None:
                if not optional:
                    raise SceneError(key, value, _allowed_text(f.metadata, tp), scene_name)
                continue
            new = _convert(value, hints[f.name], f.metadata, key, scene_name)
            if new is not value:
                object.__setattr__(self, f.name, new)
        self.check(prefix, scene_name)

    def check(self, prefix: str, scene_name: str | None) -> None:
        """Cross-field rules of this table (none by default); raise :class:`SceneError`."""

    def replace(self, **changes):
        """A copy with some keys changed (checked again)."""
        return dataclasses.replace(self, **changes)


def build_table(cls, table: dict, prefix: str = "", scene_name: str | None = None, **extra):
    """Build table class ``cls`` from a dict (as read from TOML), naming keys under ``prefix``.

    Unknown keys are refused with the known ones (and the closest match) named. ``extra`` are
    keyword arguments that are not scene keys (e.g. the scene's ``source_path``).
    """
    known = [f.name for f in dataclasses.fields(cls) if not f.metadata.get("internal")]
    for k in table:
        if k not in known:
            raise SceneError(_key(prefix, k), table[k], "unknown key" + did_you_mean(k, known)
                             + "; known keys here: " + ", ".join(sorted(known)), scene_name)
    with building(prefix, scene_name):
        return cls(**table, **extra)


def iter_table_keys(cls, prefix: str = ""):
    """Yield ``(dotted_key, type_name, unit, default, allowed, doc)`` for every key of ``cls``.

    Used to generate the scene-file reference; ``groups.*`` stands for every group.
    """
    hints = _hints(cls)
    for f in dataclasses.fields(cls):
        if f.metadata.get("internal"):
            continue
        key = f"{prefix}{f.name}"
        tp, optional = unwrap_optional(hints[f.name])
        if typing.get_origin(tp) is tuple:
            yield from iter_table_keys(typing.get_args(tp)[0], f"{key}.*.")
            continue
        if dataclasses.is_dataclass(tp):
            yield from iter_table_keys(tp, f"{key}.")
            continue
        default = "required" if f.default is REQUIRED else f.default
        yield (key, _type_name(tp), f.metadata.get("unit", ""), default,
               _allowed_text(f.metadata, tp), f.metadata.get("doc", ""))


def to_dict(obj) -> Any:
    """A table as a plain dict (what a TOML file holds); unset optional keys omitted."""
    if dataclasses.is_dataclass(obj):
        out = {}
        for f in dataclasses.fields(obj):
            if f.metadata.get("internal"):
                continue
            v = getattr(obj, f.name)
            if v is None:
                continue
            out[f.name] = to_dict(v)
        return out
    if isinstance(obj, tuple):
        return [to_dict(v) for v in obj]
    return obj


def set_path(raw: dict, key: str, value: Any, scene_name=None) -> None:
    """Set the value at a dotted path in a raw scene dict (creating tables on the way);
    a value None removes the key."""
    parts = key.split(".")
    obj: Any = raw
    for i, part in enumerate(parts[:-1]):
        here = ".".join(parts[: i + 1])
        if isinstance(obj, list):
            if not part.isdigit() or int(part) >= len(obj):
                raise SceneError(here, part, f"index must be 0..{len(obj) - 1}", scene_name)
            obj = obj[int(part)]
        else:
            nxt = obj.get(part)
            if nxt is None:
                nxt = obj[part] = {}
            elif not isinstance(nxt, (dict, list)):
                raise SceneError(here, nxt, "is a value, not a table", scene_name)
            obj = nxt
    last = parts[-1]
    if isinstance(obj, list):
        if not last.isdigit() or int(last) >= len(obj):
            raise SceneError(key, last, f"index must be 0..{len(obj) - 1}", scene_name)
        if value is None:
            raise SceneError(key, None, "a group cannot be removed by an override", scene_name)
        obj[int(last)] = value
    elif value is None:
        obj.pop(last, None)
    else:
        obj[last] = value


def parse_override(text: str) -> tuple[str, Any]:
    """Parse ``KEY=VALUE`` (VALUE as a TOML value; bare words are strings; ``none`` removes
    the key, e.g. ``heat.radiation=none`` switches radiation off)."""
    if "=" not in text:
        raise SceneError(text, text, "overrides look like KEY=VALUE, e.g. run.duration=600")
    key, raw = text.split("=", 1)
    key, raw = key.strip(), raw.strip()
    if raw.lower() == "none":
        return key, None  # removes the key: switches an effect table off
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key, value
