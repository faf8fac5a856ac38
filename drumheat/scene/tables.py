"""The tables of a scene file, one frozen dataclass each, and the :class:`Scene` that holds them.

A scene file (TOML, SI units, temperatures in kelvin) has the tables of ``DESIGN.md``
(``[run]``, ``[drum]``, ``[[groups]]``, ``[gas]``, ``[heat.*]``, ``[motion]``) and
``[packing]``. Every key is declared once below as a dataclass field with its unit, default,
constraint and documentation (:func:`~drumheat.scene.spec.spec`); the loader and the scene-file
reference are generated from these declarations. To add an effect, declare its table as a
dataclass and add one field to :class:`HeatConfig`.

Every table checks itself when it is built (:class:`~drumheat.scene.spec.Table`) and a
:class:`Scene` checks the rules between its tables (:mod:`drumheat.scene.rules`), so every bad
value is rejected before any computation by :class:`~drumheat.scene.spec.SceneError`, whose
message names the dotted key, the value and what is allowed; a scene built in Python is
checked exactly as one read from a file.

Examples
--------
>>> from drumheat.scene import load_scene
>>> scene = load_scene("weigler-static", overrides={"run.duration": 600.0})
>>> scene.groups[0].temperature
299.15
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from drumheat.materials import GASES, MATERIALS
from drumheat.scene.rules import DRUM_MOTION_MODELS, MOTION_MODEL_NAMES, check_scene
from drumheat.scene.rules import motion_name as _motion_name
from drumheat.scene.spec import (SceneError, Table, build_table, building, iter_table_keys,
                                 set_path, spec, to_dict)

@dataclass(frozen=True)
class RunConfig(Table):
    """``[run]``: duration, output and the thermal integrator."""

    TABLE = "run"

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
    checkpoint_every: float = spec(600.0, unit="s (wall clock)", ge=0,
                                   doc="A run with a result folder writes a checkpoint there "
                                       "(checkpoint.npz) after this much wall-clock time since "
                                       "the last one, so a run killed after hours can continue "
                                       "with --resume; 0: none (a stopped or failed run still "
                                       "writes one). Short runs never reach it.")
    checkpoint_interval: Optional[float] = spec(None, unit="s", gt=0,
                                                doc="A checkpoint every this much simulated "
                                                    "time as well (at the next chunk end).")


@dataclass(frozen=True)
class DrumConfig(Table):
    """``[drum]``: the drum shell (axis through the origin, along z in 3D)."""

    TABLE = "drum"

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
class GroupConfig(Table):
    """``[[groups]]``: one table per particle group (fraction)."""

    TABLE = "groups.*"

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
class GasConfig(Table):
    """``[gas]``: the gas surrounding the particles."""

    TABLE = "gas"

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


def _gap_doc(diameter: str) -> str:
    """The doc of ``[heat.contact]`` / ``[heat.wall]`` ``gap_tolerance``."""
    return (f"A contact conducts while the surfaces overlap or the gap between them is at most "
            f"this fraction of the {diameter} diameter (weigler eq. [2.4] with a tolerance): "
            "the gas gap next to a contact conducts about as well as the contact itself "
            "(Schluender's model, weigler section 3), and soft DEM contacts chatter open and "
            "shut by far less than 1 % of d. The same definition in every motion model (static "
            "beds, DEM, recording and replay, contact counts); the conductance alpha A_p does "
            "not depend on the overlap, so softened stiffness does not change it. 0: while "
            "they overlap only.")


@dataclass(frozen=True)
class ContactConfig(Table):
    """``[heat.contact]``: particle-particle contact conduction (weigler eq. [2.7])."""

    TABLE = "heat.contact"

    model: str = spec("constant", choices=("constant", "schluender"),
                      doc="'constant': alpha as given; 'schluender': alpha_pp from the gas and "
                          "the particle diameter (weigler eqs. [2.9], [2.10]).")
    alpha: Optional[float] = spec(None, unit="W/(m2 K)", gt=0,
                                  doc="alpha_pp on the projected area pi d^2/4; required for "
                                      "model 'constant'.")
    gap_tolerance: float = spec(0.01, ge=0, lt=0.5, doc=_gap_doc("smaller"))


@dataclass(frozen=True)
class WallConfig(Table):
    """``[heat.wall]``: particle-wall contact conduction (weigler eq. [2.7])."""

    TABLE = "heat.wall"

    model: str = spec("constant", choices=("constant", "schluender"),
                      doc="'constant': alpha as given; 'schluender': alpha_wp from the gas and "
                          "the particle diameter (weigler eq. [2.8]).")
    alpha: Optional[float] = spec(None, unit="W/(m2 K)", gt=0,
                                  doc="alpha_wp on the projected area pi d^2/4; required for "
                                      "model 'constant'.")
    reference_contacts: Optional[float] = spec(
        None, gt=0,
        doc="Evaluation only: the number of wall contacts n of a fixed area A = n d^2 for the "
            "column alpha_overall_A9 (eq. [1.10] on the thesis' App. A9 area; A9 uses 45 for "
            "its 370-sphere drum, weigler digest sections 6.6 and 12.9). Without it only "
            "drumheat's own alpha_overall (running mean of the wall contacts) and the "
            "convention-free alphaA_overall (W/K) are written.")
    gap_tolerance: float = spec(0.01, ge=0, lt=0.5, doc=_gap_doc("particle's"))


@dataclass(frozen=True)
class LossConfig(Table):
    """``[heat.loss]``: lumped heat loss to the gas (weigler eq. [2.7], section 7.5)."""

    TABLE = "heat.loss"

    alphaA: float = spec(unit="W/K", ge=0, doc="(alpha A)_WK per particle (per real particle: "
                                               "a parcel of dem.coarse_grain = s loses s^3 "
                                               "times this).")


DRUM_WALL_OUTSIDE = ("flux", "gas", "temperature")


@dataclass(frozen=True)
class DrumWallConfig(Table):
    """``[heat.drum_wall]``: a drum wall with its own heat capacity, in segments turning with
    the drum (docs/models/drum-wall.md). Absent: the wall is the fixed ``drum.wall_temperature``."""

    TABLE = "heat.drum_wall"

    thickness: float = spec(unit="m", gt=0, le=0.5,
                            doc="Wall thickness s; the wall stores (s rho c_p) J/(m2 K) and "
                                "conducts lambda/s W/(m2 K) through its thickness.")
    material: str = spec("steel", choices=tuple(sorted(MATERIALS)),
                         doc="Wall material from the library (drumheat.materials).")
    density: Optional[float] = spec(None, unit="kg/m3", gt=0, doc="Overrides the material's.")
    heat_capacity: Optional[float] = spec(None, unit="J/(kg K)", gt=0,
                                          doc="Overrides the material's.")
    conductivity: Optional[float] = spec(None, unit="W/(m K)", gt=0,
                                         doc="Overrides the material's.")
    segments: int = spec(36, ge=1, le=3600,
                         doc="Number of wall segments around the circumference; they turn "
                             "with the drum (segment k spans polar angles [k, k + 1) x 360/"
                             "segments degrees from +x at t = 0). Each segment has one "
                             "temperature; its initial value is drum.wall_temperature.")
    outside: str = spec(choices=DRUM_WALL_OUTSIDE,
                        doc="How the wall is heated from outside: 'flux' (outer_flux, W/m2), "
                            "'gas' (a hot gas: outer_alpha and outer_temperature, in series "
                            "with the wall's lambda/s) or 'temperature' (a fixed outer surface "
                            "temperature outer_temperature, through the wall's lambda/s).")
    outer_flux: Optional[float] = spec(None, unit="W/m2",
                                       doc="Heat flux into the outer surface (outside = "
                                           "'flux'); negative cools.")
    outer_temperature: Optional[float] = spec(None, unit="K", gt=0,
                                              doc="Hot-gas temperature (outside = 'gas') or "
                                                  "outer surface temperature (outside = "
                                                  "'temperature').")
    outer_alpha: Optional[float] = spec(None, unit="W/(m2 K)", gt=0,
                                        doc="Heat-transfer coefficient hot gas -> outer surface "
                                            "(outside = 'gas').")
    inner_alpha: float = spec(0.0, unit="W/(m2 K)", ge=0,
                              doc="Heat-transfer coefficient wall -> free gas inside the drum "
                                  "(temperature gas.temperature), on the part of each segment "
                                  "the bed does not cover (covered: d^2 per touching particle, "
                                  "the wall_area of eq. [1.10]); 0: none.")


CONVECTION_CORRELATIONS = ("constant", "gnielinski", "gnielinski-staltner", "ranz-marshall",
                           "fluidized-bed", "gnielinski-kraychev")


@dataclass(frozen=True)
class ConvectionConfig(Table):
    """``[heat.convection]``: particle-gas convection on the whole sphere surface pi d^2.

    alpha from a correlation of drumheat.models.convection (staltner-slag-particle.md section
    5, fluidized-bed-exercise.md sections 2-5, kraychev-tube-bundle.md section 4).
    """

    TABLE = "heat.convection"

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
class RadiationSurface(Table):
    """``[[heat.radiation.surfaces]]``: one grey surface of the enclosure."""

    TABLE = "heat.radiation.surfaces.*"

    name: str = spec(doc="Surface name; for enclosure 'granulator' the four zones in order "
                         "'bed', 'slots', 'wall', 'outlet' (staltner-slag-particle.md section 1).")
    temperature: float = spec(unit="K", gt=0, doc="Surface temperature.")
    emissivity: float = spec(gt=0, le=1, doc="Grey emissivity.")


@dataclass(frozen=True)
class RadiationConfig(Table):
    """``[heat.radiation]``: grey radiation between each particle and an enclosure.

    q = eps_p sigma (T_s^4 - T_rad^4) on pi d^2 (staltner-slag-particle.md sections 4, 6).
    """

    TABLE = "heat.radiation"

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
class InternalConfig(Table):
    """``[heat.internal]``: radial shell conduction inside every particle.

    Each particle carries n shells (drumheat.thermal.shells, staltner-slag-particle.md sections
    2-4); the surface shell receives the surface flows of the other effects.
    """

    TABLE = "heat.internal"

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
class FrictionConfig(Table):
    """``[heat.friction]``: the mechanical energy the contacts dissipate (damping, sliding,
    rolling resistance) becomes heat in the two partners of each contact
    (drumheat.mechanics.dissipation, docs/models/friction-heat.md). Motion model 'dem'."""

    TABLE = "heat.friction"

    partition: str = spec("conductivity", choices=("conductivity", "half"),
                          doc="How a contact's heat is split: 'conductivity' gives each partner "
                              "k / (k_A + k_B) (Kratos ThermalDEM; the steady partition at an "
                              "interface of one temperature), 'half' half and half. Equal for "
                              "particles of one material.")
    wall_material: str = spec("steel", choices=tuple(sorted(MATERIALS)),
                              doc="Material of the walls, for the conductivity split; the "
                                  "walls' share of the heat leaves the particles (time-series "
                                  "column Q_friction_walls).")


@dataclass(frozen=True)
class HeatConfig(Table):
    """``[heat]``: the heat-transfer effects; an absent table is not simulated."""

    TABLE = "heat"

    contact: Optional[ContactConfig] = spec(None, doc="Particle-particle contact conduction.")
    wall: Optional[WallConfig] = spec(None, doc="Particle-wall contact conduction.")
    loss: Optional[LossConfig] = spec(None, doc="Heat loss to the gas.")
    convection: Optional[ConvectionConfig] = spec(None, doc="Particle-gas convection.")
    radiation: Optional[RadiationConfig] = spec(None, doc="Radiation to an enclosure.")
    internal: Optional[InternalConfig] = spec(None, doc="Conduction inside the particles "
                                                        "(radial shells).")
    drum_wall: Optional[DrumWallConfig] = spec(None, doc="A drum wall with its own heat "
                                                         "capacity (segments turning with the "
                                                         "drum), heated from outside.")
    friction: Optional[FrictionConfig] = spec(None, doc="Heat from friction and damping in the "
                                                        "contacts (motion model 'dem').")

    #: tables that are heat sources of the mechanics, not effects on the contact network
    SOURCES = ("friction",)

    def effects(self) -> tuple[str, ...]:
        """Names of the effects on the contact network this scene switches on (the heat
        sources of the mechanics, ``[heat.friction]``, are not among them)."""
        return tuple(f.name for f in dataclasses.fields(self)
                     if getattr(self, f.name) is not None and f.name not in self.SOURCES)


@dataclass(frozen=True)
class MotionConfig(Table):
    """``[motion]``: how the particles move."""

    TABLE = "motion"

    model: str = spec("static", choices=MOTION_MODEL_NAMES,
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
class GranulatorConfig(Table):
    """``[granulator]``: the dry slag granulator of staltner-slag-particle.md sections 1, 7, 10.

    Zones: bed disc (radius r2, z = 0), slotted cylinder (r2, height h3), water-cooled cone
    (height h4, inclined alpha4 to the horizontal), outlet disc (r5 = r2 - h4/tan alpha4).
    """

    TABLE = "granulator"

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
    # contact_mode "ghost" added for issue 20 (staltner-coffee branch): the thesis' literal
    # Phase-2 boundary, staltner-slag-particle.md section 3 digest note ("provide both").
    contact_mode: str = spec("surface", choices=("surface", "ghost"),
                             doc="Phase-2 wall-contact boundary (staltner-slag-particle.md "
                                 "section 3): 'surface' holds the surface node n at the contact "
                                 "temperature T_m (the digest's consistent reading); 'ghost' "
                                 "puts T_m in a node n+1 one cell outside the sphere and updates "
                                 "node n with the interior stencil [5.31]-[5.32] (the thesis' "
                                 "literal reading: a contact resistance of one cell). Both "
                                 "converge to the same contact time as the shells are refined, "
                                 "from below ('surface') and from above ('ghost').")
    segments: int = spec(20, ge=1, doc="Path segments per flight phase; the radiation sink "
                                       "temperature is taken at each segment's midpoint.")
    steps_per_phase: int = spec(400, ge=10, doc="Shell time steps per phase when "
                                                "heat.internal.dt is not given (Phase 2: per "
                                                "estimated contact time).")


@dataclass(frozen=True)
class DEMConfig(Table):
    """``[dem]``: soft-sphere mechanics of motion model 'dem' (drumheat.mechanics).

    Linear spring-dashpot normal force, Cundall-Strack tangential spring with Coulomb limit,
    rotation; weigler-thermal-dem.md sections 4-5 (Table 2-1, PFC settings).
    """

    TABLE = "dem"

    stiffness: Optional[float] = spec(None, unit="N/m", gt=0,
                                      doc="Normal (= tangential) stiffness k_n of particle "
                                          "contacts; default E A_p / d_p (weigler eq. [2.3]). "
                                          "A softer value allows a larger time step. The "
                                          "contacts that conduct include those within the "
                                          "conduction gap (heat.contact.gap_tolerance, "
                                          "heat.wall.gap_tolerance) and their conductance does "
                                          "not depend on the overlap, so softening changes the "
                                          "heat transfer only through the motion; with a gap "
                                          "tolerance 0 a softer contact also touches longer "
                                          "(docs/models/coupled-dem.md).")
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
                               doc="Mechanical time step; default the smaller of safety_factor "
                                   "x t_crit (t_crit = 2 sqrt(m_min / k_n), weigler eq. [2.1]) "
                                   "and the explicit limit of the tangential dashpots (0.079 "
                                   "t_crit at damping ratio 0.3, docs/models/dem-mechanics.md); "
                                   "a larger step than t_crit is refused, one above the dashpot "
                                   "limit warned about.")
    safety_factor: float = spec(
        0.1, gt=0, le=1,
        doc="dt = safety_factor x t_crit by default, or the dashpot limit where that is smaller "
            "(with tangential damping and friction it is: 0.079 t_crit at damping ratio 0.3, "
            "0.092 at restitution 0.5). Above the dashpot limit the contacts of resting and "
            "slowly moving particles chatter and slide where they should stick "
            "(docs/models/dem-mechanics.md, time step).")
    skin: Optional[float] = spec(None, unit="m", gt=0,
                                 doc="Neighbour-list skin; default half the largest radius.")
    contact_backend: str = spec(
        "auto", choices=("auto", "jax", "cpu"),
        doc="Contact kernel: 'cpu' the C++ contact loop (compiled on first use with the "
            "machine's C++ compiler and cached; single runs on the CPU), 'jax' the JAX kernel "
            "(every platform, ensembles), 'auto' the C++ loop where it can serve and JAX "
            "elsewhere. Same contact law, results equal to round-off (a flowing bed's "
            "trajectory then diverges like any chaotic flow). 'cpu' where it cannot serve "
            "falls back to JAX with one warning line; summary.json says which ran "
            "(contact_backend).")
    precision: str = spec("float64", choices=("float32", "float64", "mixed"),
                          doc="Floating-point type of the mechanics; temperatures are always "
                              "float64. float32 is quicker but keeps the positions in float32 "
                              "too, which resolves them only to about 1e-7 of the coordinate: "
                              "a warning says where that reaches the overlap under a "
                              "particle's own weight (long periodic slices). 'mixed' keeps "
                              "the positions in float64 and the rest in float32: the contact "
                              "law reads the periodic axis folded to the cross-section's size, "
                              "which removes that limit along it. summary.json gives the "
                              "figures (precision).")
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
    coarse_grain: float = spec(
        1.0, ge=1,
        doc="Coarse-graining factor s: each DEM parcel of diameter s d stands for s^3 real "
            "particles of the group (3D drums, motion model 'dem'; groups.*.count and "
            "diameter stay those of the real bed, the parcel count is round(count / s^3)). "
            "Mechanics scaled as Bierwisch et al. 2009 (same density, friction and "
            "restitution; stiffness x s), heat so that the bed keeps the fine bed's "
            "conductivity (alpha_pp / s on the parcel's area), wall contact coefficient per "
            "wall area (alpha_wp unchanged) and loss per unit mass ((alpha A)_WK x s^3). "
            "1 = no coarse-graining (docs/models/coarse-graining.md).")
    gravity: float = spec(9.81, unit="m/s2", ge=0,
                          doc="Gravity along -y. The thesis' 2D drum was tilted 45 degrees, "
                              "which would give 9.81 sin 45 = 6.94 in the plane; the source does "
                              "not say which it used (weigler-thermal-dem.md section 12.19).")


    @property
    def replayed_cycle(self) -> Optional[float]:
        """Seconds of the recording replayed cyclically after ``replay_after``:
        ``replay_cycle``, by default the second half of the recording (None without replay)."""
        if self.replay_after is None:
            return None
        return self.replay_cycle if self.replay_cycle is not None else 0.5 * self.replay_after

@dataclass(frozen=True)
class EntranceConfig(Table):
    """``[channel.entrance]``: the jet from the pick-up slit at the foot of the channel.

    kraychev-tube-bundle.md sections 1, 2: the primary gas enters through an 8 mm slit (up to
    37 m/s) and picks the solids up; the channel's entrance ("development") length gives the
    high alpha_2. The whole primary gas passes the slit, so its velocity is ``gas_velocity x
    gap / slit_width`` (16.5 x 18/8 = 37.1 m/s, the digest's 37 m/s). Above the slit the gas
    velocity that the particles see follows the centreline of a plane free jet, constant over
    the potential core ``x_c = decay_constant**2 slit_width`` and ``u_slit (x_c/y)**0.5``
    beyond (Rajaratnam 1976), until it meets the channel's mean velocity at the entrance
    length ``x_c (gap/slit_width)**2`` (:func:`drumheat.motion.pneumatic.jet_velocity_factor`).
    An absent table: no entrance, the mean gas velocity everywhere.
    """

    TABLE = "channel.entrance"

    slit_width: float = spec(0.008, unit="m", gt=0,
                             doc="Width of the slit the whole gas flow enters through (8 mm, "
                                 "kraychev-tube-bundle.md section 2); at most channel.gap "
                                 "(slit_width = gap: no jet).")
    decay_constant: float = spec(2.47, ge=0, le=5,
                                 doc="K of the plane free jet's centreline decay u_m/u_slit = "
                                     "K (y/slit_width)^-1/2 (Rajaratnam 1976, Turbulent Jets, "
                                     "ch. 2: 3.50 with the half-width, 2.47 with the full slit "
                                     "width; Albertson et al. 1950: 2.28); potential core "
                                     "K^2 slit_width; 0: no entrance section.")


@dataclass(frozen=True)
class ChannelConfig(Table):
    """``[channel]``: vertical pneumatic channel of motion model 'pneumatic'.

    Kraychev digest (kraychev-tube-bundle.md) sections 1, 2, 6: particles carried upward by
    gas in plug flow; y up (gas and solids), x across the gap between two walls, z along the
    channel length (the simulated slice of depth ``depth`` is periodic in z).
    """

    TABLE = "channel"

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
    entrance: Optional[EntranceConfig] = spec(None, doc="The jet from the pick-up slit at the "
                                                        "channel's foot; absent: none (the "
                                                        "mean gas velocity everywhere).")

    def check(self, prefix: str, scene_name: str | None) -> None:
        """The slit is no wider than the channel (the jet decays to the mean velocity)."""
        if self.entrance is not None and self.entrance.slit_width > self.gap:
            raise SceneError(f"{prefix}.entrance.slit_width", self.entrance.slit_width,
                             f"must be at most channel.gap = {self.gap:g} m (the whole gas flow "
                             "enters through the slit)", scene_name)


@dataclass(frozen=True)
class HopperConfig(Table):
    """``[hopper]``: hopper with a staggered bundle of horizontal tubes (motion 'moving_bed').

    kraychev-tube-bundle.md sections 1, 2, 7: the solids sink through the bundle and leave
    through a bottom slit of width S; here they re-enter at the top (recycling). Coordinates:
    x across the bundle (hopper axis x = 0), y up (y = 0 at the slit lips), z along the tubes
    (a 3D slice of length ``depth``, periodic in z).
    """

    TABLE = "hopper"

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
class ReplayConfig(Table):
    """``[replay]``: thermal-only replay of a recorded contact network (motion 'replay')."""

    TABLE = "replay"

    file: str = spec(doc="contacts.npz written by a 'dem' run with dem.record_interval; "
                         "relative to the scene file.")
    cyclic: bool = spec(True, doc="Replay the recording over and over when the scene is longer "
                                  "than it; at each restart the temperatures are carried over "
                                  "to the particles whose start positions best match the end "
                                  "positions.")


@dataclass(frozen=True)
class PackingConfig(Table):
    """``[packing]``: how the initial packing is made and how contacts are found in it."""

    TABLE = "packing"

    method: str = spec("deposition", choices=("deposition", "pour", "file"),
                       doc="'deposition': particles dropped one by one at random positions roll "
                           "down to a stable rest (drumheat.mechanics.deposition, 2D); 'pour': "
                           "inserted above the bed and settled by DEM under gravity "
                           "(drumheat.mechanics.pour; needs [dem]); 'file': positions from an "
                           ".npz file.")
    arrangement: str = spec("layers", choices=("layers", "mixed"),
                            doc="'layers': groups poured one after the other (first group at "
                                "the bottom); 'mixed': pouring order shuffled.")
    contact_tolerance: Optional[float] = spec(
        None, ge=0, lt=0.5,
        doc="Deprecated: the conduction gap is heat.contact.gap_tolerance and "
            "heat.wall.gap_tolerance, the same for every motion model. When given, it replaces "
            "both (with a warning).")
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
class Scene(Table):
    """A complete, validated scene. Build with :func:`load_scene` or :func:`scene_from_dict`."""

    TABLE = ""

    name: str = spec(doc="Scene name; default result folder results/<name>.")
    run: RunConfig = spec(doc="Duration, output and integrator.")
    drum: Optional[DrumConfig] = spec(
        None, doc="The drum; required for the motion models " + ", ".join(DRUM_MOTION_MODELS)
        + ".", required_when=lambda s: _motion_name(s.motion) in DRUM_MOTION_MODELS)
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

    def __post_init__(self):
        with building("", self.name if isinstance(self.name, str) else None):
            super().__post_init__()

    def check(self, prefix: str, scene_name: str | None) -> None:
        """The cross-table rules (:mod:`drumheat.scene.rules`)."""
        check_scene(self)

    # -- convenience ---------------------------------------------------------------------
    @property
    def n_particles(self) -> int:
        """Number of particles of all groups (the real particles; with coarse-graining the
        DEM simulates :attr:`n_parcels` parcels that stand for them)."""
        return sum(g.count for g in self.groups)

    @property
    def coarse_grain(self) -> float:
        """The coarse-graining factor s of ``[dem] coarse_grain`` (1.0 without ``[dem]``)."""
        return 1.0 if self.dem is None else float(self.dem.coarse_grain)

    def parcel_counts(self) -> tuple[int, ...]:
        """Number of simulated particles (parcels) of each group: ``round(count / s^3)``
        (docs/models/coarse-graining.md); the counts themselves when s = 1."""
        s = self.coarse_grain
        if s == 1.0:
            return tuple(g.count for g in self.groups)
        return tuple(int(round(g.count / s**3)) for g in self.groups)

    @property
    def n_parcels(self) -> int:
        """Number of simulated particles (parcels) of all groups; :attr:`n_particles` when
        ``dem.coarse_grain`` = 1."""
        return sum(self.parcel_counts())

    def to_dict(self) -> dict:
        """The scene as a plain dict (what a TOML file holds); unset optional keys omitted."""
        return to_dict(self)

    def to_toml(self) -> str:
        """The scene as TOML text that :func:`~drumheat.scene.load_scene` reads back to an
        equal scene."""
        import tomli_w

        return tomli_w.dumps(self.to_dict())

    def save(self, path) -> Path:
        """Write the scene as a TOML scene file; returns the path."""
        path = Path(path)
        path.write_text(self.to_toml())
        return path

    def get(self, path: str) -> Any:
        """Value at a dotted path, e.g. ``scene.get("groups.0.temperature")``."""
        obj: Any = self
        for part in path.split("."):
            obj = obj[int(part)] if isinstance(obj, tuple) else getattr(obj, part)
        return obj

    def replace(self, overrides: dict[str, Any] | None = None, /, **changes) -> "Scene":
        """A new, checked scene with some values changed.

        Keys are dotted paths, given as a dict (``scene.replace({"heat.contact.alpha":
        120.0, "groups.0.temperature": 300.0})``) or, for top-level keys, as keyword
        arguments (``scene.replace(name="mine")``). A value None removes the key, e.g.
        switches an effect table off (see :meth:`without`).
        """
        raw = self.to_dict()
        for key, value in {**(overrides or {}), **changes}.items():
            set_path(raw, key, value, self.name)
        return build_table(Scene, raw, "", raw.get("name") if isinstance(raw.get("name"), str)
                           else None, source_path=self.source_path)

    def with_overrides(self, overrides: dict[str, Any]) -> "Scene":
        """A new validated scene with dotted-path overrides applied (:meth:`replace`)."""
        return self.replace(overrides)

    def without(self, *keys: str) -> "Scene":
        """A new scene without the given tables or keys, e.g. ``scene.without(
        "heat.radiation")`` (the effect is then not simulated)."""
        return self.replace({k: None for k in keys})


def iter_keys(cls=Scene, prefix: str = ""):
    """Yield ``(dotted_key, type_name, unit, default, allowed, doc)`` for every scene key
    (of ``cls``, default the whole :class:`Scene`); ``groups.*`` stands for every group.
    Used to generate the scene-file reference."""
    return iter_table_keys(cls, prefix)
