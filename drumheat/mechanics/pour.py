"""Bed generation: pour particles into a drum (or any walled domain) and let them settle.

Procedure (:func:`pour`):

1. Insertion sites: a square (2D) / cubic (3D) lattice of spacing ``1.1 x`` the largest
   diameter covering the domain; a site is usable if every wall is at least ``1.05 r_max``
   away and no already settled particle is closer than the two radii plus 5 % of a diameter.
   Sites are filled from the lowest up (gravity along -y), each jittered by up to 4 % of the
   spacing (seeded), so inserted particles never overlap.
2. Insert as many particles of the current batch as there are free sites, then integrate with
   the drum at rest (rpm = 0) until the kinetic energy (translation + rotation) falls below
   ``ke_tol x M g d_mean`` (the energy of lifting the whole batch by one diameter), checked
   every ``chunk`` steps after a minimum settling time.
3. Repeat until all particles are in. ``layered=True`` inserts group by group (first group at
   the bottom), each group settling before the next; ``layered=False`` inserts the particles
   in random order (mixed groups).

Packings are stored with :func:`save_packing` / :func:`load_packing` as ``.npz`` with arrays
``position`` (N, dim) m, ``radius`` (N,) m, ``group`` (N,) int, ``density`` (N,) kg/m^3,
``ptype`` (N,) int and scalar metadata.
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.devices import to_device
from drumheat.geometry.walls import expand_walls, wall_bounds, walls_at_rest
from drumheat.mechanics.integrator import make_dem, make_particles

__all__ = [
    "Packing",
    "PourWarning",
    "pour",
    "insertion_sites",
    "save_packing",
    "load_packing",
    "particles_for_filling_degree",
    "pour_sections",
    "section_of",
]


class Packing(NamedTuple):
    """A particle packing (SI). ``info`` holds scalar metadata (dim, periodic_length, ...)."""

    position: np.ndarray
    radius: np.ndarray
    group: np.ndarray
    density: np.ndarray
    ptype: np.ndarray
    info: dict = {}


def save_packing(path, packing: Packing, **meta):
    """Write a packing to ``path`` (.npz). Extra keyword arguments are stored as metadata."""
    info = dict(packing.info)
    info.update(meta)
    arrays = dict(position=np.asarray(packing.position), radius=np.asarray(packing.radius),
                  group=np.asarray(packing.group), density=np.asarray(packing.density),
                  ptype=np.asarray(packing.ptype))
    for k, v in info.items():
        arrays["meta_" + k] = np.asarray(np.nan if v is None else v)
    np.savez(path, **arrays)


def load_packing(path) -> Packing:
    """Read a packing written by :func:`save_packing`."""
    with np.load(path) as z:
        info = {}
        for k in z.files:
            if k.startswith("meta_"):
                v = z[k]
                v = v.item() if v.ndim == 0 else v
                if isinstance(v, float) and math.isnan(v):
                    v = None
                info[k[5:]] = v
        n = z["radius"].shape[0]
        return Packing(
            position=z["position"], radius=z["radius"],
            group=z["group"] if "group" in z.files else np.zeros(n, int),
            density=z["density"] if "density" in z.files else np.full(n, np.nan),
            ptype=z["ptype"] if "ptype" in z.files else np.zeros(n, int), info=info)


def particles_for_filling_degree(fill, drum_radius, particle_radius, dim, length=None,
                                 packing_fraction=None):
    """Number of particles that fill ``fill`` (0..1) of the drum cross-section.

    3D: ``N = fill pi R^2 L phi / (4/3 pi r^3)`` with bed solid fraction phi (default 0.6,
    the LIGGGHTS bed measured 0.57-0.59, peers/liggghts/README.md). 2D monolayer:
    ``N = fill pi R^2 phi / (pi r^2)`` with area fraction phi (default 0.85 for a random
    dense disc packing; 70 spheres of 4 mm in a 50 mm drum then fill 53 %, the thesis says
    about 50 %, Weigler digest sec. 12 item 22).
    """
    R, r = float(drum_radius), float(particle_radius)
    if dim == 3:
        if length is None:
            raise ValueError("3D needs the drum length")
        phi = 0.6 if packing_fraction is None else packing_fraction
        return int(round(fill * math.pi * R * R * length * phi / (4.0 / 3.0 * math.pi * r**3)))
    phi = 0.85 if packing_fraction is None else packing_fraction
    return int(round(fill * R * R * phi / (r * r)))


def insertion_sites(walls, dim, spacing, clearance, bounds=None, periodic_length=None):
    """Lattice sites (M, dim) of the given spacing whose distance to every wall > clearance."""
    walls = expand_walls(walls)
    if bounds is None:
        lo, hi = wall_bounds(walls, dim)
    else:
        lo, hi = (np.asarray(b, dtype=float).copy() for b in bounds)
    axes = []
    for a in range(dim):
        if periodic_length is not None and a == dim - 1:
            nz = max(1, int(math.floor(periodic_length / spacing)))
            axes.append((np.arange(nz) + 0.5) * periodic_length / nz)
            continue
        if not (np.isfinite(lo[a]) and np.isfinite(hi[a])):
            raise ValueError("the walls do not bound the domain; pass bounds=(lo, hi)")
        axes.append(np.arange(lo[a] + clearance, hi[a] - clearance + 1e-12, spacing))
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
    ok = np.ones(len(grid), bool)
    xg = to_device(grid)
    for w in walls:
        ok &= np.asarray(_distance(w, xg)) > clearance
    return grid[ok]


@jax.jit
def _distance(wall, x):
    """The signed distance of the points ``x`` to ``wall`` at t = 0, as one compiled program
    (an eager evaluation compiles each of its operations: drumheat.devices.to_device)."""
    return wall.distance(x, 0.0)


def _free_sites(sites, placed, r_placed, r_new, gap, periodic_length):
    if placed is None or len(placed) == 0:
        return np.ones(len(sites), bool)
    free = np.ones(len(sites), bool)
    block = 4096
    for s in range(0, len(sites), block):
        d = sites[s:s + block, None, :] - placed[None, :, :]
        if periodic_length is not None:
            d[..., -1] -= periodic_length * np.round(d[..., -1] / periodic_length)
        dist = np.sqrt(np.sum(d * d, axis=-1))
        free[s:s + block] = np.all(dist > r_placed[None, :] + r_new + gap, axis=1)
    return free


def _pour_inputs(radius, density, group, ptype, walls, seed):
    """Per-particle arrays, walls at rest, random generator and lattice spacing of a pour."""
    r_all = np.asarray(radius, dtype=float).reshape(-1)
    n = r_all.size
    rho_all = np.broadcast_to(np.asarray(density, dtype=float), (n,)).copy()
    grp = np.zeros(n, int) if group is None else np.asarray(group, int).reshape(-1)
    pt = np.zeros(n, int) if ptype is None else np.asarray(ptype, int).reshape(-1)
    r_max = float(r_all.max())
    return (r_all, rho_all, grp, pt, walls_at_rest(walls), np.random.default_rng(seed), r_max,
            2.2 * r_max)


def pour(radius, density, walls, params, *, dim, group=None, ptype=None, layered=True,
         periodic_length=None, bounds=None, gravity=None, seed=0, dt=None,
         safety_factor=0.2, ke_tol=1e-4, min_time=0.05, max_time=5.0, chunk=2000,
         dtype=jnp.float64, verbose=False) -> Packing:
    """Fill the domain with particles and let them settle (see the module docstring).

    Args:
      radius, density: per particle (m, kg/m^3); density may be a scalar.
      walls, params: as for :func:`drumheat.mechanics.make_dem` (rotation is stopped).
      dim: 2 or 3. group, ptype: per-particle group / material type (default 0).
      layered: True = group by group (first group at the bottom); False = mixed.
      ke_tol: settling threshold, KE < ke_tol * M g d_mean (J); the default 1e-4 means an rms
        speed of about sqrt(2e-4 g d) (3 mm/s for d = 4 mm). Much lower values may not be
        reached without rolling resistance: resting spheres keep rolling back and forth. min_time / max_time: settling
        time per batch (s); reaching max_time gives a warning and the current state.
    Returns:
      :class:`Packing` with the settled positions, in the input particle order.
    """
    r_all, rho_all, grp, pt, walls_rest, rng, r_max, spacing = _pour_inputs(
        radius, density, group, ptype, walls, seed)
    n = r_all.size
    sites = insertion_sites(walls_rest, dim, spacing, 1.05 * r_max, bounds, periodic_length)
    sites = sites[np.argsort(sites[:, 1], kind="stable")]  # lowest first
    if layered:
        order = np.argsort(grp, kind="stable")
        batches = [order[grp[order] == g] for g in np.unique(grp)]
    else:
        batches = [rng.permutation(n)]
    g_norm = 9.81 if gravity is None else float(np.linalg.norm(gravity))

    placed_idx = np.zeros(0, int)
    placed_pos = np.zeros((0, dim))
    for batch in batches:
        todo = list(batch)
        while todo:
            free = _free_sites(sites, placed_pos, r_all[placed_idx], r_max, 0.1 * r_max,
                               periodic_length)
            avail = sites[free]
            if len(avail) == 0:
                raise ValueError(
                    f"no room left to insert particles: {len(placed_idx)} of {n} placed; the "
                    "domain is too small for this many particles")
            k = min(len(todo), len(avail))
            new_idx = np.asarray(todo[:k])
            todo = todo[k:]
            jitter = rng.uniform(-0.04, 0.04, (k, dim)) * spacing
            new_pos = avail[:k] + jitter
            if periodic_length is not None:
                new_pos[:, -1] %= periodic_length
            placed_idx = np.concatenate([placed_idx, new_idx])
            placed_pos = np.concatenate([placed_pos, new_pos])
            placed_pos = _settle(placed_idx, placed_pos, r_all, rho_all, pt, walls_rest, params,
                                 dim, periodic_length, bounds, gravity, dt, safety_factor,
                                 ke_tol, g_norm, min_time, max_time, chunk, dtype, verbose)
    pos = np.zeros((n, dim))
    pos[placed_idx] = placed_pos
    info = dict(dim=dim, periodic_length=periodic_length, seed=seed, layered=bool(layered))
    return Packing(pos, r_all, grp, rho_all, pt, info)


def section_of(position, n_sections, phase):
    """Section index of each point of a drum with ``n_sections`` radial plates, (N,) int.

    Plate ``j`` lies at the polar angle ``phase - j 2 pi / n_sections`` (rad); section ``j`` is
    the sector between plates ``j`` and ``j + 1`` (clockwise from plate ``j``).
    """
    p = np.asarray(position, float)
    phi = np.arctan2(p[..., 1], p[..., 0])
    alpha = 2.0 * math.pi / n_sections
    k = np.floor(np.mod(phase - phi, 2.0 * math.pi) / alpha).astype(int)
    return np.clip(k, 0, n_sections - 1)


def pour_sections(radius, density, walls, params, *, n_sections, phase, dim, group=None,
                  ptype=None, layered=True, periodic_length=None, gravity=None, seed=0,
                  dt=None, safety_factor=0.2, ke_tol=1e-4, min_time=0.05, max_time=0.5,
                  surface_angle=0.0, chunk=2000, dtype=jnp.float64,
                  verbose=False) -> Packing:
    """Fill a drum divided by radial plates with the same number of particles per section.

    Like :func:`pour`, but the insertion sites (square lattice of spacing 1.1 x the largest
    diameter, at least 1.05 r_max from every wall) are assigned to the sections of
    :func:`section_of` and each section takes the lowest ``N / n_sections`` of its sites (the
    first ``N mod n_sections`` sections one more), jittered by up to 4 % of the spacing. All
    particles are inserted at once and settle together with the drum at rest. Every section so
    carries the same load (herz-sectional-drum.md section 1: all sections carry the same
    filling degree), which pouring from above would not give: it fills the lowest sections
    first. ``layered`` puts the first group at the bottom of every section.

    ``surface_angle`` (degrees) tilts the free surfaces: sites are taken lowest first along
    ``n = (sin g, cos g)``, so each section's surface falls towards +x at g (Herz's convention,
    herz-sectional-drum.md section 1), e.g. near the angle of repose to shorten a warm-up.
    The settling stops at ``max_time`` (default 0.5 s) at the latest.
    """
    r_all, rho_all, grp, pt, walls_rest, rng, r_max, spacing = _pour_inputs(
        radius, density, group, ptype, walls, seed)
    n = r_all.size
    sites = insertion_sites(walls_rest, dim, spacing, 1.05 * r_max, None, periodic_length)
    sec = section_of(sites[:, :2], n_sections, phase)
    order = np.argsort(grp, kind="stable") if layered else rng.permutation(n)
    counts = np.full(n_sections, n // n_sections)
    counts[: n % n_sections] += 1
    pos = np.zeros((n, dim))
    start = 0
    for k in range(n_sections):
        mine = sites[sec == k]
        if len(mine) < counts[k]:
            raise ValueError(f"section {k} holds {len(mine)} insertion sites but needs "
                             f"{counts[k]} particles; lower the particle count")
        g = math.radians(surface_angle)
        height = mine[:, 0] * math.sin(g) + mine[:, 1] * math.cos(g)
        mine = mine[np.argsort(height, kind="stable")][: counts[k]]
        idx = order[start:start + counts[k]]
        start += counts[k]
        pos[idx] = mine + rng.uniform(-0.04, 0.04, mine.shape) * spacing
    if periodic_length is not None:
        pos[:, -1] %= periodic_length
    g_norm = 9.81 if gravity is None else float(np.linalg.norm(gravity))
    idx = np.arange(n)
    pos = _settle(idx, pos, r_all, rho_all, pt, walls_rest, params, dim, periodic_length, None,
                  gravity, dt, safety_factor, ke_tol, g_norm, min_time, max_time, chunk, dtype,
                  verbose)
    info = dict(dim=dim, periodic_length=periodic_length, seed=seed, layered=bool(layered),
                n_sections=n_sections)
    return Packing(pos, r_all, grp, rho_all, pt, info)


class PourWarning(UserWarning):
    """A poured bed did not come to rest within the settling time (what it means and what to do
    is in the message)."""


def _settle(idx, pos, r_all, rho_all, pt, walls, params, dim, periodic_length, bounds, gravity,
            dt, safety_factor, ke_tol, g_norm, min_time, max_time, chunk, dtype, verbose):
    particles = make_particles(r_all[idx], rho_all[idx], ptype=pt[idx])
    dem = make_dem(particles, walls, params, dim=dim, dt=dt, safety_factor=safety_factor,
                   gravity=gravity, periodic_length=periodic_length, bounds=bounds, dtype=dtype,
                   chunk=chunk)
    state = dem.init(pos)
    m_tot = float(np.sum(np.asarray(particles.mass)))
    d_mean = 2.0 * float(np.mean(r_all[idx]))
    threshold = ke_tol * m_tot * g_norm * d_mean
    n_min = int(math.ceil(min_time / dem.dt))
    state = dem.run(state, n_min, chunk=chunk)
    n_max = int(math.ceil(max_time / dem.dt))
    steps = n_min
    while True:
        e = dem.energies(state)
        ke = e["kinetic"] + e["rotational"]
        if verbose:
            print(f"pour: N={len(idx)} t={float(state.time):.4f} s KE={ke:.3e} J "
                  f"(threshold {threshold:.3e})")
        if ke < threshold:
            break
        if steps >= n_max:
            warnings.warn(
                f"the poured bed has not come to rest after {max_time} s of settling (kinetic "
                f"energy {ke:.3g} J, rest means below {threshold:.3g} J = {ke_tol} x the bed's "
                "weight x one diameter); the run starts from this still-moving bed. In a turning "
                "drum that is harmless (the bed is set moving anyway; leave the first "
                "revolution out of averages, e.g. with dem.replay_cycle); for a resting bed or "
                "a packing you want to measure, settle it longer (dem.settle_time) or use "
                "softer contacts with more damping while it settles",
                PourWarning, stacklevel=3)
            break
        state = dem.run(state, chunk, chunk=chunk)
        steps += chunk
    return np.asarray(state.position, dtype=float)
