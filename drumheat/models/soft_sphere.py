"""Closed-form relations of the linear soft-sphere contact: stiffness from Young's modulus and
the critical time step (weigler-thermal-dem.md section 4, eqs. [2.1], [2.3]).

Used by the scene checks (a DEM time step above the critical one is refused when the scene is
read) and by the DEM (:mod:`drumheat.mechanics`).
"""

from __future__ import annotations

import math

__all__ = ["normal_stiffness_from_youngs", "critical_time_step"]


def normal_stiffness_from_youngs(youngs_modulus, diameter):
    """Linear contact stiffness ``k_n = E A_p / d_p`` with ``A_p = pi d_p^2 / 4`` (N/m).

    Weigler digest [2.3] (elastic-bar analogy; with the linear model ``k_s = k_n``).
    Aluminium, E = 7e10 Pa, d = 4 mm gives 2.2e8 N/m (Table 2-1: 2.18e8).
    """
    return youngs_modulus * (math.pi * diameter**2 / 4.0) / diameter


def critical_time_step(m_min, k_max):
    """Mechanical critical time step ``t_crit = 2 sqrt(m_min / k_max)`` (s), Weigler digest [2.1].

    ``k_max`` is the largest contact stiffness (normal or tangential, particle or wall).
    """
    return 2.0 * math.sqrt(m_min / k_max)
