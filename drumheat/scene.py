"""Scene description: immutable dataclasses, TOML load/save, validation with clear errors.

A scene file (TOML, SI units, temperatures in kelvin) has the tables of ``DESIGN.md``
(``[run]``, ``[drum]``, ``[[groups]]``, ``[gas]``, ``[heat.*]``, ``[motion]``) and
``[packing]``. Every key is declared once below as a dataclass field with its unit, default,
constraint and documentation; the loader and the scene-file reference are generated from these
declarations. To add an effect, declare its table as a dataclass and add one field to
:class:`HeatConfig`.

Every bad value is rejected before any computation by :class:`SceneError`, whose message names
the dotted key, the value and what is allowed.

Examples
--------
>>> scene = load_scene("weigler-static", overrides={"run.duration": 600.0})
>>> scene.groups[0].temperature
299.15
"""

from __future__ import annotations

import dataclasses
import importlib.resources
import math
import tomllib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from drumheat.materials import GASES, MATERIALS

_REQUIRED = dataclasses.MISSING


class SceneError(ValueError):
    """A scene value is missing, unknown or not allowed.

    Attributes
    ----------
    key : str
        Dotted path of the offending key, e.g. ``groups.0.diameter``.
    value : Any
        The value given (``None`` if missing).
    allowed : str
        What would be accepted.
    """

    def __init__(self, key: str, value: Any, allowed: str, scene: str | None = None):
        self.key, self.value, self.allowed, self.scene = key, value, allowed, scene
        where = f"scene {scene!r}: " if scene else ""
        if value is _MISSING_VALUE:
            msg = f"{where}required key '{key}' is missing; {allowed}."
        else:
            msg = f"{where}key '{key}' = {value!r} is not allowed; {allowed}."
        super().__init__(msg)


_MISSING_VALUE = object()


def spec(default: Any = _REQUIRED, *, unit: str = "", doc: str = "", gt: float | None = None,
         ge: float | None = None, lt: float | None = None, le: float | None = None,
         choices: tuple | None = None, default_factory: Any = _REQUIRED):
    """Declare a scene key: a dataclass field with unit, documentation and constraints."""
    meta = dict(unit=unit, doc=doc, gt=gt, ge=ge, lt=lt, le=le, choices=choices)
    if default_factory is not _REQUIRED:
        return field(default_factory=default_factory, metadata=meta)
    return field(default=default, metadata=meta)


# ---------------------------------------------------------------------------------------------
# Tables
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RunConfig:
    """``[run]``: duration, output and the thermal integrator."""

    duration: float = spec(unit="s", gt=0, doc="Simulated process time.")
    output_interval: float = spec(unit="s", gt=0, doc="Time between recorded outputs.")
    seed: int = spec(1, ge=0, doc="Seed of every random choice (packing, re-mixing).")
    solver: str = spec("adaptive", choices=("adaptive", "implicit", "explicit"),
                       doc="Thermal integrator: 'adaptive' (diffrax Tsit5 with error control), "
                           "'implicit' (diffrax Kvaerno5, for stiff scenes) or 'explicit' "
                           "(fixed-step forward Euler that checks dt < m c / sum(alpha A)).")
    rtol: float = spec(1e-8, gt=0, lt=1, doc="Relative tolerance of the adaptive solvers.")
    atol: float = spec(1e-6, unit="K", gt=0, doc="Absolute tolerance of the adaptive solvers.")
    dt: Optional[float] = spec(None, unit="s", gt=0,
                               doc="Step of the explicit thermal solver; default: 0.5 times "
                                   "its stability limit.")


@dataclass(frozen=True)
class DrumConfig:
    """``[drum]``: the drum shell (axis through the origin, along z in 3D)."""

    diameter: float = spec(unit="m", gt=0, doc="Inner drum diameter.")
    rpm: float = spec(0.0, unit="1/min", doc="Rotation speed, positive counter-clockwise "
                                             "seen from +z.")
    wall_temperature: Optional[float] = spec(None, unit="K", gt=0,
                                             doc="Shell temperature; leave out for a wall that "
                                                 "exchanges no heat.")
    depth: Optional[float] = spec(None, unit="m", gt=0,
                                  doc="Axial length of a 3D drum slice (dim = 3).")


@dataclass(frozen=True)
class GroupConfig:
    """``[[groups]]``: one table per particle group (fraction)."""

    name: str = spec(doc="Group name; time series column T_mean:<name>.")
    count: int = spec(ge=1, doc="Number of particles.")
    diameter: float = spec(unit="m", gt=0, doc="Particle diameter.")
    material: str = spec(choices=tuple(sorted(MATERIALS)),
                         doc="Material from the library (drumheat.materials).")
    temperature: float = spec(unit="K", gt=0, doc="Initial temperature.")
    density: Optional[float] = spec(None, unit="kg/m3", gt=0, doc="Overrides the material's.")
    heat_capacity: Optional[float] = spec(None, unit="J/(kg K)", gt=0,
                                          doc="Overrides the material's.")
    conductivity: Optional[float] = spec(None, unit="W/(m K)", gt=0,
                                         doc="Overrides the material's.")
    youngs_modulus: Optional[float] = spec(None, unit="Pa", gt=0, doc="Overrides the material's.")
    poisson_ratio: Optional[float] = spec(None, ge=0, lt=0.5, doc="Overrides the material's.")
    emissivity: Optional[float] = spec(None, ge=0, le=1, doc="Overrides the material's.")


@dataclass(frozen=True)
class GasConfig:
    """``[gas]``: the gas surrounding the particles."""

    temperature: float = spec(unit="K", gt=0, doc="Gas (chamber air) temperature.")
    pressure: float = spec(101325.0, unit="Pa", gt=0, doc="Gas pressure.")
    material: str = spec("air", choices=tuple(sorted(GASES)), doc="Gas from the library.")
    conductivity: Optional[float] = spec(None, unit="W/(m K)", gt=0,
                                         doc="Overrides the library's conductivity.")


@dataclass(frozen=True)
class ContactConfig:
    """``[heat.contact]``: particle-particle contact conduction (weigler eq. [2.7])."""

    model: str = spec("constant", choices=("constant", "schluender"),
                      doc="'constant': alpha as given; 'schluender': alpha_pp from the gas and "
                          "the particle diameter (weigler eqs. [2.9], [2.10]).")
    alpha: Optional[float] = spec(None, unit="W/(m2 K)", gt=0,
                                  doc="alpha_pp on the projected area pi d^2/4; required for "
                                      "model 'constant'.")


@dataclass(frozen=True)
class WallConfig:
    """``[heat.wall]``: particle-wall contact conduction (weigler eq. [2.7])."""

    model: str = spec("constant", choices=("constant", "schluender"),
                      doc="'constant': alpha as given; 'schluender': alpha_wp from the gas and "
                          "the particle diameter (weigler eq. [2.8]).")
    alpha: Optional[float] = spec(None, unit="W/(m2 K)", gt=0,
                                  doc="alpha_wp on the projected area pi d^2/4; required for "
                                      "model 'constant'.")


@dataclass(frozen=True)
class LossConfig:
    """``[heat.loss]``: lumped heat loss to the gas (weigler eq. [2.7], section 7.5)."""

    alphaA: float = spec(unit="W/K", ge=0, doc="(alpha A)_WK per particle.")


@dataclass(frozen=True)
class HeatConfig:
    """``[heat]``: the heat-transfer effects; an absent table is not simulated."""

    contact: Optional[ContactConfig] = spec(None, doc="Particle-particle contact conduction.")
    wall: Optional[WallConfig] = spec(None, doc="Particle-wall contact conduction.")
    loss: Optional[LossConfig] = spec(None, doc="Heat loss to the gas.")

    def effects(self) -> tuple[str, ...]:
        """Names of the effects this scene switches on."""
        return tuple(f.name for f in dataclasses.fields(self) if getattr(self, f.name) is not None)


#: Motion models and the class implementing each ("module:Class", imported on use).
MOTION_MODELS = {
    "static": "drumheat.mixing.static:StaticBed",
    "random": "drumheat.mixing.random:RandomBed",
}


@dataclass(frozen=True)
class MotionConfig:
    """``[motion]``: how the particles move."""

    model: str = spec("static", choices=tuple(MOTION_MODELS),
                      doc="'static': a resting packing, contacts found once from geometry; "
                          "'random': the semi-discrete penetration model, a resting packing "
                          "whose particle temperatures are re-mixed every t_R "
                          "(weigler-thermal-dem.md section 6.1, 11.1).")
    t_R: Optional[float] = spec(None, unit="s", gt=0,
                                doc="Re-mixing period of model 'random' (the rest time of the "
                                    "penetration model, weigler eq. [1.1]).")
    remix: str = spec("permute", choices=("permute", "mean"),
                      doc="Model 'random': 'permute' shuffles the temperatures over the fixed "
                          "positions (the thesis' choice), 'mean' sets every particle to the "
                          "bed mean.")


@dataclass(frozen=True)
class PackingConfig:
    """``[packing]``: how the initial packing is made and how contacts are found in it."""

    method: str = spec("deposition", choices=("deposition", "file"),
                       doc="'deposition': particles dropped one by one at random positions roll "
                           "down to a stable rest (drumheat.mechanics.deposition); 'file': "
                           "positions from an .npz file.")
    arrangement: str = spec("layers", choices=("layers", "mixed"),
                            doc="'layers': groups poured one after the other (first group at "
                                "the bottom); 'mixed': pouring order shuffled.")
    contact_tolerance: float = spec(0.01, ge=0, lt=0.5,
                                    doc="Two surfaces closer than this fraction of the smaller "
                                        "diameter count as touching.")
    file: Optional[str] = spec(None, doc="Packing .npz (arrays position, diameter, group) for "
                                         "method 'file'; relative to the scene file.")


@dataclass(frozen=True)
class Scene:
    """A complete, validated scene. Build with :func:`load_scene` or :func:`scene_from_dict`."""

    name: str = spec(doc="Scene name; default result folder results/<name>.")
    run: RunConfig = spec(doc="Duration, output and integrator.")
    drum: DrumConfig = spec(doc="The drum.")
    groups: tuple[GroupConfig, ...] = spec(doc="Particle groups, at least one.")
    description: str = spec("", doc="One line shown by `drumheat scenes`.")
    dim: int = spec(2, choices=(2, 3), doc="2: a monolayer of spheres in a drum slice; 3: a 3D "
                                           "bed.")
    gas: Optional[GasConfig] = spec(None, doc="Surrounding gas.")
    heat: HeatConfig = spec(default_factory=HeatConfig, doc="Heat-transfer effects.")
    motion: MotionConfig = spec(default_factory=MotionConfig, doc="Motion model.")
    packing: PackingConfig = spec(default_factory=PackingConfig, doc="Initial packing.")
    source_path: Optional[str] = field(default=None, compare=False,
                                       metadata=dict(internal=True))

    # -- convenience ---------------------------------------------------------------------
    @property
    def n_particles(self) -> int:
        return sum(g.count for g in self.groups)

    def to_dict(self) -> dict:
        """The scene as a plain dict (what a TOML file holds); unset optional keys omitted."""
        return _to_dict(self)

    def to_toml(self) -> str:
        """The scene as TOML text that :func:`load_scene` reads back to an equal scene."""
        import tomli_w

        return tomli_w.dumps(self.to_dict())

    def get(self, path: str) -> Any:
        """Value at a dotted path, e.g. ``scene.get("groups.0.temperature")``."""
        obj: Any = self
        for part in path.split("."):
            obj = obj[int(part)] if isinstance(obj, tuple) else getattr(obj, part)
        return obj

    def with_overrides(self, overrides: dict[str, Any]) -> "Scene":
        """A new validated scene with dotted-path overrides applied."""
        raw = self.to_dict()
        for key, value in overrides.items():
            _set_path(raw, key, value, self.name)
        return scene_from_dict(raw, source_path=self.source_path)


# ---------------------------------------------------------------------------------------------
# Generic loader
# ---------------------------------------------------------------------------------------------


def _unwrap_optional(tp):
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
    tp, _ = _unwrap_optional(tp)
    allowed = _allowed_text(meta, tp)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise SceneError(key, value, "must be a table", scene_name)
        return _build(tp, value, key, scene_name)
    if typing.get_origin(tp) is tuple:
        (item_tp, _ellipsis) = typing.get_args(tp)
        if not isinstance(value, list) or not value:
            raise SceneError(key, value, "must be a non-empty array of tables", scene_name)
        return tuple(_convert(v, item_tp, {}, f"{key}.{i}", scene_name) for i, v in enumerate(value))
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
    if meta.get("choices") is not None and value not in meta["choices"]:
        raise SceneError(key, value, allowed, scene_name)
    for k, ok in (("gt", lambda v, b: v > b), ("ge", lambda v, b: v >= b),
                  ("lt", lambda v, b: v < b), ("le", lambda v, b: v <= b)):
        if meta.get(k) is not None and not ok(value, meta[k]):
            raise SceneError(key, value, allowed, scene_name)
    return value


def _build(cls, table: dict, prefix: str, scene_name):
    hints = typing.get_type_hints(cls)
    known = {f.name: f for f in dataclasses.fields(cls) if not f.metadata.get("internal")}
    for k in table:
        if k not in known:
            key = f"{prefix}.{k}" if prefix else k
            raise SceneError(key, table[k], "unknown key; known keys here: "
                             + ", ".join(sorted(known)), scene_name)
    kwargs = {}
    for name, f in known.items():
        key = f"{prefix}.{name}" if prefix else name
        if name in table:
            kwargs[name] = _convert(table[name], hints[name], f.metadata, key, scene_name)
        elif f.default is _REQUIRED and f.default_factory is _REQUIRED:
            tp, _ = _unwrap_optional(hints[name])
            raise SceneError(key, _MISSING_VALUE, _allowed_text(f.metadata, tp), scene_name)
    return cls(**kwargs)


def _to_dict(obj) -> Any:
    if dataclasses.is_dataclass(obj):
        out = {}
        for f in dataclasses.fields(obj):
            if f.metadata.get("internal"):
                continue
            v = getattr(obj, f.name)
            if v is None:
                continue
            out[f.name] = _to_dict(v)
        return out
    if isinstance(obj, tuple):
        return [_to_dict(v) for v in obj]
    return obj


def _set_path(raw: dict, key: str, value: Any, scene_name=None) -> None:
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
        obj[int(last)] = value
    else:
        obj[last] = value


def parse_override(text: str) -> tuple[str, Any]:
    """Parse ``KEY=VALUE`` (VALUE as a TOML value; bare words are strings)."""
    if "=" not in text:
        raise SceneError(text, text, "overrides look like KEY=VALUE, e.g. run.duration=600")
    key, raw = text.split("=", 1)
    key, raw = key.strip(), raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key, value


def _check_consistency(s: Scene) -> None:
    n = s.name
    if s.run.output_interval > s.run.duration:
        raise SceneError("run.output_interval", s.run.output_interval,
                         f"must be <= run.duration = {s.run.duration:g} s", n)
    names = [g.name for g in s.groups]
    for i, g in enumerate(s.groups):
        if names.index(g.name) != i:
            raise SceneError(f"groups.{i}.name", g.name, "group names must be unique", n)
        if g.diameter >= s.drum.diameter:
            raise SceneError(f"groups.{i}.diameter", g.diameter,
                             f"must be smaller than drum.diameter = {s.drum.diameter:g} m", n)
    if s.dim == 3 and s.drum.depth is None:
        raise SceneError("drum.depth", _MISSING_VALUE, "a 3D scene (dim = 3) needs the axial "
                         "length of the drum slice, in m", n)
    if s.dim == 2:
        solid = sum(g.count * math.pi * g.diameter**2 / 4 for g in s.groups)
        drum = math.pi * s.drum.diameter**2 / 4
        if solid > 0.8 * drum:
            raise SceneError("groups", f"{s.n_particles} particles",
                             f"the particles cover {solid / drum:.0%} of the drum cross-section; "
                             "a monolayer packing holds at most about 80 %", n)
    if s.heat.wall is not None and s.drum.wall_temperature is None:
        raise SceneError("drum.wall_temperature", _MISSING_VALUE,
                         "[heat.wall] needs the wall temperature, in K", n)
    for eff in ("contact", "wall"):
        cfg = getattr(s.heat, eff)
        if cfg is not None and cfg.model == "constant" and cfg.alpha is None:
            raise SceneError(f"heat.{eff}.alpha", _MISSING_VALUE,
                             "model 'constant' needs alpha, a number > 0 in W/(m2 K)", n)
        if cfg is not None and cfg.model == "schluender" and cfg.alpha is not None:
            raise SceneError(f"heat.{eff}.alpha", cfg.alpha,
                             "model 'schluender' computes alpha; leave alpha out or use "
                             "model 'constant'", n)
    if s.heat.loss is not None and s.gas is None:
        raise SceneError("gas.temperature", _MISSING_VALUE,
                         "[heat.loss] needs the gas temperature, in K", n)
    if s.motion.model == "random" and s.motion.t_R is None:
        raise SceneError("motion.t_R", _MISSING_VALUE, "model 'random' needs the re-mixing "
                         "period t_R, a number > 0 in s", n)
    if s.packing.method == "file" and s.packing.file is None:
        raise SceneError("packing.file", _MISSING_VALUE, "method 'file' needs a path to an .npz "
                         "packing", n)
    if s.motion.model in ("static", "random") and s.dim == 3 and s.packing.method != "file":
        raise SceneError("dim", 3, "the static deposition packing is 2D; a 3D static bed needs "
                         "packing.method = 'file'", n)


def scene_from_dict(raw: dict, source_path: str | None = None) -> Scene:
    """Validate a plain dict (as read from TOML) and build a :class:`Scene`."""
    name = raw.get("name") if isinstance(raw.get("name"), str) else None
    scene = _build(Scene, raw, "", name)
    scene = dataclasses.replace(scene, source_path=source_path)
    _check_consistency(scene)
    return scene


# ---------------------------------------------------------------------------------------------
# Built-in scenes and files
# ---------------------------------------------------------------------------------------------


def _scene_dir():
    return importlib.resources.files("drumheat") / "scenes"


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
            raise SceneError("SCENE", str(name_or_path), "not a scene file; built-in scenes: "
                             + ", ".join(builtin_scenes()))
        text, src = entry.read_text(), str(entry)
    try:
        return tomllib.loads(text), src
    except tomllib.TOMLDecodeError as err:
        raise SceneError("SCENE", str(name_or_path), f"not valid TOML ({err})") from None


def load_scene(name_or_path: str | Path, overrides: dict[str, Any] | list[str] | None = None
               ) -> Scene:
    """Load and validate a built-in scene (by name) or a TOML scene file (by path).

    Parameters
    ----------
    name_or_path : str or Path
        A built-in scene name (see ``drumheat scenes``) or a path to a ``.toml`` file.
    overrides : dict or list of str, optional
        Dotted-path overrides applied before validation, as a dict
        (``{"groups.0.temperature": 300.0}``) or as ``KEY=VALUE`` strings (as ``--set``).

    Raises
    ------
    SceneError
        For every bad, unknown or missing value, naming the key.
    """
    raw, src = read_scene_dict(name_or_path)
    if isinstance(overrides, (list, tuple)):
        overrides = dict(parse_override(o) for o in overrides)
    for key, value in (overrides or {}).items():
        _set_path(raw, key, value, raw.get("name"))
    return scene_from_dict(raw, source_path=src)


def iter_keys(cls=Scene, prefix: str = ""):
    """Yield ``(dotted_key, type_name, unit, default, allowed, doc)`` for every scene key.

    Used to generate the scene-file reference; ``groups.*`` stands for every group.
    """
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if f.metadata.get("internal"):
            continue
        key = f"{prefix}{f.name}"
        tp, optional = _unwrap_optional(hints[f.name])
        if typing.get_origin(tp) is tuple:
            yield from iter_keys(typing.get_args(tp)[0], f"{key}.*.")
            continue
        if dataclasses.is_dataclass(tp):
            yield from iter_keys(tp, f"{key}.")
            continue
        default = "required" if f.default is _REQUIRED else f.default
        yield (key, _type_name(tp), f.metadata.get("unit", ""), default,
               _allowed_text(f.metadata, tp), f.metadata.get("doc", ""))
