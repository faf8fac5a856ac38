"""Particle-particle contact conduction (weigler-thermal-dem.md eqs. [2.5]-[2.7])."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jax import Array

from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.particles import ThermalParticles


def projected_area(d_i, d_j):
    """Transfer area of a pair of diameters d_i, d_j: ``A_p = pi d^2 / 4`` of the smaller one.

    weigler-thermal-dem.md section 4 uses ``A_p = pi d_p^2 / 4`` for monodisperse beds (the PFC
    script takes the first ball's radius); for unequal sizes drumheat takes the smaller one, the
    neck of the heat bridge.
    """
    return 0.25 * jnp.pi * jnp.minimum(d_i, d_j) ** 2


def pair_area(particles: ThermalParticles, i: Array, j: Array) -> Array:
    """:func:`projected_area` of the pairs (i, j) of a bed."""
    return projected_area(particles.diameter[i], particles.diameter[j])


class ContactConduction(eqx.Module):
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
        return self.alpha * pair_area(particles, net.pair_i, net.pair_j) * net.pair_weight

    def heat_flow(self, T: Array, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Heat flow into each particle, W, shape (N,)."""
        q = self.conductance(particles, net) * (T[net.pair_j] - T[net.pair_i])
        return jnp.zeros_like(T).at[net.pair_i].add(q).at[net.pair_j].add(-q)

    def conductance_sum(self, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Sum of the conductances at each particle, W/K (for the stability limit [2.2])."""
        g = self.conductance(particles, net)
        n = particles.diameter.shape[0]
        return jnp.zeros(n).at[net.pair_i].add(g).at[net.pair_j].add(g)
