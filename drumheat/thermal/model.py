"""The thermal model: the particles plus exactly the effects a scene lists.

Each effect is an equinox module in its own file (``contact.py``, ``wall.py``, ``loss.py``,
``convection.py``, ``radiation.py``), registered under the name of its scene table
(:mod:`drumheat.thermal.effect`). :func:`make_thermal_model` builds the effects named in the
scene, each from its own table and the explicit :class:`~drumheat.thermal.effect.EffectContext`;
effects whose table is absent are not built, so they are not in the traced program at all.

One table is not a heat flow but a state extension: ``[heat.internal]``
(:mod:`drumheat.thermal.internal`) gives every particle a radial shell profile; the model then
carries it in :attr:`ThermalModel.internal`, the effects act on the surface node and the solvers
of :mod:`drumheat.thermal.solvers` switch to the shell schemes. Without it ``internal`` is None
and nothing changes. A second one, ``[heat.drum_wall]`` (:mod:`drumheat.thermal.drum_wall`),
gives the drum wall segment temperatures of its own (:attr:`ThermalModel.drum_wall`,
:meth:`ThermalModel.heat_flows_wall`); without it ``drum_wall`` is None and nothing changes.
"""

from __future__ import annotations

from typing import Optional

import equinox as eqx
import jax.numpy as jnp
from jax import Array

# the effect modules register themselves on import (drumheat.thermal.effect.register)
from drumheat.thermal import contact, convection, loss, radiation, wall  # noqa: F401
from drumheat.thermal.drum_wall import build_drum_wall
from drumheat.thermal.effect import EFFECTS, EffectContext, TableValues
from drumheat.thermal.internal import build_internal
from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.particles import ThermalParticles

__all__ = ["ThermalModel", "make_thermal_model"]


class ThermalModel(eqx.Module):
    """Particles plus the effects a scene switches on.

    Attributes
    ----------
    particles : ThermalParticles
    effects : tuple of effect modules
    internal : InternalConduction or None
        Radial shells in every particle (``[heat.internal]``).
    drum_wall : DrumWall or None
        A drum wall with heat capacity in segments (``[heat.drum_wall]``,
        :mod:`drumheat.thermal.drum_wall`); the solvers then carry its state ``y["wall"]``.
    names : tuple of str (static)
        The scene-table name of each effect (``"contact"``, ``"wall"``, ...).
    """

    particles: ThermalParticles
    effects: tuple
    internal: Optional[eqx.Module] = None
    names: tuple = eqx.field(static=True, default=())
    drum_wall: Optional[eqx.Module] = None

    def effect(self, name: str):
        """The effect built from ``[heat.<name>]``, or None if the scene has none."""
        for n, e in zip(self.names, self.effects):
            if n == name:
                return e
        return None

    @property
    def accounts(self) -> tuple[str, ...]:
        """Names of the outside reservoirs the bed exchanges heat with ("wall", "gas", ...).

        An effect that splits its heat by surface (the walls of a drum with internals:
        ``wall:shell``, ``wall:plates``, ...) contributes each of its accounts."""
        names = set()
        for e in self.effects:
            names.update(e.accounts)
        return tuple(sorted(names))

    def heat_flows(self, T: Array, net: ContactNetwork) -> tuple[Array, dict[str, Array]]:
        """Total heat flow into each particle (W, shape (N,)) and the heat flow from each
        outside reservoir into the bed (W, scalars by account)."""
        total = jnp.zeros_like(T)
        external = {a: jnp.zeros((), T.dtype) for a in self.accounts}
        for effect in self.effects:
            q, ext = effect.flows(T, self.particles, net)
            total = total + q
            for a, v in ext.items():
                external[a] = external[a] + v
        return total, external

    def heat_flows_wall(self, T: Array, wall: dict, net: ContactNetwork, t
                        ) -> tuple[Array, dict[str, Array], Array, dict[str, Array]]:
        """:meth:`heat_flows` with the drum wall's segments (``[heat.drum_wall]``).

        The wall effect (``[heat.wall]``) conducts at each contact's segment temperature
        (segment from ``net.wall_angle`` at time ``t``, :meth:`DrumWall.segment`). Returns the
        heat flow into each particle (W, (N,)), the bed's accounts (W; ``wall`` is wall ->
        bed), the rate of change of the segment temperatures (K/s, (n_seg,)) and the wall's
        accounts (W; ``outside`` in from outside, ``gas`` out to the free gas).
        """
        dw = self.drum_wall
        net = eqx.tree_at(lambda n: n.wall_id, net, dw.segment(net.wall_angle, t))
        k = self.names.index("wall")
        wall_effect = eqx.tree_at(lambda e: e.wall_temperature, self.effects[k], wall["T"])
        model = eqx.tree_at(lambda m: m.effects, self,
                            self.effects[:k] + (wall_effect,) + self.effects[k + 1:])
        q, external = model.heat_flows(T, net)
        q_bed = wall_effect.heat_flow_by_wall(T, self.particles, net, dw.n_segments)
        rate, wall_flows = dw.balance(wall["T"], q_bed,
                                      dw.covered_area(self.particles.diameter, net))
        return q, external, rate, wall_flows

    def conductance_sum(self, net: ContactNetwork, T: Array | None = None) -> Array:
        """Sum over all pipes of alpha A at each particle, W/K (weigler eq. [2.2]).

        Temperature-dependent effects (radiation, film-temperature convection) use ``T`` (the
        particle or surface temperatures), else their bound over the reachable temperatures.
        """
        s = jnp.zeros_like(self.particles.diameter)
        for effect in self.effects:
            s = s + effect.conductance_sum(self.particles, net, T)
        return s

    def stability_limit(self, net: ContactNetwork) -> Array:
        """Explicit (forward Euler) thermal step limit ``min_i m_i c_i / sum(alpha A)_i``, s
        (with a drum wall also that of its segments, :meth:`DrumWall.stability_limit`).

        weigler-thermal-dem.md eq. [2.2]. Below this step each explicit update is a convex
        combination of old temperatures, so the maximum principle holds; ``inf`` when nothing
        couples the particles.
        """
        g = self.conductance_sum(net)
        limit = jnp.min(jnp.where(g > 0, self.particles.capacity / jnp.where(g > 0, g, 1.0),
                                  jnp.inf))
        if self.drum_wall is None:
            return limit
        # the wall's segments: all the network's wall contacts in one segment bound any one's
        g_bed = jnp.sum(self.effect("wall").conductance(self.particles, net))
        return jnp.minimum(limit, self.drum_wall.stability_limit(g_bed))


def make_thermal_model(tables: dict[str, TableValues], ctx: EffectContext) -> ThermalModel:
    """The thermal model with exactly the effects of ``tables``.

    Parameters
    ----------
    tables : dict
        ``{name: TableValues}`` of the scene's ``[heat.<name>]`` tables, in scene order
        (``"internal"`` among them gives the shell state extension, ``"drum_wall"`` the drum
        wall's segments).
    ctx : EffectContext
        What the effects may know besides their tables.
    """
    names = tuple(n for n in tables if n not in ("internal", "drum_wall"))
    effects = tuple(EFFECTS[n].from_table(tables[n], ctx) for n in names)
    internal = build_internal(tables["internal"], ctx) if "internal" in tables else None
    if "drum_wall" not in tables:
        return ThermalModel(particles=ctx.particles, effects=effects, internal=internal,
                            names=names)
    return ThermalModel(particles=ctx.particles, effects=effects, internal=internal,
                        names=names, drum_wall=build_drum_wall(tables["drum_wall"], ctx))
