"""Conduction inside the particles: a radial shell profile per particle (``[heat.internal]``).

With this effect the thermal state ``T`` has shape ``(N, n_shells)`` instead of ``(N,)``
(staltner-slag-particle.md sections 2-4; grid, control volumes and materials of
:mod:`drumheat.thermal.shells`). The other effects act on the surface node ``T[:, -1]``: their
summed heat flow is the surface flux of the shell problem, so every effect works unchanged with
resolved or lumped particles. Scenes without ``[heat.internal]`` never build this module and keep
the lumped state and code path.

Integrators (one step, all particles at once):

* :func:`implicit_step`: backward Euler on the finite volumes of :mod:`~drumheat.thermal.shells`
  in enthalpy form (``rho V [h(T') - h(T)] = dt F(T')``), one batched tridiagonal solve per
  Newton iteration. The surface flows of the other effects enter linearised about the iterate,
  ``q(T*) - D (T_s' - T_s*)`` with ``D`` the diagonal conductance of each effect
  (``conductance_sum``): exact Newton for effects acting on one particle (wall, loss,
  convection, radiation), a Jacobi iteration for couplings between particles (contacts, plug-flow
  gas). Unconditionally stable and monotone (an M-matrix) at any dt. The heat booked to each
  outside account is the linearised flow actually used, so the book-keeping closes to the Newton
  residual (round-off for one-particle effects).
* :func:`explicit_step`: the thesis' explicit scheme (:func:`drumheat.thermal.shells.explicit_step`,
  [5.15], [5.22], [5.27]) with the surface flux of the effects at time level k and its stability
  limit (staltner digest section 4, corrected Appendix A) computed with the effects' slope
  ``D``; a step above the limit is refused (at the start with the numbers, during a run by an
  ``equinox`` run-time error), never run.

Shell materials: :class:`PiecewiseLinearMaterial` (c_p(T), lambda(T) linear between knots, exact
enthalpy) with :func:`staltner_slag` (staltner-slag-particle.md section 9), the constant material
of the groups, and optional latent heat (:class:`drumheat.thermal.shells.LatentHeatMaterial`).
"""

from __future__ import annotations

import math
import warnings
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from drumheat.thermal import shells
from drumheat.thermal.shells import T_REF


class PiecewiseLinearMaterial(eqx.Module):
    """c_p(T) and lambda(T) linear between knots, constant beyond; rho constant.

    The enthalpy ``h(T) = int_{T_ref}^T c_p dT`` is the exact integral of the piecewise-linear
    c_p (staltner-slag-particle.md [7.1]), so the shell book-keeping closes to round-off.
    All knots are array leaves (fittable).
    """

    density: Array
    cp_T: Array
    cp_values: Array
    lam_T: Array
    lam_values: Array
    T_ref: float = eqx.field(static=True, default=T_REF)

    def conductivity(self, T):
        return jnp.interp(T, self.lam_T, self.lam_values)

    def heat_capacity(self, T):
        return jnp.interp(T, self.cp_T, self.cp_values)

    def _H(self, T):
        Tk, ck = self.cp_T, self.cp_values
        slope = (ck[1:] - ck[:-1]) / (Tk[1:] - Tk[:-1])
        seg = 0.5 * (ck[1:] + ck[:-1]) * (Tk[1:] - Tk[:-1])
        H = jnp.concatenate([jnp.zeros(1), jnp.cumsum(seg)])  # enthalpy at the knots from Tk[0]
        Tc = jnp.clip(T, Tk[0], Tk[-1])
        k = jnp.clip(jnp.searchsorted(Tk, Tc, side="right") - 1, 0, Tk.shape[0] - 2)
        x = Tc - Tk[k]
        inside = H[k] + ck[k] * x + 0.5 * slope[k] * x**2
        return inside + jnp.where(T < Tk[0], ck[0] * (T - Tk[0]), 0.0) + jnp.where(
            T > Tk[-1], ck[-1] * (T - Tk[-1]), 0.0)

    def enthalpy(self, T):
        return self._H(T) - self._H(jnp.asarray(self.T_ref, float))


def staltner_slag(liquid_conductivity=0.20, plateau_temperature=1723.15, density=2690.0):
    """VASL blast-furnace slag of staltner-slag-particle.md section 9 (knots in degC).

    c_p: 1132 J/(kg K) up to 991 degC, linear to 1194 at 1262, to 1235 at 1600, constant beyond.
    lambda: 1.58 W/(m K) up to 800 degC, 2.15 at 1100, 2.11 at 1200, 0.23 at 1400, linear to
    ``liquid_conductivity`` (0.20) at ``plateau_temperature`` and constant beyond; the source shows
    lambda only as a curve (Fig. 4.3) and leaves the plateau onset open: linear between the knots
    and 1450 degC are our choice. rho = 2690 kg/m3 constant (the model value of the source).
    """
    C0 = 273.15
    return PiecewiseLinearMaterial(
        jnp.asarray(density, float),
        jnp.asarray([C0, 991.0 + C0, 1262.0 + C0, 1600.0 + C0]),
        jnp.asarray([1132.0, 1132.0, 1194.0, 1235.0]),
        jnp.stack([jnp.asarray(v, float) for v in
                   (800.0 + C0, 1100.0 + C0, 1200.0 + C0, 1400.0 + C0, plateau_temperature)]),
        jnp.stack([jnp.asarray(v, float) for v in (1.58, 2.15, 2.11, 0.23, liquid_conductivity)]))


class InternalConduction(eqx.Module):
    """Radial shells in every particle (module docstring).

    Attributes
    ----------
    grid : :class:`drumheat.thermal.shells.ShellGrid` of the N particles.
    material : shell material (``density``, ``conductivity``, ``heat_capacity``, ``enthalpy``).
    scheme : "implicit" or "explicit" (static).
    dt : float or None (static), step from the scene; None = from the stability limit.
    on_unstable : "refuse" or "implicit" (static).
    newton_iters : int (static).
    """

    grid: shells.ShellGrid
    material: eqx.Module
    scheme: str = eqx.field(static=True, default="implicit")
    dt: float | None = eqx.field(static=True, default=None)
    on_unstable: str = eqx.field(static=True, default="refuse")
    newton_iters: int = eqx.field(static=True, default=3)

    @property
    def n_shells(self) -> int:
        return self.grid.n_shells

    def initial(self, T0):
        """Uniform profiles ``(N, n)`` from particle temperatures ``(N,)``."""
        T0 = jnp.asarray(T0, float)
        return jnp.broadcast_to(T0[:, None], (T0.shape[0], self.n_shells))

    @staticmethod
    def surface(T):
        """Surface node temperature of each particle, K."""
        return T[..., -1]

    def mean_temperature(self, T):
        """Enthalpy-mean temperature ``h^-1(h_bar)`` of each particle, K (staltner [7.1]-[7.3])."""
        if T.ndim == 3:
            return jax.vmap(lambda x: shells.mean_temperature(x, self.grid, self.material))(T)
        return shells.mean_temperature(T, self.grid, self.material)

    def volume_mean_temperature(self, T):
        """Volume-mean temperature ``sum V_i T_i / sum V_i`` of each particle, K."""
        V = self.grid.volume
        return jnp.sum(T * V, axis=-1) / jnp.sum(V, axis=-1)

    def stored_heat(self, T):
        """Stored enthalpy ``sum_i rho V_i h(T_i)`` of each particle, J (relative to T_ref)."""
        if T.ndim == 3:
            return jax.vmap(lambda x: shells.stored_enthalpy(x, self.grid, self.material))(T)
        return shells.stored_enthalpy(T, self.grid, self.material)


def build_internal(table, ctx) -> InternalConduction:
    """The :class:`InternalConduction` of a ``[heat.internal]`` table (a
    :class:`~drumheat.thermal.effect.TableValues` view): shells from the table, the material
    "constant" from the particles (density, c) and their conductivity, or "staltner-slag"."""
    cfg = table.table
    particles = ctx.particles
    grid = shells.make_grid(0.5 * particles.diameter, cfg.shells)
    rho = particles.mass / (jnp.pi * particles.diameter**3 / 6.0)
    if cfg.material == "staltner-slag":
        material = staltner_slag(table.liquid_conductivity, table.plateau_temperature)
        if ctx.density_given:
            material = eqx.tree_at(lambda m: m.density, material, rho)
    else:
        material = shells.ConstantMaterial(rho, ctx.particle_property("conductivity"),
                                           particles.heat_capacity)
    if cfg.latent_heat is not None:
        material = shells.LatentHeatMaterial(
            material, jnp.asarray(table.latent_heat, float),
            jnp.asarray(table.melting_temperature, float),
            jnp.asarray(table.melting_width, float))
    return InternalConduction(grid, material, cfg.scheme, cfg.dt, cfg.on_unstable,
                              cfg.newton_iters)


# ---------------------------------------------------------------------------------------------
# surface exchange with the other effects
# ---------------------------------------------------------------------------------------------


def surface_exchange(model, net, Ts):
    """Heat flow of every effect into each particle's surface (W) and its diagonal slope (W/K).

    Returns a list of ``(account, q (N,), D (N,))``, one entry per effect.
    """
    return [(e.account, e.heat_flow(Ts, model.particles, net), e.conductance_sum(model.particles, net, Ts))
            for e in model.effects]


def _boundary(model, net):
    """The effects as a shells boundary ``q_out(T_s)`` (W/m2, outward) with slope ``D/A``."""
    A = model.internal.grid.surface_area

    @jax.custom_jvp
    def q_out(Ts):
        q, _ = model.heat_flows(Ts, net)
        return -q / A

    @q_out.defjvp
    def _(primals, tangents):
        (Ts,), (dT,) = primals, tangents
        D = sum((d for _, _, d in surface_exchange(model, net, Ts)), jnp.zeros_like(Ts))
        return q_out(Ts), D / A * dT

    return shells.SurfaceFlux(q_out)


def _accounts(model, exchange, dT=None):
    out = {a: jnp.zeros((), exchange[0][1].dtype) if exchange else jnp.zeros(())
           for a in model.accounts}
    for account, q, D in exchange:
        if account is not None:
            out[account] = out[account] + jnp.sum(q if dT is None else q - D * dT)
    return out


def implicit_step(model, net, T, dt):
    """One backward-Euler finite-volume step of all particles' shells (module docstring).

    Returns ``(T_new (N, n), heat received per account during the step (J))``.
    """
    it = model.internal
    grid, mat = it.grid, it.material
    N, n = T.shape
    rhoV = shells._col(mat.density, T) * grid.volume
    h_old = mat.enthalpy(T)
    T_star = T
    exchange = []
    for _ in range(it.newton_iters):
        c = mat.heat_capacity(T_star)
        G = shells._face_conductance(T_star, grid, mat)
        zero = jnp.zeros((N, 1), T.dtype)
        Gm = jnp.concatenate([zero, G], axis=1)
        Gp = jnp.concatenate([G, zero], axis=1)
        C = rhoV * c / dt
        Ts = T_star[:, -1]
        exchange = surface_exchange(model, net, Ts) if model.effects else []
        q = sum((x[1] for x in exchange), jnp.zeros(N, T.dtype))
        D = sum((x[2] for x in exchange), jnp.zeros(N, T.dtype))
        diag = (C + Gm + Gp).at[:, -1].add(D)
        rhs = C * T_star - rhoV * (mat.enthalpy(T_star) - h_old) / dt
        rhs = rhs.at[:, -1].add(q + D * Ts)
        T_new = jax.lax.linalg.tridiagonal_solve(-Gm, diag, -Gp, rhs[..., None])[..., 0]
        dTs = T_new[:, -1] - Ts
        T_star = T_new
    acc = _accounts(model, exchange, dTs) if exchange else {a: jnp.zeros(()) for a in model.accounts}
    return T_star, {a: dt * v for a, v in acc.items()}


def explicit_step(model, net, T, dt, check=True):
    """One step of the thesis' explicit scheme with the effects' surface flux at level k.

    :func:`drumheat.thermal.shells.explicit_step`; with ``check`` a step above the stability
    limit raises (an equinox run-time error under ``jit``).
    """
    exchange = surface_exchange(model, net, T[:, -1]) if model.effects else []
    T_new, _ = shells.explicit_step(T, dt, model.internal.grid, model.internal.material,
                                    _boundary(model, net), check=check)
    acc = _accounts(model, exchange) if exchange else {a: jnp.zeros(()) for a in model.accounts}
    return T_new, {a: dt * v for a, v in acc.items()}


def stability_limit(model, net, T):
    """Explicit shell step limit (s) at state ``T`` (staltner digest section 4, corrected A),
    with the surface coefficient replaced by the effects' slope ``D``; and the per-node bounds."""
    nodes = shells.explicit_stability_limit(T, model.internal.grid, model.internal.material,
                                            _boundary(model, net), per_node=True)
    return jnp.min(nodes), nodes


class ShellStepError(ValueError):
    """An explicit shell step above its stability limit was asked for."""


def plan_step(model, net, T0, duration=None, default_dt=None):
    """Scheme and step of a run: ``(scheme, dt)`` (concrete), refusing an unstable explicit step.

    The step is ``heat.internal.dt`` when given, else ``default_dt`` when given (a motion model's
    own choice, e.g. a granulator phase in ``steps_per_phase`` steps), else: explicit scheme 0.9
    times its limit at the start; implicit scheme (stable at any dt, so dt is an accuracy choice)
    0.05 times the lumped surface time constant ``min_i m_i c_i / sum(alpha A)_i`` (internal
    modes faster than that are damped correctly by backward Euler), at most ``duration / 20``;
    set ``heat.internal.dt`` to resolve fast surface transients. ``"explicit"`` with dt above
    the limit: :class:`ShellStepError` with the numbers (``on_unstable = "refuse"``) or the
    implicit scheme with a warning (``on_unstable = "implicit"``).
    """
    it = model.internal
    try:
        limit_arr, nodes = stability_limit(model, net, jnp.asarray(T0, float))
        limit = float(limit_arr)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError, TypeError):
        if it.dt is None and default_dt is None:
            raise ShellStepError("[heat.internal] needs dt when its values are traced "
                                 "(calibration); set heat.internal.dt") from None
        return it.scheme, float(it.dt if it.dt is not None else default_dt)
    if it.dt is not None:
        dt = float(it.dt)
    elif default_dt is not None:
        dt = float(default_dt)
    else:
        if it.scheme == "explicit":
            dt = 0.9 * limit
        else:
            Ts = jnp.asarray(T0, float)[:, -1]
            g = model.conductance_sum(net, Ts)
            tau = float(jnp.min(jnp.where(g > 0, model.particles.capacity / jnp.where(
                g > 0, g, 1.0), jnp.inf)))
            dt = 0.05 * tau
        if duration is not None and math.isfinite(duration) and duration > 0:
            dt = min(dt, duration / 20.0)
        if not math.isfinite(dt):
            dt = limit if math.isfinite(limit) else 1.0
    if it.scheme == "explicit" and dt > limit:
        msg = shells._refusal_message(dt, np.asarray(nodes), it.grid)
        if it.on_unstable == "refuse":
            raise ShellStepError(msg + " (set heat.internal.dt, or heat.internal.on_unstable = "
                                       "'implicit')")
        warnings.warn(msg + "; switching to the implicit scheme (heat.internal.on_unstable = "
                            "'implicit')", UserWarning, stacklevel=2)
        return "implicit", dt
    return it.scheme, dt
