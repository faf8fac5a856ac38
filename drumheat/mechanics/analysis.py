"""Analysis of DEM states: dynamic angle of repose, kinetic energy, bed centre of mass, the
per-particle mechanics written for ParaView."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["free_surface", "angle_of_repose", "center_of_mass", "section_contact_lengths",
           "SECTION_LENGTHS", "particle_mechanics", "PARTICLE_MECHANICS"]

#: the per-particle arrays of :func:`particle_mechanics`, in the order result files list them
PARTICLE_MECHANICS = ("velocity", "angular_velocity", "force", "coordination", "wall_contacts")


def particle_mechanics(dem, state) -> dict:
    """What each particle does mechanically in ``state``, as float32 arrays (for output files).

    Main arguments:
      dem: the :class:`~drumheat.mechanics.DEM` system that ``state`` belongs to.
      state: a :class:`~drumheat.mechanics.DEMState`.

    Returns a dict (keys :data:`PARTICLE_MECHANICS`):

    - ``velocity`` (N, dim) m/s and ``angular_velocity`` (N,) in 2D (the z component) or
      (N, 3) rad/s: the state's;
    - ``force`` (N, dim) N: the force on the particle without its weight, i.e. the contact
      forces of particles and walls (and an external force such as a channel's gas drag);
    - ``coordination`` (N,): number of particles it overlaps (the mechanical coordination
      number; the contacts that conduct may include small gaps, ``heat.contact.gap_tolerance``);
    - ``wall_contacts`` (N,): number of wall primitives it overlaps.

    Geometry only (the overlaps, as the contact law's ``ovl > 0``), not :meth:`DEM.contacts`:
    that would evaluate the contact law, in the C++ loop where the run uses it, which cannot be
    ``vmap``-ped over an ensemble's states; this can.
    """
    pos = state.position
    n = pos.shape[0]
    radius = dem.particles.radius.astype(pos.dtype)
    # per pair slot one float32 and no (M, dim) array (NeighborSetup.squared_distance); the
    # padding slots (index N) gather a clamped particle, count 0 and fall out of the sums
    i, j = state.nbrs.idx[0], state.nbrs.idx[1]
    d2 = dem.neighbor.squared_distance(pos[j], pos[i])
    touch = ((i < n) & (d2 < (radius[i] + radius[j]) ** 2)).astype(jnp.float32)
    coordination = (jax.ops.segment_sum(touch, i, n) + jax.ops.segment_sum(touch, j, n))
    wall_contacts = jnp.zeros(n, jnp.float32)
    for wall in dem.walls:
        distance = wall.evaluate(pos, state.time)[0]
        wall_contacts = wall_contacts + (distance < radius).astype(jnp.float32)
    weight = dem.particles.mass[:, None] * jnp.asarray(dem.gravity)
    f32 = jnp.float32
    return {"velocity": state.velocity.astype(f32),
            "angular_velocity": state.angular_velocity.astype(f32),
            "force": (state.force - weight.astype(state.force.dtype)).astype(f32),
            "coordination": coordination, "wall_contacts": wall_contacts}


def free_surface(position, radius, bin_width=None, central_fraction=0.6):
    """Free-surface points of a bed: the highest particle top in each bin across the drum.

    Gravity is along -y and the drum axis along z. The horizontal extent ``[x_min, x_max]``
    of the bed (particle centres) is split into bins of ``bin_width`` (default 1.5 x the mean
    diameter) along x, and in 3D also along z; in each bin the particle with the highest top
    ``y + r`` is a surface point ``(x, [z,] y + r)``. Only bins whose centre lies in the
    middle ``central_fraction`` of ``[x_min, x_max]`` are kept: near the wall the surface bends
    (it meets the shell) and is excluded.

    Returns (K, dim) surface points; columns x, y(top) in 2D and x, y(top), z in 3D.
    """
    pos = np.asarray(position, dtype=float)
    r = np.broadcast_to(np.asarray(radius, dtype=float), pos.shape[:1])
    dim = pos.shape[1]
    if bin_width is None:
        bin_width = 3.0 * float(np.mean(r))
    x = pos[:, 0]
    top = pos[:, 1] + r
    x_lo, x_hi = float(x.min()), float(x.max())
    mid = 0.5 * (x_lo + x_hi)
    half = 0.5 * central_fraction * (x_hi - x_lo)
    nb_x = max(1, int(math.ceil((x_hi - x_lo) / bin_width)))
    ix = np.clip(((x - x_lo) / bin_width).astype(int), 0, nb_x - 1)
    if dim == 3:
        z = pos[:, 2]
        nb_z = max(1, int(math.ceil((z.max() - z.min()) / bin_width)))
        iz = np.clip(((z - z.min()) / bin_width).astype(int), 0, nb_z - 1)
        key = ix * nb_z + iz
    else:
        key = ix
    pts = []
    for k in np.unique(key):
        sel = np.flatnonzero(key == k)
        best = sel[np.argmax(top[sel])]
        cx = x_lo + (ix[best] + 0.5) * bin_width
        if abs(cx - mid) > half:
            continue
        row = [x[best], top[best]] + ([pos[best, 2]] if dim == 3 else [])
        pts.append(row)
    return np.asarray(pts, dtype=float).reshape(-1, dim)


def angle_of_repose(position, radius, bin_width=None, central_fraction=0.6):
    """Dynamic angle of repose (degrees) of a bed in a drum, from a straight-line fit.

    Method: the free-surface points of :func:`free_surface` (highest particle top per bin
    across the central part of the bed) are fitted by least squares with a line
    ``y = a + b x`` (2D) or a plane ``y = a + b x + c z`` (3D, z = drum axis); the angle is
    ``atan(b)`` in degrees, positive when the surface rises towards +x. A drum turning
    counter-clockwise (rpm > 0) lifts the bed on the +x side, so its angle is positive.

    ``position`` may be one state (N, dim) or a series (T, N, dim); a series gives an array of
    T angles (average them over a steady interval for the dynamic angle).
    """
    pos = np.asarray(position, dtype=float)
    if pos.ndim == 3:
        return np.array([angle_of_repose(p, radius, bin_width, central_fraction) for p in pos])
    pts = free_surface(pos, radius, bin_width, central_fraction)
    if len(pts) < 2:
        raise ValueError("too few surface points for a fit; use a smaller bin_width")
    cols = [np.ones(len(pts)), pts[:, 0]]
    if pos.shape[1] == 3:
        cols.append(pts[:, 2])
    A = np.stack(cols, axis=1)
    coef, *_ = np.linalg.lstsq(A, pts[:, 1], rcond=None)
    return math.degrees(math.atan(coef[1]))


def center_of_mass(position, mass=None):
    """Mass-weighted centre (m) of the particles (equal masses if ``mass`` is None)."""
    pos = np.asarray(position, dtype=float)
    if mass is None:
        return pos.mean(axis=0)
    m = np.asarray(mass, dtype=float)
    return (m[:, None] * pos).sum(axis=0) / m.sum()


#: Keys of :func:`section_contact_lengths` that are contact lengths (m).
SECTION_LENGTHS = ("P1", "P2", "Wo", "Wi", "l_SG")


def _longest_run(centre, half, lo, hi, bridge):
    """Longest connected union ``(start, end)`` of the footprints ``[centre - half, centre +
    half]`` clipped to ``[lo, hi]``; footprints closer than ``bridge`` count as connected.
    None when empty."""
    if len(centre) == 0:
        return None
    a = np.clip(centre - half, lo, hi)
    b = np.clip(centre + half, lo, hi)
    order = np.argsort(a)
    a, b = a[order], b[order]
    runs, start, end = [], a[0], b[0]
    for x, y in zip(a[1:], b[1:]):
        if x <= end + bridge:
            end = max(end, y)
        else:
            runs.append((start, end))
            start, end = x, y
    runs.append((start, end))
    return max(runs, key=lambda ab: ab[1] - ab[0])


def _extend(run, crossings, reach):
    """Length of ``run`` after moving its ends out to a surface crossing within ``reach``."""
    if run is None:
        return 0.0
    lo, hi = run
    for x in crossings:
        if hi < x <= hi + reach:
            hi = x
        if lo - reach <= x < lo:
            lo = x
    return float(hi - lo)


def section_contact_lengths(position, radius, *, R1, R2, n_sections, plate_angle,
                            touch=0.25, min_surface_points=3, gamma_deg=None, extend=4.0):
    """Contact lengths of the bed in every section of a drum with radial plates (2D), m.

    The DEM counterpart of :func:`drumheat.models.sectional_drum.contact_lengths`
    (herz-sectional-drum.md section 1): per section the plate lengths ``P1``, ``P2``, the shell
    and inner arcs ``Wo``, ``Wi`` wetted by the bed and the free-surface length ``l_SG``, plus
    the section's free-surface angle, from the particle centres at one instant.

    Definitions (d = particle diameter, r = d/2):

    * Section: particle ``i`` belongs to section ``k`` when its polar angle lies between plate
      ``k`` (at ``plate_angle - k alpha``, alpha = 2 pi / n_sections) and plate ``k + 1``
      (clockwise from it). Plate ``k`` is the section's plate 1 (``B1C1``), plate ``k + 1`` its
      plate 2, and its Herz rotation angle is ``delta = 180 deg - (plate angle of k)``, mod 360.
    * Touching: a particle touches a surface when the gap between its surface and the wall,
      ``distance(centre, wall) - r``, is below ``touch x d`` (default a quarter diameter: the
      first layer, not the second, whose gap is >= 0.87 d).
    * Wetted length of a surface: each touching particle covers its footprint on the surface,
      the projection of its diameter (``[s - r, s + r]`` along a plate; on an arc of radius R
      the angle ``+- r / rho`` at the centre's radius ``rho``), clipped to the section's part
      of the surface; footprints less than 1.5 diameters apart are joined, and the wetted
      length is the longest joined run (the model's bed touches each surface along one
      interval; a stray particle elsewhere does not count). Beads cannot fill the acute
      corner between a wall and the free surface (a disc stays ``r / tan(theta / 2)`` from
      the apex of a corner of angle theta), so an end of the run that lies within
      ``extend`` diameters of the fitted surface line is moved out to that line.
    * Free surface: the section's particles are binned along x (bins of width d); the highest
      particle of each bin is a surface point ``(x, y + r)`` unless it touches a wall (then the
      bin is left out: the surface meets a wall there, or a plate overhangs the bed). A least
      squares line ``y = a + b x`` through the surface points gives the section's angle
      ``gamma = -atan(b)`` (Herz sign: the surface falls towards +x for gamma > 0) and the
      surface line ``x sin(gamma) + y cos(gamma) = c``; ``l_SG`` is the length of that line
      inside the annular section (the model's chord DE). With fewer than
      ``min_surface_points`` points the angle is NaN, and ``l_SG`` is taken from a line of the
      given ``gamma_deg`` through the mean surface point (NaN without ``gamma_deg``).

    Parameters
    ----------
    position : array (N, 2)
        Particle centres, m (drum axis at the origin, gravity along -y).
    radius : float or array (N,)
        Particle radii, m.
    R1, R2 : float
        Shell and inner-cylinder radius, m (R2 = 0: no inner cylinder).
    n_sections : int
        Number of radial plates.
    plate_angle : float
        Polar angle of plate 0 at this instant, rad (counter-clockwise from +x).
    touch : float
        Contact gap, in particle diameters.
    min_surface_points : int
        Fewest surface points for a free-surface fit.
    gamma_deg : float, optional
        Fallback surface angle for sections with too few surface points.
    extend : float
        Reach (in diameters) within which a wetted run is extended to the surface line.

    Returns
    -------
    dict of arrays (n_sections,)
        ``delta_deg`` (Herz rotation angle, deg), ``P1``, ``P2``, ``Wo``, ``Wi``, ``l_SG`` (m),
        ``gamma_deg`` (free-surface angle, deg, NaN if not fitted), ``c`` (offset of the
        surface line ``x sin(gamma) + y cos(gamma) = c``, m; with the fallback angle where not
        fitted), ``n`` (particles) and ``n_surface`` (surface points).
    """
    from drumheat.mechanics.pour import section_of
    from drumheat.models.sectional_drum import _chord_interval

    pos = np.asarray(position, dtype=float)[:, :2]
    r = np.broadcast_to(np.asarray(radius, dtype=float), pos.shape[:1])
    d_mean = 2.0 * float(np.mean(r))
    tol = touch * 2.0 * r
    bridge = 1.5 * d_mean  # a hole of more than 1.5 d along a wall would fill in a dense bed
    alpha = 2.0 * math.pi / n_sections
    sec = section_of(pos, n_sections, plate_angle)
    rho = np.hypot(pos[:, 0], pos[:, 1])
    phi = np.arctan2(pos[:, 1], pos[:, 0])
    out = {k: np.full(n_sections, np.nan) for k in
           ("delta_deg", *SECTION_LENGTHS, "gamma_deg", "c", "n", "n_surface")}
    for k in range(n_sections):
        phi1 = plate_angle - k * alpha
        phi2 = phi1 - alpha
        out["delta_deg"][k] = math.degrees(math.pi - phi1) % 360.0
        m = sec == k
        q, rk, rh, tk = pos[m], r[m], rho[m], tol[m]
        u = np.mod(phi1 - phi[m], 2.0 * math.pi)  # angle from plate 1 towards plate 2, rad
        out["n"][k] = m.sum()
        touching = np.zeros(len(q), bool)
        runs, scale = {}, {}
        for name, ang in (("P1", phi1), ("P2", phi2)):
            e = np.array([math.cos(ang), math.sin(ang)])
            s = q @ e
            perp = np.abs(q[:, 0] * e[1] - q[:, 1] * e[0])
            on = (perp - rk < tk) & (s > R2 - rk) & (s < R1 + rk)
            touching |= on
            runs[name] = _longest_run(s[on], rk[on], R2, R1, bridge)
        on = R1 - rh - rk < tk
        touching |= on
        runs["Wo"] = _longest_run(R1 * u[on], R1 * rk[on] / rh[on], 0.0, R1 * alpha, bridge)
        runs["Wi"] = None
        if R2 > 0:
            on = rh - R2 - rk < tk
            touching |= on
            runs["Wi"] = _longest_run(R2 * u[on], R2 * rk[on] / rh[on], 0.0, R2 * alpha,
                                      bridge)
        # free surface
        pts = np.zeros((0, 2))
        if len(q):
            x0 = q[:, 0].min()
            ib = ((q[:, 0] - x0) / d_mean).astype(int)
            top = q[:, 1] + rk
            rows = []
            for b in np.unique(ib):
                sel = np.flatnonzero(ib == b)
                best = sel[np.argmax(top[sel])]
                if not touching[best]:
                    rows.append((q[best, 0], top[best]))
            pts = np.asarray(rows, float).reshape(-1, 2)
        out["n_surface"][k] = len(pts)
        g = None
        if len(pts) >= min_surface_points:
            A = np.stack([np.ones(len(pts)), pts[:, 0]], axis=1)
            (a, b), *_ = np.linalg.lstsq(A, pts[:, 1], rcond=None)
            g = -math.atan(b)
            out["gamma_deg"][k] = math.degrees(g)
            c = a * math.cos(g)
        elif len(pts) and gamma_deg is not None:
            g = math.radians(gamma_deg)
            c = float(np.mean(pts[:, 0] * math.sin(g) + pts[:, 1] * math.cos(g)))
        if g is None:
            for name in ("P1", "P2", "Wo", "Wi"):
                out[name][k] = _extend(runs[name], (), 0.0)
            out["l_SG"][k] = 0.0 if len(q) == 0 else np.nan
            continue
        out["c"][k] = c
        # a wetted run ending near the surface line reaches it: beads cannot fill the acute
        # corner between a wall and the surface (a disc stays r / tan(theta/2) from the apex)
        reach = extend * d_mean
        for name, ang in (("P1", phi1), ("P2", phi2)):
            sg = math.sin(ang + g)
            cross = [c / sg] if abs(sg) > 1e-12 and R2 <= c / sg <= R1 else []
            out[name][k] = _extend(runs[name], cross, reach)
        for name, R in (("Wo", R1), ("Wi", R2)):
            cross = []
            if R > abs(c):
                p0 = math.asin(c / R)
                for ph in (p0 - g, math.pi - p0 - g):
                    uu = (phi1 - ph) % (2.0 * math.pi)
                    if uu <= alpha:
                        cross.append(R * uu)
            out[name][k] = _extend(runs[name], cross, reach)
        chords = []
        for R in (R1, R2):
            if R <= 0:
                chords.append(0.0)
                continue
            lo, hi = _chord_interval(R, c, g, phi1, phi2)
            chords.append(max(float(hi) - float(lo), 0.0))
        out["l_SG"][k] = chords[0] - chords[1]
    return out


def count_interfraction_contacts(pairs_i, pairs_j, mask, group, fractions=None):
    """Number of contacts between particles of different fractions.

    The mechanical-mixing experiment of the thesis (weigler-thermal-dem.md, section 11.2)
    counts white-red contacts over time. Each listed pair is counted once: if the contact list
    holds every contact twice (both directions, as a full jax-md neighbour list does), halve
    the result or mask one direction (``mask & (pairs_i < pairs_j)``).

    Parameters
    ----------
    pairs_i, pairs_j : array_like of int, shape (..., P)
        Particle indices of the listed pairs (leading axes, e.g. time, are kept). Padding
        entries may hold any index, also N (jax-md's padding value), if masked out.
    mask : array_like of bool, shape (..., P) or None
        True for pairs that are real contacts. None: every pair whose indices are both < N.
    group : array_like of int, shape (N,)
        Fraction label of every particle.
    fractions : tuple (a, b), optional
        Count only contacts between group a and group b; default: any two different groups.

    Returns
    -------
    array of int, shape (...)
        Number of inter-fraction contacts: a jax.Array where an input is one (or traced), a
        numpy array for numpy or list inputs (counted on the host: the same counts, without
        the compiled program per operation and pair count that eager jnp would make,
        :func:`drumheat.devices.to_device`).
    """
    inputs = (pairs_i, pairs_j, mask, group)
    xp = jnp if any(isinstance(a, jax.Array) for a in inputs) else np
    group = xp.asarray(group)
    n = group.shape[0]
    i = xp.asarray(pairs_i)
    j = xp.asarray(pairs_j)
    in_range = (i >= 0) & (i < n) & (j >= 0) & (j < n)
    valid = in_range if mask is None else (xp.asarray(mask).astype(bool) & in_range)
    gi = group[xp.clip(i, 0, n - 1)]
    gj = group[xp.clip(j, 0, n - 1)]
    if fractions is None:
        between = gi != gj
    else:
        a, b = fractions
        between = ((gi == a) & (gj == b)) | ((gi == b) & (gj == a))
    return xp.sum(valid & between, axis=-1)
