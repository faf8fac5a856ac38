"""Particle-wall contact conduction (weigler-thermal-dem.md eq. [2.7])."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jax import Array

from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.particles import ThermalParticles


class WallConduction(eqx.Module):
    """Heat flow from walls into touching particles: ``alpha_wp A_p (T_w - T_i)`` per contact.

    weigler-thermal-dem.md eq. [2.7], with ``A_p = pi d^2 / 4`` of the particle.

    Attributes
    ----------
    alpha : scalar array
        alpha_wp, W/(m2 K).
    wall_temperature : array, shape (n_walls,)
        Temperature of each wall, K (indexed by ``ContactNetwork.wall_id``).
    """

    alpha: Array
    wall_temperature: Array
    account: ClassVar[str | None] = "wall"

    def conductance(self, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Conductance of every wall-contact slot, W/K."""
        return self.alpha * particles.area[net.wall_particle] * net.wall_weight

    def heat_flow(self, T: Array, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Heat flow into each particle, W, shape (N,)."""
        Tw = self.wall_temperature[net.wall_id]
        q = self.conductance(particles, net) * (Tw - T[net.wall_particle])
        return jnp.zeros_like(T).at[net.wall_particle].add(q)

    def conductance_sum(self, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Sum of wall conductances at each particle, W/K."""
        return jnp.zeros(particles.diameter.shape[0]).at[net.wall_particle].add(
            self.conductance(particles, net))

    def heat_flow_by_wall(self, T: Array, particles: ThermalParticles, net: ContactNetwork,
                          n_walls: int) -> Array:
        """Heat flow from each wall (indexed by ``net.wall_id``) into the particles, W,
        shape (n_walls,)."""
        Tw = self.wall_temperature[net.wall_id]
        q = self.conductance(particles, net) * (Tw - T[net.wall_particle])
        return jnp.zeros(n_walls, q.dtype).at[net.wall_id].add(q)
