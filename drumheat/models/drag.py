"""Drag on a single sphere: drag-coefficient laws, drag force and terminal settling velocity.

The default law is **Schiller-Naumann** (Schiller & Naumann 1933; Clift, Grace & Weber,
*Bubbles, Drops and Particles*, 1978, Table 5.2):

    C_D = 24/Re (1 + 0.15 Re^0.687)   for Re <= 1000,
    C_D = 0.44                         for Re > 1000 (Newton regime),

with ``Re = |u_rel| d_p / nu_f``. It reduces to Stokes' ``C_D = 24/Re`` for ``Re -> 0``.

Relation to the Kraychev digest (``reference/kraychev-tube-bundle.md``): the thesis' own
single-particle drag (C++ model, Sec. 8, eq. 6-7) is printed in two contradicting forms
(``3.54 Re_p - 0.2`` / ``3.14 (0.128 -+ 24/Re_p)``, erratum 14.2 #7) and cannot be used; its
terminal-velocity formulas (Sec. 10, eqs. 3-87..3-89) imply Stokes drag at low ``Re`` and a
constant ``C_D ~= 0.48`` in the Newton regime (``5.2 = sqrt(4 g / (3 * 0.48))``). We therefore
implement the standard Schiller-Naumann law and offer ``cd_newton(C=0.48)`` for reproducing
the thesis' Newton-regime numbers. The regime fits of the thesis are in
:func:`drumheat.models.moving_bed.terminal_velocity_kraychev`.

All functions are written with ``jax.numpy`` (array inputs, ``jit``/``grad`` friendly). SI units.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = [
    "G",
    "reynolds",
    "cd_stokes",
    "cd_schiller_naumann",
    "cd_newton",
    "DRAG_LAWS",
    "drag_force",
    "archimedes",
    "terminal_velocity",
]

G = 9.80665  # m/s^2, standard gravity


def reynolds(u_rel, d_p, nu_f):
    """Particle Reynolds number ``Re = |u_rel| d_p / nu_f`` (-).

    Parameters
    ----------
    u_rel : array_like
        Relative (slip) speed, m/s.
    d_p : array_like
        Sphere diameter, m.
    nu_f : array_like
        Kinematic viscosity of the fluid, m^2/s.
    """
    return jnp.abs(u_rel) * d_p / nu_f


def cd_stokes(Re):
    """Stokes drag coefficient ``C_D = 24/Re`` (-), creeping flow, ``Re << 1``."""
    return 24.0 / Re


def cd_schiller_naumann(Re):
    """Schiller-Naumann drag coefficient of a sphere (-).

    ``C_D = 24/Re (1 + 0.15 Re^0.687)`` for ``Re <= 1000`` and ``0.44`` above (Clift, Grace &
    Weber 1978). Accuracy about 5 % up to ``Re = 800``. See the module docstring for why this
    law is used instead of the Kraychev C++ drag (digest Sec. 8, erratum 14.2 #7).

    Parameters
    ----------
    Re : array_like
        Particle Reynolds number (> 0).
    """
    Re = jnp.asarray(Re, dtype=float)
    Re_s = jnp.where(Re > 0, Re, 1.0)
    low = 24.0 / Re_s * (1.0 + 0.15 * Re_s**0.687)
    return jnp.where(Re <= 1000.0, low, 0.44)


def cd_newton(Re, C=0.44):
    """Constant Newton-regime drag coefficient (-), ``10^3 < Re < 2 10^5``.

    ``C = 0.48`` reproduces the coefficient 5.2 of Kraychev digest eq. (3-89).
    """
    return jnp.full_like(jnp.asarray(Re, dtype=float), C)


DRAG_LAWS = {
    "schiller_naumann": cd_schiller_naumann,
    "stokes": cd_stokes,
    "newton": cd_newton,
}


def _law(drag_law):
    if callable(drag_law):
        return drag_law
    try:
        return DRAG_LAWS[drag_law]
    except KeyError:
        raise ValueError(
            f"drag_law = {drag_law!r}: unknown; use one of {sorted(DRAG_LAWS)} or a callable C_D(Re)."
        ) from None


def drag_force(u_rel, d_p, rho_f, mu_f, drag_law="schiller_naumann"):
    """Drag force on a sphere, ``F = 1/2 rho_f C_D (pi d_p^2 / 4) |u| u`` (N).

    Parameters
    ----------
    u_rel : array_like
        Fluid velocity minus particle velocity, m/s; a trailing axis of length 2 or 3 is a vector
        (the force then points along ``u_rel``); otherwise a signed scalar speed.
    d_p : array_like
        Sphere diameter, m.
    rho_f, mu_f : array_like
        Fluid density (kg/m^3) and dynamic viscosity (Pa s).
    drag_law : str or callable
        ``"schiller_naumann"`` (default), ``"stokes"``, ``"newton"`` or ``C_D(Re)``.

    Returns
    -------
    array
        Force on the particle, N (same shape as ``u_rel``).
    """
    cd = _law(drag_law)
    u = jnp.asarray(u_rel, dtype=float)
    speed = jnp.linalg.norm(u, axis=-1, keepdims=True) if u.ndim and u.shape[-1] in (2, 3) else jnp.abs(u)
    d = jnp.asarray(d_p)[..., None] if u.ndim and u.shape[-1] in (2, 3) else d_p
    Re = speed * d * rho_f / mu_f
    Re_s = jnp.where(Re > 0, Re, 1.0)
    # F = 1/2 rho C_D A |u| u, written as (C_D Re) * mu * pi d / 8 * u so that Re -> 0 is finite
    cd_re = jnp.where(Re > 0, cd(Re_s) * Re_s, 24.0)
    return cd_re * mu_f * jnp.pi * d / 8.0 * u


def archimedes(d_p, rho_p, rho_f, mu_f, g=G):
    """Archimedes number ``Ar = g d^3 (rho_p - rho_f) rho_f / mu_f^2`` (-).

    Same as Kraychev digest Sec. 4.2, ``Ar = g d^3 (rho_p - rho_G)/(nu^2 rho_G)``.
    """
    return g * d_p**3 * (rho_p - rho_f) * rho_f / mu_f**2


def terminal_velocity(d_p, rho_p, rho_f, mu_f, drag_law="schiller_naumann", g=G):
    """Terminal settling velocity of a sphere in a quiescent fluid (m/s).

    Solves the force balance ``(rho_p - rho_f) g pi d^3/6 = 1/2 rho_f C_D(Re) pi d^2/4 W^2``, i.e.
    ``C_D(Re) Re^2 = 4/3 Ar`` with ``Re = W d rho_f/mu_f``, by 64 bisections on ``ln Re`` in
    ``[1e-12, 1e9]`` (``C_D Re^2`` is increasing for the laws provided). Vectorised; for a
    heavier-than-fluid sphere only.

    Parameters
    ----------
    d_p : array_like
        Sphere diameter, m.
    rho_p, rho_f : array_like
        Particle and fluid density, kg/m^3 (``rho_p > rho_f``).
    mu_f : array_like
        Dynamic viscosity, Pa s.
    drag_law : str or callable
        As in :func:`drag_force`.
    g : float
        Gravity, m/s^2.

    Returns
    -------
    array
        Terminal velocity, m/s.
    """
    cd = _law(drag_law)
    target = 4.0 / 3.0 * archimedes(d_p, rho_p, rho_f, mu_f, g)
    target = jnp.asarray(target, dtype=float)
    lo = jnp.full_like(target, jnp.log(1e-12))
    hi = jnp.full_like(target, jnp.log(1e9))

    def body(_, lohi):
        lo, hi = lohi
        mid = 0.5 * (lo + hi)
        Re = jnp.exp(mid)
        below = cd(Re) * Re**2 < target
        return jnp.where(below, mid, lo), jnp.where(below, hi, mid)

    lo, hi = jax.lax.fori_loop(0, 64, body, (lo, hi))
    Re = jnp.exp(0.5 * (lo + hi))
    return Re * mu_f / (rho_f * d_p)
