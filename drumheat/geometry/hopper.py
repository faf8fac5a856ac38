"""The walls of a hopper slice with a staggered tube bundle (kraychev-tube-bundle.md sections 1,
2, 7): side planes, a sloped bottom ending in a slit, and the tubes.

x across the bundle (hopper axis x = 0), y up (y = 0 at the slit lips), z along the tubes. The
side walls at ``x = +-columns s1 / 2`` are symmetry planes of the staggered bundle, so tubes
centred on them are half tubes. The bottom tube row has its tubes at ``x = +-s1/2`` (no tube
right above the slit), the next row at ``x = 0, +-s1``, and so on.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from drumheat.geometry.walls import FixedCylinder, Plane, Segment

__all__ = ["HopperGeometry", "hopper_walls"]


class HopperGeometry(NamedTuple):
    """The walls of the hopper slice and what the measurements need (SI, see module docstring).

    walls: tuple of primitives (side planes, bottom plates, tubes), in wall-index order;
    tube_index: wall index of every tube; tube_center (n_tubes, 2) m; tube_fraction: 1 for a
    full tube, 0.5 for a half tube centred on a side wall; half_width m; slit_width m;
    bundle_lo / bundle_hi: y of the lowest / highest tube centre, m; crest: y of the top of the
    highest tubes, m.
    """

    walls: tuple
    tube_index: np.ndarray
    tube_center: np.ndarray
    tube_fraction: np.ndarray
    half_width: float
    slit_width: float
    bundle_lo: float
    bundle_hi: float
    crest: float


def hopper_walls(h) -> HopperGeometry:
    """Walls of a ``[hopper]`` table (any object with the attributes of
    :class:`drumheat.scene.HopperConfig`)."""
    xw = 0.5 * h.columns * h.pitch
    S = h.slit_width
    R = 0.5 * h.tube_diameter
    walls = [Plane((-xw, 0.0, 0.0), (1.0, 0.0, 0.0), wall_id=0),
             Plane((xw, 0.0, 0.0), (-1.0, 0.0, 0.0), wall_id=1),
             Segment((-xw, h.bottom_height), (-0.5 * S, 0.0), wall_id=2),
             Segment((xw, h.bottom_height), (0.5 * S, 0.0), wall_id=3)]
    y0 = h.bottom_height + h.bundle_clearance + R
    centers, frac = [], []
    tol = 1e-9
    for k in range(h.rows):
        offset = 0.5 * h.pitch if k % 2 == 0 else 0.0
        m = int(math.ceil(xw / h.pitch)) + 1
        for i in range(-m, m + 1):
            x = offset + i * h.pitch
            if abs(x) <= xw + tol:
                centers.append((x, y0 + k * h.row_pitch))
                frac.append(0.5 if abs(abs(x) - xw) <= tol else 1.0)
    tubes = [FixedCylinder(tuple(c), R, temperature=h.tube_temperature, wall_id=4 + k)
             for k, c in enumerate(centers)]
    centers = np.array(centers)
    return HopperGeometry(
        walls=tuple(walls + tubes), tube_index=np.arange(4, 4 + len(tubes)),
        tube_center=centers, tube_fraction=np.array(frac), half_width=xw, slit_width=S,
        bundle_lo=float(y0), bundle_hi=float(y0 + (h.rows - 1) * h.row_pitch),
        crest=float(y0 + (h.rows - 1) * h.row_pitch + R))
