"""The one bridge from a scene to arrays: particles, effects, walls, contact parameters, packings.

Every other layer below the motion models works on arrays and explicit arguments; this module
is the only one that reads a :class:`~drumheat.scene.Scene` to build them (docs/architecture.md).
The motion models call it to set themselves up.

Values that a user may fit are read through a ``value(dotted_key)`` getter so that a calibration
can pass traced numbers in place of the scene's (:func:`scene_values`); everything else is read
from the scene tables directly.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.devices import to_device
from drumheat.geometry.hopper import HopperGeometry, hopper_walls
from drumheat.geometry.walls import DrumShell, InnerCylinder, Plane, RadialPlate
from drumheat.materials import gas as gas_library
from drumheat.materials import material
from drumheat.mechanics import ContactParams, Particles, contact_params
from drumheat.mechanics import make_particles as mechanical_particles
from drumheat.mechanics.deposition import Packing, deposit_2d
from drumheat.mechanics.dissipation import FrictionHeat
from drumheat.models.soft_sphere import default_time_step
from drumheat.scene import Scene, SceneError
from drumheat.scene.rules import dem_critical_time_step, dem_stiffness, dem_time_step
from drumheat.thermal.effect import DrumGeometry, EffectContext, GasState, PlugFlow, TableValues
from drumheat.thermal.model import ThermalModel, make_thermal_model
from drumheat.thermal.particles import ThermalParticles

#: A getter ``value(dotted_key)`` returning a (possibly traced) scene value.
ValueFn = Callable[[str], Any]

# ---------------------------------------------------------------------------------------------
# values and particles
# ---------------------------------------------------------------------------------------------


def scene_values(scene: Scene, params: dict[str, Any] | None = None) -> ValueFn:
    """Getter of scene values by dotted key, with ``params`` taking precedence.

    ``params`` may hold JAX tracers (for gradients); missing keys fall back to the scene.
    """
    params = params or {}

    def value(key: str):
        return params[key] if key in params else scene.get(key)

    value.params = params
    return value


def group_index(scene: Scene) -> np.ndarray:
    """Group index of every simulated particle, shape (N,), particles numbered group by group;
    with ``dem.coarse_grain = s`` > 1 these are the parcels (:meth:`Scene.parcel_counts`)."""
    return np.concatenate([np.full(c, k, dtype=np.int32)
                           for k, c in enumerate(scene.parcel_counts())])


def diameters(scene: Scene) -> np.ndarray:
    """Nominal diameter of every simulated particle, m, shape (N,); with ``dem.coarse_grain =
    s`` > 1 the parcels' ``s d`` (docs/models/coarse-graining.md)."""
    cg = scene.coarse_grain
    return np.concatenate([np.full(c, cg * g.diameter)
                           for g, c in zip(scene.groups, scene.parcel_counts())])


def mean_real_diameter(scene: Scene) -> float:
    """Number-mean diameter of the real particles, m (Schluender's coefficients of a bed; the
    same as the mean of :func:`diameters` without coarse-graining)."""
    if scene.coarse_grain == 1.0:
        return float(np.mean(diameters(scene)))
    return float(sum(g.count * g.diameter for g in scene.groups) / scene.n_particles)


def group_property(scene: Scene, value: ValueFn, k: int, prop: str):
    """A material property of group ``k``: the scene's override or the library value."""
    g = scene.groups[k]
    if getattr(g, prop) is not None:
        return value(f"groups.{k}.{prop}")
    return getattr(material(g.material), prop)


def _per_particle(values, group):
    """The per-group ``values`` (a list, one per group) of every particle, shape (N,) float:
    on the host where no value is traced (eager jnp operations would each compile a program,
    :func:`drumheat.devices.to_device`), else in jnp (a fit's traced parameters)."""
    if any(isinstance(v, jax.core.Tracer) for v in values):
        return jnp.stack([jnp.asarray(v, float) for v in values])[group]
    return np.stack([np.asarray(v, float) for v in values])[group]


def particle_property(scene: Scene, value: ValueFn, prop: str):
    """A material property of every particle, shape (N,) (:func:`group_property` per group)."""
    return to_device(_per_particle([group_property(scene, value, k, prop)
                                    for k in range(len(scene.groups))], group_index(scene)))


def thermal_particles(scene: Scene, value: ValueFn) -> ThermalParticles:
    """Particles as heat reservoirs (sphere masses, weigler-thermal-dem.md section 4); with
    ``dem.coarse_grain = s`` > 1 the parcels, spheres of diameter ``s d`` and the particles'
    density, i.e. mass and heat capacity ``s^3`` times a particle's (the ``s^3`` particles a
    parcel stands for; docs/models/coarse-graining.md)."""
    group = group_index(scene)

    def per_group(f):
        return _per_particle([f(k) for k in range(len(scene.groups))], group)

    diameter = per_group(lambda k: value(f"groups.{k}.diameter"))
    if scene.coarse_grain != 1.0:
        diameter = scene.coarse_grain * diameter
    density = per_group(lambda k: group_property(scene, value, k, "density"))
    c = per_group(lambda k: group_property(scene, value, k, "heat_capacity"))
    return ThermalParticles.spheres(diameter, density, c)


def initial_temperatures(scene: Scene, value: ValueFn):
    """Initial temperature of every particle, K, shape (N,)."""
    return to_device(_per_particle([value(f"groups.{k}.temperature")
                                    for k in range(len(scene.groups))], group_index(scene)))


def output_times(scene: Scene) -> np.ndarray:
    """Output times 0, dt_out, 2 dt_out, ..., duration (the last one always included)."""
    run = scene.run
    n = int(np.floor(run.duration / run.output_interval + 1e-9))
    t = np.arange(n + 1) * run.output_interval
    if run.duration - t[-1] > 1e-9 * run.duration:
        t = np.append(t, run.duration)
    return t


def temperature_bounds(scene: Scene) -> tuple[float, float]:
    """Lowest and highest temperature a run of ``scene`` can reach, K.

    By the maximum principle every temperature stays between the extremes of the initial
    temperatures and of all outside reservoirs (gas, walls, radiating surfaces; a drum wall's
    outer temperature). A drum wall heated by a prescribed flux q_o has no such bound: each
    segment can rise by at most ``|q_o| duration / (s rho c_p)`` above it (all the flux into
    its own capacity, nothing given on). Used to bound
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
    if scene.hopper is not None:
        Ts += [scene.hopper.tube_temperature, scene.hopper.inlet_temperature]
    w = scene.heat.drum_wall
    if w is None:
        return float(min(Ts)), float(max(Ts))
    if w.outer_temperature is not None:
        Ts.append(w.outer_temperature)
    lo, hi = float(min(Ts)), float(max(Ts))
    if w.outside == "flux":  # at most the whole flux into one segment's own capacity
        lib = material(w.material)
        rho = w.density if w.density is not None else lib.density
        c = w.heat_capacity if w.heat_capacity is not None else lib.heat_capacity
        rise = abs(w.outer_flux) * scene.run.duration / (w.thickness * rho * c)
        lo, hi = (lo - rise, hi) if w.outer_flux < 0 else (lo, hi + rise)
    return lo, hi


# ---------------------------------------------------------------------------------------------
# the thermal model
# ---------------------------------------------------------------------------------------------


def gas_state(scene: Scene, value: ValueFn) -> GasState | None:
    """The ``[gas]`` table with the library's properties filled in, or None."""
    g = scene.gas
    if g is None:
        return None
    lib = gas_library(g.material)
    given = lambda key: getattr(g, key) is not None  # noqa: E731
    return GasState(
        temperature=value("gas.temperature"), pressure=value("gas.pressure"),
        conductivity=value("gas.conductivity") if given("conductivity") else lib.conductivity,
        heat_capacity=value("gas.heat_capacity") if given("heat_capacity") else lib.heat_capacity,
        molar_mass=lib.molar_mass, accommodation_constant=lib.accommodation_constant,
        density=value("gas.density") if given("density") else None,
        kinematic_viscosity=(value("gas.kinematic_viscosity") if given("kinematic_viscosity")
                             else None))


def contact_gas(scene: Scene, value: ValueFn) -> GasState:
    """The gas of Schluender's contact model: the scene's, else the thesis' Table 8-1
    conditions (air at 30 degC and 1 atm, weigler-thermal-dem.md App. A3)."""
    g = gas_state(scene, value)
    if g is not None:
        return g
    air = gas_library("air")
    return GasState(303.15, 101325.0, air.conductivity, air.heat_capacity, air.molar_mass,
                    air.accommodation_constant)


def drum_wall_temperatures(scene: Scene, value: ValueFn):
    """``(temperatures, surface names)`` of the drum's heated surfaces in wall-id order; the
    names are None for a plain drum (all heat booked as ``wall``)."""
    surfaces = scene.drum.heated_surfaces() if scene.drum is not None else ()
    if not surfaces:
        return None, None
    temps = to_device([value(key) for _, key in surfaces], float)
    names = None if not scene.drum.has_internals else tuple(s for s, _ in surfaces)
    return temps, names


def heat_tables(scene: Scene, params: dict | None = None) -> dict[str, TableValues]:
    """``{name: TableValues}`` of the scene's ``[heat.<name>]`` tables, in scene order."""
    return {name: TableValues(getattr(scene.heat, name), f"heat.{name}", params)
            for name in scene.heat.effects()}


def thermal_model(scene: Scene, params: dict | None = None, *, wall_temperatures=None,
                  wall_surfaces=None, plug_flow: PlugFlow | None = None, gas_velocity=None,
                  sink_temperature=None) -> tuple[ThermalModel, Any]:
    """The thermal model of a scene and the initial particle temperatures (K, (N,)).

    Parameters
    ----------
    scene : Scene
    params : dict, optional
        Dotted keys with (possibly traced) values replacing the scene's.
    wall_temperatures, wall_surfaces : optional
        Temperature of each wall id (K) and their account names; default the drum's heated
        surfaces (:func:`drum_wall_temperatures`).
    plug_flow : PlugFlow, optional
        The gas passes the bed in plug flow (motion model ``fluidized``).
    gas_velocity, sink_temperature : optional
        The relative gas velocity (m/s) and the radiation enclosure temperature (K) where the
        motion model sets them (``granulator``).
    """
    value = scene_values(scene, params)
    particles = thermal_particles(scene, value)
    if wall_temperatures is None:
        wall_temperatures, wall_surfaces = drum_wall_temperatures(scene, value)
    ctx = EffectContext(
        particles=particles,
        particle_property=lambda prop: particle_property(scene, value, prop),
        gas=gas_state(scene, value), contact_gas=contact_gas(scene, value),
        mean_diameter=mean_real_diameter(scene), coarse_grain=scene.coarse_grain,
        wall_temperatures=wall_temperatures, wall_surfaces=wall_surfaces,
        temperature_bounds=temperature_bounds(scene), duration=value("run.duration"),
        gas_velocity=gas_velocity, sink_temperature=sink_temperature, plug_flow=plug_flow,
        density_given=any(g.density is not None for g in scene.groups), name=scene.name,
        drum=drum_geometry(scene) if scene.heat.drum_wall is not None else None)
    return make_thermal_model(heat_tables(scene, params), ctx), initial_temperatures(scene, value)


def drum_geometry(scene: Scene) -> DrumGeometry:
    """The drum as the drum wall's segments see it (``[heat.drum_wall]``): radius, the depth a
    segment spans (3D: ``drum.depth``; 2D: the monolayer, the number-mean particle diameter)
    and rpm."""
    d = scene.drum
    depth = d.depth if scene.dim == 3 else float(np.mean(diameters(scene)))
    return DrumGeometry(radius=0.5 * d.diameter, depth=float(depth), rpm=float(d.rpm))


# ---------------------------------------------------------------------------------------------
# walls
# ---------------------------------------------------------------------------------------------


def drum_walls(scene: Scene) -> list:
    """The walls of the scene's drum: the shell, then the inner cylinder, then the plates.

    All rotate with ``drum.rpm`` about the axis. Plate ``j`` lies at the polar angle
    ``plate_phase - j 360/sections`` (degrees, counter-clockwise from +x) at t = 0, from the
    inner cylinder (or the axis) to the shell. Section ``j`` lies between plates ``j`` and
    ``j + 1``: with the drum turning clockwise (rpm < 0) plate ``j`` is the section's plate 1
    (``B1C1``) and plate ``j + 1`` its plate 2 of herz-sectional-drum.md section 1, and the
    section's rotation angle is ``delta_j = 180 - plate angle of j`` (eq. 17).

    Every surface that carries a temperature gets the wall id of its place in
    ``drum.heated_surfaces()``, so the wall effect books its heat separately; a surface without
    a temperature exchanges no heat (its wall id is irrelevant and set to 0).
    """
    d = scene.drum
    R = 0.5 * d.diameter
    ids = {name: k for k, (name, _) in enumerate(d.heated_surfaces())}
    shell_id = ids.get("shell", ids.get("wall", 0))
    walls = [DrumShell(R, rpm=d.rpm, temperature=d.wall_temperature, wall_id=shell_id)]
    R2 = 0.5 * (d.inner_diameter or 0.0)
    if R2 > 0:
        walls.append(InnerCylinder(R2, rpm=d.rpm, temperature=d.inner_temperature,
                                   wall_id=ids.get("inner", 0)))
    n_sec = d.sections or 0
    phase0 = 180.0 if d.plate_phase is None else d.plate_phase
    for j in range(n_sec):
        walls.append(RadialPlate(R2, R, phase=math.radians(phase0 - j * 360.0 / n_sec),
                                 rpm=d.rpm, thickness=d.plate_thickness or 0.0,
                                 temperature=d.plate_temperature, wall_id=ids.get("plates", 0)))
    return walls


def hopper_geometry(scene: Scene) -> HopperGeometry:
    """The hopper slice of ``[hopper]`` (:func:`drumheat.geometry.hopper.hopper_walls`)."""
    return hopper_walls(scene.hopper)


def channel_walls(scene: Scene) -> tuple:
    """The two walls of the pneumatic channel of ``[channel]``, at x = 0 and x = gap."""
    gap = scene.channel.gap
    return (Plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), wall_id=0),
            Plane((gap, 0.0, 0.0), (-1.0, 0.0, 0.0), wall_id=1))


# ---------------------------------------------------------------------------------------------
# the DEM
# ---------------------------------------------------------------------------------------------


def contact_parameters(scene: Scene) -> tuple[ContactParams, float]:
    """Contact parameters of the ``[dem]`` table and the normal stiffness k_n, N/m.

    Stiffness: :func:`drumheat.scene.rules.dem_stiffness` (default ``E A_p / d_p`` of the
    smallest particle with the softest material, weigler eq. [2.3]; times ``dem.coarse_grain``
    for parcels). Friction, rolling friction, restitution and damping ratio are the fine
    bed's: dimensionless, kept by the coarse-graining (Bierwisch et al. 2009).
    """
    cfg = scene.dem
    k_n, k_wall = dem_stiffness(scene)  # the parcels' where coarse-grained
    damping = {}
    if cfg.restitution is not None:
        damping = dict(restitution=cfg.restitution)
    elif cfg.damping_ratio is not None:
        damping = dict(damping_ratio=cfg.damping_ratio)
    params = contact_params(k_n, kn_wall=k_wall, friction=cfg.friction,
                            wall_friction=cfg.wall_friction,
                            rolling_friction=cfg.rolling_friction, **damping)
    return params, k_n


class DEMSetup(NamedTuple):
    """What every DEM-based motion model needs from the scene (``[dem]``, groups).

    particles: mechanical particles (radius, mass, inertia, group); params: contact tables;
    k_n: normal stiffness, N/m; t_crit: critical step, s; dt: the step asked for (``dem.dt``,
    else the smaller of ``safety_factor x t_crit`` and the explicit limit of the tangential
    dashpots, :meth:`ContactParams.dashpot_time_step`), s, before a motion model fits it to
    its intervals (:func:`fit_time_step`); dt_origin: which of these set it; dtype of the
    mechanics and position_dtype of the stored positions (``dem.precision``: float64 both,
    float32 both, or mixed: float32 and float64); gravity vector, m/s2; density (N,), kg/m3.
    """

    particles: Particles
    params: ContactParams
    k_n: float
    t_crit: float
    dt: float
    dt_origin: str
    dtype: Any
    gravity: np.ndarray
    density: np.ndarray
    conduction_gap: tuple[float, float]
    position_dtype: Any


def dem_setup(scene: Scene) -> DEMSetup:
    """The :class:`DEMSetup` of a scene with ``[dem]``."""
    cfg = scene.dem
    value = scene_values(scene)
    group = group_index(scene)
    density = np.array([float(group_property(scene, value, k, "density"))
                        for k in range(len(scene.groups))])[group]
    d = diameters(scene)
    params, k_n = contact_parameters(scene)
    t_crit = dem_critical_time_step(scene)
    gravity = np.zeros(scene.dim)
    gravity[1] = -cfg.gravity
    particles = mechanical_particles(0.5 * d, density, group=group)
    dt, dt_origin = dem_time_step(scene), "dem.dt"
    if dt is None:
        dt, by_dashpot = default_time_step(
            t_crit, cfg.safety_factor,
            params.dashpot_time_step(float(np.min(np.asarray(particles.mass)))))
        dt_origin = ("the explicit limit of the tangential dashpots" if by_dashpot
                     else "dem.safety_factor x t_crit")
    return DEMSetup(
        particles=particles, params=params, k_n=k_n, t_crit=t_crit, dt=dt, dt_origin=dt_origin,
        dtype=jnp.float64 if cfg.precision == "float64" else jnp.float32, gravity=gravity,
        density=density, conduction_gap=conduction_gaps(scene),
        position_dtype=jnp.float32 if cfg.precision == "float32" else jnp.float64)


def friction_heat(scene: Scene) -> FrictionHeat | None:
    """The :class:`~drumheat.mechanics.dissipation.FrictionHeat` of ``[heat.friction]``
    (None without the table): each particle's conductivity (its group's material or override)
    and the walls' (``wall_material``) for partition ``"conductivity"``, none for ``"half"``."""
    cfg = scene.heat.friction
    if cfg is None:
        return None
    if cfg.partition == "half":
        return FrictionHeat()
    value = scene_values(scene)
    return FrictionHeat(conductivity=np.asarray(particle_property(scene, value, "conductivity")),
                        wall_conductivity=float(material(cfg.wall_material).conductivity))


def conduction_gaps(scene: Scene) -> tuple[float, float]:
    """``(particle-particle, particle-wall)`` conduction gap tolerances of a scene, fractions of
    the (smaller) particle diameter: the contacts that conduct heat, the same for every motion
    model (``[heat.contact]`` / ``[heat.wall]`` ``gap_tolerance``; a table the scene leaves out
    has its default). The deprecated ``packing.contact_tolerance`` replaces both when given."""
    from drumheat.scene.tables import ContactConfig, WallConfig

    if scene.packing.contact_tolerance is not None:
        import warnings

        warnings.warn("packing.contact_tolerance is deprecated: use heat.contact.gap_tolerance "
                      "and heat.wall.gap_tolerance (the conduction gap of every motion model)",
                      DeprecationWarning, stacklevel=2)
        tol = float(scene.packing.contact_tolerance)
        return tol, tol
    pp = (scene.heat.contact or ContactConfig).gap_tolerance
    pw = (scene.heat.wall or WallConfig).gap_tolerance
    return float(pp), float(pw)


def fit_time_step(dt: float, interval: float) -> tuple[float, int]:
    """The largest step at most ``dt`` that divides ``interval`` into a whole number of steps:
    ``(step, steps per interval)``."""
    steps = max(1, math.ceil(interval / dt - 1e-9))
    return interval / steps, steps


# ---------------------------------------------------------------------------------------------
# packings
# ---------------------------------------------------------------------------------------------


def resolve_path(scene: Scene, path: str) -> Path:
    """A path of the scene (packing or recording file): relative to the scene file."""
    p = Path(path)
    if not p.is_absolute() and scene.source_path:
        p = Path(scene.source_path).parent / p
    return p


def initial_packing(scene: Scene) -> Packing:
    """The scene's initial packing: geometric deposition (2D) or an ``.npz`` file."""
    group = group_index(scene)
    diameter = diameters(scene)
    if scene.packing.method == "file":
        path = resolve_path(scene, scene.packing.file)
        if not path.exists():
            raise SceneError("packing.file", scene.packing.file, "no such file", scene.name)
        packing = Packing.load(path)
        if packing.position.shape != (len(group), scene.dim):
            raise SceneError("packing.file", scene.packing.file,
                             f"holds {packing.position.shape[0]} particles in "
                             f"{packing.position.shape[1]}D; the scene has {len(group)} in "
                             f"{scene.dim}D", scene.name)
        return Packing(packing.position, diameter, group)
    try:
        return deposit_2d(diameter, group, scene.drum.diameter, seed=scene.run.seed,
                          arrangement=scene.packing.arrangement)
    except ValueError as err:
        raise SceneError("groups", f"{scene.n_particles} particles", f"the geometric "
                         f"deposition could not place them in the drum ({err}); fewer or "
                         "smaller particles, a larger drum, or packing.method = 'pour'",
                         scene.name) from None


def drum_packing(scene: Scene, setup: DEMSetup, walls, periodic_length=None) -> np.ndarray:
    """Initial positions of a DEM drum bed: pouring (DEM settling; a drum with radial plates
    fills every section equally), deposition (2D) or a file."""
    if scene.packing.method != "pour":
        return np.asarray(initial_packing(scene).position, float)
    from drumheat.mechanics.pour import pour, pour_sections

    radius = 0.5 * diameters(scene)
    density = np.asarray(setup.particles.mass) / (4 / 3 * np.pi * radius**3)
    common = dict(dim=scene.dim, group=group_index(scene),
                  layered=scene.packing.arrangement == "layers",
                  periodic_length=periodic_length, gravity=setup.gravity, seed=scene.run.seed,
                  dtype=setup.position_dtype)  # mixed pours in float64: a pour is no run
    d = scene.drum
    if d.sections:
        pk = pour_sections(radius, density, walls, setup.params, n_sections=d.sections,
                           phase=math.radians(180.0 if d.plate_phase is None else d.plate_phase),
                           safety_factor=scene.dem.safety_factor,
                           surface_angle=scene.packing.surface_angle or 0.0, **common)
    else:
        pk = pour(radius, density, walls, setup.params, **common)
    return np.asarray(pk.position, float)
