"""Compose the thermal model of a scene from exactly the effects it lists.

Each effect is an equinox module in its own file (``contact.py``, ``wall.py``, ``loss.py``,
``convection.py``, ``radiation.py``) with one method, ``heat_flow(T, particles, net) -> W into
each particle``, and a class attribute ``account`` naming the outside reservoir it exchanges
with (``None`` for exchanges inside the bed). The registry below maps a ``[heat.<name>]`` table
to the function building the effect; adding an effect is one new file plus one entry here.
Effects whose table is absent are not built, so they are not in the traced program at all.

One entry is not a heat flow but a state extension: ``[heat.internal]``
(:mod:`drumheat.thermal.internal`, class attribute ``role = "state"``) gives every particle a
radial shell profile; the model then carries it in :attr:`ThermalModel.internal`, the effects
act on the surface node and the integrators of :mod:`drumheat.thermal.integrate` switch to the
shell schemes. Without it ``internal`` is None and nothing changes.
"""

from __future__ import annotations

from typing import Callable, Optional

import equinox as eqx
import jax.numpy as jnp
from jax import Array

from drumheat.models import schluender
from drumheat.thermal.contact import ContactConduction
from drumheat.thermal.loss import HeatLoss
from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.particles import ThermalParticles
from drumheat.thermal.wall import WallConduction

#: A getter ``value(dotted_key)`` returning a (possibly traced) scene value.
ValueFn = Callable[[str], object]


def _schluender(scene, value, d_p):
    """(alpha_wp, alpha_pp) from weigler eqs. [2.8]-[2.10] for the scene's gas (App. A3)."""
    from drumheat.materials import gas

    if scene.gas is not None:
        g = gas(scene.gas.material)
        T, p = value("gas.temperature"), value("gas.pressure")
        lam = value("gas.conductivity") if scene.gas.conductivity is not None else g.conductivity
    else:  # Table 8-1 conditions
        g = gas("air")
        T, p, lam = 303.15, 101325.0, g.conductivity
    return schluender.contact_coefficients(d_p, T=T, p=p, conductivity=lam,
                                           heat_capacity=g.heat_capacity,
                                           molar_mass=g.molar_mass, C=g.accommodation_constant)


def _mean_diameter(scene):
    n = sum(g.count for g in scene.groups)
    return sum(g.count * g.diameter for g in scene.groups) / n


def temperature_bounds(scene) -> tuple[float, float]:
    """Lowest and highest temperature a run of ``scene`` can reach, K.

    By the maximum principle every temperature stays between the extremes of the initial
    temperatures and of all outside reservoirs (gas, walls, radiating surfaces). Used to bound
    temperature-dependent conductances (stability limits) and to warn about property fits.
    """
    Ts = [g.temperature for g in scene.groups]
    if scene.gas is not None:
        Ts.append(scene.gas.temperature)
    if scene.drum is not None:
        Ts += [scene.get(key) for _, key in scene.drum.heated_surfaces()]
    r = scene.heat.radiation
    if r is not None:
        if r.sink_temperature is not None:
            Ts.append(r.sink_temperature)
        Ts += [x.temperature for x in (r.surfaces or ())]
    if scene.granulator is not None:
        Ts.append(scene.granulator.wall_temperature)
    if getattr(scene, "hopper", None) is not None:
        Ts += [scene.hopper.tube_temperature, scene.hopper.inlet_temperature]
    return float(min(Ts)), float(max(Ts))


def _contact(scene, value: ValueFn, particles=None) -> ContactConduction:
    cfg = scene.heat.contact
    if cfg.model == "constant":
        alpha = value("heat.contact.alpha")
    else:
        alpha = _schluender(scene, value, _mean_diameter(scene))[1]
    return ContactConduction(alpha=jnp.asarray(alpha, float))


def _wall(scene, value: ValueFn, particles=None) -> WallConduction:
    cfg = scene.heat.wall
    if cfg.model == "constant":
        alpha = value("heat.wall.alpha")
    else:
        alpha = _schluender(scene, value, _mean_diameter(scene))[0]
    if getattr(scene, "hopper", None) is not None:  # one temperature for all tubes
        return WallConduction(alpha=jnp.asarray(alpha, float), wall_temperature=jnp.atleast_1d(
            jnp.asarray(value("hopper.tube_temperature"), float)))
    surfaces = scene.drum.heated_surfaces()  # wall id k = surfaces[k]
    temps = jnp.stack([jnp.asarray(value(key), float) for _, key in surfaces])
    names = None if not scene.drum.has_internals else tuple(s for s, _ in surfaces)
    return WallConduction(alpha=jnp.asarray(alpha, float), wall_temperature=temps,
                          surfaces=names)


def _loss(scene, value: ValueFn, particles=None) -> HeatLoss:
    return HeatLoss(alphaA=jnp.asarray(value("heat.loss.alphaA"), float),
                    gas_temperature=jnp.asarray(value("gas.temperature"), float))


def _convection(scene, value: ValueFn, particles=None):
    from drumheat.thermal.convection import build_convection

    return build_convection(scene, value, particles, temperature_bounds(scene))


def _radiation(scene, value: ValueFn, particles=None):
    from drumheat.thermal.radiation import build_radiation

    return build_radiation(scene, value, particles, temperature_bounds(scene))


def _internal(scene, value: ValueFn, particles=None):
    from drumheat.thermal.internal import build_internal

    return build_internal(scene, value, particles)


#: ``[heat.<name>]`` -> builder(scene, value, particles) of the effect module.
EFFECTS: dict[str, Callable] = {
    "contact": _contact,
    "wall": _wall,
    "loss": _loss,
    "convection": _convection,
    "radiation": _radiation,
    "internal": _internal,
}


class ThermalModel(eqx.Module):
    """Particles plus the effects a scene switches on.

    Attributes
    ----------
    particles : ThermalParticles
    effects : tuple of effect modules
    """

    particles: ThermalParticles
    effects: tuple
    internal: Optional[eqx.Module] = None

    @property
    def accounts(self) -> tuple[str, ...]:
        """Names of the outside reservoirs the bed exchanges heat with ("wall", "gas", ...).

        An effect that splits its heat by surface (``account_flows``, e.g. the walls of a drum
        with internals: ``wall:shell``, ``wall:plates``, ...) contributes its ``accounts``."""
        names = set()
        for e in self.effects:
            if hasattr(e, "account_flows"):
                names.update(e.accounts)
            elif e.account is not None:
                names.add(e.account)
        return tuple(sorted(names))

    def heat_flows(self, T: Array, net: ContactNetwork) -> tuple[Array, dict[str, Array]]:
        """Total heat flow into each particle (W, shape (N,)) and the heat flow from each
        outside reservoir into the bed (W, scalars by account)."""
        total = jnp.zeros_like(T)
        external = {a: jnp.zeros((), T.dtype) for a in self.accounts}
        for effect in self.effects:
            if hasattr(effect, "account_flows"):
                q_slots = effect.slot_flows(T, self.particles, net)
                total = total.at[net.wall_particle].add(q_slots)
                for a, v in effect.account_flows(q_slots, net).items():
                    external[a] = external[a] + v
                continue
            q = effect.heat_flow(T, self.particles, net)
            total = total + q
            if effect.account is not None:
                external[effect.account] = external[effect.account] + jnp.sum(q)
        return total, external

    def conductance_sum(self, net: ContactNetwork, T: Array | None = None) -> Array:
        """Sum over all pipes of alpha A at each particle, W/K (weigler eq. [2.2]).

        Temperature-dependent effects (radiation, film-temperature convection) use ``T`` (the
        particle or surface temperatures), else their bound over the reachable temperatures.
        """
        s = jnp.zeros_like(self.particles.diameter)
        for effect in self.effects:
            if getattr(effect, "state_dependent", False):
                s = s + effect.conductance_sum(self.particles, net, T)
            else:
                s = s + effect.conductance_sum(self.particles, net)
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


def make_thermal_model(scene, particles: ThermalParticles, value: ValueFn) -> ThermalModel:
    """Build the thermal model of ``scene`` with exactly the effects it lists."""
    built = [EFFECTS[name](scene, value, particles) for name in scene.heat.effects()]
    state = [b for b in built if getattr(b, "role", None) == "state"]
    effects = tuple(b for b in built if getattr(b, "role", None) != "state")
    return ThermalModel(particles=particles, effects=effects,
                        internal=state[0] if state else None)
