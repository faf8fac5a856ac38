"""Lumped heat loss to the surrounding gas (weigler-thermal-dem.md eq. [2.7], section 7.5)."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jax import Array

from drumheat.devices import to_device
from drumheat.thermal.effect import AbstractEffect, EffectContext, TableValues, register
from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.particles import ThermalParticles


@register("loss")
class HeatLoss(AbstractEffect):
    """Heat flow from the gas into each particle: ``(alpha A)_WK (T_g - T_i)``.

    weigler-thermal-dem.md eq. [2.7]: the loss term lumps convection to the gas, radiation and
    conduction into the insulating drum; (alpha A)_WK = 2.5e-4 W/K per 4 mm aluminium sphere was
    fitted to heating and cooling runs (section 7.5).

    Attributes
    ----------
    alphaA : scalar array
        (alpha A)_WK per particle, W/K.
    gas_temperature : scalar array
        T_g, K.
    """

    alphaA: Array
    gas_temperature: Array
    account: ClassVar[str | None] = "gas"

    def heat_flow(self, T: Array, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Heat flow into each particle, W, shape (N,)."""
        return self.alphaA * (self.gas_temperature - T)

    def conductance_sum(self, particles: ThermalParticles, net: ContactNetwork,
                        T: Array | None = None) -> Array:
        """(alpha A)_WK of each particle, W/K."""
        return jnp.broadcast_to(self.alphaA, particles.diameter.shape)

    @classmethod
    def from_table(cls, table: TableValues, ctx: EffectContext) -> "HeatLoss":
        """``[heat.loss]`` with the gas temperature of ``[gas]``; per parcel ``s^3`` times the
        particle's (alpha A)_WK with ``dem.coarse_grain = s``: the loss goes to the gas around
        each real particle's surface, so a parcel loses what its ``s^3`` particles lose, and
        the loss per unit mass (the parcel's mass is ``s^3`` m) stays that of the fine bed
        (docs/models/coarse-graining.md)."""
        alphaA = to_device(table.alphaA, float)
        if ctx.coarse_grain != 1.0:
            alphaA = ctx.coarse_grain**3 * alphaA
        return cls(alphaA=alphaA, gas_temperature=jnp.asarray(ctx.gas.temperature, float))
