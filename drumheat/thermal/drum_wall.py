"""A drum wall with its own heat capacity, in segments that turn with the drum.

``[heat.drum_wall]`` (docs/models/drum-wall.md). Like ``[heat.internal]`` this is a state
extension, not one more heat flow into the particles: the thermal model carries it in
:attr:`drumheat.thermal.model.ThermalModel.drum_wall` and the solvers carry the segment
temperatures ``T_w`` (n_seg,) K and the wall's heat accounts next to the particle temperatures.

Each segment k is one lumped node (thin wall: one temperature through the thickness s, at the
inner surface the bed touches) with the energy balance (derivation in the docs page)::

    C_k dT_k/dt = Q_out,k - Q_bed,k - Q_gas,k
    C_k      = s rho c_p A_k                               heat capacity, J/K
    Q_out,k  = A_k (q_o + U (T_o - T_k))                     outside -> wall, W
    Q_bed,k  = sum_{contacts c in k} alpha_wp A_p w_c (T_k - T_i(c))   wall -> bed, W
    Q_gas,k  = h_i (A_k - A_cov,k) (T_k - T_g)               wall -> free gas, W

with the outside conductance per area ``U = lambda/s`` (a fixed outer surface temperature,
conduction through the thickness), ``U = 1 / (1/h_o + s/lambda)`` (a hot gas, film and wall in
series) or ``U = 0`` with a prescribed flux ``q_o`` (W/m2). ``Q_bed`` is the particle-wall
contact law of ``[heat.wall]`` (weigler-thermal-dem.md eq. [2.7]) at the segment's
temperature. The covered area ``A_cov,k = min(A_k, sum_{c in k} w_c d_i^2)`` is the wall area
of eq. [1.10] (thesis App. A7: d_p^2 per wall contact) of the segment's contacts.

Segments turn with the drum: a contact at polar angle theta (lab frame, counter-clockwise from
+x) belongs at time t to segment ``floor(mod(theta - omega t, 2 pi) / (2 pi / n_seg))``.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
from jax import Array

from drumheat.materials import material
from drumheat.thermal.effect import EffectContext, TableValues
from drumheat.thermal.network import ContactNetwork

__all__ = ["DrumWall", "outer_conductance", "build_drum_wall"]

#: the wall's heat accounts (J): heat in from outside, heat out to the free gas
WALL_ACCOUNTS = ("outside", "gas")


def outer_conductance(outside: str, conductivity, thickness, outer_alpha=None):
    """Conductance per area from the outside to the wall node, W/(m2 K).

    The node sits at the inner surface (the one the bed touches) and holds the whole heat
    capacity (a thin wall, Biot number ``U s / lambda << 1``). Through the thickness s the
    wall conducts ``lambda / s`` (Fourier's law, a plane wall: the drum's ``s << R``); a hot
    gas adds its film ``1 / h_o`` in series (thermal resistances in series, Incropera &
    DeWitt, Fundamentals of Heat and Mass Transfer, section 3.1, the plane and composite
    wall). ``"flux"`` has none (the flux is prescribed): 0.
    """
    if outside == "flux":
        return jnp.zeros(())
    wall = jnp.asarray(conductivity, float) / jnp.asarray(thickness, float)
    if outside == "temperature":
        return wall
    return 1.0 / (1.0 / jnp.asarray(outer_alpha, float) + 1.0 / wall)


class DrumWall(eqx.Module):
    """The drum wall's segments (module docstring); parameters are array leaves.

    Attributes
    ----------
    capacity : scalar array
        Heat capacity of one segment ``C_k = s rho c_p A_k``, J/K.
    area : scalar array
        Inner area of one segment ``A_k = 2 pi R depth / n_seg``, m2.
    outer_conductance : scalar array
        U, W/(m2 K) (:func:`outer_conductance`).
    outer_temperature : scalar array
        T_o, K (0 with a prescribed flux).
    outer_flux : scalar array
        q_o, W/m2 (0 unless prescribed).
    inner_alpha : scalar array
        h_i, wall -> free gas, W/(m2 K).
    gas_temperature : scalar array
        T_g of the free gas, K.
    omega : scalar array
        Angular speed of the drum, rad/s (positive counter-clockwise).
    initial_temperature : scalar array
        Temperature of every segment at t = 0, K.
    n_segments : int (static)
    """

    capacity: Array
    area: Array
    outer_conductance: Array
    outer_temperature: Array
    outer_flux: Array
    inner_alpha: Array
    gas_temperature: Array
    omega: Array
    initial_temperature: Array
    n_segments: int = eqx.field(static=True)

    def initial(self) -> dict:
        """The wall's part of the solver state at t = 0: ``{"T": (n_seg,) K, "Q": {"outside",
        "gas"}: J}``."""
        T = jnp.full(self.n_segments, self.initial_temperature, dtype=jnp.float64)
        return {"T": T, "Q": {a: jnp.zeros((), T.dtype) for a in WALL_ACCOUNTS}}

    def segment(self, angle: Array, t) -> Array:
        """Segment of each contact at polar angle ``angle`` (rad, lab frame) at time ``t``:
        ``floor(mod(angle - omega t, 2 pi) / (2 pi / n_seg))`` (module docstring)."""
        n = self.n_segments
        if n == 1:
            return jnp.zeros(jnp.shape(angle), jnp.int32)
        phase = jnp.mod(angle - self.omega * t, 2.0 * math.pi)
        k = jnp.floor(phase * (n / (2.0 * math.pi))).astype(jnp.int32)
        return jnp.clip(k, 0, n - 1)

    def covered_area(self, diameter: Array, net: ContactNetwork) -> Array:
        """Area of each segment the bed covers, ``min(A_k, sum_{c in k} w_c d_i^2)``, m2
        (``net.wall_id`` holds the segments)."""
        d2 = diameter[net.wall_particle] ** 2 * net.wall_weight
        return jnp.minimum(self.area, jnp.zeros(self.n_segments, d2.dtype).at[net.wall_id].add(d2))

    def balance(self, T_wall: Array, q_bed: Array, covered: Array) -> tuple[Array, dict]:
        """``(dT_k/dt (n_seg,) K/s, {"outside": W, "gas": W})`` of the segments' balance
        (module docstring) given the heat ``q_bed`` (n_seg,) W each gives to the bed and its
        covered area (m2)."""
        q_out = self.area * (self.outer_flux
                             + self.outer_conductance * (self.outer_temperature - T_wall))
        q_gas = self.inner_alpha * (self.area - covered) * (T_wall - self.gas_temperature)
        rate = (q_out - q_bed - q_gas) / self.capacity
        return rate, {"outside": jnp.sum(q_out), "gas": jnp.sum(q_gas)}

    def stability_limit(self, bed_conductance: Array) -> Array:
        """Explicit (forward Euler) step limit of the segments, ``C_k / (A_k (U + h_i) + G)``,
        s, where ``bed_conductance`` G bounds the wall -> bed conductance of any one segment
        (weigler eq. [2.2] applied to the wall node)."""
        g = self.area * (self.outer_conductance + self.inner_alpha) + bed_conductance
        return jnp.where(g > 0, self.capacity / jnp.where(g > 0, g, 1.0), jnp.inf)


def build_drum_wall(table: TableValues, ctx: EffectContext) -> DrumWall:
    """The :class:`DrumWall` of ``[heat.drum_wall]`` with the drum of the context
    (``ctx.drum``: radius, depth, rpm), its initial temperature ``ctx.wall_temperatures[0]``
    and the free gas of ``ctx.gas``. Material properties: the table's overrides, else the
    library's (:func:`drumheat.materials.material`)."""
    lib = material(table.table.material)
    prop = lambda k: getattr(table, k) if table.given(k) else getattr(lib, k)  # noqa: E731
    n = int(table.table.segments)
    geo = ctx.drum
    area = 2.0 * math.pi * geo.radius * geo.depth / n
    s = jnp.asarray(table.thickness, float)
    outside = table.table.outside
    U = outer_conductance(outside, prop("conductivity"), s,
                          table.outer_alpha if outside == "gas" else None)
    T_o = table.outer_temperature if outside != "flux" else 0.0
    q_o = table.outer_flux if outside == "flux" else 0.0
    T_g = ctx.gas.temperature if ctx.gas is not None else 0.0
    f = lambda v: jnp.asarray(v, float)  # noqa: E731
    return DrumWall(
        capacity=s * f(prop("density")) * f(prop("heat_capacity")) * area, area=f(area),
        outer_conductance=U, outer_temperature=f(T_o), outer_flux=f(q_o),
        inner_alpha=f(table.inner_alpha), gas_temperature=f(T_g),
        omega=f(geo.rpm * 2.0 * math.pi / 60.0),
        initial_temperature=f(jnp.atleast_1d(jnp.asarray(ctx.wall_temperatures))[0]),
        n_segments=n)
