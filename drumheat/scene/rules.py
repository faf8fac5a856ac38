"""The rules between the tables of a scene, and the requirements of each motion model.

A table checks its own keys (:class:`~drumheat.scene.spec.Table`); what depends on several
tables is checked here, by :func:`check_scene`, which every :class:`~drumheat.scene.Scene` runs
when it is built. The requirements of the motion models (which tables each needs, what it
cannot do) are scene rules too and live here, so that a scene :func:`~drumheat.load_scene`
accepts is one :func:`~drumheat.run` accepts.
"""

from __future__ import annotations

import contextvars
import math
import re
from pathlib import Path

import numpy as np

from drumheat.materials import material
from drumheat.models.soft_sphere import critical_time_step, normal_stiffness_from_youngs
from drumheat.scene.spec import REQUIRED, SceneError

#: the motion models (drumheat.motion registers one class under each name)
MOTION_MODEL_NAMES = ("static", "random", "granulator", "fluidized", "dem", "replay",
                      "pneumatic", "moving_bed")

#: Motion models whose particles lie in the drum of the ``[drum]`` table.
DRUM_MOTION_MODELS = ("static", "random", "dem", "replay")


def motion_name(motion) -> str:
    """The motion model named by a ``[motion]`` table (a MotionConfig, a dict or None)."""
    if motion is None:
        return "static"
    if isinstance(motion, dict):
        return motion.get("model", "static")
    return motion.model


#: whether the files a scene names (packing, recording) are checked (off while reading the
#: scene of a result folder, whose input files need not be at hand)
CHECK_FILES: contextvars.ContextVar = contextvars.ContextVar("drumheat_check_files",
                                                             default=True)


def check_scene(s) -> None:
    """Every cross-table rule of scene ``s``; raises :class:`SceneError` naming the key."""
    if s.heat.drum_wall is not None:  # first: it names the motion models that carry it
        _check_drum_wall(s)
    _check_consistency(s)
    if s.dem is not None:
        _check_dem(s)
    if CHECK_FILES.get():
        if s.motion.model == "replay":
            _check_replay(s)
        if s.packing.method == "file":
            _check_packing_file(s)


def scene_path(s, path: str) -> Path:
    """A file named in a scene (packing, recording): relative to the scene file."""
    p = Path(path)
    if not p.is_absolute() and s.source_path:
        p = Path(s.source_path).parent / p
    return p


def _npz_arrays(s, key: str, path: str, what: str, keys: tuple) -> dict:
    p = scene_path(s, path)
    if not p.is_file():
        raise SceneError(key, path, f"no such file ({what})", s.name)
    try:
        with np.load(p, allow_pickle=False) as f:
            missing = [k for k in keys if k not in f.files]
            if missing:
                raise SceneError(key, path, f"is not {what}: it lacks the arrays "
                                 + ", ".join(missing), s.name)
            return {k: f[k] for k in keys}
    except (OSError, ValueError) as err:
        raise SceneError(key, path, f"cannot be read as {what} ({err})", s.name) from None


def _check_replay(s) -> None:
    """The recording of motion model 'replay' exists, holds the scene's particles and fits the
    output times (drumheat.motion.replay)."""
    n = s.name
    rec = _npz_arrays(s, "replay.file", s.replay.file, "a contacts.npz recording written by a "
                      "'dem' run with dem.record_interval", ("interval", "n_particles",
                                                             "pair_ptr"))
    if int(rec["n_particles"]) != s.n_particles:
        raise SceneError("replay.file", s.replay.file, f"holds {int(rec['n_particles'])} "
                         f"particles; the scene has {s.n_particles}", n)
    tau = float(rec["interval"])
    out_iv = s.run.output_interval
    steps = round(out_iv / tau)
    if steps < 1 or abs(steps * tau - out_iv) > 1e-9 * tau:
        raise SceneError("run.output_interval", out_iv, "must be a multiple of the recording "
                         f"interval {tau:g} s", n)
    k = s.run.duration / out_iv
    if abs(k - round(k)) > 1e-9 * max(k, 1.0):
        raise SceneError("run.duration", s.run.duration, "must be a multiple of "
                         "run.output_interval for a replay", n)
    with np.load(scene_path(s, s.replay.file), allow_pickle=False) as f:
        rec_d = np.asarray(f["diameter"], float) if "diameter" in f.files else None
        rec_scene = str(f["scene"]) if "scene" in f.files else None
    if rec_d is not None and (rec_d.shape != (s.n_particles,) or not np.allclose(
            rec_d, scene_diameters(s), rtol=1e-6)):
        raise SceneError("replay.file", s.replay.file, "was recorded with particles of other "
                         f"diameters ({np.unique(rec_d)} m) than the scene's "
                         f"({np.unique(scene_diameters(s))} m)", n)
    if rec_scene:
        import tomllib

        try:
            groups = tomllib.loads(rec_scene).get("groups", [])
        except tomllib.TOMLDecodeError:
            groups = []
        recorded = [(g.get("count"), g.get("material")) for g in groups]
        if recorded and recorded != [(g.count, g.material) for g in s.groups]:
            raise SceneError("replay.file", s.replay.file, "was recorded with other particle "
                             f"groups (count, material: {recorded}) than the scene's "
                             f"({[(g.count, g.material) for g in s.groups]})", n)
    span = tau * (len(rec["pair_ptr"]) - 1)
    if s.run.duration > span * (1 + 1e-12) and not s.replay.cyclic:
        raise SceneError("run.duration", s.run.duration, f"exceeds the recording ({span:g} s); "
                         "set replay.cyclic = true or shorten the run", n)


def scene_diameters(s) -> np.ndarray:
    """Nominal diameter of every particle of the scene, group by group, m."""
    return np.concatenate([np.full(g.count, g.diameter) for g in s.groups])


def _check_packing_file(s) -> None:
    """The packing file of method 'file' exists, holds the scene's particles (count, sizes),
    all inside the drum, and no two of them overlapping by more than half the smaller radius
    (what a DEM run refuses)."""
    key, path, n = "packing.file", s.packing.file, s.name
    pk = _npz_arrays(s, key, path, "a packing (.npz with the array position)", ("position",))
    pos = np.asarray(pk["position"], float)
    if pos.shape != (s.n_particles, s.dim):
        raise SceneError(key, path, f"holds positions of shape {pos.shape}; the scene has "
                         f"{s.n_particles} particles in {s.dim}D", n)
    if not np.all(np.isfinite(pos)):
        raise SceneError(key, path, "holds positions that are not finite numbers", n)
    d = scene_diameters(s)
    with np.load(scene_path(s, path), allow_pickle=False) as f:
        d_file = np.asarray(f["diameter"], float) if "diameter" in f.files else None
    if d_file is not None and (d_file.shape != d.shape or not np.allclose(d_file, d,
                                                                           rtol=1e-6)):
        raise SceneError(key, path, "holds particles of other diameters than the scene's "
                         f"groups ({np.unique(d_file)} m vs {np.unique(d)} m)", n)
    if s.drum is not None:
        r = np.hypot(pos[:, 0], pos[:, 1]) + 0.5 * d
        worst = int(np.argmax(r - 0.5 * s.drum.diameter))
        if r[worst] > 0.5 * s.drum.diameter + 0.01 * d[worst]:
            raise SceneError(key, path, f"particle {worst} lies outside the drum (its surface "
                             f"{r[worst]:.4g} m from the axis, drum radius "
                             f"{0.5 * s.drum.diameter:g} m)", n)
    _check_overlaps(s, key, path, pos, d)


def _check_overlaps(s, key, path, pos, d) -> None:
    from scipy.spatial import cKDTree

    box = None
    if s.dim == 3 and s.drum is not None and s.drum.depth:
        pos = pos.copy()
        pos[:, 2] = np.mod(pos[:, 2], s.drum.depth)
        box = np.array([np.inf, np.inf, s.drum.depth])
        box[:2] = 1e9
        pos[:, :2] += 1e8
    pairs = cKDTree(pos, boxsize=box).query_pairs(float(d.max()), output_type="ndarray")
    if not len(pairs):
        return
    delta = pos[pairs[:, 0]] - pos[pairs[:, 1]]
    if box is not None:
        delta[:, 2] -= s.drum.depth * np.round(delta[:, 2] / s.drum.depth)
    overlap = 0.5 * (d[pairs[:, 0]] + d[pairs[:, 1]]) - np.linalg.norm(delta, axis=1)
    rel = overlap / (0.5 * np.minimum(d[pairs[:, 0]], d[pairs[:, 1]]))
    k = int(np.argmax(rel))
    if rel[k] > 0.5:
        i, j = pairs[k]
        raise SceneError(key, path, f"particles {i} and {j} overlap by {rel[k]:.0%} of the "
                         "smaller radius (a DEM run stops above 50 %); the packing does not "
                         "belong to this scene", s.name)


def group_value(s, k: int, prop: str) -> float:
    """A material property of group ``k``: the group's own value or the library's."""
    g = s.groups[k]
    v = getattr(g, prop)
    return float(v) if v is not None else float(getattr(material(g.material), prop))


def dem_stiffness(s) -> tuple[float, float]:
    """``(k_n, k_wall)`` of the ``[dem]`` table, N/m: ``dem.stiffness``, else ``E A_p / d_p``
    of the smallest particle with the softest material (weigler eq. [2.3]); the wall stiffness
    defaults to k_n.

    With ``dem.coarse_grain = s`` > 1 these are the parcels' stiffnesses: the given (fine)
    values times s, and the default ``E A_p / d_p`` of the parcel diameter ``s d``, which is
    the same factor s. A linear spring ``k ~ s`` keeps the overlap per diameter of the fine
    bed both under a static load (contact force ~ pressure x (s d)^2, overlap F/k ~ s d) and
    in an impact at the same velocity (overlap v sqrt(m/k) ~ sqrt(s^3/s) ~ s d): Bierwisch
    et al. 2009, J. Mech. Phys. Solids 57, 10-31 (docs/models/coarse-graining.md).
    """
    d = s.dem
    cg = s.coarse_grain
    k_n = d.stiffness
    if k_n is None:
        E = min(group_value(s, k, "youngs_modulus") for k in range(len(s.groups)))
        k_n = float(normal_stiffness_from_youngs(E, min(g.diameter for g in s.groups)))
    k_w = d.wall_stiffness if d.wall_stiffness is not None else k_n
    if cg == 1.0:
        return k_n, k_w
    return cg * k_n, cg * k_w


def dem_critical_time_step(s) -> float:
    """``t_crit = 2 sqrt(m_min / k_max)`` of the scene's DEM, s (weigler eq. [2.1]), with the
    lightest particle and the largest stiffness (normal = tangential, particle or wall); with
    ``dem.coarse_grain = s`` the lightest parcel (diameter s d, mass s^3 m) and the parcel
    stiffness (:func:`dem_stiffness`), so t_crit grows as s."""
    cg = s.coarse_grain
    m_min = min(group_value(s, k, "density") * math.pi * (cg * g.diameter)**3 / 6.0
                for k, g in enumerate(s.groups))
    return critical_time_step(m_min, max(dem_stiffness(s)))


def dem_time_step(s) -> float | None:
    """The mechanical step ``dem.dt`` asked for, s, or None: with ``dem.coarse_grain = s`` the
    given (fine-bed) step times s, since t_crit of the parcels is s times the fine one
    (:func:`dem_critical_time_step`)."""
    dt = s.dem.dt
    return None if dt is None else dt * s.coarse_grain


#: the heat effects that coarse-graining scales (docs/models/coarse-graining.md)
COARSE_GRAIN_EFFECTS = ("contact", "wall", "loss")


def _check_coarse_grain(s) -> None:
    """``dem.coarse_grain`` > 1: only where its scalings are derived (3D drum, motion model
    'dem', poured bed, contact/wall/loss heat), and at least one parcel per group."""
    n, cg = s.name, s.coarse_grain
    key = "dem.coarse_grain"
    if s.dim != 3:
        raise SceneError(key, cg, "coarse-graining needs dim = 3: a 2D scene is a monolayer "
                         "one particle deep, and a parcel of diameter s d would make the slice "
                         "s d deep (s monolayers, s^3 particles per parcel, not s^2), another "
                         "apparatus (docs/models/coarse-graining.md)", n)
    if s.motion.model != "dem" or s.drum is None:
        raise SceneError(key, cg, f"coarse-graining is for the DEM drum (motion model 'dem'); "
                         f"motion model {s.motion.model!r} is not supported", n)
    if s.packing.method != "pour":
        raise SceneError(key, cg, "coarse-graining needs packing.method = 'pour' (a packing "
                         "file holds particles, not parcels)", n)
    other = [e for e in s.heat.effects() if e not in COARSE_GRAIN_EFFECTS]
    if s.heat.friction is not None:
        other.append("friction")
    if other:
        tables = ", ".join(f"[heat.{e}]" for e in other)
        raise SceneError(key, cg, "the scalings are derived for [heat.contact], [heat.wall] "
                         f"and [heat.loss] only; leave out {tables} or use coarse_grain = 1", n)
    for i, (g, c) in enumerate(zip(s.groups, s.parcel_counts())):
        if c < 1:
            raise SceneError(key, cg, f"group {i} ({g.count} particles) would have no parcel: "
                             f"round(count / s^3) = 0; a smaller s or more particles", n)
        if cg * g.diameter >= 0.5 * s.drum.diameter:
            raise SceneError(key, cg, f"the parcels of group {i} (diameter s d = "
                             f"{cg * g.diameter:g} m) would not fit in the drum radius "
                             f"{0.5 * s.drum.diameter:g} m", n)


def _check_periodic_slice(s, key: str, length: float, default_skin: float) -> None:
    """A periodic slice must be at least twice the neighbour cutoff ``d_max + skin`` long."""
    d_max = s.coarse_grain * max(g.diameter for g in s.groups)  # parcels where coarse-grained
    skin = s.dem.skin if s.dem.skin is not None else default_skin * d_max
    if length < 2.0 * (d_max + skin) * (1 - 1e-12):
        raise SceneError(key, length, "the periodic slice must be at least twice the neighbour "
                         f"cutoff (largest diameter + skin = {d_max + skin:g} m) long, i.e. >= "
                         f"{2 * (d_max + skin):g} m", s.name)


def _check_dem(s) -> None:
    """The mechanical time step of ``[dem]``: at most the critical step (weigler [2.1]); the
    periodic slices of the DEM models long enough for their neighbour lists."""
    n, d = s.name, s.dem
    if s.coarse_grain != 1.0:
        _check_coarse_grain(s)
    # default skins: half the largest radius (drumheat.mechanics.make_dem), the channel's
    # whole radius (drumheat.motion.pneumatic)
    if s.motion.model == "dem" and s.dim == 3 and s.drum is not None and s.drum.depth:
        _check_periodic_slice(s, "drum.depth", s.drum.depth, 0.25)
    if s.motion.model == "pneumatic" and s.channel is not None:
        _check_periodic_slice(s, "channel.depth", s.channel.depth, 0.5)
    if d.dt is not None:
        t_crit = dem_critical_time_step(s)
        if dem_time_step(s) > t_crit:
            k_n, k_w = dem_stiffness(s)
            raise SceneError("dem.dt", d.dt, f"must not exceed the critical time step t_crit = "
                             f"2 sqrt(m_min/k) = {t_crit:.4g} s (weigler eq. [2.1], k = "
                             f"{max(k_n, k_w):.4g} N/m); leave dem.dt out for "
                             f"dem.safety_factor x t_crit, or soften dem.stiffness "
                             "(the step grows as 1/sqrt(k))", n)
    out_iv = s.run.output_interval
    if d.record_interval is not None:
        ratio = out_iv / d.record_interval
        if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
            raise SceneError("dem.record_interval", d.record_interval,
                             f"must divide run.output_interval = {out_iv:g} s into a whole "
                             "number of recording intervals", n)


_NAME_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*")


def _check_consistency(s) -> None:
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
        raise SceneError("drum.depth", REQUIRED, "a 3D scene (dim = 3) needs the axial "
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
        raise SceneError("drum.wall_temperature", REQUIRED,
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
            raise SceneError(f"heat.{eff}.alpha", REQUIRED,
                             "model 'constant' needs alpha, a number > 0 in W/(m2 K)", n)
        if cfg is not None and cfg.model == "schluender" and cfg.alpha is not None:
            raise SceneError(f"heat.{eff}.alpha", cfg.alpha,
                             "model 'schluender' computes alpha; leave alpha out or use "
                             "model 'constant'", n)
    if s.heat.loss is not None and s.gas is None:
        raise SceneError("gas.temperature", REQUIRED,
                         "[heat.loss] needs the gas temperature, in K", n)
    _check_new_effects(s)
    if s.motion.model == "dem" and s.dem is None:
        raise SceneError("dem", REQUIRED, "motion model 'dem' needs the [dem] table "
                         "(its keys all have defaults: [dem] alone is enough)", n)
    if s.heat.friction is not None and s.motion.model != "dem":
        raise SceneError("heat.friction", "a table", f"heat from friction and damping comes "
                         f"from the DEM contacts: it needs motion model 'dem', not "
                         f"'{s.motion.model}'", n)
    if s.heat.friction is not None and s.dem is not None and s.dem.replay_after is not None:
        raise SceneError("dem.replay_after", s.dem.replay_after, "a replay has no mechanics, so "
                         "no friction heat: remove dem.replay_after (--set "
                         "dem.replay_after=none) or [heat.friction]", n)
    if s.heat.internal is not None and s.motion.model in ("dem", "replay", "moving_bed"):
        raise SceneError("heat.internal", "a table", f"motion model '{s.motion.model}' "
                         "supports lumped particles only so far (radial shells need the static, "
                         "random, fluidized or granulator motion models); remove "
                         "[heat.internal]", n)
    if s.motion.model == "replay" and s.replay is None:
        raise SceneError("replay.file", REQUIRED, "motion model 'replay' needs "
                         "[replay] file = a contacts.npz recorded by a 'dem' run", n)
    if s.dem is not None and s.dem.restitution is not None and s.dem.damping_ratio not in (
            None, 0.3):
        raise SceneError("dem.restitution", s.dem.restitution, "give either dem.restitution or "
                         "dem.damping_ratio, not both", n)
    if s.dem is not None and s.dem.replay_after is not None:
        if s.dem.record_interval is None:
            raise SceneError("dem.replay_after", s.dem.replay_after, "needs dem.record_interval "
                             "(the contacts to replay)", n)
        cyc = s.dem.replayed_cycle
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
        raise SceneError("motion.t_R", REQUIRED, "model 'random' needs the re-mixing "
                         "period t_R, a number > 0 in s", n)
    if s.motion.model == "fluidized":
        if s.motion.loading is None:
            raise SceneError("motion.loading", REQUIRED, "model 'fluidized' needs the "
                             "particle mass per bed cross-section, in kg/m2", n)
        if s.gas is None or s.gas.mass_flux is None:
            raise SceneError("gas.mass_flux", REQUIRED, "model 'fluidized' needs the gas "
                             "mass flux through the bed, in kg/(m2 s)", n)
        if s.heat.convection is None:
            raise SceneError("heat.convection", REQUIRED, "model 'fluidized' exchanges "
                             "heat with the gas through [heat.convection]", n)
        if s.motion.layers > 1 and s.motion.t_R is None:
            raise SceneError("motion.t_R", REQUIRED, "model 'fluidized' with several "
                             "layers needs the re-mixing period t_R, in s", n)
    if s.motion.model == "granulator":
        if s.granulator is None:
            raise SceneError("granulator", REQUIRED, "motion model 'granulator' needs the "
                             "[granulator] table (geometry, disc, slag rate)", n)
        if s.heat.internal is None:
            raise SceneError("heat.internal", REQUIRED, "motion model 'granulator' "
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
        _check_pneumatic(s)
    if s.motion.model == "moving_bed":
        _check_hopper(s)
    if s.packing.method == "file" and s.packing.file is None:
        raise SceneError("packing.file", REQUIRED, "method 'file' needs a path to an .npz "
                         "packing", n)
    if (s.motion.model in DRUM_MOTION_MODELS and s.dim == 3
            and s.packing.method == "deposition"):
        raise SceneError("packing.method", "deposition", "the geometric deposition packing is "
                         "2D; a 3D bed needs packing.method = 'pour' (with [dem]) or 'file'", n)


def check_apparatus_tables(s, table: str, keys: str, what: str) -> None:
    """Common rules of the DEM apparatus models (``moving_bed``, ``pneumatic``): their own
    table ``[table]`` (required ``keys`` named in the message) and ``[dem]`` must be present,
    and the scene is a 3D slice (``what`` says of what)."""
    n, model = s.name, s.motion.model
    if getattr(s, table) is None:
        raise SceneError(table, REQUIRED, f"motion model '{model}' needs the [{table}] "
                         f"table ({keys})", n)
    if s.dem is None:
        raise SceneError("dem", REQUIRED, f"motion model '{model}' needs the [dem] "
                         "table (its keys all have defaults: [dem] alone is enough)", n)
    if s.dim != 3:
        raise SceneError("dim", s.dim, f"motion model '{model}' simulates a 3D slice {what}; "
                         "use dim = 3", n)


def _check_hopper(s) -> None:
    """Cross-field rules of motion model 'moving_bed' (drumheat.motion.moving_bed)."""
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


def _check_new_effects(s) -> None:
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
            raise SceneError("gas.temperature", REQUIRED,
                             "[heat.convection] needs the gas temperature, in K", n)
        if c.correlation == "constant" and c.alpha is None:
            raise SceneError("heat.convection.alpha", REQUIRED,
                             "correlation 'constant' needs alpha, a number > 0 in W/(m2 K)", n)
        if c.correlation != "constant" and c.alpha is not None:
            raise SceneError("heat.convection.alpha", c.alpha, f"correlation {c.correlation!r} "
                             "computes alpha; leave alpha out or use correlation 'constant'", n)
        if (c.correlation not in ("constant",) and c.velocity is None
                and s.motion.model not in ("granulator", "pneumatic")):
            raise SceneError("heat.convection.velocity", REQUIRED,
                             f"correlation {c.correlation!r} needs the gas velocity, in m/s", n)
        if c.properties == "gas" and c.correlation != "constant":
            for key in ("kinematic_viscosity", "conductivity", "heat_capacity"):
                if getattr(s.gas, key) is None:
                    raise SceneError(f"gas.{key}", REQUIRED, "convection with properties "
                                     "= 'gas' needs the gas constants kinematic_viscosity, "
                                     "conductivity and heat_capacity", n)
        if c.internal_resistance != "none" and h.internal is not None:
            raise SceneError("heat.convection.internal_resistance", c.internal_resistance,
                             "with [heat.internal] the shells resolve the internal resistance; "
                             "use 'none'", n)
    r = h.radiation
    if r is not None:
        if r.enclosure == "sink" and r.sink_temperature is None:
            raise SceneError("heat.radiation.sink_temperature", REQUIRED,
                             "enclosure 'sink' needs the sink temperature, in K", n)
        if r.enclosure == "granulator":
            zones = ("bed", "slots", "wall", "outlet")
            got = tuple(x.name for x in (r.surfaces or ()))
            if got != zones:
                raise SceneError("heat.radiation.surfaces", list(got), "enclosure 'granulator' "
                                 "needs four surfaces named " + ", ".join(zones) + " in this "
                                 "order", n)
            if s.granulator is None:
                raise SceneError("granulator", REQUIRED, "enclosure 'granulator' needs "
                                 "the [granulator] geometry", n)
    i = h.internal
    if i is not None and (i.latent_heat is None) != (i.melting_temperature is None):
        raise SceneError("heat.internal.melting_temperature" if i.melting_temperature is None
                         else "heat.internal.latent_heat", REQUIRED,
                         "latent heat needs both latent_heat (J/kg) and melting_temperature (K)", n)


#: motion models that carry a drum wall with heat capacity ([heat.drum_wall])
DRUM_WALL_MOTION_MODELS = ("static", "random", "dem")


def _check_drum_wall(s) -> None:
    """Rules of ``[heat.drum_wall]`` (docs/models/drum-wall.md): which motion models carry the
    wall, what it needs from the other tables, and the keys of its ``outside`` choice."""
    n, w = s.name, s.heat.drum_wall
    key = "heat.drum_wall"
    if s.motion.model not in DRUM_WALL_MOTION_MODELS:
        raise SceneError("motion.model", s.motion.model, "[heat.drum_wall] is carried by the "
                         "motion models " + ", ".join(DRUM_WALL_MOTION_MODELS) + "; leave "
                         "[heat.drum_wall] out for a wall of fixed temperature", n)
    if s.drum is None or s.drum.wall_temperature is None:
        raise SceneError("drum.wall_temperature", REQUIRED, "[heat.drum_wall] needs the "
                         "initial wall temperature drum.wall_temperature, in K", n)
    if s.drum.has_internals:
        raise SceneError("drum.sections" if s.drum.sections else "drum.inner_diameter",
                         s.drum.sections or s.drum.inner_diameter, "[heat.drum_wall] is a "
                         "plain drum's shell; internals with a drum wall are not supported", n)
    if s.heat.wall is None:
        raise SceneError("heat.wall", REQUIRED, "[heat.drum_wall] gives its heat to the bed "
                         "through the particle-wall contact law: add [heat.wall]", n)
    if s.heat.internal is not None:
        raise SceneError("heat.internal", "given", "[heat.drum_wall] with radial shells in the "
                         "particles is not supported; leave one of them out", n)
    if s.dem is not None and s.dem.replay_after is not None:
        raise SceneError("dem.replay_after", s.dem.replay_after, "the replay after "
                         "dem.replay_after does not carry the drum wall of [heat.drum_wall]; "
                         "leave dem.replay_after out", n)
    if w.inner_alpha > 0 and s.gas is None:
        raise SceneError("gas.temperature", REQUIRED, "heat.drum_wall.inner_alpha > 0 needs "
                         "the temperature of the free gas in the drum, in K ([gas])", n)
    needs = {"flux": ("outer_flux",), "gas": ("outer_alpha", "outer_temperature"),
             "temperature": ("outer_temperature",)}[w.outside]
    for k in ("outer_flux", "outer_alpha", "outer_temperature"):
        v = getattr(w, k)
        if k in needs and v is None:
            raise SceneError(f"{key}.{k}", REQUIRED, f"outside = {w.outside!r} needs "
                             + " and ".join(needs), n)
        if k not in needs and v is not None:
            raise SceneError(f"{key}.{k}", v, f"outside = {w.outside!r} does not use {k}; "
                             "leave it out (it needs " + " and ".join(needs) + ")", n)


def _check_pneumatic(s) -> None:
    """Cross-field rules of motion model 'pneumatic' (drumheat.motion.pneumatic)."""
    n = s.name
    check_apparatus_tables(s, "channel", "height, gap, depth, length, gas_velocity, "
                           "solids_mass_flow", "of the channel")
    if s.gas is None:
        raise SceneError("gas.temperature", REQUIRED, "motion model 'pneumatic' needs the gas inlet "
                         "temperature [gas] temperature, in K", n)
    for eff in ("contact", "wall", "loss", "radiation", "internal"):
        if getattr(s.heat, eff) is not None:
            raise SceneError(f"heat.{eff}", "a table", "motion model 'pneumatic' exchanges heat "
                             "with the gas only ([heat.convection]); remove this table", n)
    c = s.heat.convection
    if c is not None:
        if c.correlation == "fluidized-bed":
            raise SceneError("heat.convection.correlation", c.correlation, "the channel uses a "
                             "single-sphere correlation at each particle's slip speed, e.g. "
                             "'gnielinski-kraychev'", n)
        if c.velocity is not None:
            raise SceneError("heat.convection.velocity", c.velocity, "motion model 'pneumatic' "
                             "computes each particle's slip velocity; leave velocity out", n)
        if c.porosity is not None:
            raise SceneError("heat.convection.porosity", c.porosity, "not used by motion model "
                             "'pneumatic' (single spheres in a dilute flow); leave it out", n)
    if c is not None and c.properties == "gas" and s.gas.kinematic_viscosity is None:
        raise SceneError("gas.kinematic_viscosity", REQUIRED, "properties = 'gas' takes the drag's "
                         "viscosity from [gas]: give kinematic_viscosity, in m2/s", n)
    for key in ("record_interval", "replay_after"):
        if getattr(s.dem, key) is not None:
            raise SceneError(f"dem.{key}", getattr(s.dem, key), "not supported by motion model "
                             "'pneumatic'; leave it out", n)
    if s.dem.thermal_substeps != 1 or s.dem.settle_time != 0:
        key = "thermal_substeps" if s.dem.thermal_substeps != 1 else "settle_time"
        raise SceneError(f"dem.{key}", getattr(s.dem, key), "motion model 'pneumatic' takes a "
                         "heat step every mechanical step and starts with an empty channel; "
                         "leave it out", n)
    ch = s.channel
    d_max = max(g.diameter for g in s.groups)
    if ch.gap <= d_max:
        raise SceneError("channel.gap", ch.gap, f"must exceed the largest particle diameter "
                         f"{d_max:g} m", n)
    if ch.height <= 4 * d_max:
        raise SceneError("channel.height", ch.height, "must be at least 4 particle diameters", n)
    if ch.depth > ch.length * (1 + 1e-12):
        raise SceneError("channel.depth", ch.depth, f"the simulated slice cannot be longer "
                         f"than the channel, channel.length = {ch.length:g} m", n)
    if ch.steady_after is not None and ch.steady_after >= s.run.duration:
        raise SceneError("channel.steady_after", ch.steady_after, "must be shorter than "
                         f"run.duration = {s.run.duration:g} s", n)
