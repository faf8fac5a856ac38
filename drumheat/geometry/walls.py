"""Analytic wall primitives for granular mechanics (rotating drums, internals, tube bundles).

Conventions (shared/DESIGN.md, "Coordinates"):

* The drum axis passes through the origin; in 3D it is the z axis. In 2D the scene is the x-y
  plane (a slice through the drum).
* Gravity points along -y (that is the caller's choice; walls do not care).
* Rotation is about +z, positive = counter-clockwise seen from +z, with angular velocity
  ``omega = 2 pi rpm / 60`` (rad/s) and angle ``phi(t) = phase + omega t`` (rad).

Every primitive answers one question for an array of points ``x`` of shape ``(N, dim)`` at
time ``t`` (s), :meth:`Wall.evaluate`::

    dist, normal, v_wall = wall.evaluate(x, t)

* ``dist`` (N,), m: signed distance from the wall surface to the point, **positive inside the
  particle domain**. A sphere of radius r touches the wall when ``dist < r`` and then overlaps
  it by ``r - dist`` (Weigler digest, weigler-thermal-dem.md sec. 4 [2.4], with a wall as a
  partner of infinite radius).
* ``normal`` (N, dim): unit vector from the wall surface towards the point (into the domain);
  the wall pushes a touching particle along ``+normal``.
* ``v_wall`` (N, dim), m/s: velocity of the wall material at the surface point closest to
  ``x`` (``x - dist * normal``); for a rotating wall ``omega e_z x p``.

Walls are equinox modules, so a collection of walls is a PyTree: ``rpm``, radii, positions and
``temperature`` are array leaves (differentiable, vmappable); ``wall_id`` is static. The
integer ``wall_id`` labels a wall for the heat model; several primitives may share one id
(for example the faces of a :class:`Box`). ``temperature`` (K) is ``None`` for a wall that
exchanges no heat.
"""

from __future__ import annotations

import math
from typing import Optional, Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np

__all__ = [
    "Wall",
    "DrumShell",
    "EndPlate",
    "RadialPlate",
    "InnerCylinder",
    "FixedCylinder",
    "Plane",
    "Box",
    "Segment",
    "rpm_to_omega",
    "expand_walls",
    "walls_at_rest",
    "wall_bounds",
]

_TINY = 1e-30


def rpm_to_omega(rpm):
    """Angular velocity in rad/s from revolutions per minute: ``omega = 2 pi rpm / 60``."""
    return 2.0 * math.pi * rpm / 60.0


def _rot_velocity(omega, p, dim):
    """Velocity ``omega e_z x p`` (..., dim) of a point p of a body rotating about the z axis;
    only p's in-plane components (``p[..., :2]``) enter.

    Built in one ``stack`` from the in-plane point (not from p embedded in 3D first): on
    XLA:CPU the embedding was a pass of its own over (N, 3) per wall and step."""
    vx = -omega * p[..., 1]
    vy = omega * p[..., 0]
    return jnp.stack([vx, vy] + [jnp.zeros_like(vx)] * (dim - 2), axis=-1)


def _embed_xy(v_xy, dim):
    """Pad an (..., 2) in-plane vector to (..., dim) with a zero z component."""
    if dim == 2:
        return v_xy
    return jnp.concatenate([v_xy, jnp.zeros_like(v_xy[..., :1])], axis=-1)


def _safe_unit(v):
    """Unit vector and length of v (..., k); zero-length vectors give (1, 0, ...) and 0."""
    r = jnp.sqrt(jnp.sum(v * v, axis=-1))
    safe = jnp.where(r > _TINY, r, 1.0)
    u = v / safe[..., None]
    fallback = jnp.zeros_like(v).at[..., 0].set(1.0)
    u = jnp.where((r > _TINY)[..., None], u, fallback)
    return u, r


class Wall(eqx.Module):
    """Base class of wall primitives; see the module docstring for the contract."""

    def evaluate(self, x, t):  # pragma: no cover - abstract
        raise NotImplementedError

    def distance(self, x, t=0.0):
        """Signed distance (m), positive inside the particle domain."""
        return self.evaluate(x, t)[0]

    def normal(self, x, t=0.0):
        """Unit normal from the wall into the domain, at the point closest to x."""
        return self.evaluate(x, t)[1]

    def velocity(self, x, t=0.0):
        """Velocity (m/s) of the wall surface at the point closest to x."""
        return self.evaluate(x, t)[2]

    def primitives(self):
        """The primitives this wall is made of (a composite such as Box expands itself)."""
        return (self,)

    def bounds(self, dim):
        """Axis-aligned bounds ``(lo, hi)`` (arrays of length dim, NaN = unbounded) or None."""
        return None

    def at_rest(self):
        """A copy that does not move (rpm = 0), e.g. for pouring a bed into a resting drum."""
        return self


class DrumShell(Wall):
    """Rotating drum shell: cylinder of ``radius`` about the z axis (a circle in 2D).

    Domain: ``rho = |x_xy| < radius``. ``dist = radius - rho``, normal ``-e_rho``, wall velocity
    ``omega * radius * e_phi`` (omega = 2 pi rpm / 60, CCW positive).
    """

    radius: float
    rpm: float = 0.0
    temperature: Optional[float] = None
    wall_id: int = eqx.field(static=True, default=0)

    def evaluate(self, x, t):
        dim = x.shape[-1]
        e_rho, rho = _safe_unit(x[..., :2])
        dist = self.radius - rho
        normal = _embed_xy(-e_rho, dim)
        v = _rot_velocity(rpm_to_omega(self.rpm), self.radius * e_rho, dim)
        return dist, normal, v

    def bounds(self, dim):
        lo = np.full(dim, np.nan)
        hi = np.full(dim, np.nan)
        r = float(self.radius)
        lo[:2], hi[:2] = -r, r
        return lo, hi

    def at_rest(self):
        return eqx.tree_at(lambda w: w.rpm, self, 0.0)


class EndPlate(Wall):
    """Flat end plate normal to z at ``z = z0`` (3D only).

    ``side = +1``: the domain is ``z > z0`` (the plate at the low end); ``side = -1``: domain
    ``z < z0``. With ``rpm != 0`` the plate rotates with the drum about the z axis (its surface
    velocity is ``omega e_z x (x, y)``); its geometry does not change.
    """

    z0: float
    side: int = eqx.field(static=True, default=1)
    rpm: float = 0.0
    temperature: Optional[float] = None
    wall_id: int = eqx.field(static=True, default=0)

    def evaluate(self, x, t):
        if x.shape[-1] != 3:
            raise ValueError("EndPlate exists only in 3D (dim = 3)")
        dist = self.side * (x[..., 2] - self.z0)
        normal = jnp.broadcast_to(jnp.asarray([0.0, 0.0, float(self.side)], x.dtype), x.shape)
        v = _rot_velocity(rpm_to_omega(self.rpm), x, 3)  # at (x, y, z0): the same
        return dist, normal, v

    def bounds(self, dim):
        lo = np.full(dim, np.nan)
        hi = np.full(dim, np.nan)
        if self.side > 0:
            lo[2] = float(self.z0)
        else:
            hi[2] = float(self.z0)
        return lo, hi

    def at_rest(self):
        return eqx.tree_at(lambda w: w.rpm, self, 0.0)


class RadialPlate(Wall):
    """Radial plate (lifter / section wall) rotating with the drum.

    In the x-y plane a segment from ``r_inner`` to ``r_outer`` along the direction
    ``phi(t) = phase + omega t`` (rad; omega = 2 pi rpm / 60), of total ``thickness`` (m,
    0 = a zero-thickness plate); in 3D it extends along z. Particles may touch it from both
    sides: ``dist = |q - c| - thickness/2`` with c the closest point of the segment to the
    in-plane position q, normal ``(q - c)/|q - c|``, wall velocity ``omega e_z x c``.
    """

    r_inner: float
    r_outer: float
    phase: float = 0.0
    rpm: float = 0.0
    thickness: float = 0.0
    temperature: Optional[float] = None
    wall_id: int = eqx.field(static=True, default=0)

    def angle(self, t):
        """Plate angle (rad) at time t (s)."""
        return self.phase + rpm_to_omega(self.rpm) * t

    def evaluate(self, x, t):
        dim = x.shape[-1]
        phi = self.angle(t)
        e = jnp.stack([jnp.cos(phi), jnp.sin(phi)]).astype(x.dtype)
        q = x[..., :2]
        s = jnp.clip(q @ e, self.r_inner, self.r_outer)
        c = s[..., None] * e
        n_xy, r = _safe_unit(q - c)
        dist = r - 0.5 * self.thickness
        v = _rot_velocity(rpm_to_omega(self.rpm), c, dim)
        return dist, _embed_xy(n_xy, dim), v

    def at_rest(self):
        return eqx.tree_at(lambda w: w.rpm, self, 0.0)


class InnerCylinder(Wall):
    """Inner cylinder about the z axis (rotating with ``rpm``); domain ``rho > radius``."""

    radius: float
    rpm: float = 0.0
    temperature: Optional[float] = None
    wall_id: int = eqx.field(static=True, default=0)

    def evaluate(self, x, t):
        dim = x.shape[-1]
        e_rho, rho = _safe_unit(x[..., :2])
        dist = rho - self.radius
        v = _rot_velocity(rpm_to_omega(self.rpm), self.radius * e_rho, dim)
        return dist, _embed_xy(e_rho, dim), v

    def at_rest(self):
        return eqx.tree_at(lambda w: w.rpm, self, 0.0)


class FixedCylinder(Wall):
    """Fixed cylinder (a tube of a tube bundle), axis along z through ``center`` = (x, y).

    Domain: outside the tube, ``dist = |q - center| - radius``; the wall does not move.
    """

    center: Sequence[float]
    radius: float
    temperature: Optional[float] = None
    wall_id: int = eqx.field(static=True, default=0)

    def evaluate(self, x, t):
        dim = x.shape[-1]
        c = jnp.asarray(self.center, dtype=x.dtype)
        n_xy, r = _safe_unit(x[..., :2] - c)
        dist = r - self.radius
        return dist, _embed_xy(n_xy, dim), jnp.zeros_like(x)


class Plane(Wall):
    """Infinite plane through ``point`` with unit ``normal`` pointing into the domain.

    ``dist = (x - point) . normal``. ``surface_velocity`` (optional, m/s) is the tangential
    velocity of the plane material (a conveyor belt); the plane itself does not move.
    """

    point: Sequence[float]
    normal_vector: Sequence[float]
    surface_velocity: Optional[Sequence[float]] = None
    temperature: Optional[float] = None
    wall_id: int = eqx.field(static=True, default=0)

    def evaluate(self, x, t):
        n = jnp.asarray(self.normal_vector, dtype=x.dtype)
        n = n / jnp.linalg.norm(n)
        p = jnp.asarray(self.point, dtype=x.dtype)
        dist = (x - p) @ n
        normal = jnp.broadcast_to(n, x.shape)
        if self.surface_velocity is None:
            v = jnp.zeros_like(x)
        else:
            v = jnp.broadcast_to(jnp.asarray(self.surface_velocity, dtype=x.dtype), x.shape)
        return dist, normal, v

    def bounds(self, dim):
        n = np.asarray(self.normal_vector, dtype=float)
        n = n / np.linalg.norm(n)
        lo = np.full(dim, np.nan)
        hi = np.full(dim, np.nan)
        axis = np.flatnonzero(np.abs(n) > 1 - 1e-12)
        if axis.size == 1:  # axis-aligned plane bounds the domain on one side
            a = int(axis[0])
            if n[a] > 0:
                lo[a] = float(self.point[a])
            else:
                hi[a] = float(self.point[a])
        return lo, hi


class Box(Wall):
    """Axis-aligned box ``lo <= x <= hi`` holding the particles (a container).

    It expands into one :class:`Plane` per face (4 in 2D, 6 in 3D), all with the box's
    ``wall_id`` and ``temperature``, so that particles in an edge or a corner touch two or
    three faces at once. ``evaluate`` gives the distance to the nearest face.
    """

    lo: Sequence[float]
    hi: Sequence[float]
    temperature: Optional[float] = None
    wall_id: int = eqx.field(static=True, default=0)

    def primitives(self):
        lo = np.asarray(self.lo, dtype=float)
        hi = np.asarray(self.hi, dtype=float)
        dim = lo.size
        out = []
        for a in range(dim):
            n = np.zeros(dim)
            n[a] = 1.0
            out.append(Plane(tuple(lo), tuple(n), temperature=self.temperature,
                             wall_id=self.wall_id))
            out.append(Plane(tuple(hi), tuple(-n), temperature=self.temperature,
                             wall_id=self.wall_id))
        return tuple(out)

    def evaluate(self, x, t):
        results = [p.evaluate(x, t) for p in self.primitives()]
        d = jnp.stack([r[0] for r in results], axis=-1)
        k = jnp.argmin(d, axis=-1)
        n = jnp.stack([r[1] for r in results], axis=-2)
        normal = jnp.take_along_axis(n, k[..., None, None], axis=-2)[..., 0, :]
        return jnp.min(d, axis=-1), normal, jnp.zeros_like(x)

    def bounds(self, dim):
        return np.asarray(self.lo, dtype=float), np.asarray(self.hi, dtype=float)


class Segment(Wall):
    """Fixed flat plate: the segment from ``a`` to ``b`` = (x, y) in the x-y plane (in 3D
    extended along z), of total ``thickness`` (m, 0 = zero thickness), touchable from both
    sides and at its rounded ends.

    ``dist = |q - c| - thickness/2`` with c the point of the segment closest to the in-plane
    position q; normal ``(q - c)/|q - c|``; the plate does not move. Used for the sloped hopper
    bottom and the lips of an outlet slit (motion model ``moving_bed``).
    """

    a: Sequence[float]
    b: Sequence[float]
    thickness: float = 0.0
    temperature: Optional[float] = None
    wall_id: int = eqx.field(static=True, default=0)

    def evaluate(self, x, t):
        dim = x.shape[-1]
        a = jnp.asarray(self.a, dtype=x.dtype)
        ab = jnp.asarray(self.b, dtype=x.dtype) - a
        q = x[..., :2]
        s = jnp.clip((q - a) @ ab / jnp.dot(ab, ab), 0.0, 1.0)
        c = a + s[..., None] * ab
        n_xy, r = _safe_unit(q - c)
        return r - 0.5 * self.thickness, _embed_xy(n_xy, dim), jnp.zeros_like(x)


def expand_walls(walls) -> tuple:
    """Flatten a wall or a sequence of walls into a tuple of primitives (Box -> planes)."""
    if isinstance(walls, Wall):
        walls = (walls,)
    out = []
    for w in walls:
        out.extend(w.primitives())
    return tuple(out)


def walls_at_rest(walls) -> tuple:
    """The same walls with every rotation stopped (rpm = 0)."""
    return tuple(w.at_rest() for w in expand_walls(walls))


def wall_bounds(walls, dim):
    """Tightest axis-aligned ``(lo, hi)`` of the domain that the walls imply (NaN = open)."""
    lo = np.full(dim, -np.inf)
    hi = np.full(dim, np.inf)
    for w in walls:
        b = w.bounds(dim)
        if b is None:
            continue
        wlo, whi = (np.asarray(v, dtype=float) for v in b)
        lo = np.where(np.isnan(wlo), lo, np.maximum(lo, np.nan_to_num(wlo, nan=-np.inf)))
        hi = np.where(np.isnan(whi), hi, np.minimum(hi, np.nan_to_num(whi, nan=np.inf)))
    lo = np.where(np.isinf(lo), np.nan, lo)
    hi = np.where(np.isinf(hi), np.nan, hi)
    return lo, hi
