"""Schluender contact heat-transfer coefficients (sphere-wall and sphere-sphere).

Source: weigler-thermal-dem.md, section 3: equations [2.8] (= [1.8]), [2.9], [2.10] and
appendix A3 (modified mean free path, accommodation coefficient), with the calculation
parameters of Table 8-1 (dry air at 30 degC and 1 atm).

All functions are jnp-based and differentiable; arguments may be arrays (broadcast).
"""

from __future__ import annotations

import jax.numpy as jnp

from drumheat.materials import R_UNIVERSAL


def accommodation_coefficient(T, C=2.8):
    """Thermal accommodation coefficient gamma of the gas on the solid surface.

    weigler-thermal-dem.md, appendix A3: ``log10(1/gamma - 1) = 0.6 - (1000 K / T + 1) / C``.

    Parameters
    ----------
    T : array_like
        Gas temperature, K.
    C : array_like
        Gas constant of the correlation (2.8 for air).
    """
    x = 0.6 - (1000.0 / T + 1.0) / C
    return 1.0 / (1.0 + 10.0**x)


def mean_free_path(T, p, conductivity, heat_capacity, molar_mass, C=2.8):
    """Modified mean free path l of the gas molecules, m.

    weigler-thermal-dem.md, appendix A3::

        l = 2 (2 - gamma)/gamma * sqrt(2 pi R T / M) * lambda_g / (p (2 c_p - R/M))

    Parameters
    ----------
    T : array_like
        Gas temperature, K.
    p : array_like
        Gas pressure, Pa.
    conductivity : array_like
        Gas conductivity lambda_g, W/(m K).
    heat_capacity : array_like
        Gas c_p, J/(kg K).
    molar_mass : array_like
        kg/kmol (R = 8314 J/(kmol K)).
    C : array_like
        Accommodation constant (2.8 for air).
    """
    gamma = accommodation_coefficient(T, C)
    R_spec = R_UNIVERSAL / molar_mass
    return (
        2.0 * (2.0 - gamma) / gamma
        * jnp.sqrt(2.0 * jnp.pi * R_spec * T)
        * conductivity
        / (p * (2.0 * heat_capacity - R_spec))
    )


def _bracket(d_p, l):
    return (1.0 + 2.0 * l / d_p) * jnp.log1p(d_p / (2.0 * l)) - 1.0


def alpha_wall_particle(d_p, conductivity, l):
    """Sphere-on-flat-wall contact coefficient alpha_wp, W/(m2 K).

    weigler-thermal-dem.md, eq. [2.8]::

        alpha_wp = (4 lambda_g / d_p) [ (1 + 2 l/d_p) ln(1 + d_p/(2 l)) - 1 ]

    Parameters
    ----------
    d_p : array_like
        Particle diameter, m.
    conductivity : array_like
        Gas conductivity, W/(m K).
    l : array_like
        Modified mean free path, m (:func:`mean_free_path`).
    """
    return 4.0 * conductivity / d_p * _bracket(d_p, l)


def alpha_particle_particle(d_p, conductivity, l):
    """Sphere-sphere contact coefficient alpha_pp = alpha_wp / 2, W/(m2 K).

    weigler-thermal-dem.md, eqs. [2.9], [2.10]: the gas gap between two spheres is taken as
    doubled, which halves the coefficient.
    """
    return 0.5 * alpha_wall_particle(d_p, conductivity, l)


def contact_coefficients(d_p, T=303.15, p=101325.0, conductivity=0.0266, heat_capacity=1009.0,
                         molar_mass=28.96, C=2.8):
    """Both Schluender coefficients for a particle diameter and gas state.

    Defaults are the calculation parameters of weigler-thermal-dem.md Table 8-1 (dry air,
    30 degC, 1 atm), which give alpha_wp = 209.8 / 114.1 W/(m2 K) for d_p = 4 / 8 mm.

    Returns
    -------
    (alpha_wp, alpha_pp) : tuple of arrays, W/(m2 K)
    """
    l = mean_free_path(T, p, conductivity, heat_capacity, molar_mass, C)
    a_wp = alpha_wall_particle(d_p, conductivity, l)
    return a_wp, 0.5 * a_wp
