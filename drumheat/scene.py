"""Scene description: immutable dataclasses, TOML load/save, validation with clear errors.

A scene file (TOML, SI units, temperatures in kelvin) has the tables of ``DESIGN.md``
(``[run]``, ``[drum]``, ``[[groups]]``, ``[gas]``, ``[heat.*]``, ``[motion]``) and
``[packing]``. Every key is declared once below as a dataclass field with its unit, default,
constraint and documentation; the loader and the scene-file reference are generated from these
declarations. To add an effect, declare its table as a dataclass and add one field to
:class:`HeatConfig`.

Every bad value is rejected before any computation by :class:`SceneError`, whose message names
the dotted key, the value and what is allowed.

Examples
--------
>>> scene = load_scene("weigler-static", overrides={"run.duration": 600.0})
>>> scene.groups[0].temperature
299.15
"""

from __future__ import annotations

import dataclasses
import importlib.resources
import math
import re
import tomllib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from drumheat.materials import GASES, MATERIALS

_REQUIRED = dataclasses.MISSING


class SceneError(ValueError):
    """A scene value is missing, unknown or not allowed.

    Attributes
    ----------
    key : str
        Dotted path of the offending key, e.g. ``groups.0.diameter``.
    value : Any
        The value given (``None`` if missing).
    allowed : str
        What would be accepted.
    """

    def __init__(self, key: str, value: Any, allowed: str, scene: str | None = None):
        self.key, self.value, self.allowed, self.scene = key, value, allowed, scene
        where = f"scene {scene!r}: " if scene else ""
        if value is _MISSING_VALUE:
            msg = f"{where}required key '{key}' is missing; {allowed}."
        else:
            msg = f"{where}key '{key}' = {value!r} is not allowed; {allowed}."
        super().__init__(msg)


_MISSING_VALUE = object()


def spec(default: Any = _REQUIRED, *, unit: str = "", doc: str = "", gt: float | None = None,
         ge: float | None = None, lt: float | None = None, le: float | None = None,
         choices: tuple | None = None, default_factory: Any = _REQUIRED,
         required_when: Any = None, kw_only: bool = False):
    """Declare a scene key: a dataclass field with unit, documentation and constraints.

    ``required_when(table) -> bool`` makes an optional key required depending on the raw table
    it sits in (e.g. ``[drum]`` for the motion models that need a drum); ``kw_only`` lets such a
    key keep its place in the declaration order (the order in which missing keys are reported).
    """
    meta = dict(unit=unit, doc=doc, gt=gt, ge=ge, lt=lt, le=le, choices=choices,
                required_when=required_when)
    if default_factory is not _REQUIRED:
        return field(default_factory=default_factory, metadata=meta, kw_only=kw_only)
    return field(default=default, metadata=meta, kw_only=kw_only)


# ---------------------------------------------------------------------------------------------
# Tables
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RunConfig:
    """``[run]``: duration, output and the thermal integrator."""

    duration: float = spec(unit="s", gt=0, doc="Simulated process time.")
    output_interval: float = spec(unit="s", gt=0, doc="Time between recorded outputs.")
    seed: int = spec(1, ge=0, doc="Seed of every random choice (packing, re-mixing).")
    solver: str = spec("adaptive", choices=("adaptive", "implicit", "explicit"),
                       doc="Thermal integrator: 'adaptive' (diffrax Tsit5 with error control), "
                           "'implicit' (diffrax Kvaerno5, for stiff scenes) or 'explicit' "
                           "(fixed-step forward Euler that checks dt < m c / sum(alpha A)).")
    rtol: float = spec(1e-8, gt=0, lt=1, doc="Relative tolerance of the adaptive solvers.")
    atol: float = spec(1e-6, unit="K", gt=0, doc="Absolute tolerance of the adaptive solvers.")
    dt: Optional[float] = spec(None, unit="s", gt=0,
                               doc="Step of the explicit thermal solver; default: 0.5 times "
                                   "its stability limit.")


@dataclass(frozen=True)
class DrumConfig:
    """``[drum]``: the drum shell (axis through the origin, along z in 3D)."""

    diameter: float = spec(unit="m", gt=0, doc="Inner drum diameter.")
    rpm: float = spec(0.0, unit="1/min", doc="Rotation speed, positive counter-clockwise "
                                             "seen from +z.")
    wall_temperature: Optional[float] = spec(None, unit="K", gt=0,
                                             doc="Shell temperature; leave out for a wall that "
                                                 "exchanges no heat.")
    depth: Optional[float] = spec(None, unit="m", gt=0,
                                  doc="Axial length of a 3D drum slice (dim = 3).")
    # internals (herz-sectional-drum.md section 1); all optional, absent = a plain drum
    sections: Optional[int] = spec(None, ge=0,
                                   doc="Number of radial plates, evenly spaced, joining the "
                                       "inner cylinder (or the axis) to the shell and rotating "
                                       "with the drum; they divide the drum into as many "
                                       "sections. Leave out (or 0) for none. Motion model "
                                       "'dem' only.")
    inner_diameter: Optional[float] = spec(None, unit="m", ge=0,
                                           doc="Diameter of an inner cylinder on the drum axis, "
                                               "rotating with the drum; leave out (or 0) for "
                                               "none. Motion model 'dem' only.")
    plate_thickness: Optional[float] = spec(None, unit="m", ge=0,
                                            doc="Thickness of the radial plates (default 0: "
                                                "plates of zero thickness).")
    plate_phase: Optional[float] = spec(None, unit="deg",
                                        doc="Polar angle (counter-clockwise from +x) of plate 0 "
                                            "at t = 0; plate j lies at plate_phase - j 360/"
                                            "sections. Default 180: section 0 starts at the "
                                            "Herz angle delta = 0 (herz-sectional-drum.md eq. "
                                            "17).")
    plate_temperature: Optional[float] = spec(None, unit="K", gt=0,
                                              doc="Temperature of the radial plates; leave out "
                                                  "for plates that exchange no heat.")
    inner_temperature: Optional[float] = spec(None, unit="K", gt=0,
                                              doc="Temperature of the inner cylinder; leave out "
                                                  "for one that exchanges no heat.")

    @property
    def has_internals(self) -> bool:
        """True when the drum has radial plates or an inner cylinder."""
        return bool(self.sections) or bool(self.inner_diameter)

    def heated_surfaces(self) -> tuple[tuple[str, str], ...]:
        """``(surface name, dotted key of its temperature)`` of every surface that exchanges
        heat, in wall-id order. A plain drum has one surface named ``wall`` (the shell); a drum
        with internals names them ``shell``, ``inner`` and ``plates``."""
        if not self.has_internals:
            return (("wall", "drum.wall_temperature"),) if self.wall_temperature is not None \
                else ()
        out = []
        for name, key, present in (("shell", "wall_temperature", True),
                                   ("inner", "inner_temperature", bool(self.inner_diameter)),
                                   ("plates", "plate_temperature", bool(self.sections))):
            if present and getattr(self, key) is not None:
                out.append((name, f"drum.{key}"))
        return tuple(out)


@dataclass(frozen=True)
class GroupConfig:
    """``[[groups]]``: one table per particle group (fraction)."""

    name: str = spec(doc="Group name; time series column T_mean:<name>.")
    count: int = spec(ge=1, doc="Number of particles.")
    diameter: float = spec(unit="m", gt=0, doc="Particle diameter.")
    material: str = spec(choices=tuple(sorted(MATERIALS)),
                         doc="Material from the library (drumheat.materials).")
    temperature: float = spec(unit="K", gt=0, doc="Initial temperature.")
    density: Optional[float] = spec(None, unit="kg/m3", gt=0, doc="Overrides the material's.")
    heat_capacity: Optional[float] = spec(None, unit="J/(kg K)", gt=0,
                                          doc="Overrides the material's.")
    conductivity: Optional[float] = spec(None, unit="W/(m K)", gt=0,
                                         doc="Overrides the material's.")
    youngs_modulus: Optional[float] = spec(None, unit="Pa", gt=0, doc="Overrides the material's.")
    poisson_ratio: Optional[float] = spec(None, ge=0, lt=0.5, doc="Overrides the material's.")
    emissivity: Optional[float] = spec(None, ge=0, le=1, doc="Overrides the material's.")


@dataclass(frozen=True)
class GasConfig:
    """``[gas]``: the gas surrounding the particles."""

    temperature: float = spec(unit="K", gt=0, doc="Gas (chamber air) temperature.")
    pressure: float = spec(101325.0, unit="Pa", gt=0, doc="Gas pressure.")
    material: str = spec("air", choices=tuple(sorted(GASES)), doc="Gas from the library.")
    conductivity: Optional[float] = spec(None, unit="W/(m K)", gt=0,
                                         doc="Overrides the library's conductivity.")
    heat_capacity: Optional[float] = spec(None, unit="J/(kg K)", gt=0,
                                          doc="Overrides the library's c_p (convection with "
                                              "properties = 'gas', plug-flow gas balance).")
    density: Optional[float] = spec(None, unit="kg/m3", gt=0,
                                    doc="Gas density for convection with properties = 'gas' "
                                        "(default: ideal gas at temperature and pressure).")
    kinematic_viscosity: Optional[float] = spec(
        None, unit="m2/s", gt=0, doc="Kinematic viscosity for convection with properties = "
                                     "'gas' (default: the Staltner Table 4.6 fit at the gas "
                                     "temperature, drumheat.models.air).")
    mass_flux: Optional[float] = spec(None, unit="kg/(m2 s)", gt=0,
                                      doc="Gas mass flux through the bed cross-section "
                                          "(motion model 'fluidized': plug flow through the bed, "
                                          "fluidized-bed-exercise.md section 4).")


@dataclass(frozen=True)
class ContactConfig:
    """``[heat.contact]``: particle-particle contact conduction (weigler eq. [2.7])."""

    model: str = spec("constant", choices=("constant", "schluender"),
                      doc="'constant': alpha as given; 'schluender': alpha_pp from the gas and "
                          "the particle diameter (weigler eqs. [2.9], [2.10]).")
    alpha: Optional[float] = spec(None, unit="W/(m2 K)", gt=0,
                                  doc="alpha_pp on the projected area pi d^2/4; required for "
                                      "model 'constant'.")


@dataclass(frozen=True)
class WallConfig:
    """``[heat.wall]``: particle-wall contact conduction (weigler eq. [2.7])."""

    model: str = spec("constant", choices=("constant", "schluender"),
                      doc="'constant': alpha as given; 'schluender': alpha_wp from the gas and "
                          "the particle diameter (weigler eq. [2.8]).")
    alpha: Optional[float] = spec(None, unit="W/(m2 K)", gt=0,
                                  doc="alpha_wp on the projected area pi d^2/4; required for "
                                      "model 'constant'.")


@dataclass(frozen=True)
class LossConfig:
    """``[heat.loss]``: lumped heat loss to the gas (weigler eq. [2.7], section 7.5)."""

    alphaA: float = spec(unit="W/K", ge=0, doc="(alpha A)_WK per particle.")


CONVECTION_CORRELATIONS = ("constant", "gnielinski", "gnielinski-staltner", "ranz-marshall",
                           "fluidized-bed", "gnielinski-kraychev")


@dataclass(frozen=True)
class ConvectionConfig:
    """``[heat.convection]``: particle-gas convection on the whole sphere surface pi d^2.

    alpha from a correlation of drumheat.models.convection (staltner-slag-particle.md section
    5, fluidized-bed-exercise.md sections 2-5, kraychev-tube-bundle.md section 4).
    """

    correlation: str = spec("gnielinski", choices=CONVECTION_CORRELATIONS,
                            doc="'constant': alpha as given; 'gnielinski': single sphere, L = d, "
                                "all-Pr laminar part (fluidized-bed-exercise.md section 3); "
                                "'gnielinski-staltner': L = pi d/2, Nu_lam = 0.664 Re^1/2 "
                                "Pr^1/3 (staltner [3.25]-[3.28]); 'ranz-marshall': Nu = 2 + "
                                "0.6 Re^1/2 Pr^1/3 (kraychev (3-14)); 'fluidized-bed': mean of "
                                "the loosening point (packed bed, factor f_a) and the discharge "
                                "point (single sphere), fluidized-bed-exercise.md section 5; "
                                "'gnielinski-kraychev': L = d, Nu_lam = 0.664 Re^1/2 Pr^1/3, "
                                "exact VDI Nu_turb (kraychev (3-16)-(3-18), digest 14.1).")
    alpha: Optional[float] = spec(None, unit="W/(m2 K)", gt=0,
                                  doc="alpha on the sphere surface pi d^2; required for "
                                      "correlation 'constant'.")
    velocity: Optional[float] = spec(None, unit="m/s", ge=0,
                                     doc="Gas velocity relative to the particle (superficial "
                                         "velocity when porosity is given; discharge velocity "
                                         "u_A for 'fluidized-bed'). Motion model 'granulator' "
                                         "uses the droplet speed v_S when left out.")
    porosity: Optional[float] = spec(None, gt=0, le=1,
                                     doc="Void fraction psi of a packed bed: Re on the "
                                         "interstitial velocity u/psi and Nu times f_a = 1 + "
                                         "1.5 (1 - psi) (fluidized-bed-exercise.md section 2).")
    loosening_velocity: float = spec(1.2, unit="m/s", gt=0,
                                     doc="'fluidized-bed': superficial velocity at the "
                                         "loosening point (exercise: 1.2 m/s).")
    loosening_porosity: float = spec(0.4, gt=0.26, lt=1,
                                     doc="'fluidized-bed': porosity at the loosening point "
                                         "(exercise: 0.4).")
    properties: str = spec("polynomial", choices=("polynomial", "gas"),
                           doc="Gas properties: 'polynomial' = dry-air fits of "
                               "staltner-slag-particle.md section 9 (clamped to 273-1273 K with "
                               "a warning); 'gas' = constants of the [gas] table.")
    property_temperature: str = spec("gas", choices=("gas", "film"),
                                     doc="Temperature of the gas properties: the gas "
                                         "temperature, or the film temperature (T_s + T_g)/2 "
                                         "evaluated at every step (staltner digest section 5 "
                                         "leaves this open).")
    internal_resistance: str = spec("none", choices=("none", "transient-sphere"),
                                    doc="'transient-sphere': lumped particles get the overall "
                                        "k = 1/(1/alpha_i + 1/alpha), alpha_i from the transient "
                                        "internal Nusselt number at Fo(run.duration) "
                                        "(fluidized-bed-exercise.md section 5); use without "
                                        "[heat.internal].")


@dataclass(frozen=True)
class RadiationSurface:
    """``[[heat.radiation.surfaces]]``: one grey surface of the enclosure."""

    name: str = spec(doc="Surface name; for enclosure 'granulator' the four zones in order "
                         "'bed', 'slots', 'wall', 'outlet' (staltner-slag-particle.md section 1).")
    temperature: float = spec(unit="K", gt=0, doc="Surface temperature.")
    emissivity: float = spec(gt=0, le=1, doc="Grey emissivity.")


@dataclass(frozen=True)
class RadiationConfig:
    """``[heat.radiation]``: grey radiation between each particle and an enclosure.

    q = eps_p sigma (T_s^4 - T_rad^4) on pi d^2 (staltner-slag-particle.md sections 4, 6).
    """

    enclosure: str = spec("sink", choices=("sink", "granulator"),
                          doc="'sink': the particle sees one black surface at "
                              "sink_temperature; 'granulator': the four-zone enclosure of "
                              "[granulator] with the radiosity method and fictitious view "
                              "factors (staltner [6.29]-[6.40]), T_rad from the particle's "
                              "position (staltner digest section 4).")
    sink_temperature: Optional[float] = spec(None, unit="K", gt=0,
                                             doc="Temperature of the black sink; required for "
                                                 "enclosure 'sink'.")
    emissivity: Optional[float] = spec(None, gt=0, le=1,
                                       doc="Particle emissivity; default the group's.")
    surfaces: Optional[tuple[RadiationSurface, ...]] = spec(
        None, doc="Enclosure surfaces (enclosure 'granulator').")


@dataclass(frozen=True)
class InternalConfig:
    """``[heat.internal]``: radial shell conduction inside every particle.

    Each particle carries n shells (drumheat.thermal.shells, staltner-slag-particle.md sections
    2-4); the surface shell receives the surface flows of the other effects.
    """

    shells: int = spec(20, ge=2, le=2000, doc="Number of radial nodes n (node n on the surface).")
    scheme: str = spec("implicit", choices=("implicit", "explicit"),
                       doc="'implicit': backward-Euler finite volumes, unconditionally stable "
                           "and monotone; 'explicit': the thesis' scheme [5.15]-[5.27] with its "
                           "stability limit (staltner digest section 4) enforced.")
    dt: Optional[float] = spec(None, unit="s", gt=0,
                               doc="Shell time step; default: the explicit stability limit at "
                                   "the start (0.9 of it for 'explicit').")
    on_unstable: str = spec("refuse", choices=("refuse", "implicit"),
                            doc="'explicit' with dt above the stability limit: refuse with a "
                                "message, or switch to the implicit scheme with a warning.")
    newton_iters: int = spec(3, ge=1, le=50, doc="Newton iterations per implicit step "
                                                 "(temperature-dependent properties, radiation, "
                                                 "coupling between particles).")
    material: str = spec("constant", choices=("constant", "staltner-slag"),
                         doc="'constant': the group's density, c and lambda; 'staltner-slag': "
                             "c_p(T) and lambda(T) of staltner-slag-particle.md section 9 "
                             "(piecewise linear between the knots), rho = 2690 kg/m3.")
    liquid_conductivity: float = spec(0.20, unit="W/(m K)", gt=0,
                                      doc="'staltner-slag': lambda of the liquid plateau.")
    plateau_temperature: float = spec(1723.15, unit="K", gt=1673.15,
                                      doc="'staltner-slag': start of the liquid lambda plateau "
                                          "(not given in the source; 1450 degC chosen, linear "
                                          "from 0.23 at 1400 degC).")
    latent_heat: Optional[float] = spec(None, unit="J/kg", gt=0,
                                        doc="Latent heat released around melting_temperature "
                                            "(apparent heat capacity, shells.LatentHeatMaterial).")
    melting_temperature: Optional[float] = spec(None, unit="K", gt=0,
                                                doc="Centre of the melting range.")
    melting_width: float = spec(5.0, unit="K", gt=0, doc="Standard deviation of the melting "
                                                         "range.")


@dataclass(frozen=True)
class HeatConfig:
    """``[heat]``: the heat-transfer effects; an absent table is not simulated."""

    contact: Optional[ContactConfig] = spec(None, doc="Particle-particle contact conduction.")
    wall: Optional[WallConfig] = spec(None, doc="Particle-wall contact conduction.")
    loss: Optional[LossConfig] = spec(None, doc="Heat loss to the gas.")
    convection: Optional[ConvectionConfig] = spec(None, doc="Particle-gas convection.")
    radiation: Optional[RadiationConfig] = spec(None, doc="Radiation to an enclosure.")
    internal: Optional[InternalConfig] = spec(None, doc="Conduction inside the particles "
                                                        "(radial shells).")

    def effects(self) -> tuple[str, ...]:
        """Names of the effects this scene switches on."""
        return tuple(f.name for f in dataclasses.fields(self) if getattr(self, f.name) is not None)


#: Motion models and the class implementing each ("module:Class", imported on use).
MOTION_MODELS = {
    "static": "drumheat.mixing.static:StaticBed",
    "random": "drumheat.mixing.random:RandomBed",
    "granulator": "drumheat.mixing.granulator:GranulatorParticle",
    "fluidized": "drumheat.mixing.fluidized:FluidizedBed",
    "dem": "drumheat.mixing.dem:DEMBed",
    "replay": "drumheat.mixing.replay:ReplayBed",
    "pneumatic": "drumheat.mixing.pneumatic:PneumaticChannel",
    "moving_bed": "drumheat.mixing.moving_bed:MovingBed",
}

#: Motion models whose particles lie in the drum of the ``[drum]`` table.
DRUM_MOTION_MODELS = ("static", "random", "dem", "replay")


@dataclass(frozen=True)
class MotionConfig:
    """``[motion]``: how the particles move."""

    model: str = spec("static", choices=tuple(MOTION_MODELS),
                      doc="'static': a resting packing, contacts found once from geometry; "
                          "'random': the semi-discrete penetration model, a resting packing "
                          "whose particle temperatures are re-mixed every t_R "
                          "(weigler-thermal-dem.md section 6.1, 11.1).")
    t_R: Optional[float] = spec(None, unit="s", gt=0,
                                doc="Re-mixing period of model 'random' (the rest time of the "
                                    "penetration model, weigler eq. [1.1]).")
    remix: str = spec("permute", choices=("permute", "mean"),
                      doc="Model 'random': 'permute' shuffles the temperatures over the fixed "
                          "positions (the thesis' choice), 'mean' sets every particle to the "
                          "bed mean.")
    layers: int = spec(1, ge=1, doc="Model 'fluidized': number of layers the gas passes in "
                                    "plug flow; particles are re-assigned to random layers every "
                                    "t_R.")
    loading: Optional[float] = spec(None, unit="kg/m2", gt=0,
                                    doc="Model 'fluidized': particle mass per bed cross-section "
                                        "m_1 (fluidized-bed-exercise.md section 4).")


@dataclass(frozen=True)
class GranulatorConfig:
    """``[granulator]``: the dry slag granulator of staltner-slag-particle.md sections 1, 7, 10.

    Zones: bed disc (radius r2, z = 0), slotted cylinder (r2, height h3), water-cooled cone
    (height h4, inclined alpha4 to the horizontal), outlet disc (r5 = r2 - h4/tan alpha4).
    """

    r2: float = spec(unit="m", gt=0, doc="Radius of the bed and the slotted cylinder.")
    h4: float = spec(unit="m", gt=0, doc="Height of the water-cooled cone.")
    alpha4: float = spec(unit="deg", gt=0, lt=90, doc="Cone inclination to the horizontal.")
    disc_diameter: float = spec(unit="m", gt=0, doc="Spinning-disc diameter d_Dt.")
    disc_speed: float = spec(unit="1/min", gt=0, doc="Disc speed n_Dt; droplet speed v_S = "
                                                     "0.8 pi d_Dt n_Dt [4.1].")
    slag_rate: float = spec(unit="kg/min", gt=31.46,
                            doc="Slag mass flow m_S; wall heat Q_W [MW] = 0.0036207 m_S - "
                                "0.1139 [4.8] fixes the Phase-2 contact time [4.9].")
    h3: float = spec(1.0, unit="m", gt=0, doc="Height of the slotted cylinder (Tab. 4.3).")
    disc_height: Optional[float] = spec(None, unit="m", gt=0,
                                        doc="Height of the disc (and the horizontal Phase-1 "
                                            "path); default mid-cone h3 + h4/2 (digest note).")
    wall_temperature: float = spec(373.15, unit="K", gt=0, doc="T_4 of the water-cooled wall.")
    wall_density: float = spec(7800.0, unit="kg/m3", gt=0, doc="Steel wall, Tab. 4.7.")
    wall_heat_capacity: float = spec(500.0, unit="J/(kg K)", gt=0, doc="Steel wall, Tab. 4.7.")
    wall_conductivity: float = spec(50.0, unit="W/(m K)", gt=0, doc="Steel wall, Tab. 4.7.")
    contact_mode: str = spec("surface", choices=("surface",),
                             doc="Phase-2 Dirichlet boundary: node n held at the contact "
                                 "temperature T_m (the digest's consistent reading).")
    segments: int = spec(20, ge=1, doc="Path segments per flight phase; the radiation sink "
                                       "temperature is taken at each segment's midpoint.")
    steps_per_phase: int = spec(400, ge=10, doc="Shell time steps per phase when "
                                                "heat.internal.dt is not given (Phase 2: per "
                                                "estimated contact time).")


@dataclass(frozen=True)
class DEMConfig:
    """``[dem]``: soft-sphere mechanics of motion model 'dem' (drumheat.mechanics).

    Linear spring-dashpot normal force, Cundall-Strack tangential spring with Coulomb limit,
    rotation; weigler-thermal-dem.md sections 4-5 (Table 2-1, PFC settings).
    """

    stiffness: Optional[float] = spec(None, unit="N/m", gt=0,
                                      doc="Normal (= tangential) stiffness k_n of particle "
                                          "contacts; default E A_p / d_p (weigler eq. [2.3]). "
                                          "A softer value allows a larger time step; the "
                                          "contact conduction of drumheat does not depend on "
                                          "the overlap, so softening changes the heat transfer "
                                          "only through the motion.")
    wall_stiffness: Optional[float] = spec(None, unit="N/m", gt=0,
                                           doc="Stiffness of particle-wall contacts; default: "
                                               "the particle stiffness.")
    damping_ratio: Optional[float] = spec(0.3, ge=0, lt=1,
                                          doc="Viscous damping ratio, normal and tangential "
                                              "(PFC viscous damping 0.3 in the thesis).")
    restitution: Optional[float] = spec(None, gt=0, le=1,
                                        doc="Restitution coefficient; replaces damping_ratio "
                                            "when given.")
    friction: float = spec(0.9, ge=0, doc="Particle-particle friction coefficient (thesis 0.9).")
    wall_friction: float = spec(0.6, ge=0, doc="Particle-wall friction coefficient (0.6).")
    rolling_friction: float = spec(0.0, ge=0, doc="Rolling-resistance coefficient.")
    dt: Optional[float] = spec(None, unit="s", gt=0,
                               doc="Mechanical time step; default safety_factor x t_crit with "
                                   "t_crit = 2 sqrt(m_min / k_n) (weigler eq. [2.1]); a larger "
                                   "step than t_crit is refused.")
    safety_factor: float = spec(
        0.1, gt=0, le=1,
        doc="dt = safety_factor x t_crit by default. 0.1 because frictional drum flow needs it: "
            "at 0.2 the contacts slide where they should stick (3D glass drum slice, 9.55 rpm: "
            "angle of repose 17.6 deg at 0.2, 29-32 deg at 0.1 and 0.05, LIGGGHTS 29 deg; 2D "
            "weigler-glass-mixing-9.55: 26.8 +- 4.6 deg at 0.2, 29.8 +- 4.7 deg at 0.1).")
    skin: Optional[float] = spec(None, unit="m", gt=0,
                                 doc="Neighbour-list skin; default half the largest diameter.")
    precision: str = spec("float64", choices=("float32", "float64"),
                          doc="Floating-point type of the mechanics; temperatures are always "
                              "float64.")
    thermal_substeps: int = spec(1, ge=1,
                                 doc="Mechanical steps per thermal step; each contact's "
                                     "conductance is weighted by the time it existed within "
                                     "the thermal step.")
    record_interval: Optional[float] = spec(None, unit="s", gt=0,
                                            doc="Record the contact network (pairs with contact "
                                                "durations) every record_interval into "
                                                "contacts.npz, for motion model 'replay'.")
    replay_after: Optional[float] = spec(None, unit="s", gt=0,
                                         doc="Simulate mechanics and heat together only up to "
                                             "this time, then continue by cyclic replay of the "
                                             "contacts recorded so far (motion model 'replay', "
                                             "needs record_interval): hours of process time "
                                             "from a few revolutions of DEM.")
    replay_cycle: Optional[float] = spec(None, unit="s", gt=0,
                                         doc="With replay_after: the replayed cycle is the last "
                                             "replay_cycle seconds of the recording (default: "
                                             "its second half), leaving out the start-up from "
                                             "rest; best a whole number of revolutions.")
    settle_time: float = spec(0.0, unit="s", ge=0,
                              doc="Time the bed settles with the drum at rest before t = 0.")
    gravity: float = spec(9.81, unit="m/s2", ge=0,
                          doc="Gravity along -y. The thesis' 2D drum was tilted 45 degrees, "
                              "which would give 9.81 sin 45 = 6.94 in the plane; the source does "
                              "not say which it used (weigler-thermal-dem.md section 12.19).")


@dataclass(frozen=True)
class ChannelConfig:
    """``[channel]``: vertical pneumatic channel of motion model 'pneumatic'.

    Kraychev digest (kraychev-tube-bundle.md) sections 1, 2, 6: particles carried upward by
    gas in plug flow; y up (gas and solids), x across the gap between two walls, z along the
    channel length (the simulated slice of depth ``depth`` is periodic in z).
    """

    height: float = spec(unit="m", gt=0, doc="Channel height (inlet y = 0, outlet y = height).")
    gap: float = spec(unit="m", gt=0, doc="Clear width between the two channel walls (x).")
    depth: float = spec(unit="m", gt=0, doc="Simulated slice of the channel length (z, "
                                            "periodic); at least 2 x the neighbour cutoff.")
    length: float = spec(unit="m", gt=0, doc="Channel length along the apparatus that "
                                             "solids_mass_flow refers to (L_App).")
    gas_velocity: float = spec(unit="m/s", gt=0, doc="Superficial gas velocity at the inlet "
                                                     "(plug flow; mass flux conserved).")
    solids_mass_flow: float = spec(unit="kg/s", gt=0,
                                   doc="Solids fed into the whole channel length; the slice "
                                       "gets depth/length of it.")
    particle_inlet_velocity: float = spec(0.0, unit="m/s", ge=0,
                                          doc="Upward velocity of particles entering at y = 0.")
    inlet_velocity_spread: float = spec(0.0, unit="m/s", ge=0,
                                        doc="Entering particles get random horizontal velocity "
                                            "components, uniform in +-this value (lateral "
                                            "dispersion: collisions with walls and particles).")
    cells: int = spec(52, ge=1, doc="Axial gas cells of the plug-flow energy balance.")
    gas_coupling: str = spec("two-way", choices=("two-way", "none"),
                             doc="'two-way': the gas temperature follows from its energy "
                                 "balance cell by cell; 'none': the gas keeps its inlet "
                                 "temperature (no heat coupling back to the gas).")
    drag_law: str = spec("schiller_naumann", choices=("schiller_naumann", "newton", "stokes"),
                         doc="Single-sphere drag coefficient (drumheat.models.drag).")
    steady_after: Optional[float] = spec(None, unit="s", ge=0,
                                         doc="Start of the averaging window of the *_steady "
                                             "columns; default half the duration.")


@dataclass(frozen=True)
class HopperConfig:
    """``[hopper]``: hopper with a staggered bundle of horizontal tubes (motion 'moving_bed').

    kraychev-tube-bundle.md sections 1, 2, 7: the solids sink through the bundle and leave
    through a bottom slit of width S; here they re-enter at the top (recycling). Coordinates:
    x across the bundle (hopper axis x = 0), y up (y = 0 at the slit lips), z along the tubes
    (a 3D slice of length ``depth``, periodic in z).
    """

    slit_width: float = spec(unit="m", gt=0, doc="Outlet slit width S (4-16 mm in the source).")
    tube_temperature: float = spec(unit="K", gt=0, doc="Temperature of all tubes (t_R,OF).")
    inlet_temperature: float = spec(unit="K", gt=0,
                                    doc="Temperature of the particles re-entering at the top "
                                        "(t_1).")
    depth: float = spec(unit="m", gt=0, doc="Length of the periodic slice along the tubes.")
    tube_diameter: float = spec(0.014, unit="m", gt=0, doc="Tube outer diameter D_R.")
    pitch: float = spec(0.025, unit="m", gt=0, doc="Transverse pitch s1 (in a row).")
    row_pitch: float = spec(0.025, unit="m", gt=0, doc="Longitudinal pitch s2 (row to row).")
    rows: int = spec(4, ge=1, doc="Number of tube rows.")
    columns: int = spec(3, ge=1, doc="Hopper width in transverse pitches; the side walls are "
                                     "symmetry planes of the bundle (tubes centred on them are "
                                     "half tubes).")
    bottom_height: float = spec(0.02, unit="m", gt=0,
                                doc="Height of the sloped bottom: plates from the side walls at "
                                    "this height down to the slit lips at y = 0.")
    bundle_clearance: float = spec(0.012, unit="m", gt=0,
                                   doc="Gap between the sloped bottom's top and the lowest "
                                       "tubes' underside.")
    insertion_height: float = spec(0.06, unit="m", gt=0,
                                   doc="Bottom of the insertion band above the top tube row's "
                                       "crest; recycled particles re-enter on sites above it.")
    exit_depth: float = spec(0.02, unit="m", gt=0,
                             doc="A particle whose centre falls this far below the slit has "
                                 "left and is recycled.")
    settle_time: float = spec(0.3, unit="s", ge=0,
                              doc="Settling with the slit closed before t = 0.")
    measure_from: float = spec(1.0, unit="s", ge=0,
                               doc="Start of the window over which W_p and alpha_1 are "
                                   "averaged (after the start-up).")


@dataclass(frozen=True)
class ReplayConfig:
    """``[replay]``: thermal-only replay of a recorded contact network (motion 'replay')."""

    file: str = spec(doc="contacts.npz written by a 'dem' run with dem.record_interval; "
                         "relative to the scene file.")
    cyclic: bool = spec(True, doc="Replay the recording over and over when the scene is longer "
                                  "than it; at each restart the temperatures are carried over "
                                  "to the particles whose start positions best match the end "
                                  "positions.")


@dataclass(frozen=True)
class PackingConfig:
    """``[packing]``: how the initial packing is made and how contacts are found in it."""

    method: str = spec("deposition", choices=("deposition", "pour", "file"),
                       doc="'deposition': particles dropped one by one at random positions roll "
                           "down to a stable rest (drumheat.mechanics.deposition, 2D); 'pour': "
                           "inserted above the bed and settled by DEM under gravity "
                           "(drumheat.mechanics.pour; needs [dem]); 'file': positions from an "
                           ".npz file.")
    arrangement: str = spec("layers", choices=("layers", "mixed"),
                            doc="'layers': groups poured one after the other (first group at "
                                "the bottom); 'mixed': pouring order shuffled.")
    contact_tolerance: float = spec(0.01, ge=0, lt=0.5,
                                    doc="Two surfaces closer than this fraction of the smaller "
                                        "diameter count as touching.")
    file: Optional[str] = spec(None, doc="Packing .npz (arrays position, diameter, group) for "
                                         "method 'file'; relative to the scene file.")
    surface_angle: Optional[float] = spec(None, unit="deg", gt=-90, lt=90,
                                          doc="Drum with radial plates and method 'pour': "
                                              "inclination of each section's initial free "
                                              "surface to the horizontal, positive falling "
                                              "towards +x (a drum turning clockwise, rpm < 0, "
                                              "holds its bed so); default 0. Starting near "
                                              "the angle of repose shortens the warm-up.")


@dataclass(frozen=True)
class Scene:
    """A complete, validated scene. Build with :func:`load_scene` or :func:`scene_from_dict`."""

    name: str = spec(doc="Scene name; default result folder results/<name>.")
    run: RunConfig = spec(doc="Duration, output and integrator.")
    drum: Optional[DrumConfig] = spec(
        None, kw_only=True, doc="The drum; required for the motion models static and random.",
        required_when=lambda t: (t.get("motion") or {}).get("model", "static")
        in DRUM_MOTION_MODELS if isinstance(t.get("motion") or {}, dict) else True)
    groups: tuple[GroupConfig, ...] = spec(doc="Particle groups, at least one.")
    description: str = spec("", doc="One line shown by `drumheat scenes`.")
    dim: int = spec(2, choices=(2, 3), doc="2: a monolayer of spheres in a drum slice; 3: a 3D "
                                           "bed.")
    gas: Optional[GasConfig] = spec(None, doc="Surrounding gas.")
    heat: HeatConfig = spec(default_factory=HeatConfig, doc="Heat-transfer effects.")
    motion: MotionConfig = spec(default_factory=MotionConfig, doc="Motion model.")
    packing: PackingConfig = spec(default_factory=PackingConfig, doc="Initial packing.")
    dem: Optional[DEMConfig] = spec(None, doc="DEM mechanics (motion model 'dem').")
    replay: Optional[ReplayConfig] = spec(None, doc="Recorded contacts (motion model 'replay').")
    granulator: Optional[GranulatorConfig] = spec(None, doc="Granulator geometry and process "
                                                            "(motion model 'granulator').")
    channel: Optional[ChannelConfig] = spec(None, doc="Pneumatic channel (motion model "
                                                      "'pneumatic').")
    hopper: Optional[HopperConfig] = spec(None, doc="Hopper with a tube bundle (motion model "
                                                    "'moving_bed').")
    source_path: Optional[str] = field(default=None, compare=False,
                                       metadata=dict(internal=True))

    # -- convenience ---------------------------------------------------------------------
    @property
    def n_particles(self) -> int:
        return sum(g.count for g in self.groups)

    def to_dict(self) -> dict:
        """The scene as a plain dict (what a TOML file holds); unset optional keys omitted."""
        return _to_dict(self)

    def to_toml(self) -> str:
        """The scene as TOML text that :func:`load_scene` reads back to an equal scene."""
        import tomli_w

        return tomli_w.dumps(self.to_dict())

    def get(self, path: str) -> Any:
        """Value at a dotted path, e.g. ``scene.get("groups.0.temperature")``."""
        obj: Any = self
        for part in path.split("."):
            obj = obj[int(part)] if isinstance(obj, tuple) else getattr(obj, part)
        return obj

    def with_overrides(self, overrides: dict[str, Any]) -> "Scene":
        """A new validated scene with dotted-path overrides applied."""
        raw = self.to_dict()
        for key, value in overrides.items():
            _set_path(raw, key, value, self.name)
        return scene_from_dict(raw, source_path=self.source_path)


# ---------------------------------------------------------------------------------------------
# Generic loader
# ---------------------------------------------------------------------------------------------


def _unwrap_optional(tp):
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return args[0], True
    return tp, False


def _type_name(tp) -> str:
    if dataclasses.is_dataclass(tp):
        return "a table"
    if typing.get_origin(tp) is tuple:
        return "an array of tables"
    return {float: "a number", int: "an integer", str: "a string", bool: "true or false"}[tp]


def _allowed_text(meta: dict, tp) -> str:
    parts = []
    if meta.get("choices"):
        parts.append("allowed: " + ", ".join(repr(c) for c in meta["choices"]))
    else:
        parts.append(f"must be {_type_name(tp)}")
    for key, op in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
        if meta.get(key) is not None:
            parts.append(f"{op} {meta[key]:g}")
    if meta.get("unit"):
        parts.append(f"in {meta['unit']}")
    return " ".join(parts)


def _convert(value, tp, meta, key, scene_name):
    tp, _ = _unwrap_optional(tp)
    allowed = _allowed_text(meta, tp)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise SceneError(key, value, "must be a table", scene_name)
        return _build(tp, value, key, scene_name)
    if typing.get_origin(tp) is tuple:
        (item_tp, _ellipsis) = typing.get_args(tp)
        if not isinstance(value, list) or not value:
            raise SceneError(key, value, "must be a non-empty array of tables", scene_name)
        return tuple(_convert(v, item_tp, {}, f"{key}.{i}", scene_name) for i, v in enumerate(value))
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(key, value, allowed, scene_name)
        value = float(value)
        if not math.isfinite(value):
            raise SceneError(key, value, allowed + " (finite)", scene_name)
    elif tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                raise SceneError(key, value, allowed, scene_name)
    elif tp is str:
        if not isinstance(value, str):
            raise SceneError(key, value, allowed, scene_name)
    elif tp is bool:
        if not isinstance(value, bool):
            raise SceneError(key, value, allowed, scene_name)
    if meta.get("choices") is not None and value not in meta["choices"]:
        raise SceneError(key, value, allowed, scene_name)
    for k, ok in (("gt", lambda v, b: v > b), ("ge", lambda v, b: v >= b),
                  ("lt", lambda v, b: v < b), ("le", lambda v, b: v <= b)):
        if meta.get(k) is not None and not ok(value, meta[k]):
            raise SceneError(key, value, allowed, scene_name)
    return value


def _build(cls, table: dict, prefix: str, scene_name):
    hints = typing.get_type_hints(cls)
    known = {f.name: f for f in dataclasses.fields(cls) if not f.metadata.get("internal")}
    for k in table:
        if k not in known:
            key = f"{prefix}.{k}" if prefix else k
            raise SceneError(key, table[k], "unknown key; known keys here: "
                             + ", ".join(sorted(known)), scene_name)
    kwargs = {}
    for name, f in known.items():
        key = f"{prefix}.{name}" if prefix else name
        if name in table:
            kwargs[name] = _convert(table[name], hints[name], f.metadata, key, scene_name)
        elif (f.default is _REQUIRED and f.default_factory is _REQUIRED) or (
                f.metadata.get("required_when") is not None and f.metadata["required_when"](table)):
            tp, _ = _unwrap_optional(hints[name])
            raise SceneError(key, _MISSING_VALUE, _allowed_text(f.metadata, tp), scene_name)
    return cls(**kwargs)


def _to_dict(obj) -> Any:
    if dataclasses.is_dataclass(obj):
        out = {}
        for f in dataclasses.fields(obj):
            if f.metadata.get("internal"):
                continue
            v = getattr(obj, f.name)
            if v is None:
                continue
            out[f.name] = _to_dict(v)
        return out
    if isinstance(obj, tuple):
        return [_to_dict(v) for v in obj]
    return obj


def _set_path(raw: dict, key: str, value: Any, scene_name=None) -> None:
    parts = key.split(".")
    obj: Any = raw
    for i, part in enumerate(parts[:-1]):
        here = ".".join(parts[: i + 1])
        if isinstance(obj, list):
            if not part.isdigit() or int(part) >= len(obj):
                raise SceneError(here, part, f"index must be 0..{len(obj) - 1}", scene_name)
            obj = obj[int(part)]
        else:
            nxt = obj.get(part)
            if nxt is None:
                nxt = obj[part] = {}
            elif not isinstance(nxt, (dict, list)):
                raise SceneError(here, nxt, "is a value, not a table", scene_name)
            obj = nxt
    last = parts[-1]
    if isinstance(obj, list):
        if not last.isdigit() or int(last) >= len(obj):
            raise SceneError(key, last, f"index must be 0..{len(obj) - 1}", scene_name)
        if value is None:
            raise SceneError(key, None, "a group cannot be removed by an override", scene_name)
        obj[int(last)] = value
    elif value is None:
        obj.pop(last, None)
    else:
        obj[last] = value


def parse_override(text: str) -> tuple[str, Any]:
    """Parse ``KEY=VALUE`` (VALUE as a TOML value; bare words are strings; ``none`` removes
    the key, e.g. ``heat.radiation=none`` switches radiation off)."""
    if "=" not in text:
        raise SceneError(text, text, "overrides look like KEY=VALUE, e.g. run.duration=600")
    key, raw = text.split("=", 1)
    key, raw = key.strip(), raw.strip()
    if raw.lower() == "none":
        return key, None  # removes the key: switches an effect table off
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key, value


#: what a scene name may look like: it names the default result folder results/<name>
_NAME_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*")


def _check_consistency(s: Scene) -> None:
    n = s.name
    if not _NAME_PATTERN.fullmatch(n) or ".." in n:
        raise SceneError("name", n, "must be a plain file name (letters, digits and _ . + -, "
                         "not starting with '.' or '-'): it names the result folder "
                         "results/<name>", None)
    if s.run.output_interval > s.run.duration:
        raise SceneError("run.output_interval", s.run.output_interval,
                         f"must be <= run.duration = {s.run.duration:g} s", n)
    names = [g.name for g in s.groups]
    for i, g in enumerate(s.groups):
        if names.index(g.name) != i:
            raise SceneError(f"groups.{i}.name", g.name, "group names must be unique", n)
        if s.drum is not None and g.diameter >= s.drum.diameter:
            raise SceneError(f"groups.{i}.diameter", g.diameter,
                             f"must be smaller than drum.diameter = {s.drum.diameter:g} m", n)
    if s.drum is not None and s.dim == 3 and s.drum.depth is None:
        raise SceneError("drum.depth", _MISSING_VALUE, "a 3D scene (dim = 3) needs the axial "
                         "length of the drum slice, in m", n)
    if s.drum is not None and s.dim == 2:
        solid = sum(g.count * math.pi * g.diameter**2 / 4 for g in s.groups)
        drum = math.pi * s.drum.diameter**2 / 4
        if solid > 0.8 * drum:
            raise SceneError("groups", f"{s.n_particles} particles",
                             f"the particles cover {solid / drum:.0%} of the drum cross-section; "
                             "a monolayer packing holds at most about 80 %", n)
    if (s.heat.wall is not None and s.motion.model != "moving_bed"  # tubes: [hopper]
            and (s.drum is None or not s.drum.heated_surfaces())):
        raise SceneError("drum.wall_temperature", _MISSING_VALUE,
                         "[heat.wall] needs the wall temperature, in K", n)
    if s.drum is not None and s.drum.has_internals:
        d = s.drum
        if s.motion.model != "dem":
            raise SceneError("drum.sections" if d.sections else "drum.inner_diameter",
                             d.sections or d.inner_diameter, "drum internals (radial plates, "
                             "inner cylinder) need motion model 'dem'", n)
        if d.inner_diameter and d.inner_diameter >= d.diameter:
            raise SceneError("drum.inner_diameter", d.inner_diameter,
                             f"must be smaller than drum.diameter = {d.diameter:g} m", n)
        if d.sections and s.packing.method == "deposition":
            raise SceneError("packing.method", "deposition", "the geometric deposition does not "
                             "know the radial plates; use 'pour' (fills every section equally) "
                             "or 'file'", n)
        for key, present in (("plate_temperature", bool(d.sections)),
                             ("inner_temperature", bool(d.inner_diameter))):
            if getattr(d, key) is not None and not present:
                raise SceneError(f"drum.{key}", getattr(d, key), "there is no such surface "
                                 "(drum.sections / drum.inner_diameter is 0 or left out)", n)
    for eff in ("contact", "wall"):
        cfg = getattr(s.heat, eff)
        if cfg is not None and cfg.model == "constant" and cfg.alpha is None:
            raise SceneError(f"heat.{eff}.alpha", _MISSING_VALUE,
                             "model 'constant' needs alpha, a number > 0 in W/(m2 K)", n)
        if cfg is not None and cfg.model == "schluender" and cfg.alpha is not None:
            raise SceneError(f"heat.{eff}.alpha", cfg.alpha,
                             "model 'schluender' computes alpha; leave alpha out or use "
                             "model 'constant'", n)
    if s.heat.loss is not None and s.gas is None:
        raise SceneError("gas.temperature", _MISSING_VALUE,
                         "[heat.loss] needs the gas temperature, in K", n)
    _check_new_effects(s)
    if s.motion.model == "dem" and s.dem is None:
        raise SceneError("dem", _MISSING_VALUE, "motion model 'dem' needs the [dem] table "
                         "(its keys all have defaults: [dem] alone is enough)", n)
    if s.motion.model == "replay" and s.replay is None:
        raise SceneError("replay.file", _MISSING_VALUE, "motion model 'replay' needs "
                         "[replay] file = a contacts.npz recorded by a 'dem' run", n)
    if s.dem is not None and s.dem.restitution is not None and s.dem.damping_ratio not in (
            None, 0.3):
        raise SceneError("dem.restitution", s.dem.restitution, "give either dem.restitution or "
                         "dem.damping_ratio, not both", n)
    if s.dem is not None and s.dem.replay_after is not None:
        if s.dem.record_interval is None:
            raise SceneError("dem.replay_after", s.dem.replay_after, "needs dem.record_interval "
                             "(the contacts to replay)", n)
        cyc = s.dem.replay_cycle if s.dem.replay_cycle is not None else 0.5 * s.dem.replay_after
        kc = cyc / s.dem.record_interval
        if cyc > s.dem.replay_after * (1 + 1e-9) or abs(kc - round(kc)) > 1e-6 or round(kc) < 1:
            raise SceneError("dem.replay_cycle", cyc, "must be a whole number of "
                             f"dem.record_interval = {s.dem.record_interval:g} s and at most "
                             f"dem.replay_after = {s.dem.replay_after:g} s", n)
        k = s.dem.replay_after / s.run.output_interval
        if abs(k - round(k)) > 1e-6 or round(k) < 1:
            raise SceneError("dem.replay_after", s.dem.replay_after, "must be a positive "
                             f"multiple of run.output_interval = {s.run.output_interval:g} s", n)
    if s.packing.method == "pour" and s.dem is None:
        raise SceneError("packing.method", "pour", "pouring runs the DEM; add the [dem] table", n)
    if s.motion.model == "random" and s.motion.t_R is None:
        raise SceneError("motion.t_R", _MISSING_VALUE, "model 'random' needs the re-mixing "
                         "period t_R, a number > 0 in s", n)
    if s.motion.model == "fluidized":
        if s.motion.loading is None:
            raise SceneError("motion.loading", _MISSING_VALUE, "model 'fluidized' needs the "
                             "particle mass per bed cross-section, in kg/m2", n)
        if s.gas is None or s.gas.mass_flux is None:
            raise SceneError("gas.mass_flux", _MISSING_VALUE, "model 'fluidized' needs the gas "
                             "mass flux through the bed, in kg/(m2 s)", n)
        if s.heat.convection is None:
            raise SceneError("heat.convection", _MISSING_VALUE, "model 'fluidized' exchanges "
                             "heat with the gas through [heat.convection]", n)
        if s.motion.layers > 1 and s.motion.t_R is None:
            raise SceneError("motion.t_R", _MISSING_VALUE, "model 'fluidized' with several "
                             "layers needs the re-mixing period t_R, in s", n)
    if s.motion.model == "granulator":
        if s.granulator is None:
            raise SceneError("granulator", _MISSING_VALUE, "motion model 'granulator' needs the "
                             "[granulator] table (geometry, disc, slag rate)", n)
        if s.heat.internal is None:
            raise SceneError("heat.internal", _MISSING_VALUE, "motion model 'granulator' "
                             "resolves the droplet's radial profile; add [heat.internal]", n)
        if s.heat.contact is not None or s.heat.wall is not None:
            raise SceneError("heat.contact" if s.heat.contact else "heat.wall", "a table",
                             "a single droplet has no contacts; Phase-2 wall contact is part of "
                             "motion model 'granulator'", n)
        if s.n_particles != 1:
            raise SceneError("groups", f"{s.n_particles} particles", "motion model 'granulator' "
                             "follows one droplet (one group with count = 1); run one scene per "
                             "size class", n)
        g = s.granulator
        if g.disc_height is not None and not g.h3 <= g.disc_height < g.h3 + g.h4:
            raise SceneError("granulator.disc_height", g.disc_height, "the horizontal Phase-1 "
                             f"path must hit the water-cooled cone: h3 <= disc_height < h3 + h4 "
                             f"= {g.h3 + g.h4:g} m", n)
        if g.h4 / math.tan(math.radians(g.alpha4)) >= g.r2:
            raise SceneError("granulator.h4", g.h4, "the cone closes before its top "
                             "(r5 = r2 - h4/tan(alpha4) <= 0); reduce h4 or raise alpha4", n)
    if s.motion.model == "pneumatic":
        from drumheat.mixing.pneumatic import check_scene

        check_scene(s)
    if s.motion.model == "moving_bed":
        _check_hopper(s)
    if s.packing.method == "file" and s.packing.file is None:
        raise SceneError("packing.file", _MISSING_VALUE, "method 'file' needs a path to an .npz "
                         "packing", n)
    if (s.motion.model in DRUM_MOTION_MODELS and s.dim == 3
            and s.packing.method == "deposition"):
        raise SceneError("packing.method", "deposition", "the geometric deposition packing is "
                         "2D; a 3D bed needs packing.method = 'pour' (with [dem]) or 'file'", n)


def check_apparatus_tables(s: Scene, table: str, keys: str, what: str) -> None:
    """Common rules of the DEM apparatus models (``moving_bed``, ``pneumatic``): their own
    table ``[table]`` (required ``keys`` named in the message) and ``[dem]`` must be present,
    and the scene is a 3D slice (``what`` says of what)."""
    n, model = s.name, s.motion.model
    if getattr(s, table) is None:
        raise SceneError(table, _MISSING_VALUE, f"motion model '{model}' needs the [{table}] "
                         f"table ({keys})", n)
    if s.dem is None:
        raise SceneError("dem", _MISSING_VALUE, f"motion model '{model}' needs the [dem] "
                         "table (its keys all have defaults: [dem] alone is enough)", n)
    if s.dim != 3:
        raise SceneError("dim", s.dim, f"motion model '{model}' simulates a 3D slice {what}; "
                         "use dim = 3", n)


def _check_hopper(s: Scene) -> None:
    """Cross-field rules of motion model 'moving_bed' (drumheat.mixing.moving_bed)."""
    n = s.name
    check_apparatus_tables(s, "hopper", "slit_width, tube_temperature, inlet_temperature, "
                           "depth", "along the tubes")
    h = s.hopper
    if h.tube_diameter >= h.pitch or h.tube_diameter >= 2 * h.row_pitch:
        raise SceneError("hopper.tube_diameter", h.tube_diameter, "the tubes must not touch: "
                         f"less than pitch = {h.pitch:g} m", n)
    d_max = max(g.diameter for g in s.groups)
    if h.depth < 2.5 * d_max * 1.0001:
        raise SceneError("hopper.depth", h.depth, "the periodic slice must be at least 2.5 "
                         f"largest particle diameters long ({2.5 * d_max:g} m)", n)
    if h.slit_width >= h.columns * h.pitch:
        raise SceneError("hopper.slit_width", h.slit_width, "must be narrower than the hopper "
                         f"(columns x pitch = {h.columns * h.pitch:g} m)", n)


def _check_new_effects(s: Scene) -> None:
    """Cross-field rules of [heat.convection], [heat.radiation] and [heat.internal]."""
    n, h = s.name, s.heat
    if h.radiation is not None:
        for i, g in enumerate(s.groups):
            eps = g.emissivity if g.emissivity is not None else None
            if eps is not None and eps <= 0:
                raise SceneError(f"groups.{i}.emissivity", eps, "[heat.radiation] needs particle "
                                 "emissivities > 0 (leave [heat.radiation] out for none)", n)
    c = h.convection
    if c is not None:
        if s.gas is None:
            raise SceneError("gas.temperature", _MISSING_VALUE,
                             "[heat.convection] needs the gas temperature, in K", n)
        if c.correlation == "constant" and c.alpha is None:
            raise SceneError("heat.convection.alpha", _MISSING_VALUE,
                             "correlation 'constant' needs alpha, a number > 0 in W/(m2 K)", n)
        if c.correlation != "constant" and c.alpha is not None:
            raise SceneError("heat.convection.alpha", c.alpha, f"correlation {c.correlation!r} "
                             "computes alpha; leave alpha out or use correlation 'constant'", n)
        if (c.correlation not in ("constant",) and c.velocity is None
                and s.motion.model not in ("granulator", "pneumatic")):
            raise SceneError("heat.convection.velocity", _MISSING_VALUE,
                             f"correlation {c.correlation!r} needs the gas velocity, in m/s", n)
        if c.properties == "gas" and c.correlation != "constant":
            for key in ("kinematic_viscosity", "conductivity", "heat_capacity"):
                if getattr(s.gas, key) is None:
                    raise SceneError(f"gas.{key}", _MISSING_VALUE, "convection with properties "
                                     "= 'gas' needs the gas constants kinematic_viscosity, "
                                     "conductivity and heat_capacity", n)
        if c.internal_resistance != "none" and h.internal is not None:
            raise SceneError("heat.convection.internal_resistance", c.internal_resistance,
                             "with [heat.internal] the shells resolve the internal resistance; "
                             "use 'none'", n)
    r = h.radiation
    if r is not None:
        if r.enclosure == "sink" and r.sink_temperature is None:
            raise SceneError("heat.radiation.sink_temperature", _MISSING_VALUE,
                             "enclosure 'sink' needs the sink temperature, in K", n)
        if r.enclosure == "granulator":
            zones = ("bed", "slots", "wall", "outlet")
            got = tuple(x.name for x in (r.surfaces or ()))
            if got != zones:
                raise SceneError("heat.radiation.surfaces", list(got), "enclosure 'granulator' "
                                 "needs four surfaces named " + ", ".join(zones) + " in this "
                                 "order", n)
            if s.granulator is None:
                raise SceneError("granulator", _MISSING_VALUE, "enclosure 'granulator' needs "
                                 "the [granulator] geometry", n)
    i = h.internal
    if i is not None and (i.latent_heat is None) != (i.melting_temperature is None):
        raise SceneError("heat.internal.melting_temperature" if i.melting_temperature is None
                         else "heat.internal.latent_heat", _MISSING_VALUE,
                         "latent heat needs both latent_heat (J/kg) and melting_temperature (K)", n)


def scene_from_dict(raw: dict, source_path: str | None = None) -> Scene:
    """Validate a plain dict (as read from TOML) and build a :class:`Scene`."""
    name = raw.get("name") if isinstance(raw.get("name"), str) else None
    scene = _build(Scene, raw, "", name)
    scene = dataclasses.replace(scene, source_path=source_path)
    _check_consistency(scene)
    return scene


# ---------------------------------------------------------------------------------------------
# Built-in scenes and files
# ---------------------------------------------------------------------------------------------


def _scene_dir():
    return importlib.resources.files("drumheat") / "scenes"


def builtin_scenes() -> dict[str, str]:
    """Built-in scenes: ``{name: description}``, sorted by name."""
    out = {}
    for entry in sorted(_scene_dir().iterdir(), key=lambda p: p.name):
        if entry.name.endswith(".toml"):
            raw = tomllib.loads(entry.read_text())
            out[raw.get("name", entry.name[:-5])] = raw.get("description", "")
    return out


def read_scene_dict(name_or_path: str | Path) -> tuple[dict, str | None]:
    """Raw dict of a built-in scene (by name) or a scene file (by path), and its path."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.exists():
            raise SceneError("SCENE", str(name_or_path), "no such scene file")
        text, src = path.read_text(), str(path.resolve())
    else:
        entry = _scene_dir() / f"{name_or_path}.toml"
        if not entry.is_file():
            raise SceneError("SCENE", str(name_or_path), "not a scene file; built-in scenes: "
                             + ", ".join(builtin_scenes()))
        text, src = entry.read_text(), str(entry)
    try:
        return tomllib.loads(text), src
    except tomllib.TOMLDecodeError as err:
        raise SceneError("SCENE", str(name_or_path), f"not valid TOML ({err})") from None


def load_scene(name_or_path: str | Path, overrides: dict[str, Any] | list[str] | None = None
               ) -> Scene:
    """Load and validate a built-in scene (by name) or a TOML scene file (by path).

    Parameters
    ----------
    name_or_path : str or Path
        A built-in scene name (see ``drumheat scenes``) or a path to a ``.toml`` file.
    overrides : dict or list of str, optional
        Dotted-path overrides applied before validation, as a dict
        (``{"groups.0.temperature": 300.0}``) or as ``KEY=VALUE`` strings (as ``--set``).

    Raises
    ------
    SceneError
        For every bad, unknown or missing value, naming the key.
    """
    raw, src = read_scene_dict(name_or_path)
    if isinstance(overrides, (list, tuple)):
        overrides = dict(parse_override(o) for o in overrides)
    for key, value in (overrides or {}).items():
        _set_path(raw, key, value, raw.get("name"))
    return scene_from_dict(raw, source_path=src)


def iter_keys(cls=Scene, prefix: str = ""):
    """Yield ``(dotted_key, type_name, unit, default, allowed, doc)`` for every scene key.

    Used to generate the scene-file reference; ``groups.*`` stands for every group.
    """
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if f.metadata.get("internal"):
            continue
        key = f"{prefix}{f.name}"
        tp, optional = _unwrap_optional(hints[f.name])
        if typing.get_origin(tp) is tuple:
            yield from iter_keys(typing.get_args(tp)[0], f"{key}.*.")
            continue
        if dataclasses.is_dataclass(tp):
            yield from iter_keys(tp, f"{key}.")
            continue
        default = "required" if f.default is _REQUIRED else f.default
        yield (key, _type_name(tp), f.metadata.get("unit", ""), default,
               _allowed_text(f.metadata, tp), f.metadata.get("doc", ""))
