"""The contract of a heat-transfer effect, what an effect may know, and the registry by name.

An effect is an equinox module whose array fields are its parameters (fittable leaves) and whose
one job is the heat flow into each particle (W) from the particle temperatures and the contact
network. Each effect lives in its own module (``contact.py``, ``wall.py``, ...) and registers
itself under the name of its scene table (``[heat.contact]`` -> ``"contact"``) with
:func:`register`; adding an effect is one new file plus its import in
:mod:`drumheat.thermal.model`, as adding a ``fix`` is in LIGGGHTS.

An effect is built by :meth:`AbstractEffect.from_table` from two things only: its own scene
table (through a :class:`TableValues` view, so that a calibration can pass traced values in
place of the table's) and an explicit :class:`EffectContext` (the particles, the gas, the wall
temperatures, a radiation sink, ...), assembled from the scene by :mod:`drumheat.assemble`.
Effects never see the scene.
"""

from __future__ import annotations

import abc
from typing import Any, Callable, ClassVar, NamedTuple, Optional

import equinox as eqx
import jax.numpy as jnp
from jax import Array

from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.particles import ThermalParticles

__all__ = ["AbstractEffect", "DrumGeometry", "EffectContext", "GasState", "PlugFlow",
           "TableValues", "EFFECTS", "register"]


class TableValues:
    """An effect's scene table with some values replaced (e.g. by traced numbers of a fit).

    ``view.alpha`` is ``values["heat.contact.alpha"]`` when given, else the table's own value;
    ``view.table`` is the table itself (for static choices such as ``model``).

    Parameters
    ----------
    table : a scene table (e.g. :class:`drumheat.scene.ContactConfig`)
    prefix : str
        Its dotted path, e.g. ``"heat.contact"``.
    values : dict
        Dotted keys to values taking precedence over the table's.
    """

    def __init__(self, table, prefix: str, values: dict | None = None):
        self.table, self.prefix, self._values = table, prefix, values or {}

    def __getattr__(self, name: str):
        key = f"{self.prefix}.{name}"
        if key in self._values:
            return self._values[key]
        return getattr(self.table, name)

    def given(self, name: str) -> bool:
        """True if the key has a value (given in the table or replaced)."""
        return f"{self.prefix}.{name}" in self._values or getattr(self.table, name) is not None


class GasState(NamedTuple):
    """The gas around the particles, as the effects need it (SI; arrays may be traced).

    ``temperature`` K, ``pressure`` Pa, ``conductivity`` W/(m K), ``heat_capacity`` J/(kg K),
    ``molar_mass`` kg/kmol and ``accommodation_constant`` (Schluender's C) of the gas;
    ``density`` kg/m3 and ``kinematic_viscosity`` m2/s where the scene gives them (else None).
    """

    temperature: Any
    pressure: Any
    conductivity: Any
    heat_capacity: Any
    molar_mass: float
    accommodation_constant: float
    density: Any = None
    kinematic_viscosity: Any = None


class PlugFlow(NamedTuple):
    """Gas in plug flow through a bed of layers (fluidized-bed-exercise.md section 4): the gas
    mass flux through the bed cross-section (kg/(m2 s)), the particle mass per cross-section
    m_1 (``loading``, kg/m2), the gas's c_p (J/(kg K)) and the number of layers."""

    mass_flux: Any
    loading: Any
    heat_capacity: Any
    n_layers: int


class DrumGeometry(NamedTuple):
    """The drum as a drum wall with segments needs it (``[heat.drum_wall]``): inner
    ``radius`` (m), ``depth`` (m) of the wall a segment spans along the axis (3D: the slice's
    ``drum.depth``; 2D: the monolayer's mean particle diameter) and ``rpm`` (1/min, positive
    counter-clockwise seen from +z)."""

    radius: float
    depth: float
    rpm: float


class EffectContext(NamedTuple):
    """What an effect may know besides its own table (assembled from the scene).

    Attributes
    ----------
    particles : ThermalParticles
    particle_property : callable
        ``particle_property(name) -> (N,) array``: a material property of every particle
        (``"conductivity"``, ``"emissivity"``, ...), the group's value or the library's.
    gas : GasState or None
        The scene's ``[gas]``; None where it has none.
    contact_gas : GasState
        The gas of the contact models (Schluender): the scene's, else the thesis' Table 8-1
        conditions (air, 30 degC, 1 atm).
    mean_diameter : float
        Number-mean particle diameter, m (Schluender's coefficients of a bed).
    wall_temperatures : array or None
        Temperature of each wall id, K.
    wall_surfaces : tuple of str or None
        Names of the wall ids when each books its heat separately (``wall:<name>``).
    temperature_bounds : (float, float)
        Lowest and highest temperature the run can reach (maximum principle), K.
    duration : float or array
        Simulated time of the run, s.
    gas_velocity : array or None
        Relative gas velocity where the motion sets it (the granulator's droplet speed), m/s.
    sink_temperature : array or None
        Radiation temperature of the enclosure at the start (the granulator's), K.
    plug_flow : PlugFlow or None
        The gas passes the bed in plug flow (a fluidised bed).
    density_given : bool
        A particle density was given in the scene (not the material library's).
    name : str
        The scene's name, for warnings.
    drum : DrumGeometry or None
        The drum, where a drum wall with segments needs it (``[heat.drum_wall]``).
    coarse_grain : float
        Coarse-graining factor s (``[dem] coarse_grain``): the particles are parcels of
        diameter ``s d`` standing for ``s^3`` real particles each; the effects that support it
        scale their conductances so that the bed keeps the fine bed's properties
        (docs/models/coarse-graining.md). ``mean_diameter`` is the real particles' then.
    """

    particles: ThermalParticles
    particle_property: Callable[[str], Array]
    gas: Optional[GasState]
    contact_gas: GasState
    mean_diameter: float
    wall_temperatures: Any = None
    wall_surfaces: Optional[tuple] = None
    temperature_bounds: tuple = (273.15, 1273.15)
    duration: Any = 0.0
    gas_velocity: Any = None
    sink_temperature: Any = None
    plug_flow: Optional[PlugFlow] = None
    density_given: bool = False
    name: str = ""
    drum: Optional[DrumGeometry] = None
    coarse_grain: float = 1.0


class AbstractEffect(eqx.Module):
    """A heat-transfer effect (module docstring). Subclasses set ``account``.

    ``account`` names the outside reservoir the effect exchanges heat with (``"wall"``,
    ``"gas"``, ``"radiation"``), None for an exchange inside the bed (contacts).
    """

    account: ClassVar[Optional[str]] = None

    @abc.abstractmethod
    def heat_flow(self, T: Array, particles: ThermalParticles, net: ContactNetwork) -> Array:
        """Heat flow into each particle, W, shape (N,), at surface temperatures ``T`` (N,)."""

    @abc.abstractmethod
    def conductance_sum(self, particles: ThermalParticles, net: ContactNetwork,
                        T: Array | None = None) -> Array:
        """Sum of the conductances at each particle, W/K (the diagonal slope of
        :meth:`heat_flow`; weigler eq. [2.2]). Temperature-dependent effects use ``T``, else
        their bound over the temperatures the run can reach."""

    @classmethod
    @abc.abstractmethod
    def from_table(cls, table: TableValues, ctx: EffectContext) -> "AbstractEffect":
        """The effect of a scene table (module docstring)."""

    @property
    def accounts(self) -> tuple[str, ...]:
        """The outside accounts this effect books heat into."""
        return () if self.account is None else (self.account,)

    def flows(self, T: Array, particles: ThermalParticles, net: ContactNetwork
              ) -> tuple[Array, dict[str, Array]]:
        """Heat flow into each particle (W, (N,)) and from each of :attr:`accounts` (W)."""
        q = self.heat_flow(T, particles, net)
        return q, ({self.account: jnp.sum(q)} if self.account is not None else {})


#: ``[heat.<name>]`` -> effect class (filled by :func:`register`)
EFFECTS: dict[str, type] = {}


def register(name: str):
    """Class decorator: register an effect class under the name of its scene table."""
    def deco(cls):
        EFFECTS[name] = cls
        return cls
    return deco
