"""Particle-wall contact conduction (weigler-thermal-dem.md eq. [2.7])."""

from __future__ import annotations

from typing import ClassVar, Optional

import equinox as eqx
import jax.numpy as jnp
from jax import Array

from drumheat.devices import to_device

from drumheat.thermal.contact import schluender_coefficients
from drumheat.thermal.effect import AbstractEffect, EffectContext, TableValues, register
from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.particles import ThermalParticles


@register("wall")
class WallConduction(AbstractEffect):
    """Heat flow from walls into touching particles: ``alpha_wp A_p (T_w - T_i)`` per contact.

    weigler-thermal-dem.md eq. [2.7], with ``A_p = pi d^2 / 4`` of the particle.

    Coarse-graining (``[dem] coarse_grain = s``) keeps alpha_wp: a parcel at the wall has the
    projected area of the ``s^2`` real particles of the wall layer it covers, so the contact
    conductance per unit wall area (the penetration model's contact coefficient alpha_WS,
    weigler eq. [2.9] / Schluender 1984) is the fine bed's; docs/models/coarse-graining.md says
    where this holds (wall contacts short against a first-layer particle's time constant).

    Attributes
    ----------
    alpha : scalar array
        alpha_wp, W/(m2 K).
    wall_temperature : array, shape (n_walls,)
        Temperature of each wall, K (indexed by ``ContactNetwork.wall_id``).

    surfaces : tuple of str or None (static)
        Names of the walls (one per wall id). When given, the heat from each wall is booked
        in its own account ``wall:<name>`` (:meth:`account_flows`), so a drum with internals
        reports the shell, the inner cylinder and the plates separately; when None all walls
        share the account ``wall``.
    """

    alpha: Array
    wall_temperature: Array
    surfaces: Optional[tuple] = eqx.field(static=True, default=None)
    account: ClassVar[str | None] = "wall"

    @property
    def accounts(self) -> tuple[str, ...]:
        """The accounts this effect books heat into."""
        if self.surfaces is None:
            return ("wall",)
        return tuple(f"wall:{s}" for s in self.surfaces)

    def flows(self, T: Array, particles: ThermalParticles, net: ContactNetwork
              ) -> tuple[Array, dict[str, Array]]:
        """Heat flow into each particle (W) and from each wall account (W)."""
        q_slots = self.slot_flows(T, particles, net)
        q = jnp.zeros_like(T).at[net.wall_particle].add(q_slots)
        if self.surfaces is None:
            return q, {"wall": jnp.sum(q_slots)}
        per = _per_wall(q_slots, net, len(self.surfaces))
        return q, {a: per[k] for k, a in enumerate(self.accounts)}

    def slot_flows(self, T: Array, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Heat flow through every wall-contact slot into its particle, W."""
        Tw = self.wall_temperature[net.wall_id]
        return self.conductance(particles, net) * (Tw - T[net.wall_particle])

    def conductance(self, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Conductance of every wall-contact slot, W/K."""
        return self.alpha * particles.area[net.wall_particle] * net.wall_weight

    def heat_flow(self, T: Array, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Heat flow into each particle, W, shape (N,)."""
        q = self.slot_flows(T, particles, net)
        return jnp.zeros_like(T).at[net.wall_particle].add(q)

    def conductance_sum(self, particles: ThermalParticles, net: ContactNetwork,
                        T: Array | None = None) -> Array:
        """Sum of wall conductances at each particle, W/K."""
        return jnp.zeros(particles.diameter.shape[0]).at[net.wall_particle].add(
            self.conductance(particles, net))

    @classmethod
    def from_table(cls, table: TableValues, ctx: EffectContext) -> "WallConduction":
        """``[heat.wall]``: alpha as given (model "constant") or Schluender's alpha_wp; the
        wall temperatures and surface names from the context."""
        if table.table.model == "constant":
            alpha = table.alpha
        else:
            alpha = schluender_coefficients(ctx)[0]
        return cls(alpha=to_device(alpha, float),
                   wall_temperature=to_device(ctx.wall_temperatures, float, ndmin=1),
                   surfaces=ctx.wall_surfaces)

    def heat_flow_by_wall(self, T: Array, particles: ThermalParticles, net: ContactNetwork,
                          n_walls: int) -> Array:
        """Heat flow from each wall (indexed by ``net.wall_id``) into the particles, W,
        shape (n_walls,)."""
        return _per_wall(self.slot_flows(T, particles, net), net, n_walls)


def _per_wall(q_slots: Array, net: ContactNetwork, n_walls: int) -> Array:
    """Sum of the per-slot heat flows of each wall id, W, shape (n_walls,)."""
    return jnp.zeros(n_walls, q_slots.dtype).at[net.wall_id].add(q_slots)
