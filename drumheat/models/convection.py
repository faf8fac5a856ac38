"""Particle-gas convection correlations and the bed-level plug-flow gas balance.

Pure ``jax.numpy`` functions on SI arrays (broadcasting), so ``jax.grad``/``vmap`` work.

Sources (digests in ``shared/reference/``):

* ``staltner-slag-particle.md`` section 5 (Ch. 3.2 of the thesis, [3.17]-[3.32]);
* ``kraychev-tube-bundle.md`` section 4 ((3-1)-(3-19), (3-45)-(3-47)) and errata 14.1;
* ``fluidized-bed-exercise.md`` sections 2-5 (packed-bed factor, bed-level balance).

Gnielinski sphere, the variants in the digests
-----------------------------------------------
All write ``Nu = Nu_min + sqrt(Nu_lam**2 + Nu_turb**2)`` with ``Nu_min = 2`` (sphere), but differ:

==============================  ===============================  =============================================  ==========
place                            Nu_lam                           Nu_turb denominator                            length L
==============================  ===============================  =============================================  ==========
Staltner [3.25]-[3.28]           0.664 Re^1/2 Pr^1/3              1 + 2.443 Re^-0.1 (Pr^2/3 - 1)                  pi d / 2
Kraychev (3-16)-(3-18)           0.664 Re^0.5 Pr^0.33             1 + 2.443 Re^-0.1 (Pr^0.66 - 1)  "exact VDI"    d_p
Kraychev tables 10.8.x           as (3-17)                        1 + 2.443 Re^-0.3 (Pr^0.66 - 1)                 d_p
Kraychev App. 10.9 (Mathcad)     0.664 Re^0.5 Pr^0.39             1 + 2.443 Re^-0.3 (Pr^0.66 - 1)                 d_p
fluidized-bed exercise sec. 3    (2/(1+22 Pr))^1/6 sqrt(Re Pr)    1 + 2.443 Re^-0.1 (Pr^2/3 - 1)                  d
==============================  ===============================  =============================================  ==========

"Exact VDI" (the form :func:`gnielinski_sphere_nu` implements with ``variant="vdi"``) is
``Nu_lam = 0.664 Re^(1/2) Pr^(1/3)`` and ``Nu_turb = 0.037 Re^0.8 Pr / (1 + 2.443 Re^-0.1
(Pr^(2/3) - 1))``. Kraychev's 0.33/0.66 are the rounded 1/3 and 2/3; we use the exact fractions
(differences < 0.3 % at Pr = 0.7). The ``Re^-0.3`` forms are kept only as named variants to
reproduce the Kraychev tables (digest 14.1: "Use the Re^-0.3 variant only when reproducing
the source's tables"). The characteristic length is *not* part of the Nusselt function: the
caller builds Re with the length of the form being reproduced (Staltner: ``L = pi r``;
Kraychev, fluidised bed: ``d``). :func:`sphere_alpha_gnielinski` makes that choice explicit.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = [
    "reynolds",
    "prandtl",
    "grashof",
    "archimedes",
    "convection_regime",
    "gnielinski_nu_lam",
    "gnielinski_nu_turb",
    "gnielinski_sphere_nu",
    "nu_lam_all_pr",
    "fluidized_bed_sphere_nu",
    "gnielinski_cylinder_crossflow_nu",
    "sphere_alpha_gnielinski",
    "ranz_marshall_nu",
    "stagnant_film_nu",
    "kraychev_pascal_nu",
    "muschtaev_nu",
    "mcadams_nu",
    "mixed_convection_alpha",
    "MIXED_CONVECTION_EXPONENT",
    "packed_bed_factor",
    "interstitial_reynolds",
    "nusselt_to_alpha",
    "series_coefficient",
    "bed_area_per_cross_section",
    "bed_ntu",
    "bed_outlet_gas_temperature",
    "log_mean_temperature_difference",
    "bed_gas_heat_flux",
    "bed_mean_temperature_rate",
    "batch_bed_mean_temperature",
]

# ----------------------------------------------------------------------------------------------
# dimensionless groups
# ----------------------------------------------------------------------------------------------


def reynolds(w, length, nu):
    """Reynolds number ``Re = w L / nu``.

    staltner-slag-particle.md section 5 (definitions before [3.17]).

    Parameters
    ----------
    w : array_like
        Velocity (m/s). For beds use the interstitial velocity (:func:`interstitial_reynolds`).
    length : array_like
        Characteristic length (m).
    nu : array_like
        Kinematic viscosity of the fluid (m^2/s).
    """
    return jnp.asarray(w) * length / nu


def prandtl(nu, rho, cp, lam):
    """Prandtl number ``Pr = nu rho c_p / lambda`` (fluidized-bed-exercise.md section 3).

    Parameters
    ----------
    nu : kinematic viscosity (m^2/s); rho : density (kg/m^3); cp : J/(kg K); lam : W/(m K).
    """
    return jnp.asarray(nu) * rho * cp / lam


def grashof(length, T_wall, T_fluid, nu, g=9.81):
    """Grashof number ``Gr = L^3 g beta_T dT / nu^2`` with ``beta_T = 1/T_ref``.

    staltner-slag-particle.md section 5: ``T_ref = (T_W + T_F)/2``, ``dT = T_W - T_F``.
    Returned with its sign (negative for a wall colder than the fluid); temperatures in K.
    """
    T_ref = 0.5 * (jnp.asarray(T_wall) + T_fluid)
    return length**3 * g * (T_wall - T_fluid) / T_ref / nu**2


def archimedes(length, T_wall, T_fluid, w, g=9.81):
    """Archimedes number ``Ar = L g beta_T dT / w^2 = Gr/Re^2``.

    staltner-slag-particle.md section 5 (definitions); the magnitude is used in
    :func:`convection_regime`. Temperatures in K, ``w`` in m/s.
    """
    T_ref = 0.5 * (jnp.asarray(T_wall) + T_fluid)
    return length * g * (T_wall - T_fluid) / T_ref / jnp.asarray(w) ** 2


def convection_regime(Ar):
    """Regime of staltner-slag-particle.md section 5 [3.17] (quoted for a heated plate).

    Returns an integer array: 0 forced (|Ar| < 0.25), 1 mixed (0.25-16), 2 free (> 16).
    """
    a = jnp.abs(jnp.asarray(Ar))
    return jnp.where(a < 0.25, 0, jnp.where(a <= 16.0, 1, 2))


# ----------------------------------------------------------------------------------------------
# Gnielinski
# ----------------------------------------------------------------------------------------------


def gnielinski_nu_lam(Re, Pr, pr_exponent=1.0 / 3.0):
    """Laminar part ``Nu_lam = 0.664 Re^(1/2) Pr^(1/3)``.

    staltner-slag-particle.md [3.25]; kraychev-tube-bundle.md (3-17).
    ``pr_exponent=0.39`` reproduces Kraychev's Mathcad sheet (digest 14.1), nothing else.
    """
    return 0.664 * jnp.sqrt(Re) * jnp.asarray(Pr) ** pr_exponent


def gnielinski_nu_turb(Re, Pr, re_exponent=-0.1, pr_exponent=2.0 / 3.0):
    """Turbulent part ``Nu_turb = 0.037 Re^0.8 Pr / (1 + 2.443 Re^-0.1 (Pr^(2/3) - 1))``.

    staltner-slag-particle.md [3.26]; kraychev-tube-bundle.md (3-18), the exact VDI form.
    ``re_exponent=-0.3`` (with ``pr_exponent=0.66``) is the Kraychev-table variant (digest
    14.1) and exists only to reproduce those tables.
    """
    Re = jnp.asarray(Re)
    Pr = jnp.asarray(Pr)
    return 0.037 * Re**0.8 * Pr / (1.0 + 2.443 * Re**re_exponent * (Pr**pr_exponent - 1.0))


_GNIELINSKI_VARIANTS = {
    # name: (Nu_lam Pr exponent, Nu_turb Re exponent, Nu_turb Pr exponent)
    "vdi": (1.0 / 3.0, -0.1, 2.0 / 3.0),
    "kraychev_tables": (0.33, -0.3, 0.66),
    "kraychev_mathcad": (0.39, -0.3, 0.66),
}


def gnielinski_sphere_nu(Re, Pr, variant="vdi", nu_min=2.0):
    """Single sphere, Gnielinski: ``Nu = 2 + sqrt(Nu_lam^2 + Nu_turb^2)``.

    staltner-slag-particle.md [3.25]-[3.28]; kraychev-tube-bundle.md (3-16)-(3-18).
    Valid for 0.7 < Pr < 600 and 1 <= Re <= 1e6 (Staltner [3.28]); not checked here.

    Parameters
    ----------
    Re, Pr : array_like
        Reynolds number built with the caller's characteristic length and (for beds) the
        interstitial velocity; Prandtl number.
    variant : {"vdi", "kraychev_tables", "kraychev_mathcad"}
        ``"vdi"`` is the exact VDI form (Pr^(1/3), Re^-0.1, Pr^(2/3)). The other two reproduce
        the deviating exponents of kraychev-tube-bundle.md 14.1 and are *not* recommended.
    nu_min : float
        Conduction limit, 2 for a sphere.

    Returns
    -------
    Nu : array
    """
    p_lam, re_t, p_t = _GNIELINSKI_VARIANTS[variant]
    lam = gnielinski_nu_lam(Re, Pr, p_lam)
    turb = gnielinski_nu_turb(Re, Pr, re_t, p_t)
    return nu_min + jnp.sqrt(lam**2 + turb**2)


def nu_lam_all_pr(Re, Pr):
    """Laminar part valid for all Pr: ``Nu_lam = (2/(1 + 22 Pr))^(1/6) sqrt(Re Pr)``.

    fluidized-bed-exercise.md section 3 (used there with ``L = d``).
    """
    Pr = jnp.asarray(Pr)
    return (2.0 / (1.0 + 22.0 * Pr)) ** (1.0 / 6.0) * jnp.sqrt(Re * Pr)


def fluidized_bed_sphere_nu(Re, Pr):
    """Single sphere exactly as in fluidized-bed-exercise.md section 3 (``L = d``).

    ``Nu = 2 + sqrt(Nu_lam^2 + Nu_turb^2)`` with :func:`nu_lam_all_pr` and the exact VDI
    :func:`gnielinski_nu_turb`. Do not mix with the Staltner form (digest note in both files).
    """
    return 2.0 + jnp.sqrt(nu_lam_all_pr(Re, Pr) ** 2 + gnielinski_nu_turb(Re, Pr) ** 2)


def gnielinski_cylinder_crossflow_nu(Re, Pr):
    """Profile cylinder in cross-flow, ``L = a_P + b_P``.

    staltner-slag-particle.md [3.29]-[3.32]:
    ``Nu_lam = (2/sqrt(pi)) Re^(1/2) Pr^(1/2) / (1 + 1.973 Pr^0.272 + 21.29 Pr)^(1/6)``,
    ``Nu_turb`` as for the sphere, ``Nu = 0.3 + sqrt(Nu_lam^2 + Nu_turb^2)``;
    valid for 0.6 < Pr < 1000, 1 <= Re <= 1e7.
    """
    Pr = jnp.asarray(Pr)
    lam = (2.0 / jnp.sqrt(jnp.pi)) * jnp.sqrt(Re * Pr) / (
        1.0 + 1.973 * Pr**0.272 + 21.29 * Pr
    ) ** (1.0 / 6.0)
    return 0.3 + jnp.sqrt(lam**2 + gnielinski_nu_turb(Re, Pr) ** 2)


def nusselt_to_alpha(Nu, lam, length):
    """``alpha = Nu lambda / L`` in W/(m^2 K) (staltner-slag-particle.md section 5)."""
    return jnp.asarray(Nu) * lam / length


def sphere_alpha_gnielinski(w, d, nu, Pr, lam, length="overflow", variant="vdi"):
    """Heat-transfer coefficient of a single sphere (W/(m^2 K)) from the Gnielinski form.

    Parameters
    ----------
    w : relative velocity (m/s); d : sphere diameter (m); nu : m^2/s; Pr : -; lam : W/(m K).
    length : {"overflow", "diameter"}
        ``"overflow"``: ``L = pi d / 2`` with Nu_lam = 0.664 Re^(1/2) Pr^(1/3)
        (staltner-slag-particle.md [3.25]-[3.28]). ``"diameter"``: ``L = d`` with the
        all-Pr laminar part (fluidized-bed-exercise.md section 3).
    variant : passed to :func:`gnielinski_sphere_nu` (only for ``length="overflow"``).
    """
    if length == "overflow":
        L = jnp.pi * jnp.asarray(d) / 2.0
        Nu = gnielinski_sphere_nu(reynolds(w, L, nu), Pr, variant)
    elif length == "diameter":
        L = jnp.asarray(d)
        Nu = fluidized_bed_sphere_nu(reynolds(w, L, nu), Pr)
    else:
        raise ValueError(f"length must be 'overflow' or 'diameter', got {length!r}")
    return nusselt_to_alpha(Nu, lam, L)


# ----------------------------------------------------------------------------------------------
# other single-particle correlations (Kraychev)
# ----------------------------------------------------------------------------------------------


def ranz_marshall_nu(Re, Pr):
    """Ranz-Marshall ``Nu = 2 + 0.6 Re^(1/2) Pr^(1/3)``, ``L = d``.

    kraychev-tube-bundle.md (3-14). The digest prints ``Pr^0.33``; the original Ranz-Marshall
    exponent is 1/3, which we use (0.1 % difference at Pr = 0.7).
    """
    return 2.0 + 0.6 * jnp.sqrt(Re) * jnp.asarray(Pr) ** (1.0 / 3.0)


def stagnant_film_nu(eps):
    """Stagnant-film limit in a bed of porosity eps: ``Nu = 2 / (1 - (1 - eps)^(1/3))``.

    kraychev-tube-bundle.md (3-8) (parentheses of (3-7) corrected, digest 14.2 item 5).
    Tends to 2 as eps -> 1.
    """
    return 2.0 / (1.0 - (1.0 - jnp.asarray(eps)) ** (1.0 / 3.0))


def kraychev_pascal_nu(Re, Pr):
    """``Nu = 2 + 0.459 Re^0.55 Pr^0.33`` (kraychev-tube-bundle.md 4.4, Pascal program)."""
    return 2.0 + 0.459 * jnp.asarray(Re) ** 0.55 * jnp.asarray(Pr) ** 0.33


def muschtaev_nu(Re, Pr):
    """Pneumatic transport, ``Nu = 2 + 0.51 Re^0.52 Pr^0.33`` (kraychev-tube-bundle.md (3-47))."""
    return 2.0 + 0.51 * jnp.asarray(Re) ** 0.52 * jnp.asarray(Pr) ** 0.33


def mcadams_nu(Re, coefficient=0.415):
    """Pneumatic transport, McAdams ``Nu = 0.415 Re^0.6`` (kraychev-tube-bundle.md (3-45)).

    Table 3.2.2.1 of the source gives 0.425 (digest 14.2 item 5); pass ``coefficient=0.425``
    to use that.
    """
    return coefficient * jnp.asarray(Re) ** 0.6


# ----------------------------------------------------------------------------------------------
# mixed convection
# ----------------------------------------------------------------------------------------------

#: Exponent n_K of staltner-slag-particle.md section 5 [3.18] by configuration. Digest erratum
#: reading: 3 when the flow is parallel to gravity ("senkrecht"), 4 when it is transverse.
MIXED_CONVECTION_EXPONENT = {
    "vertical_flow_body": 3.0,
    "vertical_wall": 3.0,
    "pipe_constant_wall_temperature": 3.0,
    "horizontal_plate": 3.5,
    "sphere_cross_flow": 4.0,
    "cylinder_cross_flow": 4.0,
    "pipe_constant_flux": 6.0,
}


def mixed_convection_alpha(alpha_forced, alpha_free, n=4.0, assisting=True):
    """Superposition ``alpha = |alpha_EK^n +- alpha_FK^n|^(1/n)``.

    staltner-slag-particle.md [3.18]; "+" when forced and free flow assist, "-" when they
    oppose. ``n`` from :data:`MIXED_CONVECTION_EXPONENT` (4 for spheres in cross-flow).
    No free-convection correlation is given in the digest; the caller supplies ``alpha_free``.
    """
    s = 1.0 if assisting else -1.0
    return jnp.abs(jnp.asarray(alpha_forced) ** n + s * jnp.asarray(alpha_free) ** n) ** (1.0 / n)


# ----------------------------------------------------------------------------------------------
# packed and fluidised beds
# ----------------------------------------------------------------------------------------------


def packed_bed_factor(psi):
    """Arrangement factor ``f_a = 1 + 1.5 (1 - psi)`` for sphere packings, 0.26 < psi < 1.

    fluidized-bed-exercise.md section 2; kraychev-tube-bundle.md 4.3 (VDI packed-bed factor).
    ``Nu_bed = f_a Nu_single(Re_psi, Pr)``.
    """
    return 1.0 + 1.5 * (1.0 - jnp.asarray(psi))


def interstitial_reynolds(u_empty, d, nu, psi):
    """``Re_psi = u_empty d / (psi nu)`` (fluidized-bed-exercise.md section 2; Kraychev (3-19)).

    ``u_empty`` is the superficial velocity (m/s), ``psi`` the void fraction.
    """
    return jnp.asarray(u_empty) * d / (psi * nu)


def series_coefficient(*alphas):
    """Overall coefficient of resistances in series, ``1/k = sum 1/alpha_i``.

    fluidized-bed-exercise.md section 5 (``1/k = 1/alpha_i + 1/alpha_a``).
    """
    return 1.0 / sum(1.0 / jnp.asarray(a) for a in alphas)


def bed_area_per_cross_section(m1, d, rho1):
    """Total particle surface per bed cross-section ``A/f = 6 m_1 / (d rho_1)`` (m^2/m^2).

    fluidized-bed-exercise.md section 5. ``m1`` is the loading (kg/m^2).
    """
    return 6.0 * jnp.asarray(m1) / (d * rho1)


def bed_ntu(k, A_per_f, mdot2, cp2):
    """Number of transfer units ``NTU = k A / (f mdot_2 c_p,2)``.

    fluidized-bed-exercise.md section 4. ``k`` W/(m^2 K), ``A_per_f`` m^2/m^2,
    ``mdot2`` gas flux kg/(m^2 s), ``cp2`` J/(kg K).
    """
    return jnp.asarray(k) * A_per_f / (mdot2 * cp2)


def bed_outlet_gas_temperature(T_bed, T_gas_in, ntu):
    """Plug-flow outlet gas temperature ``T_2,aus = T1 - (T1 - T_2,ein) exp(-NTU)``.

    fluidized-bed-exercise.md section 4 ("Outlet gas temperature").
    """
    return T_bed - (T_bed - T_gas_in) * jnp.exp(-jnp.asarray(ntu))


def log_mean_temperature_difference(dT_a, dT_b):
    """Log-mean temperature difference ``(dT_a - dT_b) / ln(dT_a / dT_b)``.

    fluidized-bed-exercise.md section 4 with ``dT_a = T1 - T_2,ein``, ``dT_b = T1 - T_2,aus``.
    The removable singularity at ``dT_a = dT_b`` is handled by a second-order series
    (``m (1 - x^2/12)`` with ``m`` the arithmetic mean and ``x = ln(dT_a/dT_b)``), so the
    function and its gradient stay finite there. Both differences must have the same sign.
    """
    a = jnp.asarray(dT_a, dtype=float)
    b = jnp.asarray(dT_b, dtype=float)
    ratio = a / b
    close = jnp.abs(ratio - 1.0) < 1e-4
    safe_ratio = jnp.where(close, 2.0, ratio)
    exact = (a - b) / jnp.log(safe_ratio)
    x = jnp.log(jnp.where(close, ratio, 1.0))
    series = 0.5 * (a + b) * (1.0 - x**2 / 12.0)
    return jnp.where(close, series, exact)


def bed_gas_heat_flux(T_bed, T_gas_in, ntu, mdot2, cp2):
    """Heat taken up by the gas per bed cross-section (W/m^2), positive when the bed cools.

    fluidized-bed-exercise.md section 4: ``mdot_2 c_p,2 (T_2,aus - T_2,ein)
    = k (A/f) dT_LM = mdot_2 c_p,2 (T1 - T_2,ein)(1 - exp(-NTU))``.
    """
    return mdot2 * cp2 * (T_bed - T_gas_in) * (1.0 - jnp.exp(-jnp.asarray(ntu)))


def bed_mean_temperature_rate(T_bed, T_gas_in, ntu, m1, cp1, mdot2, cp2):
    """``dT1/dt = (mdot_2 c_p,2)/(m_1 c_p,1) (T_2,ein - T1)(1 - exp(-NTU))`` in K/s.

    fluidized-bed-exercise.md section 4 (ODE for the mean bean temperature).
    """
    return -bed_gas_heat_flux(T_bed, T_gas_in, ntu, mdot2, cp2) / (m1 * cp1)


def batch_bed_mean_temperature(t, T1_start, T_gas_in, ntu, m1, cp1, mdot2, cp2):
    """Closed-form batch cooling curve of a perfectly mixed bed with plug-flow gas.

    fluidized-bed-exercise.md section 4 ("Closed-form solution"):
    ``T1(t) = T_2,ein - (T_2,ein - T1_A) exp{-(mdot_2 c_p,2)/(m_1 c_p,1) (1 - exp(-NTU)) t}``.

    Parameters
    ----------
    t : array_like, s. T1_start, T_gas_in : K (or degC). ntu : from :func:`bed_ntu` (k held
    constant, as in the exercise). m1 : kg/m^2. cp1 : J/(kg K). mdot2 : kg/(m^2 s).
    cp2 : J/(kg K).
    """
    rate = mdot2 * cp2 / (m1 * cp1) * (1.0 - jnp.exp(-jnp.asarray(ntu)))
    return T_gas_in - (T_gas_in - T1_start) * jnp.exp(-rate * jnp.asarray(t))
