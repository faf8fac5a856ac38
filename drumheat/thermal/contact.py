"""Particle-particle contact conduction (weigler-thermal-dem.md eqs. [2.5]-[2.7])."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jax import Array

from drumheat.devices import to_device
from drumheat.models import schluender
from drumheat.models.contact_conductance import projected_area
from drumheat.thermal.effect import AbstractEffect, EffectContext, TableValues, register
from drumheat.thermal.network import ContactNetwork, native_pair_sum
from drumheat.thermal.particles import ThermalParticles


def pair_area(particles: ThermalParticles, i: Array, j: Array) -> Array:
    """:func:`projected_area` of the pairs (i, j) of a bed."""
    return projected_area(particles.diameter[i], particles.diameter[j])


def _pair_conductance(alpha, diameter, i, j, w) -> Array:
    """``alpha_pp A_p w`` of the pair slots (i, j) with contact-time fractions w, W/K
    (weigler-thermal-dem.md eq. [2.7])."""
    return alpha * projected_area(diameter[i], diameter[j]) * w


def schluender_coefficients(ctx: EffectContext):
    """(alpha_wp, alpha_pp) of Schluender's model (weigler eqs. [2.8]-[2.10]) for the contact
    gas and the mean particle diameter of the context (thesis App. A3)."""
    g = ctx.contact_gas
    return schluender.contact_coefficients(ctx.mean_diameter, T=g.temperature, p=g.pressure,
                                           conductivity=g.conductivity,
                                           heat_capacity=g.heat_capacity,
                                           molar_mass=g.molar_mass, C=g.accommodation_constant)


@register("contact")
class ContactConduction(AbstractEffect):
    """Heat flow through particle-particle contacts: ``alpha_pp A_p (T_j - T_i)`` per contact.

    weigler-thermal-dem.md eq. [2.7] (the thermal pipe of eqs. [2.5], [2.6] reduces to this,
    the pipe length cancels). Internal exchange: it moves heat between particles and sums to
    zero over the bed.

    Attributes
    ----------
    alpha : scalar array
        alpha_pp, W/(m2 K), on the projected area pi d^2 / 4.
    """

    alpha: Array
    account: ClassVar[str | None] = None

    def conductance(self, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Conductance of every pair slot, W/K (0 for unused slots)."""
        return _pair_conductance(self.alpha, particles.diameter, net.pair_i, net.pair_j,
                                 net.pair_weights(particles.diameter.shape[0]))

    def heat_flow(self, T: Array, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Heat flow into each particle, W, shape (N,): in JAX, or where the network has one
        in native code (:attr:`ContactNetwork.native_conduction`, the same sum; its
        derivatives those of the JAX sum)."""
        def in_jax(T, diameter, alpha):
            return net.pair_sum(
                lambda i, j, w: _pair_conductance(alpha, diameter, i, j, w) * (T[j] - T[i]),
                jnp.zeros_like(T))

        args = (T, particles.diameter, self.alpha)
        if net.native_conduction is None or net.pair_unit is None:
            return in_jax(*args)
        return native_pair_sum(lambda *a: net.native_conduction(*a, net), in_jax, *args)

    def conductance_sum(self, particles: ThermalParticles, net: ContactNetwork,
                        T: Array | None = None) -> Array:
        """Sum of the conductances at each particle, W/K (for the stability limit [2.2])."""
        n = particles.diameter.shape[0]
        return net.pair_sum(
            lambda i, j, w: _pair_conductance(self.alpha, particles.diameter, i, j, w),
            jnp.zeros(n), sign=1.0)

    @classmethod
    def from_table(cls, table: TableValues, ctx: EffectContext) -> "ContactConduction":
        """``[heat.contact]``: alpha as given (model "constant") or Schluender's alpha_pp (of
        the real particles' mean diameter); divided by s for parcels
        (:func:`coarse_grained_alpha`)."""
        if table.table.model == "constant":
            alpha = table.alpha
        else:
            alpha = schluender_coefficients(ctx)[1]
        return cls(alpha=coarse_grained_alpha(to_device(alpha, float), ctx.coarse_grain))


def coarse_grained_alpha(alpha, s: float):
    """alpha_pp of parcels of scale factor ``s`` that keeps the fine bed's conductivity.

    Derivation (docs/models/coarse-graining.md): in a bed of spheres of diameter d whose
    contacts have conductance G, a temperature gradient dT/dx drops ``d dT/dx`` across each
    contact and ``1/d^2`` contact columns cross a unit area, so the effective conductivity is
    ``lambda_eff = c G / d`` with a factor c of the contact network alone (simple cubic lattice
    c = 1; the mean-field network of a random packing, ``lambda_eff = (N_c / V) G d^2 / 3 =
    phi z G / (pi d)`` with solid fraction phi and coordination number z, Argento & Bouvard
    1996, Int. J. Heat Mass Transfer 39, 1343). A geometrically similar network of
    parcels of diameter ``s d`` keeps c, so it keeps ``lambda_eff`` iff ``G_parcel = s G``.
    With ``G = alpha_pp pi d^2 / 4`` (weigler eq. [2.7]) on the parcel's own projected area
    (``s^2`` times larger) that is ``alpha_parcel = alpha_pp / s``. s = 1 returns ``alpha``
    itself (today's code path).
    """
    return alpha if s == 1.0 else alpha / s
