"""drumheat.geometry: analytic wall primitives (signed distance, normal, wall velocity)."""

from drumheat.geometry.walls import (  # noqa: F401
    Box,
    DrumShell,
    EndPlate,
    FixedCylinder,
    InnerCylinder,
    Plane,
    RadialPlate,
    Wall,
    expand_walls,
    rpm_to_omega,
    wall_bounds,
    walls_at_rest,
)

__all__ = [
    "Box", "DrumShell", "EndPlate", "FixedCylinder", "InnerCylinder", "Plane", "RadialPlate",
    "Wall", "expand_walls", "rpm_to_omega", "wall_bounds", "walls_at_rest",
]
