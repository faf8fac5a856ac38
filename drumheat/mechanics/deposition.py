"""Geometric deposition of a 2D packing in a drum (drop and roll).

Each particle is dropped at a random horizontal position, falls straight down until it touches
the bed or the drum wall, and then rolls down over what it touches (steepest descent, no
friction, no bouncing) until it rests in a stable position: supported by two contacts on
opposite sides of its centre, or at the lowest point of the drum. This is the classical
sequential deposition of Visscher & Bolsterli (1972) in a circular container. It gives a
random packing with a mean coordination near 4, like a poured monolayer (the packings of
weigler-thermal-dem.md Table 5-2 / App. A4 have about 3.7 contacts per particle, section 10).

Groups are poured in the order of the scene (first group at the bottom) or in shuffled order.
Runs on the host with numpy; it is called once per scene.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Packing(NamedTuple):
    """Particle positions and sizes.

    Attributes
    ----------
    position : ndarray, shape (N, dim)
        Centre positions, m; drum axis through the origin, gravity along -y.
    diameter : ndarray, shape (N,)
        m.
    group : ndarray of int, shape (N,)
        Group index of each particle (order of ``[[groups]]``).
    """

    position: np.ndarray
    diameter: np.ndarray
    group: np.ndarray

    def save(self, path) -> None:
        """Write the packing to an ``.npz`` file (arrays position, diameter, group)."""
        np.savez(path, position=self.position, diameter=self.diameter, group=self.group)

    @classmethod
    def load(cls, path) -> "Packing":
        """Read a packing written by :meth:`save`, or by
        :func:`drumheat.mechanics.pour.save_packing` (which stores radii instead of diameters)."""
        with np.load(path) as f:
            d = f["diameter"] if "diameter" in f.files else 2.0 * f["radius"]
            return cls(np.asarray(f["position"], float), np.asarray(d, float),
                       np.asarray(f["group"], int))


_EPS = 1e-12


def _arc_hits(P, L, theta0, direction, travel_max, centres, radii):
    """Travel (rad) along the circle (P, L) from theta0 in ``direction`` to the first entry
    into any circle (centres, radii); inf where none within travel_max."""
    d = centres - P
    dd = np.hypot(d[:, 0], d[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_half = (L**2 + dd**2 - radii**2) / (2 * L * dd)
    ok = (np.abs(cos_half) <= 1.0) & (dd > _EPS)
    base = np.arctan2(d[:, 1], d[:, 0])
    half = np.arccos(np.clip(cos_half, -1.0, 1.0))
    best = np.full(len(radii), np.inf)
    for sgn in (-1.0, 1.0):
        ang = base + sgn * half
        travel = np.mod(direction * (ang - theta0), 2 * np.pi)
        # the circle must be entered, not left: just past the crossing we must be inside
        probe = theta0 + direction * (travel + 1e-7)
        pos = P + L * np.stack([np.cos(probe), np.sin(probe)], axis=1)
        inside = np.hypot(*(pos - centres).T) < radii
        valid = ok & (travel > 1e-9) & (travel <= travel_max) & inside
        best = np.where(valid & (travel < best), travel, best)
    return best


def _wall_exit(P, L, theta0, direction, travel_max, R_wall):
    """Travel along the circle (P, L) to the first point outside the circle |p| = R_wall."""
    dd = np.hypot(*P)
    if dd < _EPS:
        return np.inf
    cos_half = (L**2 + dd**2 - R_wall**2) / (2 * L * dd)
    if abs(cos_half) > 1.0:
        return np.inf
    base = np.arctan2(-P[1], -P[0])  # direction from P to the origin
    half = np.arccos(cos_half)
    best = np.inf
    for sgn in (-1.0, 1.0):
        travel = np.mod(direction * (base + sgn * half - theta0), 2 * np.pi)
        probe = theta0 + direction * (travel + 1e-7)
        pos = P + L * np.array([np.cos(probe), np.sin(probe)])
        if 1e-9 < travel <= travel_max and np.hypot(*pos) > R_wall:
            best = min(best, travel)
    return best


def _drop_one(rng, r, pos, rad, R_wall, max_moves=2000):
    """Position of one disc of radius r dropped into the drum, or None if it got stuck."""
    n = len(rad)
    x = rng.uniform(-0.95, 0.95) * R_wall
    p = np.array([x, np.sqrt(max(R_wall**2 - x**2, 0.0))])
    pivot = None  # None: falling; -1: wall; k >= 0: disc k
    exclude = -2
    for _ in range(max_moves):
        if pivot is None:
            # fall straight down from p
            y_best, who = -np.sqrt(max(R_wall**2 - p[0] ** 2, 0.0)), -1
            if n:
                dx = p[0] - pos[:, 0]
                reach = rad + r
                close = np.abs(dx) < reach
                if exclude >= 0:
                    close[exclude] = False
                y_land = np.where(close, pos[:, 1] + np.sqrt(np.maximum(reach**2 - dx**2, 0)),
                                  -np.inf)
                y_land = np.where(y_land <= p[1] + 1e-12, y_land, -np.inf)
                k = int(np.argmax(y_land))
                if y_land[k] > y_best:
                    y_best, who = y_land[k], k
            p = np.array([p[0], y_best])
            pivot, exclude = who, -2
            continue
        if pivot == -1:
            theta = np.arctan2(p[1], p[0])
            if abs(p[0]) < 1e-12 * R_wall:
                return p
            direction = -1.0 if p[0] > 0 else 1.0  # toward -pi/2
            travel_max = abs(np.mod(direction * (-np.pi / 2 - theta), 2 * np.pi))
            hits = _arc_hits(np.zeros(2), R_wall, theta, direction, travel_max, pos, rad + r) \
                if n else np.array([np.inf])
            k = int(np.argmin(hits))
            if not np.isfinite(hits[k]):
                return np.array([0.0, -R_wall])
            theta += direction * hits[k]
            p = R_wall * np.array([np.cos(theta), np.sin(theta)])
            # supports: wall (contact on the side of p) and disc k
            if np.sign(pos[k, 0] - p[0]) != np.sign(p[0]):
                return p
            pivot = k
            continue
        # rolling over disc `pivot`
        P, L = pos[pivot], rad[pivot] + r
        theta = np.arctan2(p[1] - P[1], p[0] - P[0])
        if np.sin(theta) <= 1e-12:
            pivot, exclude = None, pivot  # below the equator: it falls
            continue
        c = np.cos(theta)
        direction = -1.0 if c > 0 else (1.0 if c < 0 else rng.choice([-1.0, 1.0]))
        end = 0.0 if direction < 0 else np.pi
        travel_max = abs(end - theta)
        others = np.ones(n, bool)
        others[pivot] = False
        hits = np.full(n, np.inf)
        hits[others] = _arc_hits(P, L, theta, direction, travel_max, pos[others],
                                 rad[others] + r)
        t_wall = _wall_exit(P, L, theta, direction, travel_max, R_wall)
        k = int(np.argmin(hits))
        t_disc = hits[k]
        if not np.isfinite(t_disc) and not np.isfinite(t_wall):
            theta = end
            p = P + L * np.array([np.cos(theta), np.sin(theta)])
            pivot, exclude = None, pivot
            continue
        if t_wall < t_disc:
            theta += direction * t_wall
            p = P + L * np.array([np.cos(theta), np.sin(theta)])
            p *= R_wall / np.hypot(*p)  # snap onto the wall circle
            if np.sign(P[0] - p[0]) != np.sign(p[0]):
                return p
            pivot = -1
            continue
        theta += direction * t_disc
        p = P + L * np.array([np.cos(theta), np.sin(theta)])
        if np.sign(P[0] - p[0]) != np.sign(pos[k, 0] - p[0]):
            return p
        pivot = k
    return None


def deposit_2d(diameters, groups, drum_diameter, seed=0, arrangement="layers",
               max_attempts=50) -> Packing:
    """Pour discs (spheres in a monolayer) one by one into a 2D drum.

    Parameters
    ----------
    diameters : array_like, shape (N,)
        Particle diameters, m, in pouring order of the groups.
    groups : array_like of int, shape (N,)
        Group index per particle.
    drum_diameter : float
        Inner drum diameter, m.
    seed : int
        Random seed; the same seed gives the same packing.
    arrangement : {"layers", "mixed"}
        "layers" pours the particles in the given order (first group at the bottom); "mixed"
        shuffles the pouring order.
    max_attempts : int
        Drops tried per particle before giving up.

    Returns
    -------
    Packing
        Particles in the order given (not the pouring order).

    Raises
    ------
    ValueError
        If a particle finds no place (the drum is too full).
    """
    diameters = np.asarray(diameters, float)
    groups = np.asarray(groups, int)
    rng = np.random.default_rng(seed)
    order = np.arange(len(diameters))
    if arrangement == "mixed":
        order = rng.permutation(order)
    elif arrangement != "layers":
        raise ValueError(f"arrangement must be 'layers' or 'mixed', not {arrangement!r}")
    R = 0.5 * drum_diameter
    pos = np.zeros((0, 2))
    rad = np.zeros(0)
    placed = np.zeros((len(diameters), 2))
    for idx in order:
        r = 0.5 * diameters[idx]
        for _ in range(max_attempts):
            p = _drop_one(rng, r, pos, rad, R - r)
            if p is None:
                continue
            if len(rad) and np.min(np.hypot(*(pos - p).T) - rad - r) < -1e-9 * r:
                continue  # numerical trouble: try another drop
            break
        else:
            raise ValueError(f"deposition: particle {idx} found no stable place after "
                             f"{max_attempts} drops; the drum (D = {drum_diameter} m) is too full")
        pos = np.vstack([pos, p])
        rad = np.append(rad, r)
        placed[idx] = p
    return Packing(placed, diameters, groups)
