"""Per-particle thermal properties (heat reservoirs)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
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

    def host_capacity(self):
        """:attr:`capacity` as a numpy array, the product taken on the host (the same
        numbers; an eager product would compile a program: drumheat.devices.to_device)."""
        return np.asarray(self.mass) * np.asarray(self.heat_capacity)

    @property
    def area(self) -> Array:
        """Transfer area ``A_p = pi d^2 / 4`` (weigler-thermal-dem.md section 4, eq. [2.7])."""
        return 0.25 * jnp.pi * self.diameter**2

    @classmethod
    def spheres(cls, diameter, density, heat_capacity) -> "ThermalParticles":
        """Spheres of the given diameter (m), density (kg/m3) and c (J/(kg K))."""
        return cls(*_spheres(diameter, density, heat_capacity))


@jax.jit
def _spheres(diameter, density, heat_capacity):
    """``(diameter, mass, heat capacity)`` of :meth:`ThermalParticles.spheres` as one compiled
    program (evaluated eagerly, each operation compiles one of its own, which stays in memory:
    drumheat.devices.to_device)."""
    diameter = jnp.asarray(diameter, float)
    mass = jnp.asarray(density) * jnp.pi * diameter**3 / 6.0
    return diameter, mass, jnp.broadcast_to(jnp.asarray(heat_capacity, float), diameter.shape)
