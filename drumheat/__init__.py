"""drumheat: thermal discrete-element simulation of particle beds, written in JAX.

Temperatures and every parameter a user may fit are carried in float64, so importing drumheat
enables JAX's 64-bit mode (``jax_enable_x64``). Mechanics may still run in float32 by asking
for it explicitly.

The public API, in one namespace (``dir(drumheat)`` lists it; each name is imported on first
use, so ``import drumheat.models.penetration`` stays light)::

    import drumheat as dh

    scene = dh.load_scene("weigler-static").replace({"run.duration": 600.0})
    result = dh.run(scene)                       # a Result
    result.timeseries                            # pandas DataFrame: t, T_mean, T_mean:<group>
    dh.plot(result)                              # mean temperatures over time
    dh.explain(scene)                            # which heat-transfer effects matter
    ensemble = dh.run_ensemble(scene, {"heat.contact.alpha": [80.0, 105.0, 130.0]})
    fit = dh.fit(scene, "measured.csv", ["heat.loss.alphaA"])

A scene can be built in Python from its tables (``dh.Scene(name=..., run=dh.RunConfig(...),
...)``, nested tables also as dicts), edited (``scene.replace``, ``scene.without``) and saved
(``scene.save``); see docs/python-scenes.md.
"""

import importlib

import jax

jax.config.update("jax_enable_x64", True)

from drumheat import _aliases  # noqa: E402
from drumheat._version import __version__  # noqa: E402

_aliases.install()

#: public name -> module that defines it
_API = {
    # scenes
    "load_scene": "drumheat.scene", "Scene": "drumheat.scene", "SceneError": "drumheat.scene",
    "builtin_scenes": "drumheat.scene",
    **{name: "drumheat.scene" for name in (
        "RunConfig", "DrumConfig", "GroupConfig", "GasConfig", "HeatConfig", "ContactConfig",
        "WallConfig", "LossConfig", "ConvectionConfig", "RadiationConfig", "RadiationSurface",
        "InternalConfig", "FrictionConfig", "MotionConfig", "PackingConfig", "DEMConfig",
        "ReplayConfig", "GranulatorConfig", "ChannelConfig", "HopperConfig", "EntranceConfig")},
    # running
    "run": "drumheat.runner.loop", "run_ensemble": "drumheat.runner.ensemble",
    "EnsembleResult": "drumheat.runner.ensemble", "Result": "drumheat.results.result",
    # results
    "plot": "drumheat.results.plot", "animate": "drumheat.results.animate",
    "export_vtk": "drumheat.results.vtk", "particle_table": "drumheat.results.particles",
    # analysis
    "explain": "drumheat.analysis.advisor", "fit": "drumheat.analysis.calibrate",
    "Experiment": "drumheat.analysis.calibrate",
    "calibrate_lambda_bed": "drumheat.analysis.calibrate",
}
#: public modules, imported on first use
_MODULES = {"materials": "drumheat.materials", "observe": "drumheat.results.observe",
            "models": "drumheat.models"}

__all__ = sorted(list(_API) + list(_MODULES) + ["__version__"])


def __getattr__(name):
    if name in _API:
        value = getattr(importlib.import_module(_API[name]), name)
    elif name in _MODULES:
        value = importlib.import_module(_MODULES[name])
    else:
        raise AttributeError(f"module 'drumheat' has no attribute {name!r}")
    globals()[name] = value  # later lookups do not come here again
    return value


def __dir__():
    return __all__
