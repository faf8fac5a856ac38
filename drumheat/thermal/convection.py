"""Particle-gas convection (``[heat.convection]``).

Heat flow into particle i: ``alpha_i pi d_i^2 (T_g - T_i)`` on the whole sphere surface, with
``alpha`` from a correlation of :mod:`drumheat.models.convection`:

* ``"gnielinski"``: single sphere with ``L = d`` and the all-Pr laminar part
  (fluidized-bed-exercise.md section 3, :func:`~drumheat.models.convection.fluidized_bed_sphere_nu`);
* ``"gnielinski-staltner"``: ``L = pi d / 2``, ``Nu_lam = 0.664 Re^1/2 Pr^1/3``
  (staltner-slag-particle.md [3.25]-[3.28]);
* ``"gnielinski-kraychev"``: ``L = d``, ``Nu_lam = 0.664 Re^1/2 Pr^1/3`` and the exact VDI
  ``Nu_turb`` (kraychev-tube-bundle.md (3-16)-(3-19), errata 14.1);
* ``"ranz-marshall"``: ``Nu = 2 + 0.6 Re^1/2 Pr^1/3``, ``L = d`` (kraychev-tube-bundle.md (3-14));
* ``"fluidized-bed"``: the exercise's mean ``alpha_a = (alpha_L + alpha_A)/2`` of the loosening
  point (packed bed, ``f_a = 1 + 1.5 (1 - psi_L)``, interstitial Re) and the discharge point
  (single sphere at u_A), fluidized-bed-exercise.md sections 2 and 5;
* ``"constant"``: alpha as given.

With ``porosity`` psi the Reynolds number is built on the interstitial velocity ``u/psi`` and Nu
is multiplied by the packed-bed factor ``f_a`` (fluidized-bed-exercise.md section 2).

Gas properties: the dry-air polynomials of staltner-slag-particle.md section 9
(:mod:`drumheat.models.air`) or the constants of ``[gas]``, at the gas temperature or at the
film temperature ``(T_s + T_g)/2``. The film temperature changes during a run, so it is
evaluated at every step; the polynomials are clamped to their validity range 273.15-1273.15 K,
and the builder warns once (not at every step) when the temperatures the run can reach (between
the initial, gas and sink temperatures, by the maximum principle) leave that range.

``internal_resistance = "transient-sphere"`` replaces alpha by the overall coefficient
``k = 1/(1/alpha_i + 1/alpha)`` with ``alpha_i = Nu_i lambda_p / d`` of the transient internal
Nusselt number at ``Fo(t_E)``, ``t_E`` = run duration (fluidized-bed-exercise.md section 5, with
the corrected Nu_i0 denominator): the exercise's bed-level model for lumped particles.

:class:`PlugFlowConvection` is the same exchange when the gas passes the bed in plug flow
(motion model ``fluidized``): the gas warms layer by layer and every particle sees the gas
temperature of its layer (fluidized-bed-exercise.md section 4, NTU form applied per layer).
"""

from __future__ import annotations

import warnings
from typing import ClassVar, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import Array

from drumheat.models import air
from drumheat.models import convection as corr
from drumheat.models.sphere_conduction import internal_transient_nu
from drumheat.thermal.effect import AbstractEffect, EffectContext, TableValues, register
from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.particles import ThermalParticles


def _air_clipped(T):
    """Dry-air properties (rho, cp, lam, nu) from the staltner section-9 fits, T clamped.

    No run-time warning (the builder warns once); see :mod:`drumheat.models.air`.
    """
    Tc = jnp.clip(T, air.T_MIN, air.T_MAX)
    c = air.COEFFICIENTS
    rho, cp = air._poly(Tc, c["rho"]), air._poly(Tc, c["cp"])
    lam, eta = air._poly(Tc, c["lam"]), air._poly(Tc, c["eta"])
    return rho, cp, lam, eta / rho


def nusselt_alpha(correlation, d, velocity, rho, cp, lam, nu, porosity=None,
                  loosening_velocity=1.2, loosening_porosity=0.4):
    """alpha (W/(m2 K)) of a sphere of diameter ``d`` for the named correlation (module doc).

    Parameters are arrays (broadcasting); ``porosity`` None is a single particle.
    """
    Pr = nu * rho * cp / lam
    if correlation == "fluidized-bed":
        # fluidized-bed-exercise.md section 5: loosening point (packed, f_a) and discharge point
        Re_L = corr.interstitial_reynolds(loosening_velocity, d, nu, loosening_porosity)
        a_L = corr.packed_bed_factor(loosening_porosity) * corr.fluidized_bed_sphere_nu(Re_L, Pr)
        a_A = corr.fluidized_bed_sphere_nu(corr.reynolds(velocity, d, nu), Pr)
        return 0.5 * (a_L + a_A) * lam / d
    psi = 1.0 if porosity is None else porosity
    f_a = 1.0 if porosity is None else corr.packed_bed_factor(porosity)
    w = velocity / psi
    if correlation == "gnielinski":
        L = d
        Nu = corr.fluidized_bed_sphere_nu(corr.reynolds(w, L, nu), Pr)
    elif correlation == "gnielinski-staltner":
        L = jnp.pi * d / 2.0
        Nu = corr.gnielinski_sphere_nu(corr.reynolds(w, L, nu), Pr)
    elif correlation == "gnielinski-kraychev":
        L = d  # kraychev (3-16)-(3-19), exact VDI form (digest 14.1), Re on d_p
        Nu = corr.gnielinski_sphere_nu(corr.reynolds(w, L, nu), Pr, "vdi")
    elif correlation == "ranz-marshall":
        L = d
        Nu = corr.ranz_marshall_nu(corr.reynolds(w, L, nu), Pr)
    else:
        raise ValueError(f"unknown convection correlation {correlation!r}")
    return f_a * Nu * lam / L


def series_with_transient_sphere(alpha_a, d, lam_p, rho_c_p, t_end):
    """``k = 1/(1/alpha_i + 1/alpha_a)``, fluidized-bed-exercise.md section 5.

    ``Bi = alpha_a d/lambda_p`` and ``Fo = lambda_p t_E/(rho c d^2)`` on the diameter; ``alpha_i
    = Nu_i lambda_p/d`` from :func:`~drumheat.models.sphere_conduction.internal_transient_nu`.
    """
    Bi = alpha_a * d / lam_p
    Fo = lam_p * t_end / (rho_c_p * d**2)
    alpha_i = internal_transient_nu(Bi, Fo) * lam_p / d
    return corr.series_coefficient(alpha_i, alpha_a)


@register("convection")
class Convection(AbstractEffect):
    """Convection between each particle and a gas of uniform temperature (module docstring).

    Attributes
    ----------
    gas_temperature : scalar array, K.
    velocity : scalar array, m/s (relative; superficial with porosity).
    alpha_value : scalar or (N,) array or None
        A fixed alpha, W/(m2 K) ('constant', or any correlation evaluated at the gas
        temperature, or the transient-sphere k); None when alpha follows the film temperature.
    gas_constants : (rho, cp, lam, nu) arrays or None
        Constant gas properties (``properties = "gas"``); None for the air polynomials.
    porosity, loosening_velocity, loosening_porosity : arrays or None.
    T_bounds : array (2,)
        Lowest and highest temperature the run can reach, K (for the conductance bound).
    correlation : str (static).
    """

    gas_temperature: Array
    velocity: Array
    alpha_value: Optional[Array]
    gas_constants: Optional[tuple]
    porosity: Optional[Array]
    loosening_velocity: Array
    loosening_porosity: Array
    T_bounds: Array  # (lowest, highest) temperature the run can reach, K (an array leaf, so
    # that variants with other gas temperatures share the module's structure)
    correlation: str = eqx.field(static=True)
    account: ClassVar[str | None] = "gas"

    def alpha(self, T: Array, particles: ThermalParticles) -> Array:
        """alpha of each particle, W/(m2 K), at surface temperatures ``T`` (N,)."""
        if self.alpha_value is not None:
            return jnp.broadcast_to(self.alpha_value, T.shape)
        T_film = 0.5 * (T + self.gas_temperature)
        props = self.gas_constants if self.gas_constants is not None else _air_clipped(T_film)
        return nusselt_alpha(self.correlation, particles.diameter, self.velocity, *props,
                             porosity=self.porosity, loosening_velocity=self.loosening_velocity,
                             loosening_porosity=self.loosening_porosity)

    def conductance(self, T, particles):
        return self.alpha(T, particles) * jnp.pi * particles.diameter**2

    def heat_flow(self, T: Array, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Heat flow into each particle, W, shape (N,)."""
        return self.conductance(T, particles) * (self.gas_temperature - T)

    @classmethod
    def from_table(cls, table: TableValues, ctx: EffectContext):
        """``[heat.convection]`` (see :func:`_from_table`)."""
        return _from_table(table, ctx)

    def conductance_sum(self, particles: ThermalParticles, net: ContactNetwork, T=None) -> Array:
        """``alpha pi d^2`` of each particle, W/K; without ``T`` the largest value over the
        temperatures the run can reach (a bound for the stability limit)."""
        if T is not None or self.alpha_value is not None:
            T = jnp.zeros_like(particles.diameter) + (self.gas_temperature if T is None else T)
            return self.conductance(T, particles)
        grid = jnp.linspace(self.T_bounds[0], self.T_bounds[1], 16)
        g = jax.vmap(lambda t: self.conductance(jnp.full_like(particles.diameter, t), particles))(grid)
        return jnp.max(g, axis=0)


class PlugFlowConvection(AbstractEffect):
    """Convection to a gas in plug flow through a bed of layers (motion model ``fluidized``).

    fluidized-bed-exercise.md section 4 applied layer by layer: the gas enters layer k at
    ``T_in,k`` (layer 0 at the inlet temperature), sees the conductance-weighted mean surface
    temperature ``T_bar,k`` of the layer's particles and leaves it at
    ``T_out,k = T_bar,k - (T_bar,k - T_in,k) exp(-NTU_k)``, ``NTU_k = sum_k (alpha A)/(mdot c_p)``
    (the NTU form of the outlet gas temperature). Particle i in layer k receives
    ``(alpha A)_i (T_eff,k - T_i)`` with ``T_eff,k = T_bar,k - (T_bar,k - T_in,k)(1 -
    exp(-NTU_k))/NTU_k``, so that the layer's particles give exactly what the gas takes up
    (``mdot c_p (T_out,k - T_in,k)``): energy is conserved by construction. With one layer and
    equal particles this is the exercise's bed-level balance.

    Attributes
    ----------
    convection : Convection
        Supplies alpha (its gas_temperature is the inlet temperature).
    capacity_rate : scalar array
        ``mdot c_p`` of the gas through the simulated cross-section, W/K.
    layer : int array (N,)
        Layer of each particle (0 at the gas inlet); replaced by the motion model on re-mixing.
    n_layers : int (static).
    """

    convection: Convection
    capacity_rate: Array
    layer: Array
    n_layers: int = eqx.field(static=True)
    account: ClassVar[str | None] = "gas"

    @classmethod
    def from_table(cls, table: TableValues, ctx: EffectContext) -> "PlugFlowConvection":
        """See :meth:`Convection.from_table` (a context with ``plug_flow``)."""
        return Convection.from_table(table, ctx)

    def _layers(self, T, particles):
        G = self.convection.conductance(T, particles)
        Gk = jax.ops.segment_sum(G, self.layer, self.n_layers)
        GTk = jax.ops.segment_sum(G * T, self.layer, self.n_layers)
        has = Gk > 0
        ntu = Gk / self.capacity_rate

        def march(T_in, k):
            Tbar = jnp.where(has[k], GTk[k] / jnp.where(has[k], Gk[k], 1.0), T_in)
            n = ntu[k]
            frac = jnp.where(n > 1e-12, -jnp.expm1(-n) / jnp.where(n > 1e-12, n, 1.0), 1.0)
            T_eff = Tbar - (Tbar - T_in) * frac
            T_out = Tbar - (Tbar - T_in) * jnp.exp(-n)
            return T_out, T_eff

        T_out, T_eff = jax.lax.scan(march, jnp.asarray(self.convection.gas_temperature, T.dtype),
                                    jnp.arange(self.n_layers))
        return G, T_eff, T_out

    def heat_flow(self, T: Array, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Heat flow into each particle, W, shape (N,)."""
        G, T_eff, _ = self._layers(T, particles)
        return G * (T_eff[self.layer] - T)

    def outlet_temperature(self, T: Array, particles: ThermalParticles) -> Array:
        """Gas temperature leaving the bed, K (fluidized-bed-exercise.md section 4)."""
        return self._layers(T, particles)[2]

    def conductance_sum(self, particles: ThermalParticles, net: ContactNetwork, T=None) -> Array:
        """``alpha pi d^2`` of each particle, W/K (an upper bound of the diagonal slope)."""
        return self.convection.conductance_sum(particles, net, T)


def _from_table(table: TableValues, ctx: EffectContext):
    """:meth:`Convection.from_table` (module docstring): the correlation's alpha at the gas
    temperature (or at the film temperature during the run), optionally in series with the
    transient internal coefficient; wrapped in :class:`PlugFlowConvection` when the context's
    gas passes the bed in plug flow."""
    cfg = table.table
    gas = ctx.gas
    Tg = jnp.asarray(gas.temperature, float)
    if table.given("velocity"):
        velocity = table.velocity
    else:  # the motion's relative velocity (granulator droplet, staltner [4.1]) or none
        velocity = ctx.gas_velocity if ctx.gas_velocity is not None else 0.0
    velocity = jnp.asarray(velocity, float)
    porosity = jnp.asarray(table.porosity, float) if table.given("porosity") else None
    uL = jnp.asarray(table.loosening_velocity, float)
    psiL = jnp.asarray(table.loosening_porosity, float)
    gas_constants = None
    if cfg.properties == "gas":
        rho = gas.density if gas.density is not None else (
            gas.pressure * gas.molar_mass / (8314.0 * Tg))
        gas_constants = tuple(jnp.asarray(x, float) for x in (
            rho, gas.heat_capacity, gas.conductivity, gas.kinematic_viscosity))
    film = cfg.property_temperature == "film"
    T_bounds = ctx.temperature_bounds
    if cfg.properties == "polynomial" and cfg.correlation != "constant":
        Tg0 = float(Tg)
        lo, hi = (0.5 * (T_bounds[0] + Tg0), 0.5 * (T_bounds[1] + Tg0)) if film else (Tg0,) * 2
        if lo < air.T_MIN or hi > air.T_MAX:
            warnings.warn(f"scene {ctx.name!r}: [heat.convection] air properties at "
                          f"{lo:.1f}-{hi:.1f} K lie outside the validity range 273.15-1273.15 K "
                          "of the staltner Table 4.6 fits; they are clamped to it",
                          UserWarning, stacklevel=4)
    particles = ctx.particles
    conv = Convection(Tg, velocity, None, gas_constants, porosity, uL, psiL,
                      jnp.asarray([float(x) for x in T_bounds]), cfg.correlation)
    if cfg.correlation == "constant":
        alpha = jnp.asarray(table.alpha, float)
    elif not film:
        alpha = conv.alpha(jnp.broadcast_to(Tg, particles.diameter.shape), particles)
    else:
        alpha = None
    if cfg.internal_resistance == "transient-sphere":
        lam_p = ctx.particle_property("conductivity")
        rho_c = particles.capacity / (jnp.pi * particles.diameter**3 / 6.0)
        a_ext = alpha if alpha is not None else conv.alpha(
            jnp.broadcast_to(Tg, particles.diameter.shape), particles)
        alpha = series_with_transient_sphere(a_ext, particles.diameter, lam_p, rho_c,
                                             ctx.duration)
    conv = eqx.tree_at(lambda c: c.alpha_value, conv, alpha, is_leaf=lambda x: x is None)
    if ctx.plug_flow is not None:
        return plug_flow(conv, ctx.plug_flow, particles)
    return conv


def plug_flow(conv: Convection, flow, particles: ThermalParticles) -> PlugFlowConvection:
    """Wrap ``conv`` for gas in plug flow through the bed (fluidized-bed-exercise.md section 4).

    The simulated particles stand for the bed cross-section ``f = sum(m_i) / m_1`` (loading
    m_1), through which ``mdot_2 f`` of gas flows: capacity rate ``W = mdot_2 f c_p``.
    ``flow`` is the context's :class:`~drumheat.thermal.effect.PlugFlow`. Layers are assigned
    in turn (0, 1, ..., L-1, 0, ...); the motion model re-draws them.
    """
    f = jnp.sum(particles.mass) / flow.loading
    W = flow.mass_flux * f * flow.heat_capacity
    L = flow.n_layers
    layer = jnp.arange(particles.diameter.shape[0]) % L
    return PlugFlowConvection(conv, jnp.asarray(W, float), layer, L)
