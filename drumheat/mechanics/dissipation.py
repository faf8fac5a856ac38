"""Heat from friction and damping: the mechanical energy the contacts dissipate, as heat.

What a contact dissipates
-------------------------
A soft-sphere contact stores energy in its springs (``U = k_n delta^2/2 + k_t |xi|^2/2``, the
elastic energy of :meth:`~drumheat.mechanics.DEM.energies`) and exchanges energy with the
particles by the work of its force (and rolling torque) on their relative motion. Whatever
the particles lose and the springs do not store is dissipated. Per contact and step::

    D = -dt (F . u + M_r . w_rel) - (U_new - U_old)

with F the contact force on partner B, u the velocity of B's contact point relative to A's,
M_r the rolling torque on B and w_rel the relative spin, all at the end of the step (the
full-step velocities of the velocity-Verlet step). This is the discrete energy balance of the
integrator, not an estimate of it: the kick-drift-kick update changes the kinetic energy by
exactly ``sum_n dt F_n . v_n`` plus boundary terms of the first and last step
(``dt/2 F.v + dt^2/8 |F|^2/m`` and the rotational analogue, :func:`boundary_energy`), so the
heat of all contacts equals the loss of ``kinetic + rotational + potential + elastic + boundary``
energy to round-off (tests/test_friction_heat.py: an adiabatic box). With a fixed wall the wall
does no work; a moving wall's work is the drum's drive and is not dissipation (u is relative to
the wall).

Where it comes from
-------------------
The loss is reported by source with the rates of the continuous contact law evaluated at the
step's velocities (:func:`~drumheat.mechanics.contact_forces.contact_law` with
``dissipation=True``, :func:`~drumheat.mechanics.contact_forces.rolling_loss`):

* ``damping``: the normal and tangential dashpots (inelastic impacts, damped sticking);
* ``sliding``: the Coulomb limit (the friction force times the slip; the spring of a contact
  that opens);
* ``rolling``: the rolling-resistance torque against the relative rolling;
* ``integration``: the remainder ``D - damping - sliding - rolling``: what the discrete motion
  lost beyond (or short of) the continuous rates. It shrinks with the time step (the dashpots
  act on half-step velocities, so a damped collision loses a little more than the continuous
  law says, Weigler digest [2.1] and docs/models/friction-heat.md) and is where the
  integrator's energy error on elastic contacts goes.

Where it goes
-------------
``make_dem(..., friction_heat=FrictionHeat(...))`` gives every step's ``D`` to the two partners
of each contact,

    particle A gets  k_A / (k_A + k_B) D,  particle B gets  k_B / (k_A + k_B) D   (conductivity)

with the thermal conductivities k of their materials (a wall's from its material), or half and
half (``conductivity=None``). The conductivity split is Kratos ThermalDEM's
(``GenerationDissipation::ComputePartitionCoeff``) and the steady partition of heat generated
on the interface of two bodies touching over the same circle: with one interface temperature
(Blok's postulate) each takes a flow proportional to its conductivity times the same spreading
factor. Between particles of one material, the usual drum, both rules give half and half. A
wall's share leaves the particles into the wall and is booked on its own account.

The C++ contact loop computes the same ``D``, rates and split
(:mod:`drumheat.mechanics.cpu_kernel`: its contact rows and
:func:`~drumheat.mechanics.cpu_kernel.contact_heat`, a second pass after the second half-kick;
tests/test_friction_heat.py holds the two equal to round-off).

:class:`Dissipation` (one step's heat per particle, into the walls, per source) reaches the
step's ``extra_update`` in ``Contacts.dissipation`` (:mod:`drumheat.motion.coupling` adds it to
the temperatures). Sums are float64 whatever the mechanics' float type.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["FrictionHeat", "ContactWork", "Dissipation", "SOURCES", "step_heat",
           "boundary_energy"]

#: the sources of :attr:`Dissipation.by_source`, in this order (module docstring)
SOURCES = ("damping", "sliding", "rolling", "integration")


class FrictionHeat(NamedTuple):
    """How the contacts' losses are split between their partners.

    conductivity: (N,) W/(m K), the particles' thermal conductivities for the split
    ``k_A / (k_A + k_B)``; None: half and half. wall_conductivity: W/(m K), the walls' (with
    ``conductivity``).
    """

    conductivity: Optional[jax.Array] = None
    wall_conductivity: float = 0.0

    def checked(self, n: int) -> "FrictionHeat":
        """This configuration with its arrays in float64, checked against N particles."""
        if self.conductivity is None:
            return self
        k = np.asarray(self.conductivity, float)
        if k.shape != (n,) or np.any(k <= 0) or not float(self.wall_conductivity) > 0:
            raise ValueError(f"friction heat split by conductivity needs {n} positive particle "
                             f"conductivities and a positive wall conductivity, got shape "
                             f"{k.shape} and wall {self.wall_conductivity}")
        return self._replace(conductivity=jnp.asarray(k))


class ContactWork(NamedTuple):
    """What a step's contacts leave for :func:`step_heat` (arrays in the mechanics dtype).

    Pairs (M neighbour pairs, padding index N): ``i``, ``j``; ``force`` (M, dim) on j;
    ``lever_i``, ``lever_j`` (M, dim) from the centres to the contact point; ``roll`` the
    rolling torque on j ((M,) 2D, (M, 3) 3D) or None; ``elastic`` (M,) ``U_new - U_old``, J;
    ``rates`` (3, M) damping, sliding and rolling losses at the continuous rates, J.
    Walls ((N, W) slots): ``wall_force``, ``wall_lever``, ``wall_velocity`` (N, W, dim);
    ``wall_roll`` and ``wall_spin`` (the walls' own spin, broadcast like ``wall_roll``) or
    None; ``wall_elastic`` (N, W); ``wall_rates`` (3, N, W).
    """

    i: jax.Array
    j: jax.Array
    force: jax.Array
    lever_i: jax.Array
    lever_j: jax.Array
    roll: Optional[jax.Array]
    elastic: jax.Array
    rates: jax.Array
    wall_force: jax.Array
    wall_lever: jax.Array
    wall_velocity: jax.Array
    wall_roll: Optional[jax.Array]
    wall_spin: Optional[jax.Array]
    wall_elastic: jax.Array
    wall_rates: jax.Array


class Dissipation(NamedTuple):
    """The heat of one step (J, float64): ``particle`` (N,) into each particle, ``walls`` ()
    into the walls, ``by_source`` (4,) into particles and walls per source (:data:`SOURCES`)."""

    particle: jax.Array
    walls: jax.Array
    by_source: jax.Array


def _cross_w_a(w, a):
    if a.shape[-1] == 3:
        return jnp.cross(w, a)
    return w[..., None] * jnp.stack([-a[..., 1], a[..., 0]], axis=-1)


def _dot(a, b, vector: bool):
    return jnp.sum(a * b, axis=-1) if vector else a * b


def step_heat(fh: FrictionHeat, work: ContactWork, vel, spin, dt: float) -> Dissipation:
    """The heat of one step: each contact's loss ``D`` (module docstring) at the full-step
    velocities ``vel`` (N, dim) and spins ``spin`` ((N,) 2D, (N, 3) 3D), split between its
    partners.

    Main arguments
    --------------
    fh : FrictionHeat
        The split.
    work : ContactWork
        The step's contacts (:class:`~drumheat.mechanics.forces.ContactForces` with
        ``friction_heat``).
    vel, spin : arrays
        Velocities and spins at the end of the step (after the second half-kick).
    dt : float
        Time step, s.
    """
    f64 = jnp.float64
    n = vel.shape[0]
    vector = spin.ndim == 2
    i, j = work.i, work.j
    valid = i < n
    ii, jj = jnp.where(valid, i, 0), jnp.where(valid, j, 0)
    u = (vel[jj] + _cross_w_a(spin[jj], work.lever_j)) - (vel[ii] + _cross_w_a(spin[ii],
                                                                               work.lever_i))
    power = jnp.sum(work.force * u, axis=-1).astype(f64)
    if work.roll is not None:
        power = power + _dot(work.roll, spin[jj] - spin[ii], vector).astype(f64)
    d_pair = jnp.where(valid, -dt * power - work.elastic.astype(f64), 0.0)

    u_w = (vel[:, None, :] + _cross_w_a(spin[:, None], work.wall_lever) - work.wall_velocity)
    power_w = jnp.sum(work.wall_force * u_w, axis=-1).astype(f64)
    if work.wall_roll is not None:
        power_w = power_w + _dot(work.wall_roll, spin[:, None] - work.wall_spin,
                                 vector).astype(f64)
    d_wall = -dt * power_w - work.wall_elastic.astype(f64)

    if fh.conductivity is None:
        share_i, share_w = jnp.full(i.shape, 0.5), jnp.full((n, 1), 0.5)
    else:
        k = fh.conductivity
        share_i = k[ii] / (k[ii] + k[jj])
        share_w = k[:, None] / (k[:, None] + fh.wall_conductivity)
    seg = jnp.concatenate([i, j])  # padding n is dropped by segment_sum
    particle = jax.ops.segment_sum(jnp.concatenate([share_i * d_pair, (1 - share_i) * d_pair]),
                                   seg, n)
    particle = particle + jnp.sum(share_w * d_wall, axis=1)
    walls = jnp.sum((1 - share_w) * d_wall)
    rates = (jnp.sum(jnp.where(valid, work.rates.astype(f64), 0.0), axis=1)
             + jnp.sum(work.wall_rates.astype(f64), axis=(1, 2)))
    total = jnp.sum(d_pair) + jnp.sum(d_wall)
    return Dissipation(particle, walls, jnp.concatenate([rates, (total - jnp.sum(rates))[None]]))


def boundary_energy(force, torque, vel, spin, mass, inertia, gravity, dt: float):
    """The velocity-Verlet boundary term of a state (J): with it, ``kinetic + rotational +
    potential + elastic + boundary`` falls over a run by exactly the heat of
    :func:`step_heat` (module docstring).

    ``sum dt/2 (C.v + T.w) + dt^2/(4m) C.F - dt^2/(8m) |F|^2 + dt^2/(8I) |T|^2`` with F the
    state's force (contacts and gravity), C = F - m g the contacts' part and T the torque:
    summing ``dt/2 (C_n + C_n+1) . v_n+1/2``, the exact change of kinetic energy by the
    contacts in a kick-drift-kick step, as ``dt C_n . v_n`` over the steps leaves these terms
    of the first and the last state (gravity does exactly ``m g . dx``).
    """
    f64 = jnp.float64
    force, torque, vel, spin, mass, inertia = (
        jnp.asarray(a, f64) for a in (force, torque, vel, spin, mass, inertia))
    c = force - mass[:, None] * jnp.asarray(gravity, f64)
    t2 = torque**2 if torque.ndim == 1 else jnp.sum(torque**2, axis=-1)
    ts = torque * spin if torque.ndim == 1 else jnp.sum(torque * spin, axis=-1)
    return jnp.sum(0.5 * dt * (jnp.sum(c * vel, axis=-1) + ts)
                   + dt * dt / (4.0 * mass) * jnp.sum(c * force, axis=-1)
                   - dt * dt / (8.0 * mass) * jnp.sum(force**2, axis=-1)
                   + dt * dt / (8.0 * inertia) * t2)
