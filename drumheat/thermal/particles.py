"""Per-particle thermal properties (heat reservoirs)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jax import Array


class ThermalParticles(eqx.Module):
    """Particles as lumped heat reservoirs (weigler-thermal-dem.md section 4).

    Attributes
    ----------
    diameter : array, shape (N,)
        m.
    mass : array, shape (N,)
        kg; sphere mass ``rho pi d^3 / 6`` (the mass convention of the thesis' Matlab codes).
    heat_capacity : array, shape (N,)
        Specific heat capacity c, J/(kg K).
    """

    diameter: Array
    mass: Array
    heat_capacity: Array

    @property
    def capacity(self) -> Array:
        """Heat capacity m c of each particle, J/K."""
        return self.mass * self.heat_capacity

    @property
    def area(self) -> Array:
        """Transfer area ``A_p = pi d^2 / 4`` (weigler-thermal-dem.md section 4, eq. [2.7])."""
        return 0.25 * jnp.pi * self.diameter**2

    @classmethod
    def spheres(cls, diameter, density, heat_capacity) -> "ThermalParticles":
        """Spheres of the given diameter (m), density (kg/m3) and c (J/(kg K))."""
        diameter = jnp.asarray(diameter, float)
        mass = jnp.asarray(density) * jnp.pi * diameter**3 / 6.0
        return cls(diameter, mass, jnp.broadcast_to(jnp.asarray(heat_capacity, float),
                                                    diameter.shape))
