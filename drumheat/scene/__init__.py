"""Scenes: the tables of a scene file, each checking itself; TOML load and save; built-in scenes.

Build a scene from a file or a built-in name with :func:`load_scene`, or in Python from its
tables (each accepts keyword arguments, nested tables also as dicts)::

    from drumheat.scene import Scene, load_scene

    scene = load_scene("weigler-static").replace({"heat.contact.alpha": 120.0})
    scene.without("heat.loss").save("mine.toml")

Layer 2 of drumheat (docs/architecture.md): imports only :mod:`drumheat.materials`.
"""

from drumheat.scene.files import builtin_scenes, load_scene, read_scene_dict, scene_from_dict
from drumheat.scene.rules import (DRUM_MOTION_MODELS, MOTION_MODEL_NAMES,
                                  check_apparatus_tables, check_scene)
from drumheat.scene.spec import REQUIRED, SceneError, Table, parse_override, spec, to_dict
from drumheat.scene.tables import (CONVECTION_CORRELATIONS, ChannelConfig, ContactConfig,
                                   ConvectionConfig, DEMConfig, DrumConfig, EntranceConfig,
                                   FrictionConfig, GasConfig, GranulatorConfig, GroupConfig,
                                   HeatConfig, HopperConfig, InternalConfig, LossConfig,
                                   MotionConfig, PackingConfig, RadiationConfig,
                                   RadiationSurface, ReplayConfig, RunConfig,
                                   Scene, WallConfig, iter_keys)

__all__ = [
    "Scene", "SceneError", "load_scene", "builtin_scenes", "scene_from_dict", "read_scene_dict",
    "parse_override", "iter_keys", "to_dict", "spec", "Table", "REQUIRED", "check_scene",
    "check_apparatus_tables", "MOTION_MODEL_NAMES", "DRUM_MOTION_MODELS",
    "CONVECTION_CORRELATIONS", "RunConfig", "DrumConfig", "GroupConfig", "GasConfig",
    "HeatConfig", "ContactConfig", "WallConfig", "LossConfig", "ConvectionConfig",
    "RadiationConfig", "RadiationSurface", "InternalConfig", "FrictionConfig", "MotionConfig",
    "PackingConfig", "DEMConfig", "ReplayConfig", "GranulatorConfig", "ChannelConfig",
    "HopperConfig", "EntranceConfig",
]
