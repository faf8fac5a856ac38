"""Penetration model (PM) of Schluender/Mollekopf for wall heating of a mixed bed.

Closed-form engineering model, written as small pure ``jax.numpy`` functions so that they take
scalars or arrays, broadcast, and can be differentiated with :func:`jax.grad` (e.g. a fit of
``lambda_bed`` to a measured mean-temperature curve).

All quantities are SI: rotational speed in revolutions per minute (``rpm``, the one exception,
because that is how drums are specified; it is converted to n = rpm/60 in 1/s), lengths in m,
times in s, temperatures in K, coefficients in W/(m^2 K), conductivities in W/(m K), densities
in kg/m^3, heat capacities in J/(kg K).

Source: ``reference/weigler-thermal-dem.md`` (digest of Weigler 2012), section 2, eqs.
[1.1]-[1.12], and section 11.2 (eqs. [5.1], [5.3], [5.4]).

The model in one paragraph: the bed rests for periods of length t_R (eq. [1.1]-[1.4]); during
a period it takes up heat from the wall like a semi-infinite body (penetration coefficient
alpha_bed, eq. [1.12]); at the end of the period it is mixed perfectly. The wall-to-first-layer
resistance 1/alpha_ws (eq. [1.7]) and the bed resistance 1/alpha_bed are in series (eq. [1.6]);
the overall alpha is constant in time, so the mean bed temperature relaxes exponentially
(eq. [1.10]).

Example
-------
>>> import drumheat
>>> from drumheat.models import penetration as pm
>>> t_R = pm.rest_time(10.0, 0.25)                    # ~ 40.9 s
>>> a = pm.alpha_overall(114.0, 0.9, 1274.0, 836.0, t_R)
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = [
    "G",
    "froude",
    "mixing_number",
    "rest_time",
    "alpha_wall_bed",
    "alpha_bed",
    "alpha_bed_instantaneous",
    "alpha_overall",
    "mean_temperature",
    "lambda_bed_from_alpha_bed",
    "thermal_mixing_time",
]

#: Gravitational acceleration used by the thesis, m/s^2 (weigler-thermal-dem.md, section 2).
G = 9.81

# Mollekopf (1983) drum constants of eq. [1.3] (weigler-thermal-dem.md, section 2).
_C_DRUM = 16.0
_X_DRUM = 0.2


def _rev_per_s(rpm):
    """Rotational frequency n in 1/s from revolutions per minute."""
    return jnp.asarray(rpm, dtype=float) / 60.0


def froude(rpm, diameter, g=G):
    """Froude number of a rotating drum.

    weigler-thermal-dem.md, eq. [1.4]: ``Fr = (2 pi n)^2 D / (2 g)``, i.e. omega^2 R / g with
    omega = 2 pi n and R = D/2.

    Parameters
    ----------
    rpm : array_like
        Rotational speed in revolutions per minute (n = rpm/60 in 1/s).
    diameter : array_like
        Drum (inner) diameter D, m.
    g : float, optional
        Gravitational acceleration, m/s^2 (default 9.81).

    Returns
    -------
    jax.Array
        Fr, dimensionless. For D = 0.25 m and 10 rpm, Fr ~ 0.0140 (digest note, section 2).
    """
    omega = 2.0 * jnp.pi * _rev_per_s(rpm)
    return omega**2 * jnp.asarray(diameter, dtype=float) / (2.0 * g)


def mixing_number(rpm, diameter, C=_C_DRUM, x=_X_DRUM, g=G):
    """Number of drum revolutions needed for perfect mixing.

    weigler-thermal-dem.md, eq. [1.3]: ``N_mix = C Fr^x`` with C = 16, x = 0.2 for drums
    (Mollekopf 1983); Fr from eq. [1.4].

    Parameters
    ----------
    rpm : array_like
        Rotational speed, revolutions per minute.
    diameter : array_like
        Drum diameter D, m.
    C, x : float, optional
        Empirical constants of eq. [1.3] (default 16 and 0.2).
    g : float, optional
        Gravitational acceleration, m/s^2.

    Returns
    -------
    jax.Array
        N_mix, dimensionless (number of revolutions). D = 0.25 m, 10 rpm gives ~ 6.81.
    """
    return C * froude(rpm, diameter, g) ** x


def rest_time(rpm, diameter, C=_C_DRUM, x=_X_DRUM, g=G):
    """Rest time t_R of the penetration model (length of one resting period).

    weigler-thermal-dem.md, eqs. [1.1]-[1.2]: ``t_R = t_mix N_mix = N_mix / n`` with
    t_mix = 1/n and N_mix from eq. [1.3]. [5.4] uses the same value as the PM's thermal mixing
    time.

    Because Fr is proportional to n^2, t_R = C (2 pi)^(2x) (D/(2g))^x n^(2x-1); this form is
    used so that a resting drum (rpm = 0) gives t_R = inf (for x < 1/2) instead of 0/0.

    Parameters
    ----------
    rpm : array_like
        Rotational speed, revolutions per minute (> 0 for a finite rest time).
    diameter : array_like
        Drum diameter D, m.
    C, x : float, optional
        Empirical constants of eq. [1.3] (default 16 and 0.2).
    g : float, optional
        Gravitational acceleration, m/s^2.

    Returns
    -------
    jax.Array
        t_R in s. D = 0.25 m and 10 rpm give ~ 40.9 s (the thesis rounds to 40 s).
    """
    n = _rev_per_s(rpm)
    D = jnp.asarray(diameter, dtype=float)
    return C * (2.0 * jnp.pi) ** (2.0 * x) * (D / (2.0 * g)) ** x * n ** (2.0 * x - 1.0)


def alpha_wall_bed(alpha_wp, phi=0.8):
    """Wall-to-bed (first particle layer) heat-transfer coefficient.

    weigler-thermal-dem.md, eq. [1.7]: ``alpha_ws = Phi alpha_wp``, with Phi the coverage of the
    wall by the bed (projected over contact area), Phi = 0.8 for a monodisperse sphere bed, and
    alpha_wp the Schluender sphere-on-plane coefficient (eq. [1.8]/[2.8]).

    Note (digest item 12.9): the thesis' analysis scripts (A7/A8) instead use alpha_wp itself
    with a wall area d_p^2 per wall contact; since (pi d^2/4)/d^2 = pi/4 ~ 0.785 ~ Phi the two
    conventions are close, but not identical.

    Parameters
    ----------
    alpha_wp : array_like
        Particle-wall contact coefficient, W/(m^2 K).
    phi : array_like, optional
        Wall coverage Phi, dimensionless (default 0.8).

    Returns
    -------
    jax.Array
        alpha_ws, W/(m^2 K).
    """
    return jnp.asarray(phi, dtype=float) * jnp.asarray(alpha_wp, dtype=float)


def alpha_bed(lambda_bed, rho_bed, c_bed, t_R):
    """Time-averaged penetration coefficient of the bed over one rest period.

    weigler-thermal-dem.md, eq. [1.12]:
    ``alpha_bed = (2/sqrt(pi)) sqrt(rho_bed c_bed lambda_bed / t_R)``
    (mean of the semi-infinite-body coefficient [1.11] over 0 < t < t_R).

    Parameters
    ----------
    lambda_bed : array_like
        Effective bed conductivity, W/(m K).
    rho_bed : array_like
        Bulk density of the bed, kg/m^3.
    c_bed : array_like
        Heat capacity of the bed (= particle value), J/(kg K).
    t_R : array_like
        Rest time, s (see :func:`rest_time`).

    Returns
    -------
    jax.Array
        alpha_bed, W/(m^2 K).
    """
    effusivity2 = jnp.asarray(rho_bed, float) * jnp.asarray(c_bed, float) * jnp.asarray(lambda_bed, float)
    return 2.0 / jnp.sqrt(jnp.pi) * jnp.sqrt(effusivity2 / jnp.asarray(t_R, float))


def alpha_bed_instantaneous(lambda_bed, rho_bed, c_bed, t):
    """Instantaneous penetration coefficient of a semi-infinite continuum.

    weigler-thermal-dem.md, eq. [1.11]:
    ``alpha_bed,t = (1/sqrt(pi)) sqrt(rho_bed c_bed lambda_bed / t)``.

    The digest (item 12.12) notes that the source writes t_R here; physically the argument is
    the elapsed contact time t since the last mixing, and that is what this function takes.
    Its mean over [0, t_R] is twice its value at t_R, which is eq. [1.12] (:func:`alpha_bed`).

    Parameters
    ----------
    lambda_bed, rho_bed, c_bed : array_like
        Bed conductivity W/(m K), bulk density kg/m^3, heat capacity J/(kg K).
    t : array_like
        Contact time since the last mixing, s (> 0; t = 0 gives inf).

    Returns
    -------
    jax.Array
        alpha_bed,t, W/(m^2 K).
    """
    effusivity2 = jnp.asarray(rho_bed, float) * jnp.asarray(c_bed, float) * jnp.asarray(lambda_bed, float)
    return 1.0 / jnp.sqrt(jnp.pi) * jnp.sqrt(effusivity2 / jnp.asarray(t, float))


def alpha_overall(alpha_wp, lambda_bed, rho_bed, c_bed, t_R, phi=0.8):
    """Overall wall-to-bed coefficient of the penetration model.

    weigler-thermal-dem.md, eq. [1.6]: ``1/alpha = 1/alpha_ws + 1/alpha_bed`` with
    alpha_ws = Phi alpha_wp (eq. [1.7]) and alpha_bed from eq. [1.12].

    Parameters
    ----------
    alpha_wp : array_like
        Particle-wall contact coefficient, W/(m^2 K).
    lambda_bed : array_like
        Effective bed conductivity, W/(m K).
    rho_bed : array_like
        Bulk density, kg/m^3.
    c_bed : array_like
        Bed heat capacity, J/(kg K).
    t_R : array_like
        Rest time, s.
    phi : array_like, optional
        Wall coverage Phi of eq. [1.7] (default 0.8). Pass ``phi=1`` to use alpha_wp directly
        as alpha_ws (the A7/A8 script convention, digest item 12.9).

    Returns
    -------
    jax.Array
        alpha (overall, constant in time for fixed t_R), W/(m^2 K).
    """
    a_ws = alpha_wall_bed(alpha_wp, phi)
    a_bed = alpha_bed(lambda_bed, rho_bed, c_bed, t_R)
    return 1.0 / (1.0 / a_ws + 1.0 / a_bed)


def mean_temperature(t, T_w, T_0, alpha, area, mass, c):
    """Mean bed temperature for a constant overall coefficient (closed form).

    weigler-thermal-dem.md, eq. [1.10] (integral of the bed balance [1.9]):
    ``T_mean(t) = T_w - (T_w - T_0) exp(-alpha A t / (m c))``.

    This is the "analytic PM" mean temperature of the A8 script (digest section 6.5). Works for
    heating (T_w > T_0) and cooling (T_w < T_0).

    Parameters
    ----------
    t : array_like
        Time since the start of heating, s.
    T_w : array_like
        Wall temperature, K.
    T_0 : array_like
        Initial (mean) bed temperature, K.
    alpha : array_like
        Overall coefficient, W/(m^2 K) (e.g. :func:`alpha_overall`).
    area : array_like
        Heat-transfer area A, m^2 (the area alpha refers to).
    mass : array_like
        Bed mass m, kg.
    c : array_like
        Bed heat capacity, J/(kg K).

    Returns
    -------
    jax.Array
        T_mean(t), K.
    """
    t = jnp.asarray(t, float)
    rate = jnp.asarray(alpha, float) * jnp.asarray(area, float) / (jnp.asarray(mass, float) * jnp.asarray(c, float))
    T_w = jnp.asarray(T_w, float)
    return T_w - (T_w - jnp.asarray(T_0, float)) * jnp.exp(-rate * t)


def lambda_bed_from_alpha_bed(alpha_bed, t, rho_bed, c_bed):
    """Bed conductivity that reproduces a penetration coefficient at time t.

    weigler-thermal-dem.md, eq. [5.1] (eq. [1.12] solved for lambda_bed; printed without its
    number in the source, digest item 12.11):
    ``lambda_bed = alpha_bed^2 pi t / (4 rho_bed c_bed)``.

    Parameters
    ----------
    alpha_bed : array_like
        Penetration (bed) coefficient, W/(m^2 K).
    t : array_like
        Time (rest time t_R, or the evaluation time of the A7 calibration), s.
    rho_bed : array_like
        Bulk density, kg/m^3.
    c_bed : array_like
        Bed heat capacity, J/(kg K).

    Returns
    -------
    jax.Array
        lambda_bed, W/(m K).
    """
    a = jnp.asarray(alpha_bed, float)
    return a**2 * jnp.pi * jnp.asarray(t, float) / (4.0 * jnp.asarray(rho_bed, float) * jnp.asarray(c_bed, float))


def thermal_mixing_time(alpha_bed, rho_bed, c_bed, lambda_bed):
    """Thermal mixing time: the rest time that makes eq. [1.12] give ``alpha_bed``.

    weigler-thermal-dem.md, eq. [5.3]:
    ``t_th = 4 (rho c lambda)_bed / (pi alpha_bed^2)``
    (used with alpha_bed,DEM back-calculated from a DEM run, section 11.2).

    Parameters
    ----------
    alpha_bed : array_like
        Bed (penetration) coefficient, W/(m^2 K).
    rho_bed : array_like
        Bulk density, kg/m^3.
    c_bed : array_like
        Bed heat capacity, J/(kg K).
    lambda_bed : array_like
        Bed conductivity, W/(m K).

    Returns
    -------
    jax.Array
        t_th, s.
    """
    prod = jnp.asarray(rho_bed, float) * jnp.asarray(c_bed, float) * jnp.asarray(lambda_bed, float)
    return 4.0 * prod / (jnp.pi * jnp.asarray(alpha_bed, float) ** 2)
