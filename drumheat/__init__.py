"""drumheat: thermal discrete-element simulation of particle beds, written in JAX.

Temperatures and every parameter a user may fit are carried in float64, so importing
drumheat enables JAX's 64-bit mode (``jax_enable_x64``). Mechanics may still run in float32
by asking for it explicitly.

The public API is imported lazily so that ``import drumheat.models.penetration`` stays light::

    import drumheat as dh
    scene = dh.load_scene("weigler-static", overrides={"run.duration": 600.0})
    result = dh.run(scene)
    result.timeseries          # pandas DataFrame: t, T_mean, T_mean:<group>, ...
    ensemble = dh.run_ensemble(scene, {"heat.contact.alpha": [80.0, 105.0, 130.0]})
"""

import importlib

import jax

jax.config.update("jax_enable_x64", True)

from drumheat import _aliases  # noqa: E402

_aliases.install()

__version__ = "0.1.0"

_LAZY = {
    "load_scene": "drumheat.scene",
    "Scene": "drumheat.scene",
    "SceneError": "drumheat.scene",
    "builtin_scenes": "drumheat.scene",
    "run": "drumheat.runner.loop",
    "Result": "drumheat.runner.loop",
    "materials": "drumheat.materials",
    "run_ensemble": "drumheat.runner.ensemble",
    "EnsembleResult": "drumheat.runner.ensemble",
}


def __getattr__(name):
    if name in _LAZY:
        module = importlib.import_module(_LAZY[name])
        return module if name == "materials" else getattr(module, name)
    raise AttributeError(f"module 'drumheat' has no attribute {name!r}")


__all__ = sorted(_LAZY)
