"""Contact conduction computed in the DEM force loop, every mechanical step.

drumheat's coupled thermal DEM (:mod:`drumheat.motion.dem`) records contacts and advances the
thermal network every few mechanical steps with the full set of heat paths. This module is the
lean alternative for runs that want conduction through the touching pairs only, updated every
step the way LIGGGHTS' ``fix heat/gran/conduction`` does it (``scripts/bench_vs_liggghts.py``
runs both codes so): ``make_dem(..., conduction=PairConduction(...))`` keeps the particle
temperatures (float64) in ``DEMState.extra`` and advances them by explicit Euler after the
forces of each step,

    T_i <- T_i + dt Q_i / C_i,    Q_i = sum_j g_ij (T_j - T_i)  over the touching pairs,

with one of two conductance laws:

* ``"projected"``: ``g = h pi min(r_i, r_j)^2``, h = alpha_pp in W/(m^2 K) on the projected
  area ``A_p = pi d^2 / 4`` of the smaller sphere: weigler-thermal-dem.md eq. [2.7] (the same
  law and area, :func:`drumheat.models.contact_conductance.projected_area`, as
  :class:`drumheat.thermal.contact.ContactConduction`).
* ``"overlap"``: ``g = h sqrt(A_c)`` with ``A_c = pi a^2`` the area of the circle where the two
  spheres overlap, ``a^2 = r_i^2 - ((L^2 + r_i^2 - r_j^2) / 2L)^2`` at centre distance L, and
  h = 4 k_i k_j / (k_i + k_j) in W/(m K) (LIGGGHTS ``heat/gran/conduction`` without area
  correction, shared/peers/liggghts).

A pair conducts while it overlaps (Weigler digest eq. [2.4]: the thermal pipe exists while the
particles touch, sec. 4) or, with ``gap_tolerance`` > 0, while the gap between the surfaces is at
most ``gap_tolerance`` times the smaller diameter, ``L - r_i - r_j <= tol min(d_i, d_j)`` (the
contact tolerance of :func:`drumheat.thermal.network.find_contacts_2d_drum`, for beds whose
soft contacts leave hairline gaps between particles that rest on each other). Such a pair
conducts with ``g`` of the ``"projected"`` law; the ``"overlap"`` law has no overlap circle
there and gives ``g = 0``. 0 (default) is overlap only.

The heat flows sum to zero over the bed (each pair moves q from one particle to the other), so
the bed's heat content is conserved to round-off. The explicit update is stable for
``dt <= C_i / sum_j g_ij`` (weigler-thermal-dem.md [2.2]); for millimetre particles at DEM time
steps it holds by orders of magnitude (C / sum g scales with the particle size). With
``make_dem(..., pair_kernel="cpu")`` the heat flows are summed inside the C++ contact loop
(:mod:`drumheat.mechanics.cpu_kernel`); the JAX
kernel computes them with :func:`heat_flow`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.models.contact_conductance import projected_area

__all__ = ["LAWS", "PairConduction", "pair_conductance", "heat_flow", "softening_area_correction"]

LAWS = ("projected", "overlap")


class PairConduction(NamedTuple):
    """Per-step contact conduction for :func:`drumheat.mechanics.make_dem` (module docstring).

    Attributes:
      law: ``"projected"`` (h = alpha_pp, W/(m^2 K)) or ``"overlap"`` (h in W/(m K)).
      coefficient: h of the law.
      heat_capacity: m c of every particle, J/K, shape (N,).
      gap_tolerance: a pair conducts while its surface gap is at most this fraction of the
        smaller diameter (module docstring); 0 = while it overlaps.
      area_correction: law ``"overlap"`` only: factor on the overlap-circle area that undoes a
        softened stiffness (:func:`softening_area_correction`); 1 = none. Applied as
        ``sqrt(area_correction)`` on h, so both contact kernels carry it.
    """

    law: str
    coefficient: float
    heat_capacity: object
    gap_tolerance: float = 0.0
    area_correction: float = 1.0

    def checked(self, n: int) -> "PairConduction":
        """Validated copy with a float64 heat-capacity array of length n."""
        if self.law not in LAWS:
            raise ValueError(f"conduction law must be one of {LAWS}, got {self.law!r}")
        h = float(self.coefficient)
        if not (np.isfinite(h) and h >= 0):
            raise ValueError(f"conduction coefficient must be finite and >= 0, got {h}")
        cap = np.broadcast_to(np.asarray(self.heat_capacity, dtype=float), (n,))
        if not np.all(cap > 0):
            raise ValueError("heat capacities m c must be positive")
        tol = float(self.gap_tolerance)
        if not (np.isfinite(tol) and tol >= 0):
            raise ValueError(f"conduction gap tolerance must be finite and >= 0, got {tol}")
        f = float(self.area_correction)
        if not (np.isfinite(f) and f > 0):
            raise ValueError(f"area correction must be finite and > 0, got {f}")
        if f != 1.0 and self.law != "overlap":
            raise ValueError("area_correction applies to the 'overlap' law only (the "
                             "'projected' law does not depend on the overlap)")
        # g = h sqrt(f A_c) = (h sqrt(f)) sqrt(A_c): carried by h into both kernels
        return PairConduction(self.law, h * math.sqrt(f), jnp.asarray(cap, jnp.float64), tol)


def softening_area_correction(k_simulated: float, k_real: float, exponent: float = 1.0) -> float:
    """Factor on the overlap contact area of a softened contact: ``(k_sim / k_real)^a``.

    A softer spring overlaps more under the same force, so an area computed from the overlap
    is too large. LIGGGHTS' ``fix heat/gran/conduction`` with ``area_correction yes`` scales
    the overlap area by ``(Y*/Y*_orig)^a`` with a = 1 for a Hooke (linear) contact and a = 2/3
    for a Hertz contact (LIGGGHTS-PUBLIC doc/fix_heat_gran_conduction.html); for a linear
    spring the overlap is F / k and the overlap circle's area ~ pi R* F / k, so with the
    stiffnesses themselves ``(k_sim / k_real)^1`` restores the area of the real contact
    under the same force. Use ``exponent = 2/3`` with Young's moduli of a Hertz contact.

    Parameters
    ----------
    k_simulated, k_real : float
        The softened (simulated) and the real stiffness (or Young's moduli, with exponent 2/3).
    exponent : float
        a of the scaling law.
    """
    if not (k_simulated > 0 and k_real > 0):
        raise ValueError("stiffnesses must be positive")
    return float((k_simulated / k_real) ** exponent)


def pair_conductance(law: str, h, ri, rj, distance):
    """Conductance g (W/K) of touching pairs at centre distance ``distance`` (module docstring)."""
    ri, rj, L = (jnp.asarray(a, jnp.float64) for a in (ri, rj, distance))
    if law == "projected":
        return h * projected_area(2.0 * ri, 2.0 * rj)
    area = -0.25 * jnp.pi * ((L - ri - rj) * (L + ri - rj) * (L - ri + rj) * (L + ri + rj)) / (
        L * L)
    return h * jnp.sqrt(jnp.maximum(area, 0.0))


def heat_flow(T, contacts, radius, law: str, h, gap_tolerance: float = 0.0, distance=None):
    """Heat flow into each particle (W, float64, shape (N,)) through the conducting pairs.

    ``contacts`` is the step's :class:`~drumheat.mechanics.Contacts` (pair_i, pair_j,
    pair_mask, pair_distance), radius the particle radii (N,). With ``gap_tolerance`` > 0 the
    pairs whose surface gap is at most ``gap_tolerance min(d_i, d_j)`` conduct too (module
    docstring); ``distance`` must then be the centre distance of every neighbour pair (M,),
    also where nothing touches (``Contacts.pair_distance`` is zero there), in the dtype of the
    mechanics: the gap test is made in that dtype, as the mechanics test the overlap.
    """
    if gap_tolerance > 0 and distance is None:
        raise ValueError("heat_flow with a gap tolerance needs the pair distances")
    n = T.shape[0]
    mask = contacts.pair_mask
    if gap_tolerance > 0:
        valid = contacts.pair_i < n
        i0 = jnp.where(valid, contacts.pair_i, 0)
        j0 = jnp.where(valid, contacts.pair_j, 0)
        r = jnp.asarray(radius).astype(distance.dtype)
        ri, rj = r[i0], r[j0]
        overlap = ri + rj - distance  # as the mechanics compute it
        mask = mask | (valid & (overlap >= -(gap_tolerance * (2 * jnp.minimum(ri, rj)))))
        dist_all = distance
    else:
        dist_all = contacts.pair_distance
    i = jnp.where(mask, contacts.pair_i, 0)
    j = jnp.where(mask, contacts.pair_j, 0)
    dist = jnp.where(mask, dist_all, 1.0)
    g = pair_conductance(law, h, radius[i], radius[j], dist)
    q = jnp.where(mask, g * (T[j] - T[i]), 0.0)
    # one scatter for both ends of every pair (padding index n is dropped)
    seg = jnp.concatenate([jnp.where(mask, i, n), jnp.where(mask, j, n)])
    return jax.ops.segment_sum(jnp.concatenate([q, -q]), seg, n)
