"""Analysis of DEM states: dynamic angle of repose, kinetic energy, bed centre of mass."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["free_surface", "angle_of_repose", "center_of_mass"]


def free_surface(position, radius, bin_width=None, central_fraction=0.6):
    """Free-surface points of a bed: the highest particle top in each bin across the drum.

    Gravity is along -y and the drum axis along z. The horizontal extent ``[x_min, x_max]``
    of the bed (particle centres) is split into bins of ``bin_width`` (default 1.5 x the mean
    diameter) along x, and in 3D also along z; in each bin the particle with the highest top
    ``y + r`` is a surface point ``(x, [z,] y + r)``. Only bins whose centre lies in the
    middle ``central_fraction`` of ``[x_min, x_max]`` are kept: near the wall the surface bends
    (it meets the shell) and is excluded.

    Returns (K, dim) surface points; columns x, y(top) in 2D and x, y(top), z in 3D.
    """
    pos = np.asarray(position, dtype=float)
    r = np.broadcast_to(np.asarray(radius, dtype=float), pos.shape[:1])
    dim = pos.shape[1]
    if bin_width is None:
        bin_width = 3.0 * float(np.mean(r))
    x = pos[:, 0]
    top = pos[:, 1] + r
    x_lo, x_hi = float(x.min()), float(x.max())
    mid = 0.5 * (x_lo + x_hi)
    half = 0.5 * central_fraction * (x_hi - x_lo)
    nb_x = max(1, int(math.ceil((x_hi - x_lo) / bin_width)))
    ix = np.clip(((x - x_lo) / bin_width).astype(int), 0, nb_x - 1)
    if dim == 3:
        z = pos[:, 2]
        nb_z = max(1, int(math.ceil((z.max() - z.min()) / bin_width)))
        iz = np.clip(((z - z.min()) / bin_width).astype(int), 0, nb_z - 1)
        key = ix * nb_z + iz
    else:
        key = ix
    pts = []
    for k in np.unique(key):
        sel = np.flatnonzero(key == k)
        best = sel[np.argmax(top[sel])]
        cx = x_lo + (ix[best] + 0.5) * bin_width
        if abs(cx - mid) > half:
            continue
        row = [x[best], top[best]] + ([pos[best, 2]] if dim == 3 else [])
        pts.append(row)
    return np.asarray(pts, dtype=float).reshape(-1, dim)


def angle_of_repose(position, radius, bin_width=None, central_fraction=0.6):
    """Dynamic angle of repose (degrees) of a bed in a drum, from a straight-line fit.

    Method: the free-surface points of :func:`free_surface` (highest particle top per bin
    across the central part of the bed) are fitted by least squares with a line
    ``y = a + b x`` (2D) or a plane ``y = a + b x + c z`` (3D, z = drum axis); the angle is
    ``atan(b)`` in degrees, positive when the surface rises towards +x. A drum turning
    counter-clockwise (rpm > 0) lifts the bed on the +x side, so its angle is positive.

    ``position`` may be one state (N, dim) or a series (T, N, dim); a series gives an array of
    T angles (average them over a steady interval for the dynamic angle).
    """
    pos = np.asarray(position, dtype=float)
    if pos.ndim == 3:
        return np.array([angle_of_repose(p, radius, bin_width, central_fraction) for p in pos])
    pts = free_surface(pos, radius, bin_width, central_fraction)
    if len(pts) < 2:
        raise ValueError("too few surface points for a fit; use a smaller bin_width")
    cols = [np.ones(len(pts)), pts[:, 0]]
    if pos.shape[1] == 3:
        cols.append(pts[:, 2])
    A = np.stack(cols, axis=1)
    coef, *_ = np.linalg.lstsq(A, pts[:, 1], rcond=None)
    return math.degrees(math.atan(coef[1]))


def center_of_mass(position, mass=None):
    """Mass-weighted centre (m) of the particles (equal masses if ``mass`` is None)."""
    pos = np.asarray(position, dtype=float)
    if mass is None:
        return pos.mean(axis=0)
    m = np.asarray(mass, dtype=float)
    return (m[:, None] * pos).sum(axis=0) / m.sum()
