"""Closed-form relations of the linear soft-sphere contact: stiffness from Young's modulus, the
critical time step (weigler-thermal-dem.md section 4, eqs. [2.1], [2.3]) and the explicit limit
of the tangential dashpot on a particle's spin.

Used by the scene checks (a DEM time step above the critical one is refused when the scene is
read) and by the DEM (:mod:`drumheat.mechanics`).
"""

from __future__ import annotations

import math

__all__ = ["normal_stiffness_from_youngs", "critical_time_step", "dashpot_time_step",
           "default_time_step", "STICKING_CONTACTS"]

#: sticking contacts of one particle assumed by :func:`dashpot_time_step`: the most a sphere
#: has in a monolayer (hexagonal, the 2D drums) and the mean coordination of a jammed 3D
#: packing (isostatic, 2 x 3)
STICKING_CONTACTS = 6


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


def dashpot_time_step(m_min, gamma_pair, gamma_wall, contacts=STICKING_CONTACTS):
    """Largest time step at which the tangential dashpots keep a particle's spin stable (s).

    Derived here from drumheat's integrator (no reference digest covers it). The velocity-
    Verlet step evaluates the dashpots with the half-step velocities, i.e. explicitly: a
    velocity damped at the rate ``lambda`` (``dv/dt = -lambda v``) is updated as
    ``v <- (1 - lambda dt) v``, which alternates in sign for ``lambda dt > 1`` and grows for
    ``lambda dt > 2`` (with the spring as well, the leapfrog amplification matrix has
    determinant ``1 - lambda dt``: stable while ``lambda dt < 2`` and ``omega dt < 2``).
    The fastest damped motion of a dense bed is a spin: a solid sphere (``I = 2/5 m r^2``,
    ``r^2 / I = 5 / (2 m)``) whose ``z`` sticking contacts all brake it. If its particle
    neighbours spin the same way, every contact slips at ``2 r omega``, so
    ``lambda = z 2 gamma_pp r^2 / I = 5 z gamma_pp / m``; against a wall (which does not spin)
    ``lambda = 5 z gamma_pw / (2 m)``. The limit is ``2 / lambda`` for the larger of the two.
    Above it the contacts of a resting bed chatter between sticking and sliding at half the
    step frequency (the dashpot force reverses every step until the Coulomb cap stops it).

    Main arguments:
      m_min: mass of the lightest particle, kg.
      gamma_pair: largest tangential damping coefficient of particle-particle contacts of that
        particle, ``2 zeta_t sqrt(m* k_t)`` with ``m* = m_min / 2`` (N s/m).
      gamma_wall: the same for particle-wall contacts, ``m* = m_min`` (N s/m).

    Other arguments:
      contacts: sticking contacts of the particle (default :data:`STICKING_CONTACTS`).

    For equal spheres with ``k_t = k_n`` this is ``(sqrt(2) / (5 z zeta_t)) sqrt(m/k)``, i.e.
    ``0.0236 / zeta_t`` times ``t_crit`` of :func:`critical_time_step` at z = 6 (0.079 t_crit at
    zeta_t = 0.3). Without tangential damping there is no limit (``inf``).
    """
    rate = 2.5 * contacts * max(2.0 * gamma_pair, gamma_wall) / m_min
    return math.inf if rate <= 0 else 2.0 / rate


def default_time_step(t_crit, safety_factor, t_dashpot) -> tuple[float, bool]:
    """The default DEM step, s: the smaller of ``safety_factor x t_crit``
    (:func:`critical_time_step`) and the dashpot limit ``t_dashpot`` (:func:`dashpot_time_step`),
    and whether the dashpot limit set it."""
    step = safety_factor * t_crit
    return (t_dashpot, True) if t_dashpot < step else (step, False)
