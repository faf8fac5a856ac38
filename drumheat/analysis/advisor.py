"""Effect advisor: how large is each heat-transfer effect in a scene? (``drumheat explain``)

For the scene's conditions at the start of a run, every effect gets a conductance per particle
``G`` (W/K), a driving temperature difference ``dT`` (K) and so a heat flow ``G dT`` (W per
particle); sizes are shown relative to the largest. Effects the scene leaves out are estimated
too, so the advisor can say which included effects are negligible and which absent ones are not:

* contact conduction: ``alpha_pp pi d^2/4`` times the mean number of contacts per particle (from
  the scene's packing for static beds, else 4 in 2D / 6 in 3D), ``dT`` the spread of the
  initial temperatures (weigler-thermal-dem.md eq. [2.7]); absent tables estimated with the
  Schluender alpha_pp (weigler eqs. [2.9], [2.10]);
* wall contact: ``alpha_wp pi d^2/4`` times the fraction of particles touching the wall, ``dT =
  T_wall - T``; for the granulator droplet the Phase-2 contact (staltner [3.10]-[3.11]) with
  the mean coefficient ``2 b_eff / sqrt(pi t_2)`` of two semi-infinite bodies (weigler [1.12]);
* heat loss: ``(alpha A)_WK``, ``dT = T_gas - T``;
* convection: ``alpha pi d^2`` from the scene's correlation; absent: the conduction limit
  Nu = 2 (``alpha = 2 lambda_gas / d``, kraychev (3-3)), a lower bound;
* radiation: ``h_r pi d^2``, ``h_r = eps sigma (T^2 + T_r^2)(T + T_r)`` (staltner digest
  section 4); absent: a black surrounding at the wall (else gas) temperature;
* an external effect that is small at the start but acts over the whole run (``G t_run / (m c)
  >= 0.05``, it moves the bed mean by more than 5 % of its driving difference) is kept;
* heat from friction (a source, not a conductance): in steady rotation the drive's work is all
  dissipated in the bed, ``P = omega M g x_c`` with ``x_c = r_c sin(theta)`` the horizontal
  offset of the bed's centre of mass (``r_c = 4 R sin^3(eps) / (3 (2 eps - sin 2 eps))``, the
  centroid of the circular segment of the fill; ``theta`` the dynamic angle of repose:
  ``packing.surface_angle`` if given, else ``atan(dem.friction)`` for a DEM bed, else 30 deg);
  docs/models/friction-heat.md compares it with the DEM's heat;
* conduction inside the particles: the Biot number ``Bi = h R / lambda_p`` with ``h`` the sum
  of all surface coefficients of the included effects (the largest case: contacts and walls on
  their share of the surface) -- lumped particles are fine for Bi < 0.1.

The verdicts: an included effect below 1 % of the largest "could be dropped"; an absent one
above 5 % "should be added"; ``[heat.loss]`` lumps convection and radiation, so those two are
"covered" when it is present.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import jax.numpy as jnp
import numpy as np

from drumheat.assemble import contact_gas, scene_values
from drumheat.geometry.hopper import hopper_walls
from drumheat.materials import gas, material
from drumheat.models import schluender
from drumheat.models.granulator import wall_heat_per_mass
from drumheat.models.sectional_drum import cycle_means
from drumheat.models.sphere_conduction import effusivity
from drumheat.motion import make_motion
from drumheat.scene import Scene, SceneError, load_scene
from drumheat.thermal.convection import PlugFlowConvection

SIGMA = 5.670374419e-8


@dataclass
class Term:
    """One effect's size."""

    name: str
    table: str
    included: bool
    conductance: float  # W/K per particle
    dT: float  # K
    note: str = ""
    relative: float = 0.0
    verdict: str = ""
    power: float | None = None  # W per particle, for a source (no conductance, no dT)
    rise: float = 0.0  # K, a source's warming of the bed over the run

    @property
    def heat_flow(self) -> float:
        return abs(self.power) if self.power is not None else abs(self.conductance * self.dT)


@dataclass
class Advice:
    """The advisor's findings for one scene."""

    scene: str
    conditions: str
    terms: list = field(default_factory=list)
    biot: float = 0.0
    biot_verdict: str = ""

    def text(self) -> str:
        lines = [f"drumheat explain: {self.scene}", self.conditions, ""]
        head = (f"{'effect':<22} {'table':<18} {'in scene':<8} {'G / (W/K)':>10} "
                f"{'dT / K':>8} {'G dT / W':>10} {'relative':>9}  verdict")
        lines += [head, "-" * len(head)]
        for t in self.terms:
            G, dT = (("-", "-") if t.power is not None else
                     (f"{t.conductance:.3g}", f"{t.dT:.3g}"))
            lines.append(f"{t.name:<22} {t.table:<18} {'yes' if t.included else 'no':<8} "
                         f"{G:>10} {dT:>8} {t.heat_flow:>10.3g} "
                         f"{t.relative:>9.2%}  {t.verdict}")
            if t.note:
                lines.append(f"{'':<22} {t.note}")
        lines += ["", f"Biot number of the particles (h R / lambda_p, all surface exchange): "
                      f"Bi = {self.biot:.3g}", f"  -> {self.biot_verdict}"]
        return "\n".join(lines)


def _props(scene):
    N = scene.n_particles
    d = sum(g.count * g.diameter for g in scene.groups) / N
    g0 = scene.groups[0]
    m = material(g0.material)
    lam = g0.conductivity or m.conductivity
    eps = g0.emissivity or m.emissivity
    rho = g0.density or m.density
    c = g0.heat_capacity or m.heat_capacity
    caps = [g.count * (g.density or material(g.material).density) * g.diameter**3
            * (g.heat_capacity or material(g.material).heat_capacity) for g in scene.groups]
    T0 = sum(cp * g.temperature for cp, g in zip(caps, scene.groups)) / sum(caps)
    spread = max(g.temperature for g in scene.groups) - min(g.temperature for g in scene.groups)
    return d, lam, eps, rho, c, T0, spread


def _radiation_term(scene, eff, eps, T0, T_wall, Tg, frac_wall, A_s, *, seen_by_wall_layer,
                    drum_bed) -> Term:
    """The radiation term: the scene's own effect, or an estimate against a black surrounding
    at the wall (or gas) temperature seen by part of the bed (only the particles at the tubes in
    a hopper, ``seen_by_wall_layer``); ``A_s`` the particle surface, m2."""
    if "radiation" in eff:
        r = eff["radiation"]
        Tr = float(np.asarray(r.sink_temperature)[0])
        e = float(np.asarray(r.emissivity)[0])
        note = f"eps = {e:.2g}, T_rad = {Tr:.1f} K"
        seen = 1.0
    else:
        Tr = T_wall if T_wall is not None else (Tg if Tg is not None else T0)
        e = eps
        # in a drum bed only the particles at the wall and at the free surface see the
        # surroundings (about twice the wall-contact fraction); elsewhere an upper bound
        # (a hopper: only the particles at the tubes see a surface at another temperature)
        if seen_by_wall_layer:
            seen = frac_wall
        elif drum_bed or frac_wall > 0:
            seen = min(1.0, 2.0 * frac_wall)
        else:
            seen = 1.0
        note = (f"estimate: black surrounding at {Tr:.1f} K, eps = {e:.2g}, "
                + (f"{seen:.0%} of the particles see it" if seen < 1.0 else
                   "every particle sees it (upper bound)"))
    h_r = e * SIGMA * (T0**2 + Tr**2) * (T0 + Tr)
    return Term("radiation", "[heat.radiation]", scene.heat.radiation is not None,
                h_r * A_s * seen, Tr - T0, note + f", h_r = {h_r:.3g} W/(m2 K)")


def _grade(terms, contact, scene, model) -> None:
    """Each term's size relative to the largest and its verdict (keep, could be dropped,
    should be added, ...), set on the terms."""
    big = max(t.heat_flow for t in terms) or 1.0
    loss = scene.heat.loss is not None
    C = float(np.mean(np.asarray(model.particles.capacity)))
    duration = float(scene.run.duration)
    drive = max((abs(t.dT) for t in terms if t.power is None), default=0.0)
    for t in terms:
        t.relative = t.heat_flow / big
        exposure = t.conductance * duration / C  # fraction of an e-folding over the run
        if t.power is not None:  # a source: by its size, or by what it adds over the run
            lasting = t.rise >= 0.05 * drive
            t.verdict = ("keep" if t.included and (t.relative >= 0.01 or lasting) else
                         "could be dropped (< 1 % of the largest)" if t.included else
                         "should be added (> 5 % of the largest)" if t.relative >= 0.05 else
                         f"should be added (warms the bed by {t.rise:.3g} K over the run, "
                         f"> 5 % of the largest driving difference)" if lasting else
                         "negligible (absent: fine)")
            continue
        if t.included:
            if t.relative >= 0.01:
                t.verdict = "keep"
            elif t is not contact and exposure >= 0.05:
                t.verdict = (f"keep (small now, but acts over the run: G t_run/(m c) = "
                             f"{exposure:.2g})")
            else:
                t.verdict = "could be dropped (< 1 % of the largest)"
        elif loss and t.name in ("convection", "radiation"):
            t.verdict = "covered by [heat.loss]"
        elif t.conductance == 0 or t.relative < 0.05:
            t.verdict = "negligible (absent: fine)"
        else:
            t.verdict = "should be added (> 5 % of the largest)"


def explain(scene) -> Advice:
    """Sizes of all effects for ``scene`` (a Scene, a built-in name or a path)."""
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    d, lam_p, eps, rho, c, T0, spread = _props(scene)
    N = scene.n_particles
    A_s, A_p = math.pi * d**2, math.pi * d**2 / 4
    motion = make_motion(scene)
    model, _ = motion.model()
    if model is None:
        raise SceneError("motion.model", scene.motion.model,
                         "'drumheat explain' sizes the effects of beds whose heat runs through "
                         "the thermal network (static, random, replay, dem, granulator, "
                         "fluidized, moving_bed); this motion model couples its gas itself and "
                         "reports its heat balance in the result files", scene.name)
    eff = {name: model.effect(name) for name in model.names}
    Tg = scene.gas.temperature if scene.gas is not None else None
    T_wall = scene.drum.wall_temperature if scene.drum is not None else None
    moving_bed = scene.motion.model == "moving_bed"
    if moving_bed:
        T_wall = scene.hopper.tube_temperature
    terms = []

    # contact conduction
    drum_bed = scene.motion.model in ("static", "random")
    wall_note = ""
    if drum_bed:
        net = motion.net
        z = 2.0 * float(np.sum(np.asarray(net.pair_weight))) / N
        frac_wall = float(np.sum(np.asarray(net.wall_weight))) / N
    else:
        z = 0.0 if scene.motion.model in ("granulator", "fluidized") else (4.0 if scene.dim == 2
                                                                           else 6.0)
        frac_wall, wall_note = _wall_layer_fraction(scene, d)
    if "contact" in eff:
        alpha_pp = float(np.asarray(eff["contact"].alpha))
    else:
        alpha_pp = _schluender_alpha(scene, d)[1]
    contact = Term("contact conduction", "[heat.contact]", scene.heat.contact is not None,
                   alpha_pp * A_p * z, spread,
                      f"{z:.2g} contacts per particle, alpha_pp = {alpha_pp:.3g} W/(m2 K)"
                   if z else "no particle contacts in this motion model")
    terms.append(contact)
    # wall
    if scene.motion.model == "granulator":
        g = scene.granulator
        mat = model.internal.material
        Ts = jnp.asarray([T0])
        b_S = float(effusivity(mat.conductivity(Ts), mat.heat_capacity(Ts), rho)[0])
        b_W = float(effusivity(g.wall_conductivity, g.wall_heat_capacity, g.wall_density))
        b = b_S * b_W / (b_S + b_W)
        t2 = math.pi * (wall_heat_per_mass(g) * rho * d / 6 / (2 * b * (T0 - g.wall_temperature))) ** 2
        h2 = 2 * b / math.sqrt(math.pi * t2)
        terms.append(Term("wall contact (Phase 2)", "motion granulator", True, h2 * A_s,
                          T0 - g.wall_temperature,
                          f"two semi-infinite bodies, mean 2 b/sqrt(pi t2) = {h2:.3g} W/(m2 K) "
                          f"over t2 ~ {1e3 * t2:.3g} ms (Phase 2 only)"))
    elif T_wall is not None or scene.heat.wall is not None:
        alpha_wp = float(np.asarray(eff["wall"].alpha)) if "wall" in eff \
            else _schluender_alpha(scene, d)[0]
        terms.append(Term("wall contact", "[heat.wall]", scene.heat.wall is not None,
                          alpha_wp * A_p * frac_wall, (T_wall or T0) - T0,
                          f"{frac_wall:.1%} of the particles touch the "
                          f"{'tubes' if moving_bed else 'wall'}{wall_note}, alpha_wp = "
                          f"{alpha_wp:.3g} W/(m2 K)"))
    # heat loss
    if scene.heat.loss is not None:
        terms.append(Term("heat loss (lumped)", "[heat.loss]", True, scene.heat.loss.alphaA,
                          Tg - T0, "lumps convection, radiation and losses through the drum"))
    # convection
    if moving_bed:
        # kraychev-tube-bundle.md sec. 5: no secondary gas (W_SG = 0) -- the gas in the voids
        # moves with the bed, it is no sink at a fixed temperature; its conduction near the
        # contacts is part of the Schluender coefficients
        terms.append(Term("convection", "[heat.convection]", scene.heat.convection is not None,
                          0.0, 0.0, "no gas flows through the moving bed (no secondary gas): "
                          "the gas in the voids moves with the particles"))
    elif Tg is not None:
        if "convection" in eff:
            conv = eff["convection"]
            conv = conv.convection if isinstance(conv, PlugFlowConvection) else conv
            a = float(conv.alpha(jnp.full(N, T0), model.particles)[0])
            note = f"alpha = {a:.3g} W/(m2 K) ({scene.heat.convection.correlation})"
        else:
            lam_g = scene.gas.conductivity or gas(scene.gas.material).conductivity
            a = 2.0 * lam_g / d
            note = f"estimate: conduction limit Nu = 2, alpha = {a:.3g} W/(m2 K)"
        terms.append(Term("convection", "[heat.convection]", scene.heat.convection is not None,
                          a * A_s, Tg - T0, note))
    terms.append(_radiation_term(scene, eff, eps, T0, T_wall, Tg, frac_wall, A_s,
                                 seen_by_wall_layer=moving_bed, drum_bed=drum_bed))
    friction = _friction_heat_term(scene, d, c)
    if friction is not None:
        terms.append(friction)
    # heat brought in or taken out at the boundary must pass the contacts: their driving
    # difference is at least the external one (a wall-heated bed starts uniform)
    if contact.conductance > 0:
        ext = [abs(t.dT) for t in terms if t is not contact and t.included]
        contact.dT = max([spread] + ext)
        if contact.dT > spread:
            contact.note += (f"; dT = the external driving difference (initial spread "
                             f"{spread:.3g} K)")

    _grade(terms, contact, scene, model)
    # Biot number: all surface exchange of included effects per particle surface
    G_in = sum(t.conductance for t in terms if t.included)
    h = G_in / A_s
    Bi = h * (d / 2) / lam_p
    if scene.heat.internal is not None:
        lam_note = "" if scene.heat.internal.material == "constant" else \
            f" (lambda_p = {lam_p:.3g} W/(m K) of the group; the T-dependent shell material varies)"
        if scene.motion.model == "granulator":
            mat = model.internal.material
            lam_p = float(mat.conductivity(jnp.asarray(T0)))
            G_flight = sum(t.conductance for t in terms if t.included and "Phase 2" not in t.name)
            Bi = G_flight / A_s * (d / 2) / lam_p
            lam_note = (f" (flight phases, lambda_p = {lam_p:.3g} W/(m K) at {T0:.0f} K; "
                        "Phase 2 wall contact: Bi -> infinity)")
        verdict = ("[heat.internal] included and needed (Bi > 0.1)" if Bi > 0.1 else
                   "[heat.internal] included but could be dropped (Bi < 0.1: lumped particles "
                   "suffice)") + lam_note
    elif Bi < 0.1:
        verdict = "lumped particles are fine (Bi < 0.1); [heat.internal] not needed"
    else:
        try:  # recommend only what this scene's motion model can do
            scene.replace({"heat.internal": {}})
            verdict = "internal gradients matter (Bi > 0.1): add [heat.internal]"
        except SceneError as err:
            verdict = ("internal gradients matter (Bi > 0.1), but this scene cannot resolve "
                       f"them ({err.allowed}); read the lumped temperatures as the particles' "
                       "mean and expect the surface to run ahead of it")
    cond = (f"conditions at t = 0: {N} particle(s), d = {1e3 * d:.3g} mm "
            f"{scene.groups[0].material}, T = {T0:.2f} K, motion '{scene.motion.model}'"
            + (f", gas {Tg:.2f} K" if Tg is not None else "")
            + (f", wall {T_wall:.2f} K" if T_wall is not None else ""))
    return Advice(scene.name, cond, terms, Bi, verdict)


#: solids fraction of a 3D bed and area fraction of a 2D monolayer, for the bed's size
SOLIDS_FRACTION, AREA_FRACTION = 0.6, 0.8


def _wall_layer_fraction(scene, d):
    """Fraction of the particles in the layer at the heated walls (estimate), and a note.

    The wall layer holds the particles within one diameter of the wetted wall at the bed's
    solids fraction (0.6 in 3D, an area fraction of 0.8 for a 2D monolayer); an upper bound of
    those that touch it.

    * plain drum (``dem``, ``replay``, ``mixing``): the bed is a circular segment of the drum's
      cross-section with the particles' area; its wetted arc ``2 eps R`` follows from the
      filling degree ``f = (2 eps - sin 2 eps) / (2 pi)`` (herz-sectional-drum.md sec. 2 at
      ``R2 = 0``);
    * sectional drum: the revolution means of the contact lengths ``Wo + Wi + P1 + P2`` of the
      sectional-drum model (herz-sectional-drum.md sec. 5), per section, times the sections;
    * moving bed (``[hopper]``): the tube surface in the slice (kraychev-tube-bundle.md eq.
      5-15 area).
    Returns ``(0, "")`` where no wall applies (granulator, fluidized bed, pneumatic channel).
    """
    N = scene.n_particles
    beta = SOLIDS_FRACTION
    if scene.motion.model == "moving_bed":
        h = scene.hopper
        g = hopper_walls(h)
        A = float(np.sum(g.tube_fraction)) * math.pi * h.tube_diameter * h.depth
        return min(1.0, A * d * beta / (math.pi * d**3 / 6) / N), " (tube surface x one layer)"
    dr = scene.drum
    if dr is None or scene.motion.model in ("granulator", "fluidized", "pneumatic"):
        return 0.0, ""
    R = 0.5 * dr.diameter
    if scene.dim == 3 and not dr.depth:
        return 0.0, ""
    bed_area = _bed_area(scene, d)
    per_length = dr.depth * d * beta / (math.pi * d**3 / 6) if scene.dim == 3 else 1.0 / d
    if dr.sections:
        R2 = 0.5 * (dr.inner_diameter or 0.0)
        sec_area = (math.pi * (R * R - R2 * R2)) / dr.sections
        fill = min(0.95, bed_area / dr.sections / sec_area)
        gamma = scene.packing.surface_angle if scene.packing.surface_angle is not None else 30.0
        m = cycle_means(R1=R, R2=R2, fill=fill, gamma_deg=abs(gamma),
                        alpha_deg=360.0 / dr.sections)
        length = m["all_walls"] * dr.sections
        note = (f" (sectional-drum model: {fill:.0%} per section, revolution mean of the "
                "wetted walls and plates x one layer)")
    else:
        fill = min(0.99, bed_area / (math.pi * R * R))
        length = 2.0 * _segment_half_angle(fill) * R
        note = f" (bed segment {fill:.0%} of the drum: wetted arc x one layer)"
    return min(1.0, length * per_length / N), note


def _segment_half_angle(fill: float) -> float:
    """Half central angle eps (rad) of the circular segment filling ``fill`` of a circle:
    ``fill = (2 eps - sin 2 eps) / (2 pi)`` (herz-sectional-drum.md sec. 2 at ``R2 = 0``)."""
    lo, hi = 0.0, math.pi  # the fill grows monotonically from 0 to 1
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if (2 * mid - math.sin(2 * mid)) / (2 * math.pi) < fill else (lo, mid)
    return lo


def _bed_area(scene, d) -> float:
    """Cross-section of the bed in a plain drum, m2: the particles' volume over the depth at
    solids fraction 0.6 (3D), their area at area fraction 0.8 (2D monolayer)."""
    if scene.dim == 3:
        return sum(g.count * math.pi * g.diameter**3 / 6 for g in scene.groups) / (
            SOLIDS_FRACTION * scene.drum.depth)
    return sum(g.count * math.pi * g.diameter**2 / 4 for g in scene.groups) / AREA_FRACTION


def _friction_heat_term(scene, d, c) -> Term | None:
    """Heat from friction and damping in a turning plain drum: the drive's power in steady
    rotation, ``omega M g x_c`` (see the module docstring), per particle; None where the scene
    has no turning plain drum."""
    dr = scene.drum
    if (dr is None or not dr.rpm or dr.sections or (scene.dim == 3 and not dr.depth)
            or scene.motion.model not in ("dem", "random", "replay", "mixing")):
        return None
    R = 0.5 * dr.diameter
    fill = min(0.99, _bed_area(scene, d) / (math.pi * R * R))
    eps = _segment_half_angle(fill)
    r_c = 4 * R * math.sin(eps) ** 3 / (3 * (2 * eps - math.sin(2 * eps)))
    if scene.packing.surface_angle is not None:
        theta, why = math.radians(abs(scene.packing.surface_angle)), "packing.surface_angle"
    elif scene.motion.model == "dem":
        theta, why = math.atan(scene.dem.friction), "atan(dem.friction)"
    else:
        theta, why = math.radians(30.0), "nominal"
    mass = sum(g.count * (g.density or material(g.material).density) * math.pi
               * g.diameter**3 / 6 for g in scene.groups)
    omega = 2 * math.pi * abs(dr.rpm) / 60
    power = omega * mass * 9.81 * r_c * math.sin(theta)
    rise = power * float(scene.run.duration) / (mass * c)
    return Term("friction heat", "[heat.friction]", scene.heat.friction is not None, 0.0, 0.0,
                f"estimate: drive power omega M g x_c = {power:.3g} W for the bed, x_c = "
                f"{1e3 * r_c * math.sin(theta):.3g} mm at angle of repose "
                f"{math.degrees(theta):.3g} deg ({why}); alone it would warm the bed by "
                f"{rise:.3g} K over the run", power=power / scene.n_particles, rise=rise)


def _schluender_alpha(scene, d):
    """(alpha_wp, alpha_pp) from weigler eqs. [2.8]-[2.10] for the scene's gas."""
    g = contact_gas(scene, scene_values(scene))
    a_wp, a_pp = schluender.contact_coefficients(d, T=g.temperature, p=g.pressure,
                                                 conductivity=g.conductivity,
                                                 heat_capacity=g.heat_capacity,
                                                 molar_mass=g.molar_mass,
                                                 C=g.accommodation_constant)
    return float(a_wp), float(a_pp)
