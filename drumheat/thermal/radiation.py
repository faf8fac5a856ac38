"""Grey radiation between each particle and its enclosure (``[heat.radiation]``).

Heat flow into particle i: ``eps_i sigma pi d_i^2 (T_rad,i^4 - T_i^4)``.

* ``enclosure = "sink"``: ``T_rad`` is the temperature of a black surface surrounding the
  particle (``sink_temperature``).
* ``enclosure = "granulator"``: the particle is a tiny surface 1 in the grey four-zone enclosure
  of the dry slag granulator (staltner-slag-particle.md sections 1, 6, 7). Its view factors to
  the zones are the exact solid angles at the particle's position (section 7.1, digest
  recommendation), the zone-to-zone view factors are Appendix B in its corrected form (7.2); the
  radiosity method gives the fictitious view factors phi~ ([6.37]-[6.40]) and with them the
  effective sink temperature ``T_rad^4 = -(1/eps_1) sum_{j>=2} eps_j phi~_1j T_j^4`` (digest
  section 4), so ``q_Str = eps_1 sigma (T_n^4 - T_rad^4)`` exactly. ``T_rad`` depends on the
  position only; a motion model that moves the particle replaces the ``sink_temperature`` leaf
  (``granulator_sink_temperature``) segment by segment.

The conductance (slope of the heat flow) is ``4 eps sigma A T^3``; without a temperature the
largest value over the temperatures the run can reach is used (stability limit).
"""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jax import Array

from drumheat.models import view_factors as vf
from drumheat.thermal.effect import AbstractEffect, EffectContext, TableValues, register
from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.particles import ThermalParticles

SIGMA = vf.SIGMA


@register("radiation")
class Radiation(AbstractEffect):
    """Particle-to-enclosure radiation (module docstring).

    Attributes
    ----------
    emissivity : (N,) array, particle emissivities.
    sink_temperature : (N,) array, effective radiation temperature T_rad seen by each particle, K.
    T_max : scalar array, highest temperature the run can reach (conductance bound), K.
    """

    emissivity: Array
    sink_temperature: Array
    T_max: Array
    account: ClassVar[str | None] = "radiation"

    def heat_flow(self, T: Array, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Heat flow into each particle, W, shape (N,)."""
        A = jnp.pi * particles.diameter**2
        return self.emissivity * SIGMA * A * (self.sink_temperature**4 - T**4)

    def conductance_sum(self, particles: ThermalParticles, net: ContactNetwork, T=None) -> Array:
        """``4 eps sigma A T^3`` (W/K): the slope of the outgoing flow."""
        T = self.T_max if T is None else T
        return 4.0 * self.emissivity * SIGMA * jnp.pi * particles.diameter**2 * T**3

    @classmethod
    def from_table(cls, table: TableValues, ctx: EffectContext) -> "Radiation":
        """``[heat.radiation]``: the particles' emissivities (the table's or the groups'),
        the sink temperature (enclosure "sink") or the context's enclosure temperature
        (enclosure "granulator", at the droplet's start position)."""
        N = ctx.particles.diameter.shape[0]
        if table.given("emissivity"):
            eps = jnp.full(N, jnp.asarray(table.emissivity, float))
        else:
            eps = ctx.particle_property("emissivity")
        if table.table.enclosure == "sink":
            T_rad = jnp.full(N, jnp.asarray(table.sink_temperature, float))
        else:
            T_rad = jnp.broadcast_to(jnp.asarray(ctx.sink_temperature, float), (N,))
        return cls(eps, T_rad, jnp.asarray(float(ctx.temperature_bounds[1]), float))


def granulator_sink_temperature(rho, z, granulator, surfaces, particle_emissivity):
    """Effective radiation temperature of a small sphere at (rho, z) in the granulator, K.

    staltner-slag-particle.md [6.29]-[6.40] and section 4: zones (2, 3, 4, 5) = (bed, slots,
    wall, outlet) with the temperatures and emissivities of ``surfaces``; view factors from
    :func:`drumheat.models.view_factors.sphere_to_granulator_view_factors` and
    :func:`~drumheat.models.view_factors.granulator_view_factors`.

    Parameters
    ----------
    rho, z : arrays (broadcast), radial offset from the axis and height above the bed, m.
    granulator : GranulatorConfig (r2, h3, h4, alpha4 in degrees).
    surfaces : sequence of RadiationSurface (4, zone order).
    particle_emissivity : scalar.
    """
    g = granulator
    a4 = math.radians(g.alpha4)
    F, _ = vf.granulator_view_factors(g.r2, g.h3, g.h4, a4)
    eps = jnp.asarray([particle_emissivity] + [s.emissivity for s in surfaces], float)
    Tz = jnp.asarray([0.0] + [s.temperature for s in surfaces], float)
    phi = vf.sphere_to_granulator_view_factors(rho, z, g.r2, g.h3, g.h4, a4)

    def one(p):
        full = vf.particle_view_factor_matrix(p, F)
        row = vf.fictitious_view_factors(eps, full)[0]
        return vf.radiation_sink_temperature(row, eps, Tz)

    flat = phi.reshape(-1, 4)
    import jax

    return jax.vmap(one)(flat).reshape(phi.shape[:-1])
