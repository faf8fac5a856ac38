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
and nothing changes.
"""

from __future__ import annotations

from typing import Optional

import equinox as eqx
import jax.numpy as jnp
from jax import Array

# the effect modules register themselves on import (drumheat.thermal.effect.register)
from drumheat.thermal import contact, convection, loss, radiation, wall  # noqa: F401
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
    names : tuple of str (static)
        The scene-table name of each effect (``"contact"``, ``"wall"``, ...).
    """

    particles: ThermalParticles
    effects: tuple
    internal: Optional[eqx.Module] = None
    names: tuple = eqx.field(static=True, default=())

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
        """Explicit (forward Euler) thermal step limit ``min_i m_i c_i / sum(alpha A)_i``, s.

        weigler-thermal-dem.md eq. [2.2]. Below this step each explicit update is a convex
        combination of old temperatures, so the maximum principle holds; ``inf`` when nothing
        couples the particles.
        """
        g = self.conductance_sum(net)
        return jnp.min(jnp.where(g > 0, self.particles.capacity / jnp.where(g > 0, g, 1.0),
                                 jnp.inf))


def make_thermal_model(tables: dict[str, TableValues], ctx: EffectContext) -> ThermalModel:
    """The thermal model with exactly the effects of ``tables``.

    Parameters
    ----------
    tables : dict
        ``{name: TableValues}`` of the scene's ``[heat.<name>]`` tables, in scene order
        (``"internal"`` among them gives the shell state extension).
    ctx : EffectContext
        What the effects may know besides their tables.
    """
    names = tuple(n for n in tables if n != "internal")
    effects = tuple(EFFECTS[n].from_table(tables[n], ctx) for n in names)
    internal = build_internal(tables["internal"], ctx) if "internal" in tables else None
    return ThermalModel(particles=ctx.particles, effects=effects, internal=internal,
                        names=names)
