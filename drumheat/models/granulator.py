"""Geometry and process numbers of the dry slag granulator (staltner-slag-particle.md sections 1,
4, 8): the droplet speed, the droplet's paths and the wall heat per kilogram of slag.

The functions take the ``[granulator]`` table (any object with its attributes: ``r2``, ``h3``,
``h4``, ``alpha4`` in degrees, ``disc_height``, ``disc_diameter``, ``disc_speed``,
``slag_rate``).

Paths (digest note in section 1, a reconstruction): the disc sits at ``z_D = h3 + h4/2`` unless
``disc_height`` says otherwise; the droplet hits the cone at radius ``r_w = r2 - (z_D -
h3)/tan(alpha4)`` (``s_1 = r_w``), is reflected specularly and falls at the angle ``2 alpha4``
below the outward horizontal (``s_3 = z_D / sin(2 alpha4)``). Sub-phase 3* (inside the conical
freeboard) is the fraction ``(z_D - h3)/z_D`` of Phase 3.
"""

from __future__ import annotations

import math

__all__ = ["droplet_speed", "wall_heat_per_mass", "path_geometry"]


def droplet_speed(g) -> float:
    """``v_S = 0.8 pi d_Dt n_Dt`` in m/s, staltner-slag-particle.md [4.1] (n_Dt in 1/min)."""
    return 0.8 * math.pi * g.disc_diameter * g.disc_speed / 60.0


def wall_heat_per_mass(g) -> float:
    """``Q_W / m_S`` in J/kg: Q_W [MW] = 0.0036207 m_S[kg/min] - 0.1139 ([4.8], [4.9])."""
    Q_W = (0.0036207 * g.slag_rate - 0.1139) * 1e6
    return Q_W / (g.slag_rate / 60.0)


def path_geometry(g) -> dict:
    """Disc height, impact radius, path lengths and the landing point (module docstring)."""
    a = math.radians(g.alpha4)
    z_D = g.disc_height if g.disc_height is not None else g.h3 + 0.5 * g.h4
    r_w = g.r2 - (z_D - g.h3) / math.tan(a)
    s1 = r_w
    s3 = z_D / math.sin(2.0 * a)
    rho_land = r_w + s3 * math.cos(2.0 * a)
    return dict(z_disc=z_D, r_wall=r_w, s1=s1, s3=s3, rho_land=rho_land,
                fbk_fraction=(z_D - g.h3) / z_D)
