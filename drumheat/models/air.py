"""Dry-air properties at about 1 bar.

Temperature-dependent fits: staltner-slag-particle.md section 9, Table 4.6 of the thesis,
``P(T) = sum_{i=0..6} c_i T^i`` with T in K, fitted to VDI Heat Atlas data and valid for
273.15-1273.15 K. Outside that range the input temperature is clamped to the range (so the
polynomials never extrapolate; the derivative is zero there) and a ``UserWarning`` is issued:
with ``warnings.warn`` for concrete inputs, and through ``jax.debug.callback`` at run time when
the temperature is traced (inside ``jit``/``grad``).

The polynomials are evaluated in float64 (``import drumheat`` enables x64): the fits cancel
terms of order 1e2 (c_6 T^6 at 1273 K is ~ 2.6 for rho) to give results of order 1, so float32
loses several digits (digest section 9: "Use float64 (cancellation)").

Constant fallback: :data:`AIR_30C` from weigler-thermal-dem.md Table 8-1 (dry air at 30 degC,
1 atm: lambda = 0.0266 W/(m K), c_p = 1009 J/(kg K), M = 28.96 kg/kmol).
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "T_MIN",
    "T_MAX",
    "COEFFICIENTS",
    "density",
    "heat_capacity",
    "conductivity",
    "viscosity",
    "kinematic_viscosity",
    "thermal_diffusivity",
    "prandtl",
    "AirProperties",
    "properties",
    "AIR_30C",
    "constant_properties",
]

#: Validity range of the Table 4.6 fits (K), staltner-slag-particle.md section 9.
T_MIN = 273.15
T_MAX = 1273.15

#: Coefficients c_0..c_6 of staltner-slag-particle.md section 9 (Table 4.6), T in K.
COEFFICIENTS = {
    "rho": (4.298, -2.157e-2, 5.712e-5, -8.638e-8, 7.486e-11, -3.456e-14, 6.581e-18),
    "cp": (1010.685, 8.783e-2, -1.158e-3, 3.999e-6, -5.019e-9, 2.826e-12, -6.061e-16),
    "lam": (-1.058e-3, 1.155e-4, -1.086e-7, 1.177e-10, -8.478e-14, 3.526e-17, -6.323e-21),
    "eta": (-2.663e-7, 8.308e-8, -9.271e-11, 1.022e-13, -7.498e-17, 3.172e-20, -5.795e-24),
}


def _warn_host(lo, hi, name):
    if lo < T_MIN or hi > T_MAX:
        warnings.warn(
            f"drumheat.models.air.{name}: temperature range [{lo:.2f}, {hi:.2f}] K lies outside "
            f"the validity range [{T_MIN}, {T_MAX}] K of the Staltner Table 4.6 fit; "
            "the temperature was clamped to that range.",
            UserWarning,
            stacklevel=4,
        )


def _clamp(T, name):
    """Clamp T to [T_MIN, T_MAX], warning if anything was outside."""
    T = jnp.asarray(T, dtype=jnp.float64)
    if isinstance(T, jax.core.Tracer):
        jax.debug.callback(
            lambda lo, hi: _warn_host(float(lo), float(hi), name), jnp.min(T), jnp.max(T)
        )
    else:
        if T.size:
            _warn_host(float(jnp.min(T)), float(jnp.max(T)), name)
    return jnp.clip(T, T_MIN, T_MAX)


def _poly(T, coeffs):
    # Horner form, float64
    out = jnp.zeros_like(T) + coeffs[-1]
    for c in coeffs[-2::-1]:
        out = out * T + c
    return out


def density(T):
    """Density of dry air rho_L(T) in kg/m^3 (staltner-slag-particle.md section 9, Table 4.6).

    Parameters
    ----------
    T : array_like
        Temperature in K; clamped to 273.15-1273.15 K with a warning.
    """
    return _poly(_clamp(T, "density"), COEFFICIENTS["rho"])


def heat_capacity(T):
    """Isobaric heat capacity c_pL(T) in J/(kg K) (staltner-slag-particle.md section 9)."""
    return _poly(_clamp(T, "heat_capacity"), COEFFICIENTS["cp"])


def conductivity(T):
    """Thermal conductivity lambda_L(T) in W/(m K) (staltner-slag-particle.md section 9)."""
    return _poly(_clamp(T, "conductivity"), COEFFICIENTS["lam"])


def viscosity(T):
    """Dynamic viscosity eta_L(T) in Pa s (staltner-slag-particle.md section 9)."""
    return _poly(_clamp(T, "viscosity"), COEFFICIENTS["eta"])


def kinematic_viscosity(T):
    """Kinematic viscosity ``nu = eta / rho`` in m^2/s (staltner-slag-particle.md section 9)."""
    Tc = _clamp(T, "kinematic_viscosity")
    return _poly(Tc, COEFFICIENTS["eta"]) / _poly(Tc, COEFFICIENTS["rho"])


def thermal_diffusivity(T):
    """``a = lambda / (rho c_p)`` in m^2/s (from the section-9 fits)."""
    Tc = _clamp(T, "thermal_diffusivity")
    return _poly(Tc, COEFFICIENTS["lam"]) / (
        _poly(Tc, COEFFICIENTS["rho"]) * _poly(Tc, COEFFICIENTS["cp"])
    )


def prandtl(T):
    """Prandtl number ``Pr = eta c_p / lambda`` (staltner-slag-particle.md section 9)."""
    Tc = _clamp(T, "prandtl")
    return (
        _poly(Tc, COEFFICIENTS["eta"])
        * _poly(Tc, COEFFICIENTS["cp"])
        / _poly(Tc, COEFFICIENTS["lam"])
    )


class AirProperties(NamedTuple):
    """Gas properties in SI units (a PyTree of arrays)."""

    rho: jax.Array  #: density, kg/m^3
    cp: jax.Array  #: heat capacity, J/(kg K)
    lam: jax.Array  #: conductivity, W/(m K)
    eta: jax.Array  #: dynamic viscosity, Pa s
    nu: jax.Array  #: kinematic viscosity, m^2/s
    Pr: jax.Array  #: Prandtl number


def properties(T):
    """All dry-air properties at T (K) from the section-9 fits, one warning at most.

    staltner-slag-particle.md section 9 (Table 4.6); ``nu = eta/rho``, ``Pr = eta c_p/lambda``.
    """
    Tc = _clamp(T, "properties")
    rho = _poly(Tc, COEFFICIENTS["rho"])
    cp = _poly(Tc, COEFFICIENTS["cp"])
    lam = _poly(Tc, COEFFICIENTS["lam"])
    eta = _poly(Tc, COEFFICIENTS["eta"])
    return AirProperties(rho, cp, lam, eta, eta / rho, eta * cp / lam)


def _constant_30c():
    # weigler-thermal-dem.md Table 8-1: lambda_g, c_p,g, M, p, T.
    lam, cp, M, p, T, R = 0.0266, 1009.0, 28.96, 101325.0, 303.15, 8314.0
    rho = p * M / (R * T)  # ideal gas, kg/m^3 (= 1.1643)
    # Table 8-1 gives no viscosity; take it from the Staltner Table 4.6 fit at 303.15 K
    # (1.869e-5 Pa s; VDI Heat Atlas 1.872e-5), so nu and Pr are defined.
    eta = float(np.polyval(COEFFICIENTS["eta"][::-1], T))
    return AirProperties(
        *(np.float64(x) for x in (rho, cp, lam, eta, eta / rho, eta * cp / lam))
    )


#: Constant dry air at 30 degC and 1 atm: weigler-thermal-dem.md Table 8-1 (lambda, c_p, M, p,
#: T); rho from the ideal-gas law with R = 8314 J/(kmol K); eta from the Staltner fit at 303.15 K.
AIR_30C = _constant_30c()


def constant_properties(T=None):
    """Constant-property fallback :data:`AIR_30C` (weigler-thermal-dem.md Table 8-1).

    ``T`` is accepted for signature compatibility with :func:`properties` and ignored except
    for broadcasting: with ``T`` given, every field has ``T``'s shape.
    """
    if T is None:
        return AIR_30C
    z = jnp.zeros_like(jnp.asarray(T, dtype=jnp.float64))
    return AirProperties(*(z + v for v in AIR_30C))
