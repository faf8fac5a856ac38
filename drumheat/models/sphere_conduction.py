"""Closed-form transient conduction: sphere with a convective boundary, semi-infinite contact.

* Sphere, uniform initial temperature, convective boundary (the classical series solution,
  e.g. Carslaw & Jaeger, *Conduction of Heat in Solids*, section 9.4; VDI Heat Atlas Ec).
  The digests use it without writing it out: staltner-slag-particle.md section 2 ([5.1] with
  constant properties and a convective surface) is the problem it solves, and it is the
  reference for the shell solver (:mod:`drumheat.thermal.shells`). The Biot number here is
  built with the **radius**, ``Bi = alpha R / lambda``, so the eigen-equation reads
  ``1 - lambda cot(lambda) = Bi``.
* Two semi-infinite bodies in contact: staltner-slag-particle.md section 3, Phase 2
  ([3.10]-[3.11], [4.2], [4.10]): effusivity ``b = sqrt(lambda c rho)`` and the
  time-independent contact temperature; the flux of a semi-infinite body follows the
  penetration law of weigler-thermal-dem.md [1.11]-[1.12]; the thesis' literal Phase-2
  boundary (contact temperature one cell outside the sphere, [5.31]-[5.32]) as a surface flux.
* The transient internal coefficient of a cooling sphere of fluidized-bed-exercise.md
  section 5 (Nu_i with the corrected Nu_i0 denominator).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

__all__ = [
    "sphere_eigenvalues",
    "sphere_series_coefficients",
    "sphere_temperature",
    "sphere_mean_temperature",
    "sphere_surface_heat_flux",
    "effusivity",
    "contact_temperature",
    "semi_infinite_contact_flux",
    "semi_infinite_contact_heat",
    "ghost_node_contact_flux",
    "internal_transient_nu",
]


def _g(lam, Bi):
    # 1 - lam cot(lam) = Bi, multiplied by sin(lam): lam cos(lam) + (Bi - 1) sin(lam) = 0
    return lam * jnp.cos(lam) + (Bi - 1.0) * jnp.sin(lam)


@functools.partial(jax.jit, static_argnames="n_terms")
def sphere_eigenvalues(Bi, n_terms=60):
    """Positive roots ``lambda_k`` of ``1 - lambda cot(lambda) = Bi`` (Bi = alpha R / lambda).

    Series solution for a sphere with a convective boundary (see module docstring; not written
    out in the digests). Root k (k = 1..n_terms) lies in ``((k-1) pi, k pi)`` for Bi > 0.
    Found by bisection on ``g = lambda cos(lambda) + (Bi - 1) sin(lambda)`` (80 halvings,
    gradients stopped), then one Newton step that carries the implicit-function derivative
    ``d lambda/d Bi = -g_Bi/g_lambda`` to ``jax.grad``.

    Parameters
    ----------
    Bi : scalar or array, Bi > 0.
    n_terms : number of roots.

    Returns
    -------
    array of shape ``Bi.shape + (n_terms,)``.
    """
    Bi = jnp.asarray(Bi, dtype=float)[..., None]
    k = jnp.arange(1, n_terms + 1, dtype=float)
    lo = (k - 1.0) * jnp.pi + 1e-12
    hi = k * jnp.pi - 1e-12
    Bs = jax.lax.stop_gradient(Bi)
    glo = _g(lo, Bs)

    def body(_, lh):
        lo, hi = lh
        mid = 0.5 * (lo + hi)
        gm = _g(mid, Bs)
        same = jnp.sign(gm) == jnp.sign(glo)
        return jnp.where(same, mid, lo), jnp.where(same, hi, mid)

    lo, hi = jax.lax.fori_loop(0, 80, body, (jnp.broadcast_to(lo, (Bs * k).shape), hi + 0 * Bs))
    lam0 = jax.lax.stop_gradient(0.5 * (lo + hi))
    dg = jnp.cos(lam0) - lam0 * jnp.sin(lam0) + (Bi - 1.0) * jnp.cos(lam0)
    return lam0 - _g(lam0, Bi) / jax.lax.stop_gradient(dg)


def sphere_series_coefficients(lam):
    """``C_k = 4 (sin l_k - l_k cos l_k) / (2 l_k - sin(2 l_k))`` (series solution, see module)."""
    return 4.0 * (jnp.sin(lam) - lam * jnp.cos(lam)) / (2.0 * lam - jnp.sin(2.0 * lam))


@functools.partial(jax.jit, static_argnames="n_terms")
def sphere_temperature(r_over_R, Fo, Bi, T0, T_inf, n_terms=60):
    """Temperature in a sphere cooled (or heated) by convection, uniform start.

    ``(T - T_inf)/(T0 - T_inf) = sum_k C_k exp(-l_k^2 Fo) sin(l_k r/R) / (l_k r/R)``,
    ``Fo = a t / R^2``, ``Bi = alpha R / lambda``, l_k from :func:`sphere_eigenvalues`.
    Classical series (module docstring); the reference for staltner-slag-particle.md [5.1].

    Parameters
    ----------
    r_over_R : array_like, 0..1 (broadcasts with Fo).
    Fo : Fourier number(s) on the radius. Use Fo >~ 1e-3: the series needs ~1/sqrt(Fo) terms.
    Bi : scalar Biot number on the radius.
    T0, T_inf : initial and ambient temperature.
    n_terms : series length.
    """
    lam = sphere_eigenvalues(Bi, n_terms)
    C = sphere_series_coefficients(lam)
    x = jnp.asarray(r_over_R, dtype=float)[..., None] * lam
    sinc = jnp.where(x == 0.0, 1.0, jnp.sin(x) / jnp.where(x == 0.0, 1.0, x))
    theta = jnp.sum(C * jnp.exp(-(lam**2) * jnp.asarray(Fo, dtype=float)[..., None]) * sinc, axis=-1)
    return T_inf + (T0 - T_inf) * theta


@functools.partial(jax.jit, static_argnames="n_terms")
def sphere_mean_temperature(Fo, Bi, T0, T_inf, n_terms=60):
    """Volume-mean temperature of the convectively cooled sphere.

    ``(T_mean - T_inf)/(T0 - T_inf) = sum_k C_k exp(-l_k^2 Fo) 3 (sin l_k - l_k cos l_k)/l_k^3``
    (series solution, module docstring). Equivalent to ``sum_k 6 Bi^2 exp(-l_k^2 Fo) /
    (l_k^2 (l_k^2 + Bi^2 - Bi))``.
    """
    lam = sphere_eigenvalues(Bi, n_terms)
    C = sphere_series_coefficients(lam)
    w = 3.0 * (jnp.sin(lam) - lam * jnp.cos(lam)) / lam**3
    theta = jnp.sum(C * w * jnp.exp(-(lam**2) * jnp.asarray(Fo, dtype=float)[..., None]), axis=-1)
    return T_inf + (T0 - T_inf) * theta


def sphere_surface_heat_flux(Fo, Bi, T0, T_inf, conductivity, radius, n_terms=60):
    """Heat flux leaving the surface (W/m^2): ``q = alpha (T(R) - T_inf)``, ``alpha = Bi lambda/R``."""
    Ts = sphere_temperature(1.0, Fo, Bi, T0, T_inf, n_terms)
    return Bi * conductivity / radius * (Ts - T_inf)


def effusivity(conductivity, heat_capacity, density):
    """Thermal effusivity ``b = sqrt(lambda c rho)`` in W s^0.5/(m^2 K).

    staltner-slag-particle.md section 3 (Phase 2), [4.2] (slag) and [4.10] (wall).
    """
    return jnp.sqrt(jnp.asarray(conductivity) * heat_capacity * density)


def contact_temperature(T1, b1, T2, b2):
    """Contact temperature of two semi-infinite bodies, ``(b1 T1 + b2 T2)/(b1 + b2)``.

    staltner-slag-particle.md section 3 ([3.10]-[3.11], [5.29]): written there as
    ``T_m = T_4 + b_S/(b_S + b_W) (T_S - T_4)``. Constant in time.
    """
    return (b1 * jnp.asarray(T1) + b2 * jnp.asarray(T2)) / (b1 + b2)


def semi_infinite_contact_flux(T1, b1, T2, b2, t):
    """Heat flux (W/m^2) from body 1 into body 2 a time t (s) after contact.

    Each body sees a constant surface temperature T_m (:func:`contact_temperature`), so its
    flux is the penetration law ``q = b (T_body - T_m)/sqrt(pi t)`` (weigler-thermal-dem.md
    [1.11]: instantaneous coefficient ``b/sqrt(pi t)``): ``q = b1 b2/(b1 + b2) (T1 - T2)/
    sqrt(pi t)``. Diverges as t -> 0 like t^-1/2 (integrable).
    """
    return b1 * b2 / (b1 + b2) * (jnp.asarray(T1) - T2) / jnp.sqrt(jnp.pi * jnp.asarray(t))


def semi_infinite_contact_heat(T1, b1, T2, b2, t):
    """Heat per contact area (J/m^2) passed from body 1 to body 2 during [0, t].

    Time integral of :func:`semi_infinite_contact_flux`: ``2 b1 b2/(b1 + b2) (T1 - T2)
    sqrt(t/pi)``, the mean coefficient ``2 b/sqrt(pi t)`` of weigler-thermal-dem.md [1.12].
    """
    return 2.0 * b1 * b2 / (b1 + b2) * (jnp.asarray(T1) - T2) * jnp.sqrt(jnp.asarray(t) / jnp.pi)


def ghost_node_contact_flux(T_s, T_m, lam_s, lam_m, radius, dr):
    """Phase-2 wall flux of the thesis' literal contact boundary, W/m^2 on the sphere surface.

    staltner-slag-particle.md section 3, Phase 2 ([5.31]-[5.32] and the digest note): the source
    stores the contact temperature T_m in node n+1, one cell *outside* the sphere, and updates
    the surface node n with the interior stencil [5.32], whose east term
    ``M~_n a_E,n (T_m - T_n)`` with ``a_E,n = (lam_n + lam_{n+1})(2 r_n + dr)^2`` and
    ``M~_n = dt/(8 dr^2 r_n^2 c rho)`` [5.14] is the conduction through the face at
    ``R + dr/2`` with the arithmetic-mean conductivity ([5.7] corrected) over the distance dr.
    Written per unit of the surface area 4 pi R^2 (so that a flux boundary of a finite-volume
    scheme removes the same heat flow):

        q = ((R + dr/2)/R)^2 (lam_s + lam_m)/2 (T_s - T_m)/dr

    The reading amounts to a contact resistance of one cell between the surface node and the
    wall; it vanishes as dr -> 0, as does the difference to holding node n at T_m.

    Parameters
    ----------
    T_s : surface-node temperature, K. T_m : contact temperature (:func:`contact_temperature`), K.
    lam_s, lam_m : slag conductivity at T_s and at T_m (lambda_{n+1}), W/(m K).
    radius : sphere radius R, m. dr : node spacing R/(n - 1/2), m.
    """
    area = ((radius + 0.5 * dr) / radius) ** 2
    return area * 0.5 * (lam_s + lam_m) * (jnp.asarray(T_s) - T_m) / dr


def internal_transient_nu(Bi, Fo, a_star=6.0, b=0.4, nu_inf=2.0 * jnp.pi**2 / 3.0):
    """Transient internal Nusselt number of a cooling sphere (L = d).

    fluidized-bed-exercise.md section 5:
    ``Nu_i = sqrt(Nu_i_inf^2 - b^2 + (Nu_i0 + b)^2)``, b = 0.4;
    ``Nu_i0 = (sqrt(pi) + 10 Bi sqrt(Fo)) / (1 + 5 Bi sqrt(pi Fo)) / sqrt(Fo)`` -- the corrected
    denominator ``1 + 5 Bi sqrt(pi Fo)`` (the printed "1 + 5 Bi sqrt(pi) Fo" is garbled; the
    digest states only the corrected one reproduces the worked numbers);
    ``Nu_i_inf = (4 + a* + Bi)/(1 + Bi/Nu_inf)``, a* = 6, Nu_inf = 2 pi^2/3 (as printed).

    Parameters
    ----------
    Bi : ``alpha_a d / lambda_1`` (outer coefficient, diameter). Fo : ``lambda_1 t/(rho c d^2)``.
    """
    Bi = jnp.asarray(Bi, dtype=float)
    Fo = jnp.asarray(Fo, dtype=float)
    sF = jnp.sqrt(Fo)
    nu0 = (jnp.sqrt(jnp.pi) + 10.0 * Bi * sF) / (1.0 + 5.0 * Bi * jnp.sqrt(jnp.pi * Fo)) / sF
    nuinf = (4.0 + a_star + Bi) / (1.0 + Bi / nu_inf)
    return jnp.sqrt(nuinf**2 - b**2 + (nu0 + b) ** 2)
