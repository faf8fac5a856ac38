"""Moving bed through a staggered tube bundle and pneumatic channel (Kraychev 2005).

Closed-form engineering fits of the slot-type spouted-bed heat exchanger "MKKM-02"
(reference: ``reference/kraychev-tube-bundle.md``, cited as *Kraychev digest*; equation numbers
``(x-y)`` are the thesis' own):

- hopper discharge velocity between the tubes, eqs. (5-3)..(5-6), and Senkov's slit hydraulic
  radius (5-1, 5-2);
- tube-bundle-to-moving-bed heat transfer ``Nu_1 = 0.155 Pe*^0.22 (D_R/d_p)^0.33``,
  eqs. (5-16)..(5-19);
- the apparatus-level evaluation of the channel coefficient ``alpha_2`` (Sec. 6: eqs. 3-34..3-36,
  8-2, 8-4, 8-5, 5-20, 5-21) and the Gnielinski sphere correlation (3-16)..(3-18) used to
  predict it;
- terminal velocity (3-87)..(3-89), (3-13) and the design channel velocity (8-6);
- pressure-drop fits (5-7)..(5-12) and Hobler's bundle coefficient (3-70, 3-71);
- residence time (5-26)..(5-28).

Units are SI unless a docstring says otherwise (the discharge fit takes SI lengths and converts
to the millimetres it was fitted in). Functions use ``jax.numpy`` and accept arrays. Validity
ranges are checked when the inputs are concrete numbers and ``check=True``: outside them a
``ValueError`` names the value and the allowed range (inside ``jit`` no check is possible).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.models.drag import G

__all__ = [
    "BETA_HOPPER",
    "H_SCH",
    "D_R",
    "NU1_COEFFICIENTS",
    "discharge_repose_angle_deg",
    "discharge_velocity",
    "senkov_hydraulic_radius",
    "effective_conductivity",
    "peclet_star",
    "nusselt_tube_bundle",
    "alpha_tube_bundle",
    "specific_surface",
    "circulating_solids_flow",
    "exchange_area",
    "lmtd",
    "lmtd_cocurrent",
    "ChannelEvaluation",
    "channel_alpha2",
    "nusselt_sphere_gnielinski",
    "archimedes_kraychev",
    "reynolds_terminal_archimedes",
    "TerminalVelocity",
    "terminal_velocity_kraychev",
    "design_channel_velocity",
    "reduced_slit_reynolds",
    "xi_apparatus",
    "pressure_drop_slit_and_apparatus",
    "pressure_drop_empty",
    "xi_hobler",
    "bundle_residence_time",
    "mean_residence_time",
    "prescribed_residence_time",
]

BETA_HOPPER = 0.59  # solids volume fraction in the hopper (eps = 0.41), Kraychev digest Sec. 2
H_SCH = 0.21  # m, hopper bed height with tubes, Kraychev digest Sec. 2
D_R = 0.014  # m, tube outer diameter of the bundle, Kraychev digest Sec. 2

# Table 5.2.1: Nu = C1 Pe*^a (D_R/d_p)^b
NU1_COEFFICIENTS = {
    "kraychev": (0.155, 0.22, 0.33),  # own data, eq. (5-18)
    "kalenderjan_dusts": (0.409, 0.28, 0.276),
    "kalenderjan_grains": (0.79, 0.28, 0.404),
}


def _concrete(x):
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        return None


def _check(name, value, lo, hi, where, check=True, lo_open=False, hi_open=False):
    """Raise ValueError if a concrete ``value`` leaves ``[lo, hi]``; skip traced values."""
    if not check:
        return
    v = _concrete(value)
    if v is None:
        return
    bad_lo = (v <= lo) if lo_open else (v < lo)
    bad_hi = (v >= hi) if hi_open else (v > hi)
    if np.any(bad_lo | bad_hi) or np.any(~np.isfinite(v)):
        lb, hb = ("(" if lo_open else "["), (")" if hi_open else "]")
        raise ValueError(
            f"{name} = {v if v.ndim == 0 else v[bad_lo | bad_hi]}: outside the validity range "
            f"{lb}{lo:g}, {hi:g}{hb} of {where}. Pass check=False to extrapolate knowingly."
        )


# --------------------------------------------------------------------------------------------
# hopper discharge (Sec. 7)
# --------------------------------------------------------------------------------------------


def discharge_repose_angle_deg(d_p):
    """Angle term of the discharge fit, ``gamma = 8.2 (d_p[mm] - 1.65)`` degrees.

    Kraychev digest eq. (5-4). ``d_p`` in m.
    """
    return 8.2 * (jnp.asarray(d_p) * 1e3 - 1.65)


def discharge_velocity(S, d_p, W_SG=0.0, check=True):
    """Mean downward velocity of the moving bed between the tubes, ``W_p`` (m/s).

    Without secondary gas, Kraychev digest eqs. (5-3)-(5-5) (fit +-7.2 %)::

        W_p,0 = 0.01 tan(58 deg + 8.2 (d_p[mm] - 1.65) deg) (S/d_p - 1.1)      [m/s]

    and with secondary gas of superficial velocity ``W_SG``, eq. (5-6) (error < 10 %)::

        W_p = W_p,0 + 0.008 W_SG + 0.04 W_SG^2 + 0.95 W_SG^3                   [m/s]

    ``W_p,0 = 0`` at ``S/d_p = 1.1``; below that the slit jams and 0 is returned (the fit would be
    negative). Valid for this apparatus only (14/25 mm staggered bundle, ``H_Sch = 0.21 m``),
    near-spherical particles of 1.43-5 mm, ``0 <= W_SG <= 0.132 m/s``. The tangent reaches 90 deg
    at ``d_p ~= 5.55 mm``; with ``check=False`` the tangent argument uses ``d_p`` clamped at 5 mm
    as the digest advises, so larger particles do not blow up (an extrapolation).

    Parameters
    ----------
    S : array_like
        Outlet slit width, m (4-16 mm in the tests).
    d_p : array_like
        Particle diameter, m.
    W_SG : array_like
        Secondary-gas superficial velocity on the free hopper cross-section, m/s.
    check : bool
        Raise ValueError for concrete inputs outside the fit's range.

    Returns
    -------
    array
        ``W_p``, m/s.
    """
    _check("d_p", d_p, 1.43e-3, 5.0e-3, "the discharge fit (5-5), in m", check)
    _check("W_SG", W_SG, 0.0, 0.132, "the secondary-gas fit (5-6), in m/s", check)
    d_mm = jnp.minimum(jnp.asarray(d_p) * 1e3, 5.0)
    angle = jnp.deg2rad(58.0 + 8.2 * (d_mm - 1.65))  # (5-4) inserted in (5-3) = (5-5)
    W0 = 0.01 * jnp.tan(angle) * jnp.maximum(jnp.asarray(S) / d_p - 1.1, 0.0)
    W_SG = jnp.asarray(W_SG)
    return W0 + 0.008 * W_SG + 0.04 * W_SG**2 + 0.95 * W_SG**3  # (5-6)


def senkov_hydraulic_radius(A, s, d_p, K_k=1.4):
    """Senkov's hydraulic radius of an outlet slit of length ``A`` and width ``s`` (m).

    Kraychev digest eqs. (5-1), (5-2), ``a' = K_k d_p``. The printed signs of (5-1) are
    probably misprinted (erratum 14.2 #6); we implement the intended form
    ``R_h = (A - a')(s - a') / [2 (A + s - 2 a')]``, the hydraulic radius of the slit reduced by
    ``a'/2`` on every side. For ``A >> s`` both give ``R_h ~= (s - 1.4 d_p)/2`` (millet,
    ``s = 4 mm``: 0.84 mm, the C++ example input).

    Parameters
    ----------
    A, s : array_like
        Slit length and width, m.
    d_p : array_like
        Equivalent particle diameter, m.
    K_k : float
        Senkov's coefficient (1.4).
    """
    a = K_k * d_p
    return (A - a) * (s - a) / (2.0 * (A + s - 2.0 * a))


# --------------------------------------------------------------------------------------------
# tube bundle to moving bed (Sec. 5.2)
# --------------------------------------------------------------------------------------------


def effective_conductivity(lambda_M, lambda_G, beta=BETA_HOPPER):
    """Bed conductivity ``lambda* = beta lambda_M + (1 - beta) lambda_G`` (W/(m K)).

    Kraychev digest eq. (5-17) (``0.59 lambda_M + 0.41 lambda_G``) and (3-41); (3-40) prints a
    plain sum, which we do not use.

    Parameters
    ----------
    lambda_M, lambda_G : array_like
        Conductivity of the particle material and of the gas, W/(m K).
    beta : float
        Solids volume fraction (0.59 in the hopper).
    """
    return beta * lambda_M + (1.0 - beta) * lambda_G


def peclet_star(W_p, d_p, rho_M, c_pM, lambda_star, W_SG=0.0, rho_G=1.2, c_pG=1005.0,
                beta=BETA_HOPPER):
    """Modified Peclet number of the moving bed (-).

    Kraychev digest eq. (5-19)::

        Pe* = [rho_G c_pG (1 - beta) W_SG + rho_M c_pM beta W_p] d_p / lambda*

    (3-39 writes ``W_G,F`` for the gas velocity; 5-19, used here, the secondary-gas velocity
    ``W_SG``; erratum 14.2 #10. The Mathcad sheet's ``eps`` on the gas term is ``1 - beta``.)

    Parameters
    ----------
    W_p : array_like
        Bed velocity between the tubes, m/s (:func:`discharge_velocity`).
    d_p : array_like
        Particle diameter, m.
    rho_M, c_pM : array_like
        Particle density (kg/m^3) and heat capacity (J/(kg K)).
    lambda_star : array_like
        Bed conductivity (:func:`effective_conductivity`), W/(m K).
    W_SG : array_like
        Secondary-gas superficial velocity, m/s.
    rho_G, c_pG : array_like
        Gas density (kg/m^3) and heat capacity (J/(kg K)).
    beta : float
        Solids volume fraction.
    """
    return (rho_G * c_pG * (1.0 - beta) * W_SG + rho_M * c_pM * beta * W_p) * d_p / lambda_star


def nusselt_tube_bundle(Pe_star, D_R, d_p, coefficients="kraychev", check=True):
    """Tube-to-moving-bed Nusselt number ``Nu_1 = alpha_1 d_p / lambda*`` (-).

    Kraychev digest eq. (5-18): ``Nu_1 = 0.155 Pe*^0.22 (D_R/d_p)^0.33`` (the exponent form; the
    Mathcad sheet's ``(D_R/d_p)*0.33`` is a typesetting error, erratum 14.2 #1). Valid for
    ``54 < Pe* < 4200`` and ``3.43 < D_R/d_p < 9.79`` (5.2.2.4 and the summary; 5.2.2.5 states
    ``> 2.80``, erratum #4: we check the stricter bound), ``W_SG <= 0.132 m/s``, no fluidisation
    between the tubes. Other coefficient sets of Table 5.2.1 are selectable by name.

    Parameters
    ----------
    Pe_star : array_like
        Modified Peclet number (:func:`peclet_star`).
    D_R, d_p : array_like
        Tube and particle diameter, m.
    coefficients : str or tuple
        Key of :data:`NU1_COEFFICIENTS` or ``(C1, a, b)``.
    check : bool
        Raise ValueError for concrete inputs outside the validity range (Kraychev set only).
    """
    C1, a, b = NU1_COEFFICIENTS[coefficients] if isinstance(coefficients, str) else coefficients
    if coefficients == "kraychev":
        _check("Pe*", Pe_star, 54.0, 4200.0, "eq. (5-18)", check)
        # 9.79 is the rounded sand value 14/1.43 = 9.7902 of the data basis: allow the rounding
        _check("D_R/d_p", jnp.asarray(D_R) / jnp.asarray(d_p), 3.43, 9.795, "eq. (5-18)", check)
    return C1 * jnp.asarray(Pe_star) ** a * (jnp.asarray(D_R) / d_p) ** b


def alpha_tube_bundle(d_p, rho_M, c_pM, lambda_M, W_p, *, lambda_G=0.026, W_SG=0.0, rho_G=1.2,
                      c_pG=1005.0, D_R=D_R, beta=BETA_HOPPER, check=True):
    """Heat-transfer coefficient tube bundle -> moving bed, ``alpha_1`` (W/(m^2 K)).

    Chains Kraychev digest eqs. (5-17) ``lambda*``, (5-19) ``Pe*``, (5-18) ``Nu_1`` and
    (5-16) ``alpha_1 = Nu_1 lambda* / d_p``. The area it refers to (``A_Sch1`` of 5-14) is not
    stated in chapter 5; chapter 8 uses a particle area (8-1), see :func:`exchange_area`.

    Parameters
    ----------
    d_p, rho_M, c_pM, lambda_M : array_like
        Particle diameter (m), density (kg/m^3), heat capacity (J/(kg K)), conductivity
        (W/(m K); not given by the thesis for its seeds: supply it).
    W_p : array_like
        Bed velocity, m/s (:func:`discharge_velocity`).
    lambda_G, W_SG, rho_G, c_pG : array_like
        Gas conductivity (W/(m K)), secondary-gas velocity (m/s), density, heat capacity.
    D_R : float
        Tube diameter, m (0.014).
    beta : float
        Solids volume fraction (0.59).
    check : bool
        Validity check of (5-18).

    Returns
    -------
    array
        ``alpha_1``, W/(m^2 K).
    """
    lam = effective_conductivity(lambda_M, lambda_G, beta)
    pe = peclet_star(W_p, d_p, rho_M, c_pM, lam, W_SG=W_SG, rho_G=rho_G, c_pG=c_pG, beta=beta)
    return nusselt_tube_bundle(pe, D_R, d_p, check=check) * lam / d_p


# --------------------------------------------------------------------------------------------
# channel coefficient alpha_2 (Sec. 6)
# --------------------------------------------------------------------------------------------


def specific_surface(rho_M, d_p):
    """Specific surface of spheres per mass, ``sigma_M = 6/(rho_M d_p)`` (m^2/kg).

    Kraychev digest Sec. 6, eq. (3-36) (cited as "5-36" in chapter 8, erratum 14.2 #8).
    """
    return 6.0 / (rho_M * d_p)


def circulating_solids_flow(L_App, S, W_p, rho_M, beta=BETA_HOPPER):
    """Solids flow through the outlet slit, ``(m_M)' = L_App S W_p beta rho_M`` (kg/s).

    Kraychev digest eq. (8-5) (loading including the hopper recirculation). Use ``W_p`` from
    eq. (5-5) (:func:`discharge_velocity`): the ``W_p`` printed in Appendix 10.4 is off by a
    factor of 10 between text and arithmetic (digest Sec. 6).

    Parameters
    ----------
    L_App : array_like
        Apparatus (slit) length, m.
    S : array_like
        Slit width, m.
    W_p : array_like
        Bed velocity, m/s.
    rho_M : array_like
        Particle density, kg/m^3.
    beta : float
        Solids volume fraction.
    """
    return L_App * S * W_p * beta * rho_M


def exchange_area(m_solids, m_gas, V, rho_G, rho_M, d_p):
    """Apparatus-level particle surface available for heat exchange (m^2).

    Kraychev digest eqs. (3-34)-(3-36), (8-1)-(8-4): ``A_Sch = mu V rho_G sigma_M`` with the
    loading ``mu = m_solids / m_gas`` and ``sigma_M = 6/(rho_M d_p)``. This equals
    ``m_solids (V / V_dot_G) sigma_M``: the surface of the solids held in ``V`` if they moved
    without slip with the gas (an apparatus-level, not a local, area; digest Sec. 6).

    For the channel (phase 2) use ``V = V_KAM2 L_App`` (``V_KAM2 = 0.360 m^3/m``) and, per
    eq. (8-4), ``m_solids`` = the circulating flow of eq. (8-5) (:func:`circulating_solids_flow`);
    the Mathcad design sheet instead uses the feed ``m_M`` (no recirculation; erratum 14.2 #8).
    For the bundle (phase 1), ``V = V_KAM1 L_App`` (0.0105 m^3/m) and ``m_gas`` the secondary gas.

    Parameters
    ----------
    m_solids, m_gas : array_like
        Solids and gas mass flows, kg/s.
    V : array_like
        Gas volume of the apparatus part, m^3.
    rho_G, rho_M : array_like
        Gas and particle density, kg/m^3.
    d_p : array_like
        Particle diameter, m.
    """
    return (m_solids / m_gas) * V * rho_G * specific_surface(rho_M, d_p)


def lmtd(dt_a, dt_b):
    """Logarithmic mean of two temperature differences (K); the arithmetic mean if equal.

    ``(dt_a - dt_b) / ln(dt_a / dt_b)``; both differences must have the same sign.
    """
    dt_a = jnp.asarray(dt_a, dtype=float)
    dt_b = jnp.asarray(dt_b, dtype=float)
    r = dt_a / dt_b
    close = jnp.abs(r - 1.0) < 1e-9
    r_s = jnp.where(close, 2.0, r)
    return jnp.where(close, 0.5 * (dt_a + dt_b), (dt_a - dt_b) / jnp.log(r_s))


def lmtd_cocurrent(t_M1, t_M2, T_L1, T_L2):
    """Co-current LMTD of the channel, Kraychev digest Sec. 6 step 2 (K).

    ``[(t_M1 - T_L1) - (t_M2 - T_L2)] / ln[(t_M1 - T_L1)/(t_M2 - T_L2)]``; ``t_M`` solids,
    ``T_L`` air, index 1 inlet, 2 outlet (any consistent temperature unit).
    """
    return lmtd(jnp.asarray(t_M1) - T_L1, jnp.asarray(t_M2) - T_L2)


class ChannelEvaluation(NamedTuple):
    """Result of :func:`channel_alpha2` (SI units)."""

    Q_2: jax.Array  # W, heat flow taken up by the air
    dt_ln: jax.Array  # K, co-current LMTD
    A_Sch2: jax.Array  # m^2, apparatus-level exchange area
    alpha_2: jax.Array  # W/(m^2 K)
    Nu_2: jax.Array  # -, alpha_2 d_p / lambda_G


def channel_alpha2(*, m_L, c_pL, T_L1, T_L2, t_M1, t_M2, m_solids, V, rho_G, rho_M, d_p,
                   lambda_G):
    """Evaluate the channel coefficient ``alpha_2`` from a steady test, as the thesis does.

    Kraychev digest Sec. 6:

    1. ``Q_2 = m_L c_pL (T_L2 - T_L1)`` (air side; the difference to the solids side counts as
       loss);
    2. co-current ``dt_m,ln2`` (:func:`lmtd_cocurrent`);
    3. ``A_Sch2 = mu_2 V rho_G sigma_M``, ``mu_2 = m_solids / m_L`` (3-34..3-36, 8-2, 8-4):
       pass ``m_solids`` from :func:`circulating_solids_flow` for eq. (8-4) or the feed for the
       Mathcad sheet's variant;
    4. ``alpha_2 = Q_2 / (A_Sch2 dt_m,ln)`` (5-20), ``Nu_2 = alpha_2 d_p / lambda_G`` (5-21).

    Parameters
    ----------
    m_L, c_pL : array_like
        Air mass flow (kg/s) and heat capacity (J/(kg K)).
    T_L1, T_L2, t_M1, t_M2 : array_like
        Air and solids inlet/outlet temperatures (K or degC).
    m_solids : array_like
        Solids mass flow used in the loading ``mu_2``, kg/s.
    V : array_like
        Gas volume of the channel part, m^3 (``V_KAM2 L_App``).
    rho_G, rho_M, d_p, lambda_G : array_like
        Gas density, particle density (kg/m^3), particle diameter (m), gas conductivity.

    Returns
    -------
    ChannelEvaluation
    """
    Q_2 = m_L * c_pL * (jnp.asarray(T_L2) - T_L1)
    dt = lmtd_cocurrent(t_M1, t_M2, T_L1, T_L2)
    A = exchange_area(m_solids, m_L, V, rho_G, rho_M, d_p)
    alpha = Q_2 / (A * dt)
    return ChannelEvaluation(Q_2, dt, A, alpha, alpha * d_p / lambda_G)


def nusselt_sphere_gnielinski(Re, Pr, variant="exact"):
    """Gnielinski's single-sphere Nusselt number used for the channel (-).

    Kraychev digest eqs. (3-16)-(3-18), ``Re = Re_psi = W d_p/(nu psi)`` (3-19; ``psi = 1`` in
    the channel)::

        Nu = 2 + sqrt(Nu_lam^2 + Nu_turb^2)
        Nu_lam  = 0.664 Re^(1/2) Pr^(1/3)
        Nu_turb = 0.037 Re^0.8 Pr / [1 + 2.443 Re^(-0.1) (Pr^(2/3) - 1)]

    ``variant="exact"`` (default) is this VDI form, as the digest prescribes (Sec. 14.1).
    ``variant="source_tables"`` uses ``Pr^0.33``, ``Re^(-0.3)`` and ``Pr^0.66``, the variant the
    thesis' Tables 10.8.1/10.8.2 follow: only for reproducing those tables.

    The formulas live in :func:`drumheat.models.convection.gnielinski_sphere_nu` (variants
    ``"vdi"`` and ``"kraychev_tables"``); this name is kept for the moving-bed API.
    """
    from drumheat.models.convection import gnielinski_sphere_nu

    names = {"exact": "vdi", "source_tables": "kraychev_tables"}
    if variant not in names:
        raise ValueError(f"variant = {variant!r}: use 'exact' or 'source_tables'.")
    return gnielinski_sphere_nu(jnp.asarray(Re, dtype=float), jnp.asarray(Pr, dtype=float),
                                variant=names[variant])


# --------------------------------------------------------------------------------------------
# terminal velocity (Sec. 10, Sec. 4.2)
# --------------------------------------------------------------------------------------------


def archimedes_kraychev(d_p, rho_p, rho_G, nu_G, g=G):
    """``Ar = g d_p^3 (rho_p - rho_G) / (nu_G^2 rho_G)`` (-), Kraychev digest Sec. 4.2."""
    return g * d_p**3 * (rho_p - rho_G) / (nu_G**2 * rho_G)


def reynolds_terminal_archimedes(Ar):
    """Terminal (entrainment) Reynolds number ``Re_aus = 18 [sqrt(1 + sqrt(Ar)/9) - 1]^2`` (-).

    Kraychev digest eq. (3-13), with the bracket as corrected in the digest (printed misplaced
    in the source); ``Ar < 2e10``. Tends to ``Ar/18`` (Stokes) for small ``Ar``.
    """
    return 18.0 * (jnp.sqrt(1.0 + jnp.sqrt(jnp.asarray(Ar, dtype=float)) / 9.0) - 1.0) ** 2


class TerminalVelocity(NamedTuple):
    """Terminal velocity from the thesis' regime fits."""

    W: float  # m/s
    Re: float  # -, W d_p / nu_G
    regime: str  # "stokes" (3-87), "intermediate" (3-88) or "newton" (3-89)


def terminal_velocity_kraychev(d_p, rho_M, rho_G=1.2, nu_G=1.5e-5, regime="auto", g=G):
    """Terminal velocity of a particle in air from the thesis' regime formulas (m/s).

    Kraychev digest Sec. 10::

        Stokes          W = g d^2 rho_M / (18 nu_G rho_G)         (3-87)
        10 < Re < 1000  W = 39 d rho_M^0.67   (dimensional, SI)  (3-88)
        Re > 1000       W = 5.2 sqrt(d rho_M / rho_G)             (3-89)

    (3-87) is printed with ``d^3`` and the coefficient ``0.54``; we implement the Stokes law it
    stands for, ``d^2`` and ``g/18 = 0.545`` (digest Sec. 10; buoyancy neglected as printed).
    (3-88) is a dimensional fit for air. ``regime="auto"`` takes the Newton form if its own
    ``Re >= 1000``, else the intermediate form if its ``Re >= 10``, else Stokes if its
    ``Re <= 1``; in the gap ``1 < Re < 10`` the fits do not apply and ValueError is raised (use
    :func:`drumheat.models.drag.terminal_velocity`). Scalar inputs.

    Parameters
    ----------
    d_p : float
        Particle diameter, m.
    rho_M, rho_G : float
        Particle and gas density, kg/m^3.
    nu_G : float
        Kinematic viscosity of the gas, m^2/s.
    regime : {"auto", "stokes", "intermediate", "newton"}
        Force a formula, or choose by consistency of the resulting ``Re``.
    g : float
        Gravity, m/s^2.

    Returns
    -------
    TerminalVelocity
        ``W`` (m/s), ``Re`` (-), the regime used.
    """
    d_p, rho_M, rho_G, nu_G = (float(v) for v in (d_p, rho_M, rho_G, nu_G))
    W = {
        "stokes": g * d_p**2 * rho_M / (18.0 * nu_G * rho_G),  # (3-87)
        "intermediate": 39.0 * d_p * rho_M**0.67,  # (3-88)
        "newton": 5.2 * math.sqrt(d_p * rho_M / rho_G),  # (3-89)
    }
    if regime == "auto":
        Re = {k: v * d_p / nu_G for k, v in W.items()}
        if Re["newton"] >= 1000.0:
            regime = "newton"
        elif Re["intermediate"] >= 10.0:
            regime = "intermediate"
        elif Re["stokes"] <= 1.0:
            regime = "stokes"
        else:
            raise ValueError(
                f"d_p = {d_p:g} m, rho_M = {rho_M:g} kg/m3: the terminal Reynolds number falls "
                "between 1 and 10, where none of (3-87)-(3-89) applies; use "
                "drumheat.models.drag.terminal_velocity."
            )
    if regime not in W:
        raise ValueError(f"regime = {regime!r}: use 'auto', 'stokes', 'intermediate' or 'newton'.")
    return TerminalVelocity(W[regime], W[regime] * d_p / nu_G, regime)


def design_channel_velocity(W_aus, factor=1.5):
    """Design air velocity in the channel, ``W_L,AK = 1.5 W_aus`` (up to 1.6), m/s.

    Kraychev digest Sec. 10 (8-6) and Sec. 13 step 5; stable conveying needs about 1.5
    ``W_aus``. (8-6 misplaces ``rho_L``: compute ``W_aus`` from 3-89, as the digest says.)
    """
    return factor * jnp.asarray(W_aus)


# --------------------------------------------------------------------------------------------
# pressure drop (Sec. 11)
# --------------------------------------------------------------------------------------------


def reduced_slit_reynolds(W_G, d_eq, nu_G):
    """``Re*_Sp = 0.01 Re_Sp``, ``Re_Sp = W_G d_eq / nu`` at the entrance slit (-).

    Kraychev digest eqs. (5-7), (5-8).
    """
    return 0.01 * W_G * d_eq / nu_G


def xi_apparatus(Re_star, check=True):
    """Loss coefficient of the empty apparatus without the entrance slit (-).

    Kraychev digest eq. (5-9): ``xi_App = 0.52 + 135/Re* + 6250/Re*^2`` (R^2 = 0.99,
    ``Re*_Sp = 50-350``). The source does not state its reference velocity and diameter; for
    this rig prefer :func:`pressure_drop_empty` (5-12).
    """
    _check("Re*_Sp", Re_star, 50.0, 350.0, "eq. (5-9)", check)
    Re_star = jnp.asarray(Re_star, dtype=float)
    return 0.52 + 135.0 / Re_star + 6250.0 / Re_star**2


def pressure_drop_slit_and_apparatus(W, rho, Re_star, xi_Sp=1.0, check=True):
    """``dp_LA = (xi_Sp + xi_App) rho W^2 / 2`` (Pa), Kraychev digest eqs. (5-10), (5-11).

    Evaluated with slit values throughout this overestimates the tabulated empty losses (digest
    Sec. 11.2); see :func:`pressure_drop_empty`.
    """
    return (xi_Sp + xi_apparatus(Re_star, check)) * rho * jnp.asarray(W) ** 2 / 2.0


def pressure_drop_empty(W_L, check=True):
    """Pressure drop of the empty apparatus, ``dp_LA = 0.67 W^2 + 0.84 W + 25.93`` (Pa).

    Kraychev digest eq. (5-12), a dimensional fit with ``W_L`` the air velocity at the entrance
    slit in m/s, valid 0-37 m/s; preferred for this rig (non-zero intercept).
    """
    _check("W_L", W_L, 0.0, 37.0, "eq. (5-12), in m/s", check)
    W_L = jnp.asarray(W_L, dtype=float)
    return 0.67 * W_L**2 + 0.84 * W_L + 25.93


def xi_hobler(Re_d, check=True):
    """Hobler's drag coefficient of gas through a moving bed in a tube bundle (-).

    Kraychev digest eqs. (3-70), (3-71): ``xi_d = 448 / Re_d^0.73 + 15``,
    ``Re_d = W_G,0 d_p / nu`` (alumosilicate 3.5 mm, ``s1 = s2 = 1.93 D_R``, 0.28-7 m/s).
    """
    Re_d = jnp.asarray(Re_d, dtype=float)
    return 448.0 / Re_d**0.73 + 15.0


# --------------------------------------------------------------------------------------------
# residence time (Sec. 12)
# --------------------------------------------------------------------------------------------


def bundle_residence_time(W_p, H_Sch=H_SCH):
    """One pass through the bundle, ``tau_1 = H_Sch / W_p`` (s), Kraychev digest eq. (5-26).

    ``H_Sch = 0.21 m`` with tubes (the measured ``W_p`` is defined as ``H_Sch / tau``, Sec. 7).
    """
    return H_Sch / jnp.asarray(W_p)


def mean_residence_time(tau_1, tau_2):
    """``tau_mean = tau_1 + tau_2`` (s): bundle pass plus inlet-to-outlet transport (5-26, 5-27)."""
    return jnp.asarray(tau_1) + tau_2


def prescribed_residence_time(n, tau_1):
    """``tau = n tau_1`` (s) when every n-th hopper zone is fed (Kraychev digest eq. 5-28)."""
    return n * jnp.asarray(tau_1)
