"""Motion models: how the particles of a scene move, on one contract (:mod:`.base`).

Each model registers itself under its ``[motion] model`` name: ``static``, ``random``
(semi-discrete penetration model), ``replay`` (recorded contacts), ``dem`` (DEM in a drum),
``granulator`` (a slag droplet's flight), ``fluidized`` (a batch fluidised bed),
``moving_bed`` (a hopper with a tube bundle) and ``pneumatic`` (a riser channel).
"""

from drumheat.motion import (dem, fluidized, granulator, moving_bed, pneumatic,  # noqa: F401
                             random, replay, static)
from drumheat.motion.base import MOTIONS, AbstractMotion, register
from drumheat.motion.trajectory import Trajectory
from drumheat.scene import Scene

__all__ = ["AbstractMotion", "MOTIONS", "Trajectory", "make_motion", "register"]


def make_motion(scene: Scene) -> AbstractMotion:
    """The motion model of a scene (its ``[motion] model``), set up from the scene."""
    return MOTIONS[scene.motion.model](scene)
