"""View factors and grey-enclosure radiation exchange (radiosity method).

Sources: staltner-slag-particle.md sections 6 (radiosity, [3.39]-[3.43], [6.29]-[6.40]),
7.1 (small sphere to the granulator zones, exact solid angles as the digest recommends) and
7.2 (surface-to-surface view factors of Appendix B in their corrected form).

Granulator geometry (staltner-slag-particle.md section 1 and 7.2), axis z upwards, bed at z = 0:

* zone 2: bottom disc, radius r_2, at z = 0;
* zone 3: cylinder, radius r_2, 0 <= z <= h_3;
* zone 4: conical frustum, z from h_3 to H = h_3 + h_4, radius r_2 -> r_5, wall inclined alpha_4
  to the horizontal, r_5 = r_2 - h_4 / tan(alpha_4);
* zone 5: top outlet disc, radius r_5, at z = H.

Arrays that index the zones use the order (2, 3, 4, 5) -> (0, 1, 2, 3).

All functions are ``jax.numpy`` and differentiable; quadratures are fixed Gauss-Legendre or
trapezoidal rules (no adaptivity), so ``jit``/``grad``/``vmap`` work.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "SIGMA",
    "sphere_to_coaxial_disc",
    "disc_solid_angle",
    "sphere_to_disc",
    "coaxial_discs_exchange",
    "coaxial_discs",
    "GranulatorGeometry",
    "granulator_geometry",
    "granulator_view_factors",
    "sphere_to_granulator_view_factors",
    "particle_view_factor_matrix",
    "radiosity",
    "radiosity_exchange",
    "fictitious_view_factors",
    "particle_radiative_flux",
    "radiation_sink_temperature",
    "linearised_radiation_coefficient",
]

#: Stefan-Boltzmann constant, W/(m^2 K^4) (CODATA 2018).
SIGMA = 5.670374419e-8

_TINY = 1e-300

# ----------------------------------------------------------------------------------------------
# small sphere -> disc (solid angles)
# ----------------------------------------------------------------------------------------------


def sphere_to_coaxial_disc(h, a):
    """View factor from a sphere to a coaxial disc, ``F = (1 - h / sqrt(h^2 + a^2)) / 2``.

    Closed form (Howell's catalogue, sphere to coaxial disc; independent of the sphere radius),
    equal to Omega/(4 pi) of staltner-slag-particle.md section 7.1 at radial offset 0.

    Parameters
    ----------
    h : distance of the sphere centre from the disc plane (m), ``h >= 0``.
    a : disc radius (m).
    """
    h = jnp.asarray(h, dtype=float)
    return 0.5 * (1.0 - h / jnp.sqrt(h**2 + a**2))


def _sqrt_pos(x):
    return jnp.sqrt(jnp.maximum(x, _TINY))


@functools.partial(jax.jit, static_argnames="n_quad")
def disc_solid_angle(h, a, rho, n_quad=96):
    """Solid angle (sr) of a disc of radius a seen from height h, radial offset rho.

    staltner-slag-particle.md section 7.1 (digest recommendation, exact solid angle):

    * ``rho < a``: ``Omega = int_0^{2 pi} [1 - h / sqrt(h^2 + R^2)] dphi``,
      ``R = -rho cos(phi) + sqrt(a^2 - rho^2 sin^2 phi)``;
    * ``rho > a``: ``Omega = int_{-phi_m}^{phi_m} [h/sqrt(h^2 + R_-^2) - h/sqrt(h^2 + R_+^2)]
      dphi``, ``R_+- = rho cos(phi) +- sqrt(a^2 - rho^2 sin^2 phi)``, ``phi_m = arcsin(a/rho)``.

    Quadrature: the periodic inner integrand is integrated with the trapezoidal rule (spectral
    accuracy except very close to the rim); the outer one after the substitution
    ``phi = phi_m sin(u)``, which removes the square-root end-point behaviour, with
    Gauss-Legendre. Accuracy ~1e-10 sr away from the rim, ~1e-4 sr within 1e-3 a of it
    (checked in the tests against a 2-D adaptive quadrature). ``h`` may be 0 (point on the
    plane: 2 pi inside, 0 outside). Broadcasts over ``h``, ``a``, ``rho``.
    """
    h, a, rho = jnp.broadcast_arrays(*(jnp.asarray(x, dtype=float) for x in (h, a, rho)))
    h = jnp.abs(h)[..., None]
    inside = rho < a
    a = a[..., None]
    # double-where: each branch only ever sees arguments valid for it (finite gradients)
    rho_in = jnp.where(inside, rho, 0.0)[..., None]
    rho_ = jnp.where(inside, 2.0 * a[..., 0], rho)[..., None]

    # inside, trapezoid on [0, 2 pi)
    phi = 2.0 * jnp.pi * jnp.arange(2 * n_quad) / (2 * n_quad)
    R = -rho_in * jnp.cos(phi) + _sqrt_pos(a**2 - rho_in**2 * jnp.sin(phi) ** 2)
    f_in = 1.0 - h / _sqrt_pos(h**2 + R**2)
    omega_in = jnp.mean(f_in, axis=-1) * 2.0 * jnp.pi

    # outside, Gauss-Legendre in u with phi = phi_m sin(u)
    x, w = np.polynomial.legendre.leggauss(n_quad)
    u = 0.5 * jnp.pi * jnp.asarray(x)
    wu = 0.5 * jnp.pi * jnp.asarray(w)
    ratio = jnp.clip(a / jnp.maximum(rho_, _TINY), 0.0, 1.0)
    phim = jnp.arcsin(ratio)
    ph = phim * jnp.sin(u)
    root = _sqrt_pos(a**2 - rho_**2 * jnp.sin(ph) ** 2)
    Rm = rho_ * jnp.cos(ph) - root
    Rp = rho_ * jnp.cos(ph) + root
    g = h / _sqrt_pos(h**2 + Rm**2) - h / _sqrt_pos(h**2 + Rp**2)
    omega_out = jnp.sum(g * phim * jnp.cos(u) * wu, axis=-1)

    return jnp.where(inside, omega_in, omega_out)


def sphere_to_disc(h, a, rho=0.0, n_quad=96):
    """View factor from a small sphere to a disc, ``phi = Omega / (4 pi)``.

    staltner-slag-particle.md section 7.1 (phi_1j equals the solid angle of surface j at the
    sphere centre divided by 4 pi); see :func:`disc_solid_angle` for h, a, rho.
    """
    return disc_solid_angle(h, a, rho, n_quad) / (4.0 * jnp.pi)


# ----------------------------------------------------------------------------------------------
# surface <-> surface: coaxial discs, cylinder, frustum (Appendix B, corrected)
# ----------------------------------------------------------------------------------------------


def coaxial_discs_exchange(a, b, L):
    """``Pi(a, b, L) = A_a F_ab = (pi/2) [S - sqrt(S^2 - 4 a^2 b^2)]``, ``S = a^2 + b^2 + L^2``.

    staltner-slag-particle.md section 7.2 (Howell C-41 in reciprocity form), m^2. Symmetric
    in a and b. The subtraction is evaluated as ``2 pi a^2 b^2 / (S + sqrt(...))`` to avoid
    cancellation for distant discs.
    """
    a = jnp.asarray(a, dtype=float)
    S = a**2 + b**2 + L**2
    return 2.0 * jnp.pi * a**2 * b**2 / (S + jnp.sqrt(S**2 - 4.0 * a**2 * b**2))


def coaxial_discs(a, b, L):
    """View factor from a disc of radius a to a coaxial parallel disc of radius b at distance L.

    staltner-slag-particle.md section 7.2, ``F_ab = Pi(a, b, L) / (pi a^2)``.
    """
    return coaxial_discs_exchange(a, b, L) / (jnp.pi * jnp.asarray(a, dtype=float) ** 2)


class GranulatorGeometry(NamedTuple):
    """Derived dimensions of the granulator enclosure (staltner-slag-particle.md 1, 7.2), m/m^2."""

    r2: jnp.ndarray
    h3: jnp.ndarray
    h4: jnp.ndarray
    alpha4: jnp.ndarray  #: rad
    r5: jnp.ndarray
    H: jnp.ndarray
    areas: jnp.ndarray  #: (4,) A_2, A_3, A_4, A_5


def granulator_geometry(r2, h3, h4, alpha4):
    """Zone dimensions and areas (staltner-slag-particle.md section 7.2).

    ``r_5 = r_2 - h_4/tan(alpha_4)``, ``A_2 = pi r_2^2``, ``A_3 = 2 pi r_2 h_3``,
    ``A_4 = pi (r_2^2 - r_5^2)/cos(alpha_4)``, ``A_5 = pi r_5^2``. ``alpha4`` in radians.
    Raises ValueError (for concrete inputs) when r_5 <= 0.
    """
    r2, h3, h4, alpha4 = (jnp.asarray(x, dtype=float) for x in (r2, h3, h4, alpha4))
    r5 = r2 - h4 / jnp.tan(alpha4)
    try:
        bad = bool(jnp.any(r5 <= 0.0))
    except Exception:  # traced: cannot check here
        bad = False
    if bad:
        raise ValueError(
            f"granulator geometry has no top opening: r5 = r2 - h4/tan(alpha4) = {r5} m <= 0 "
            f"(r2={r2}, h4={h4}, alpha4={alpha4} rad); reduce h4 or increase alpha4."
        )
    areas = jnp.stack(
        [
            jnp.pi * r2**2,
            2.0 * jnp.pi * r2 * h3,
            jnp.pi * (r2**2 - r5**2) / jnp.cos(alpha4),
            jnp.pi * r5**2,
        ]
    )
    return GranulatorGeometry(r2, h3, h4, alpha4, r5, h3 + h4, areas)


def granulator_view_factors(r2, h3, h4, alpha4):
    """4x4 view-factor matrix of the enclosure zones 2..5 and their areas.

    staltner-slag-particle.md section 7.2 (Appendix B [B.3]-[B.25], corrected forms: the
    ``-4[r_2 t (r_2 t - h_4)]^2`` terms inside the roots, i.e. the coaxial-disc exchange
    ``Pi``; phi45 with ``-phi_{4,4~}``; digest forms written without the t^2 multiplication):

    ====  =====================================================================
    phi23  h_3 (s - h_3) / (2 r_2^2),  s = sqrt(4 r_2^2 + h_3^2)            [B.3]
    phi25  Pi(r_2, r_5, H) / A_2                                           [B.8]
    phi24  (s - h_3)^2 / (4 r_2^2) - phi25                                 [B.6, B.7]
    phi32  (s - h_3) / (4 r_2)                                             [B.9]
    phi33  (2 r_2 + h_3 - s) / (2 r_2)                                     [B.10]
    phi35  [Pi(r_2, r_5, h_4) - Pi(r_2, r_5, H)] / A_3                     [B.13]
    phi34  phi32 - phi35                                                   [B.12]
    phi44  1 - pi [sqrt(S_4^2 - 4 r_2^2 r_5^2) - h_4^2] / A_4               [B.18]
    phi45  [pi r_5^2 - Pi(r_2, r_5, h_4)] / A_4                            [B.20]
    phi42, phi43, phi52, phi53, phi54 by reciprocity           [B.15, B.17, B.21, B.23, B.25]
    ====  =====================================================================

    Parameters
    ----------
    r2, h3, h4 : m. alpha4 : inclination of the frustum wall to the horizontal, rad.

    Returns
    -------
    F : (4, 4) array, ``F[i, j]`` from zone i+2 to zone j+2.
    areas : (4,) array, m^2.
    """
    g = granulator_geometry(r2, h3, h4, alpha4)
    r2, h3, h4, r5, H = g.r2, g.h3, g.h4, g.r5, g.H
    A2, A3, A4, A5 = g.areas
    s = jnp.sqrt(4.0 * r2**2 + h3**2)
    Pi_H = coaxial_discs_exchange(r2, r5, H)
    Pi_4 = coaxial_discs_exchange(r2, r5, h4)

    f23 = h3 * (s - h3) / (2.0 * r2**2)
    f25 = Pi_H / A2
    f24 = (s - h3) ** 2 / (4.0 * r2**2) - f25
    f32 = (s - h3) / (4.0 * r2)
    f33 = (2.0 * r2 + h3 - s) / (2.0 * r2)
    f35 = (Pi_4 - Pi_H) / A3
    f34 = f32 - f35
    S4 = r2**2 + r5**2 + h4**2
    f44 = 1.0 - jnp.pi * (jnp.sqrt(S4**2 - 4.0 * r2**2 * r5**2) - h4**2) / A4
    f45 = (jnp.pi * r5**2 - Pi_4) / A4
    f42 = A2 * f24 / A4
    f43 = A3 * f34 / A4
    f52 = A2 * f25 / A5
    f53 = A3 * f35 / A5
    f54 = A4 * f45 / A5
    z = jnp.zeros_like(f23)
    F = jnp.stack(
        [
            jnp.stack([z, f23, f24, f25]),
            jnp.stack([f32, f33, f34, f35]),
            jnp.stack([f42, f43, f44, f45]),
            jnp.stack([f52, f53, f54, z]),
        ]
    )
    return F, g.areas


def sphere_to_granulator_view_factors(rho, z, r2, h3, h4, alpha4, n_quad=96):
    """View factors phi_12..phi_15 from a small sphere at (rho, z) to the zones 2..5.

    staltner-slag-particle.md section 7.1, digest recommendation (exact solid angles instead of
    the source's 16-gon construction [6.1]-[6.20] and its polynomial fits [6.21]-[6.28]):
    Omega_2 and Omega_5 from :func:`disc_solid_angle`; Omega_c the solid angle of the circle of
    radius r_2 at z = h_3; for z <= h_3, Omega_4 = Omega_c - Omega_5; for z > h_3,
    Omega_3 = Omega_c - Omega_2; the remaining zone from sum Omega = 4 pi (convex enclosure).
    (Digest erratum: EB lies at height h_3, not h_4.)

    The point must lie inside the enclosure (on the wall gives the half-space split, as for
    "half the particle inside the wall"). Broadcasts over rho, z.

    Returns
    -------
    phi : array of shape ``broadcast(rho, z).shape + (4,)``, summing to 1.
    """
    g = granulator_geometry(r2, h3, h4, alpha4)
    rho = jnp.asarray(rho, dtype=float)
    z = jnp.asarray(z, dtype=float)
    om2 = disc_solid_angle(z, g.r2, rho, n_quad)
    om5 = disc_solid_angle(g.H - z, g.r5, rho, n_quad)
    omc = disc_solid_angle(z - g.h3, g.r2, rho, n_quad)
    below = z <= g.h3
    om4 = jnp.where(below, omc - om5, 4.0 * jnp.pi - om2 - (omc - om2) - om5)
    om3 = jnp.where(below, 4.0 * jnp.pi - om2 - om4 - om5, omc - om2)
    return jnp.stack([om2, om3, om4, om5], axis=-1) / (4.0 * jnp.pi)


def particle_view_factor_matrix(phi_particle, F_enclosure):
    """Full (m+1)x(m+1) view-factor matrix with a tiny particle as surface 1 (index 0).

    staltner-slag-particle.md section 6: the droplet is tiny, so phi_i1 = 0 for all i;
    row 0 is ``[0, phi_12, ..., phi_1,m+1]``, the other rows are the enclosure's.
    """
    phi = jnp.asarray(phi_particle, dtype=float)
    F = jnp.asarray(F_enclosure, dtype=float)
    m = F.shape[0]
    top = jnp.concatenate([jnp.zeros((1,)), phi])[None, :]
    rest = jnp.concatenate([jnp.zeros((m, 1)), F], axis=1)
    return jnp.concatenate([top, rest], axis=0)


# ----------------------------------------------------------------------------------------------
# radiosity
# ----------------------------------------------------------------------------------------------


def _K_matrix(emissivity, F):
    eps = jnp.asarray(emissivity, dtype=float)
    F = jnp.asarray(F, dtype=float)
    return jnp.eye(F.shape[0]) - (1.0 - eps)[:, None] * F


def radiosity(emissivity, F, T, sigma=SIGMA):
    """Radiosities H (W/m^2) of a grey, diffuse, opaque enclosure.

    staltner-slag-particle.md [6.29]-[6.35]: ``sum_j [delta_ij - (1 - eps_i) phi_ij] H_j =
    eps_i sigma T_i^4``, i.e. ``K H = E``, ``H = K^-1 E`` (the source prints E K^-1; the
    digest's corrected order is used).
    """
    E = jnp.asarray(emissivity, dtype=float) * sigma * jnp.asarray(T, dtype=float) ** 4
    return jnp.linalg.solve(_K_matrix(emissivity, F), E)


def radiosity_exchange(emissivity, area, F, T, sigma=SIGMA):
    """Net heat flow leaving each surface of a grey enclosure (W), and the radiosities.

    staltner-slag-particle.md [3.39]-[3.43] and [6.29]-[6.35]:
    ``Q_i = A_i (H_i - G_i)``, ``G_i = sum_j phi_ij H_j`` (irradiation), which equals
    ``A_i eps_i/(1 - eps_i) (sigma T_i^4 - H_i)`` for eps_i < 1 and also works for black
    surfaces (eps_i = 1).

    Parameters
    ----------
    emissivity : (n,) grey emissivities. area : (n,) m^2. F : (n, n) view factors.
    T : (n,) surface temperatures, K.

    Returns
    -------
    Q : (n,) W, positive when the surface loses heat. Sums to 0 for a closed enclosure
        (``sum_j F_ij = 1`` and reciprocity).
    H : (n,) radiosities, W/m^2.
    """
    H = radiosity(emissivity, F, T, sigma)
    G = jnp.asarray(F, dtype=float) @ H
    return jnp.asarray(area, dtype=float) * (H - G), H


def fictitious_view_factors(emissivity, F):
    """Fictitious view factors ``phi~ = (I - F) K^-1`` of the radiosity method.

    staltner-slag-particle.md [6.37]-[6.40]: the net flux density of surface i is
    ``q_i = sum_j (delta_ij - phi_ij) H_j = sum_j eps_j sigma phi~_ij T_j^4``. For the tiny
    particle (row 0 of :func:`particle_view_factor_matrix`) ``phi~_00 = 1`` and
    ``phi~_0j <= 0`` for j >= 1 (digest note, verified in the tests).

    Returns
    -------
    (n, n) array; row i gives surface i's coefficients.
    """
    F = jnp.asarray(F, dtype=float)
    Kinv = jnp.linalg.inv(_K_matrix(emissivity, F))
    return (jnp.eye(F.shape[0]) - F) @ Kinv


def particle_radiative_flux(T_s, eps_s, phi_particle, eps_enc, F_enc, T_enc, sigma=SIGMA):
    """Net radiative flux density leaving a small particle (W/m^2), reduced form.

    staltner-slag-particle.md section 6, digest note: ``q_Str = eps_1 (sigma T_s^4 - G)``,
    ``G = sum_m phi_1m H_m`` with ``H`` from the closed enclosure alone (the particle is
    too small to change it). Identical to ``sum_j eps_j sigma phi~_1j T_j^4`` of [6.37]-[6.40].

    Parameters
    ----------
    T_s : particle surface temperature(s), K (any shape). eps_s : particle emissivity.
    phi_particle : (m,) view factors particle -> enclosure zones (sum 1).
    eps_enc, T_enc : (m,) enclosure emissivities and temperatures (K). F_enc : (m, m).
    """
    H = radiosity(eps_enc, F_enc, T_enc, sigma)
    G = jnp.dot(jnp.asarray(phi_particle, dtype=float), H)
    return eps_s * (sigma * jnp.asarray(T_s, dtype=float) ** 4 - G)


def radiation_sink_temperature(phi_tilde_row, emissivity, T, particle_index=0):
    """Effective radiation temperature ``T_rad`` seen by the particle.

    staltner-slag-particle.md section 4 (digest recommendation):
    ``T_rad^4 = -(1/eps_1) sum_{j != 1} eps_j phi~_1j T_j^4``, so that
    ``q_Str = eps_1 sigma (T_n^4 - T_rad^4)``.

    Parameters
    ----------
    phi_tilde_row : (n,) row of :func:`fictitious_view_factors` for the particle.
    emissivity, T : (n,) including the particle entry (its T is ignored).
    """
    eps = jnp.asarray(emissivity, dtype=float)
    T = jnp.asarray(T, dtype=float)
    mask = jnp.arange(eps.shape[0]) != particle_index
    s = jnp.sum(jnp.where(mask, eps * phi_tilde_row * T**4, 0.0))
    return (-s / eps[particle_index]) ** 0.25


def linearised_radiation_coefficient(T_s, T_rad, eps_s, sigma=SIGMA):
    """``h_r = eps_1 sigma (T_n^2 + T_rad^2)(T_n + T_rad)`` in W/(m^2 K).

    staltner-slag-particle.md section 4 (digest recommendation), so that
    ``q_Str = h_r (T_n - T_rad)`` exactly.
    """
    T_s = jnp.asarray(T_s, dtype=float)
    return eps_s * sigma * (T_s**2 + T_rad**2) * (T_s + T_rad)
