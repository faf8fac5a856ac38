"""From a scene to particle arrays: groups, sizes, materials, initial temperatures, packing.

Values that a user may fit are read through a ``value(dotted_key)`` getter so that a
calibration can pass traced numbers in place of the scene's (see :func:`scene_values`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import jax.numpy as jnp
import numpy as np

from drumheat.materials import material
from drumheat.mechanics.deposition import Packing, deposit_2d
from drumheat.scene import Scene, SceneError
from drumheat.thermal.particles import ThermalParticles


def scene_values(scene: Scene, params: dict[str, Any] | None = None) -> Callable[[str], Any]:
    """Getter of scene values by dotted key, with ``params`` taking precedence.

    ``params`` may hold JAX tracers (for gradients); missing keys fall back to the scene.
    """
    params = params or {}

    def value(key: str):
        return params[key] if key in params else scene.get(key)

    return value


def group_index(scene: Scene) -> np.ndarray:
    """Group index of every particle, shape (N,), particles numbered group by group."""
    return np.concatenate([np.full(g.count, k, dtype=np.int32) for k, g in enumerate(scene.groups)])


def group_property(scene: Scene, value, k: int, prop: str):
    """A material property of group ``k``: the scene's override or the library value."""
    g = scene.groups[k]
    if getattr(g, prop) is not None:
        return value(f"groups.{k}.{prop}")
    return getattr(material(g.material), prop)


def make_particles(scene: Scene, value) -> ThermalParticles:
    """Particles as heat reservoirs (sphere masses, weigler-thermal-dem.md section 4)."""
    group = group_index(scene)
    per_group = lambda f: jnp.stack([jnp.asarray(f(k), float) for k in range(len(scene.groups))])
    diameter = per_group(lambda k: value(f"groups.{k}.diameter"))[group]
    density = per_group(lambda k: group_property(scene, value, k, "density"))[group]
    c = per_group(lambda k: group_property(scene, value, k, "heat_capacity"))[group]
    return ThermalParticles.spheres(diameter, density, c)


def initial_temperatures(scene: Scene, value):
    """Initial temperature of every particle, K, shape (N,)."""
    T = jnp.stack([jnp.asarray(value(f"groups.{k}.temperature"), float)
                   for k in range(len(scene.groups))])
    return T[group_index(scene)]


def initial_packing(scene: Scene) -> Packing:
    """The scene's initial packing: geometric deposition or an ``.npz`` file."""
    group = group_index(scene)
    diameter = np.concatenate([np.full(g.count, g.diameter) for g in scene.groups])
    if scene.packing.method == "file":
        path = Path(scene.packing.file)
        if not path.is_absolute() and scene.source_path:
            path = Path(scene.source_path).parent / path
        if not path.exists():
            raise SceneError("packing.file", scene.packing.file, "no such file", scene.name)
        packing = Packing.load(path)
        if packing.position.shape != (len(group), scene.dim):
            raise SceneError("packing.file", scene.packing.file,
                             f"holds {packing.position.shape[0]} particles in "
                             f"{packing.position.shape[1]}D; the scene has {len(group)} in "
                             f"{scene.dim}D", scene.name)
        return Packing(packing.position, diameter, group)
    return deposit_2d(diameter, group, scene.drum.diameter, seed=scene.run.seed,
                      arrangement=scene.packing.arrangement)


def output_times(scene: Scene) -> np.ndarray:
    """Output times 0, dt_out, 2 dt_out, ..., duration (the last one always included)."""
    run = scene.run
    n = int(np.floor(run.duration / run.output_interval + 1e-9))
    t = np.arange(n + 1) * run.output_interval
    if run.duration - t[-1] > 1e-9 * run.duration:
        t = np.append(t, run.duration)
    return t
