"""Radial shell conduction inside a batch of spheres (intra-particle conduction).

Model: staltner-slag-particle.md section 2, [5.1]
``rho c_p(T) dT/dt = (1/r^2) d/dr (r^2 lambda(T) dT/dr)``, rho constant, on N spheres at once;
temperatures have shape ``(N, n_shells)``.

Grid (staltner-slag-particle.md section 3): equidistant, node-centred surface,
``r_i = (i - 1/2) dr`` for i = 1..n, ``r_n = R``, ``dr = R/(n - 1/2)``; the symmetry plane lies
halfway between the mirror node 0 and node 1. Control volumes (digest section 3, "Mean
enthalpy"): shell i spans ``[(i-1) dr, i dr]``, node n owns the half shell ``[R - dr/2, R]``.

Two integrators
---------------
:func:`explicit_step` is the thesis' explicit scheme [5.15], [5.22], [5.27] (Phase 1/3 flux
boundary with ghost node [5.26]) and [5.32] (Phase 2 Dirichlet), with face conductivities the
arithmetic mean of the nodes ([5.7] corrected). Its stability limit is the corrected Appendix A
of digest section 4 ([A.2], [A.4], [A.7], [A.15]), with the surface coefficient alpha replaced
by the local slope ``dq_out/dT_s`` of the supplied boundary flux (for a radiating surface this is
``4 eps sigma T^3 >= h_r``, the digest's linearisation, so the bound is at least as safe). The
step refuses (``ValueError`` listing the numbers) when ``dt`` exceeds the limit;
:func:`explicit_integrate` offers ``on_unstable="raise" | "substep"``. Being a finite-difference
(not finite-volume) form, the thesis scheme does not conserve the enthalpy of the digest's
control volumes exactly; its balance error is O(dr^2) (measured in the tests).

:func:`implicit_step` is a conservative finite-volume theta scheme on the same grid and control
volumes (``theta = 1``: backward Euler, the default; ``theta = 1/2``: Crank-Nicolson), solved with
a batched tridiagonal solve (``jax.lax.linalg.tridiagonal_solve``). It is written in *enthalpy
form*: the residual ``rho V [h(T^{k+1}) - h(T^k)] = dt [theta F(T^{k+1}) + (1 - theta) F(T^k)]``
is solved by ``newton_iters`` Newton steps (properties and the boundary flux linearised about the
current iterate, conductivity lagged at the iterate). With constant properties one step is exact;
with a converged Newton loop the enthalpy balance closes to round-off for any c_p(T), including
latent heat. Why this and not diffrax/Kvaerno5: each sphere couples only neighbouring shells, so
a tridiagonal solve costs O(N n) per step, whereas diffrax's implicit solvers build and factor a
dense (N n) x (N n) Jacobian (10^4 spheres x 20 shells would need 3 GB per Jacobian). Backward
Euler is L-stable and its matrix is an M-matrix, so it is unconditionally stable *and*
monotone (no over- or undershoot at any dt, important for stiff radiation and the Phase-2
temperature jump); Crank-Nicolson is second order in time but can ring at large dt.

Latent heat: apparent-heat-capacity form, :class:`LatentHeatMaterial` adds
``L g(T)`` (g a normalised Gaussian of width ``width``) to c_p and the matching
``L (1 + erf)/2`` to the enthalpy, so the enthalpy-form implicit step books it exactly; the
explicit step needs dt and the melting width resolved.

Energy book-keeping: :func:`stored_enthalpy` gives ``sum_i rho V_i h(T_i)`` per sphere
(``h(T) = int_{T_ref}^T c_p dT``, T_ref = 273.15 K, digest [7.1]); every step returns the heat
that left through the surface during the step, so ``H(t) + Q_out_cumulative = H(0)``.
"""

from __future__ import annotations

import math
from typing import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import erf

__all__ = [
    "ShellGrid",
    "make_grid",
    "ConstantMaterial",
    "CallableMaterial",
    "LatentHeatMaterial",
    "SurfaceFlux",
    "ConvectionRadiation",
    "FixedSurfaceTemperature",
    "stored_enthalpy",
    "mean_temperature",
    "explicit_stability_limit",
    "explicit_step",
    "explicit_integrate",
    "implicit_step",
    "implicit_integrate",
    "SIGMA",
]

SIGMA = 5.670374419e-8
T_REF = 273.15  # staltner-slag-particle.md [7.1], T_B

# ----------------------------------------------------------------------------------------------
# grid
# ----------------------------------------------------------------------------------------------


class ShellGrid(eqx.Module):
    """Radial grid of N spheres with n shells each (staltner-slag-particle.md section 3).

    Attributes
    ----------
    radius : (N,) sphere radii R, m.
    dr : (N,) node spacing ``R/(n - 1/2)``, m.
    r : (N, n) node radii ``(i - 1/2) dr``, m (``r[:, -1] == R``).
    volume : (N, n) control volumes, m^3: shell i = [(i-1) dr, i dr], node n = [R - dr/2, R].
    face_area : (N, n-1) areas ``4 pi (i dr)^2`` of the faces between node i and i+1, m^2.
    surface_area : (N,) ``4 pi R^2``, m^2.
    n_shells : int (static).
    """

    radius: jax.Array
    dr: jax.Array
    r: jax.Array
    volume: jax.Array
    face_area: jax.Array
    surface_area: jax.Array
    n_shells: int = eqx.field(static=True)


def make_grid(radius, n_shells):
    """Build a :class:`ShellGrid` (staltner-slag-particle.md section 3, ``r_i = (i - 1/2) dr``).

    Parameters
    ----------
    radius : scalar or (N,) array of sphere radii, m.
    n_shells : number of nodes n >= 2 ("Schalenanzahl").
    """
    n = int(n_shells)
    if n < 2:
        raise ValueError(f"n_shells must be >= 2 (got {n_shells}): node n is the surface.")
    R = jnp.atleast_1d(jnp.asarray(radius, dtype=jnp.float64))
    dr = R / (n - 0.5)
    i = jnp.arange(1, n + 1, dtype=jnp.float64)
    r = (i - 0.5) * dr[:, None]
    r_out = jnp.concatenate([i[:-1] * dr[:, None], R[:, None]], axis=1)
    r_in = jnp.concatenate([jnp.zeros_like(R)[:, None], i[:-1] * dr[:, None]], axis=1)
    volume = 4.0 / 3.0 * jnp.pi * (r_out**3 - r_in**3)
    face_area = 4.0 * jnp.pi * (i[:-1] * dr[:, None]) ** 2
    return ShellGrid(R, dr, r, volume, face_area, 4.0 * jnp.pi * R**2, n)


# ----------------------------------------------------------------------------------------------
# materials
# ----------------------------------------------------------------------------------------------

_GL_X, _GL_W = np.polynomial.legendre.leggauss(48)


def _enthalpy_by_quadrature(cp_fn, T, T_ref):
    """int_{T_ref}^T c_p dT by 48-point Gauss-Legendre (exact for polynomials up to degree 95)."""
    T = jnp.asarray(T, dtype=jnp.float64)
    half = 0.5 * (T - T_ref)
    mid = 0.5 * (T + T_ref)
    nodes = mid[..., None] + half[..., None] * jnp.asarray(_GL_X)
    return half * jnp.sum(cp_fn(nodes) * jnp.asarray(_GL_W), axis=-1)


class ConstantMaterial(eqx.Module):
    """Constant properties (all three may be fitted; scalars or (N,) arrays broadcast per sphere).

    density kg/m^3, conductivity_value W/(m K), heat_capacity_value J/(kg K).
    """

    density: jax.Array
    conductivity_value: jax.Array
    heat_capacity_value: jax.Array
    T_ref: float = eqx.field(static=True, default=T_REF)

    def conductivity(self, T):
        return jnp.zeros_like(T) + _col(self.conductivity_value, T)

    def heat_capacity(self, T):
        return jnp.zeros_like(T) + _col(self.heat_capacity_value, T)

    def enthalpy(self, T):
        """Specific enthalpy ``c (T - T_ref)``, J/kg (staltner-slag-particle.md [7.1])."""
        return _col(self.heat_capacity_value, T) * (T - self.T_ref)


class CallableMaterial(eqx.Module):
    """Temperature-dependent properties given as callables of T (K), elementwise.

    ``enthalpy_fn(T)`` (J/kg, from ``T_ref``) is optional; without it the enthalpy is
    the 48-point Gauss-Legendre integral of ``heat_capacity_fn`` (exact for polynomials, about
    1e-4 relative for piecewise-linear c_p with kinks; give ``enthalpy_fn`` for exact
    book-keeping in that case). Callables are static (hashable) fields; fittable parameters
    belong in an equinox module of your own that implements the same four members.
    """

    density: jax.Array
    conductivity_fn: Callable = eqx.field(static=True)
    heat_capacity_fn: Callable = eqx.field(static=True)
    enthalpy_fn: Callable | None = eqx.field(static=True, default=None)
    T_ref: float = eqx.field(static=True, default=T_REF)

    def conductivity(self, T):
        return self.conductivity_fn(T)

    def heat_capacity(self, T):
        return self.heat_capacity_fn(T)

    def enthalpy(self, T):
        if self.enthalpy_fn is not None:
            return self.enthalpy_fn(T) - self.enthalpy_fn(jnp.asarray(self.T_ref))
        return _enthalpy_by_quadrature(self.heat_capacity_fn, T, self.T_ref)


class LatentHeatMaterial(eqx.Module):
    """Adds latent heat to a base material in the apparent-heat-capacity form.

    ``c_app(T) = c(T) + L exp(-x^2/2)/(width sqrt(2 pi))``, ``x = (T - T_melt)/width``, and the
    consistent enthalpy ``h(T) + L [erf(x/sqrt 2) - erf(x_ref/sqrt 2)]/2``. (The slag of the
    Staltner digest has no latent heat; this is for other materials.)

    Attributes
    ----------
    base : material with ``density``, ``conductivity``, ``heat_capacity``, ``enthalpy``.
    latent_heat : J/kg. T_melt : K. width : K (standard deviation of the melting peak).
    """

    base: eqx.Module
    latent_heat: jax.Array
    T_melt: jax.Array
    width: jax.Array

    @property
    def density(self):
        return self.base.density

    @property
    def T_ref(self):
        return self.base.T_ref

    def conductivity(self, T):
        return self.base.conductivity(T)

    def heat_capacity(self, T):
        x = (T - self.T_melt) / self.width
        peak = jnp.exp(-0.5 * x**2) / (self.width * jnp.sqrt(2.0 * jnp.pi))
        return self.base.heat_capacity(T) + self.latent_heat * peak

    def enthalpy(self, T):
        s = jnp.sqrt(2.0) * self.width
        frac = 0.5 * (erf((T - self.T_melt) / s) - erf((self.base.T_ref - self.T_melt) / s))
        return self.base.enthalpy(T) + self.latent_heat * frac


def _col(x, T):
    """Broadcast a scalar or per-sphere (N,) parameter against T of shape (N, n) or (N,)."""
    x = jnp.asarray(x, dtype=jnp.float64)
    if x.ndim == 1 and T.ndim == 2:
        return x[:, None]
    return x


# ----------------------------------------------------------------------------------------------
# boundary conditions
# ----------------------------------------------------------------------------------------------


class SurfaceFlux(eqx.Module):
    """Surface boundary from a callable ``q_out(T_surface) -> W/m^2`` (positive outwards).

    ``q_out`` must act elementwise on the (N,) surface temperatures (its slope is taken with one
    forward-mode derivative). Phases 1/3 of staltner-slag-particle.md section 3 ([5.23]-[5.27]).
    """

    q_out: Callable = eqx.field(static=True)

    def flux(self, Ts):
        return self.q_out(Ts)


class ConvectionRadiation(eqx.Module):
    """``q_out = alpha (T_s - T_gas) + eps sigma (T_s^4 - T_rad^4)`` (W/m^2).

    staltner-slag-particle.md [5.23]-[5.27] with the radiative term in the form of section 4
    (``T_rad^4 = -(1/eps_1) sum_j eps_j phi~_j T_j^4``, see
    :func:`drumheat.models.view_factors.radiation_sink_temperature`). Fields are scalars or (N,)
    arrays and may be fitted.
    """

    alpha: jax.Array
    T_gas: jax.Array
    emissivity: jax.Array = 0.0
    T_rad: jax.Array = 0.0

    def flux(self, Ts):
        return self.alpha * (Ts - self.T_gas) + self.emissivity * SIGMA * (Ts**4 - self.T_rad**4)


class FixedSurfaceTemperature(eqx.Module):
    """Dirichlet boundary, e.g. Phase-2 wall contact at T_m (staltner-slag-particle.md sec. 3).

    ``mode="surface"`` (the digest's consistent alternative): node n is held at ``T_wall`` and
    nodes 1..n-1 are updated. ``mode="ghost"`` (the thesis' literal reading [5.31]-[5.32]):
    ``T_wall`` sits in a ghost node n+1 one dr outside the sphere and node n is updated with the
    interior stencil; explicit scheme only. ``T_wall`` is a scalar or (N,) array (K); compute it
    with :func:`drumheat.models.sphere_conduction.contact_temperature`.
    """

    T_wall: jax.Array
    mode: str = eqx.field(static=True, default="surface")

    def __check_init__(self):
        if self.mode not in ("surface", "ghost"):
            raise ValueError(f"mode must be 'surface' or 'ghost', got {self.mode!r}")


def _as_boundary(boundary):
    if isinstance(boundary, (SurfaceFlux, ConvectionRadiation, FixedSurfaceTemperature)):
        return boundary
    if hasattr(boundary, "flux"):
        return boundary
    if callable(boundary):
        return SurfaceFlux(boundary)
    raise TypeError(f"boundary must be a callable q_out(T_s) or a boundary object, got {boundary!r}")


def _flux_and_slope(boundary, Ts):
    q, dq = jax.jvp(boundary.flux, (Ts,), (jnp.ones_like(Ts),))
    return q, dq


def _wall_T(boundary, N):
    return jnp.broadcast_to(jnp.asarray(boundary.T_wall, dtype=jnp.float64), (N,))


# ----------------------------------------------------------------------------------------------
# energy
# ----------------------------------------------------------------------------------------------


@eqx.filter_jit
def stored_enthalpy(T, grid, material):
    """Stored enthalpy of each sphere, ``sum_i rho V_i h(T_i)`` in J (relative to T_ref).

    staltner-slag-particle.md [7.1]-[7.2] (h from T_B = 273.15 K; V_i as in section 3).
    """
    rho = _col(material.density, grid.volume)
    return jnp.sum(rho * grid.volume * material.enthalpy(T), axis=-1)


@eqx.filter_jit
def mean_temperature(T, grid, material, iters=12):
    """Enthalpy-mean temperature ``T_bar = h^-1(sum h_i V_i / sum V_i)`` per sphere, K.

    staltner-slag-particle.md [7.1]-[7.3] (rho constant within a sphere). Inverted with Newton
    steps from the volume-weighted mean temperature.
    """
    V = grid.volume
    hbar = jnp.sum(material.enthalpy(T) * V, axis=-1) / jnp.sum(V, axis=-1)
    Tm = jnp.sum(T * V, axis=-1) / jnp.sum(V, axis=-1)
    for _ in range(iters):
        Tm = Tm - (material.enthalpy(Tm) - hbar) / material.heat_capacity(Tm)
    return Tm


# ----------------------------------------------------------------------------------------------
# explicit scheme (thesis)
# ----------------------------------------------------------------------------------------------


def _explicit_coefficients(T, grid, material, boundary, ghost_conductivity):
    """a_W, a_E, M~/dt, east temperature and the surface flux (staltner digest section 3)."""
    lam = material.conductivity(T)
    c = material.heat_capacity(T)
    rho = _col(material.density, T)
    dr = grid.dr[:, None]
    r = grid.r
    lam_W = jnp.concatenate([lam[:, :1], lam[:, :-1]], axis=1)  # lambda_0 = lambda_1 (mirror)
    T_W = jnp.concatenate([T[:, :1], T[:, :-1]], axis=1)  # T_0 = T_1 [5.22]
    aW = (lam_W + lam) * (2.0 * r - dr) ** 2  # = 0 at i = 1 since 2 r_1 = dr
    Ts = T[:, -1]
    lam_n = lam[:, -1]
    if isinstance(boundary, FixedSurfaceTemperature):
        Tw = _wall_T(boundary, T.shape[0])
        q = dq = None
        if boundary.mode == "ghost":
            T_ghost = Tw  # [5.31]-[5.32]: T_m stored in node n+1
            lam_ghost = material.conductivity(Tw)
        else:
            T_ghost = Tw  # unused: node n is held at T_m
            lam_ghost = lam_n
    else:
        q, dq = _flux_and_slope(boundary, Ts)
        # ghost node [5.26]: T_{n+1} = T_{n-1} - (2 dr / lambda_n) q_out
        T_ghost = T[:, -2] - 2.0 * grid.dr / lam_n * q
        # lambda_{n+1}: no rule in the source (digest section 3). "surface": lambda_n (default;
        # the ghost temperature can be unphysical, Fig. 3.18); "ghost": lambda(T_{n+1}).
        if ghost_conductivity == "surface":
            lam_ghost = lam_n
        elif ghost_conductivity == "ghost":
            lam_ghost = material.conductivity(T_ghost)
        else:
            raise ValueError(f"ghost_conductivity must be 'surface' or 'ghost', got {ghost_conductivity!r}")
    lam_E = jnp.concatenate([lam[:, 1:], lam_ghost[:, None]], axis=1)
    T_E = jnp.concatenate([T[:, 1:], T_ghost[:, None]], axis=1)
    aE = (lam + lam_E) * (2.0 * r + dr) ** 2
    cap = 8.0 * dr**2 * r**2 * c * rho  # dt / M~  [5.14]
    return aW, aE, cap, T_W, T_E, q, dq, lam_n


def _node_limits(aW, aE, cap, dq, lam_n, grid, boundary):
    """Per-node stability bounds (N, n), staltner-slag-particle.md section 4 (corrected A)."""
    lim = cap / (aW + aE)  # interior [A.2], centre [A.4], Phase-2 node n (ghost) [A.15]
    if isinstance(boundary, FixedSurfaceTemperature):
        if boundary.mode == "surface":
            lim = lim.at[:, -1].set(jnp.inf)  # node n is prescribed
        return lim
    h = jnp.maximum(dq, 0.0)  # alpha (+ radiative slope) in [A.7]
    surf = cap[:, -1] * lam_n / (aW[:, -1] * lam_n + aE[:, -1] * (lam_n + 2.0 * grid.dr * h))
    return lim.at[:, -1].set(surf)


def explicit_stability_limit(T, grid, material, boundary, ghost_conductivity="surface", per_node=False):
    """Largest stable explicit time step, s (staltner-slag-particle.md section 4, corrected).

    All update coefficients >= 0 ("positivity"): interior [A.2]
    ``dt <= 8 dr^2 r_i^2 c rho/(a_W + a_E)``, centre [A.4] ``dt <= 8 dr^2 r_1^2 c rho/a_E,1
    ~ dr^2/(4a)``, surface [A.7] ``dt <= 8 dr^2 r_n^2 c rho lambda_n / [a_W lambda_n + a_E
    (lambda_n + 2 dr h)]`` with ``h = max(dq_out/dT_s, 0)`` (alpha, plus ``4 eps sigma T^3`` for
    radiation: covers the digest's linearised ``alpha + h_r``), Phase-2 ghost mode [A.15].
    Properties at the current temperatures.

    Parameters
    ----------
    T : (N, n) temperatures, K. grid, material, boundary : as for :func:`explicit_step`.
    per_node : return the (N, n) bounds instead of the (N,) minimum.
    """
    boundary = _as_boundary(boundary)
    T = jnp.asarray(T, dtype=jnp.float64)
    aW, aE, cap, _, _, _, dq, lam_n = _explicit_coefficients(T, grid, material, boundary, ghost_conductivity)
    lim = _node_limits(aW, aE, cap, dq, lam_n, grid, boundary)
    return lim if per_node else jnp.min(lim, axis=-1)


def _is_concrete(*xs):
    return not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(xs))


def _refusal_message(dt, lim_nodes, grid):
    lim_nodes = np.asarray(lim_nodes)
    p, k = np.unravel_index(np.argmin(lim_nodes), lim_nodes.shape)
    n = lim_nodes.shape[1]
    where = "centre [A.4]" if k == 0 else ("surface [A.7]/[A.15]" if k == n - 1 else "interior [A.2]")
    lim = float(lim_nodes[p, k])
    dt = float(dt)
    return (
        f"explicit shell step refused: dt = {dt:.6g} s exceeds the stability limit "
        f"{lim:.6g} s (ratio {dt / lim:.3g}); binding node {k + 1} of {n} ({where}) of sphere "
        f"{p} (R = {float(grid.radius[p]):.4g} m, dr = {float(grid.dr[p]):.4g} m). Use dt <= "
        f"{lim:.6g} s, fewer shells, explicit_integrate(..., on_unstable='substep'), or "
        f"implicit_step (unconditionally stable)."
    )


def explicit_step(T, dt, grid, material, boundary, check=True, ghost_conductivity="surface"):
    """One step of the thesis' explicit scheme (staltner-slag-particle.md section 3).

    Interior [5.15] ``T_i' = M a_W T_{i-1} + [1 - M (a_W + a_E)] T_i + M a_E T_{i+1}`` with
    ``a_W = (lam_{i-1} + lam_i)(2 r_i - dr)^2``, ``a_E = (lam_i + lam_{i+1})(2 r_i + dr)^2``,
    ``M = dt/(8 dr^2 r_i^2 c rho)`` [5.14]; centre [5.22] (``a_W,1 = 0``); surface [5.27] via
    the ghost node [5.26] ``T_{n+1} = T_{n-1} - 2 dr q_out/lam_n`` (q_out at time level k);
    Phase 2 [5.32] for a :class:`FixedSurfaceTemperature`. Properties at level k.

    Parameters
    ----------
    T : (N, n) temperatures, K.
    dt : time step, s.
    grid : :class:`ShellGrid`. material : material object (see :class:`ConstantMaterial`).
    boundary : callable ``q_out(T_s)`` (W/m^2, outward), :class:`ConvectionRadiation`,
        :class:`SurfaceFlux` or :class:`FixedSurfaceTemperature`.
    check : refuse a ``dt`` above :func:`explicit_stability_limit`. With concrete inputs a
        ``ValueError`` with the numbers is raised; under ``jit`` an ``equinox`` runtime error.
    ghost_conductivity : ``"surface"`` (lambda_{n+1} = lambda_n, default) or ``"ghost"``
        (lambda(T_{n+1})); the source gives no rule.

    Returns
    -------
    T_new : (N, n) K.
    Q_out : (N,) heat that left each sphere during the step, J. Flux boundary:
        ``4 pi R^2 q_out(T_s^k) dt``; Dirichlet: the decrease of :func:`stored_enthalpy`.
    """
    boundary = _as_boundary(boundary)
    T = jnp.asarray(T, dtype=jnp.float64)
    fixed = isinstance(boundary, FixedSurfaceTemperature)
    if fixed and boundary.mode == "surface":
        T_start = T
        T = T.at[:, -1].set(_wall_T(boundary, T.shape[0]))
    aW, aE, cap, T_W, T_E, q, dq, lam_n = _explicit_coefficients(T, grid, material, boundary, ghost_conductivity)
    if check:
        lim_nodes = _node_limits(aW, aE, cap, dq, lam_n, grid, boundary)
        if _is_concrete(lim_nodes, dt):
            if float(dt) > float(jnp.min(lim_nodes)):
                raise ValueError(_refusal_message(dt, lim_nodes, grid))
        else:
            T = eqx.error_if(
                T,
                dt > jnp.min(lim_nodes),
                "explicit shell step refused: dt exceeds the stability limit "
                "(drumheat.thermal.shells.explicit_stability_limit); use "
                "on_unstable='substep' or implicit_step.",
            )
    M = dt / cap
    T_new = T + M * (aW * (T_W - T) + aE * (T_E - T))
    if fixed:
        if boundary.mode == "surface":
            T_new = T_new.at[:, -1].set(T[:, -1])
            Q = stored_enthalpy(T_start, grid, material) - stored_enthalpy(T_new, grid, material)
        else:
            Q = stored_enthalpy(T, grid, material) - stored_enthalpy(T_new, grid, material)
    else:
        Q = grid.surface_area * q * dt
    return T_new, Q


def explicit_integrate(
    T0,
    dt,
    n_steps,
    grid,
    material,
    boundary,
    on_unstable="raise",
    safety=0.95,
    ghost_conductivity="surface",
):
    """Advance ``n_steps`` explicit steps of size ``dt`` (one ``lax.scan``).

    Parameters
    ----------
    T0 : (N, n) initial temperatures, K. dt : outer step, s. n_steps : int.
    on_unstable : ``"raise"``: refuse when dt exceeds :func:`explicit_stability_limit`
        (checked before the run with the numbers, and at every step at run time);
        ``"substep"``: split every outer step into ``ceil(dt / (safety * limit))`` equal
        sub-steps, with the limit evaluated at the start of the outer step. The sub-step count
        is data dependent (a ``while_loop``): forward-mode and values only, no reverse-mode
        gradient; use :func:`implicit_integrate` or a fixed stable dt for ``jax.grad``.
    safety : margin for ``"substep"`` (property changes within one outer step).

    Returns
    -------
    T : (N, n) final temperatures. Q_out : (N,) total heat out through the surface, J.
    """
    boundary = _as_boundary(boundary)
    T0 = jnp.asarray(T0, dtype=jnp.float64)
    if on_unstable == "raise":
        lim = explicit_stability_limit(T0, grid, material, boundary, ghost_conductivity, per_node=True)
        if _is_concrete(lim, dt) and float(dt) > float(jnp.min(lim)):
            raise ValueError(_refusal_message(dt, lim, grid))
    elif on_unstable != "substep":
        raise ValueError(f"on_unstable must be 'raise' or 'substep', got {on_unstable!r}")
    return _explicit_integrate_jit(
        T0, jnp.asarray(dt, dtype=jnp.float64), int(n_steps), grid, material, boundary,
        on_unstable, safety, ghost_conductivity,
    )


@eqx.filter_jit
def _explicit_integrate_jit(T0, dt, n_steps, grid, material, boundary, on_unstable, safety, ghost_conductivity):
    if on_unstable == "raise":

        def body(carry, _):
            T, Q = carry
            T, dQ = explicit_step(T, dt, grid, material, boundary, True, ghost_conductivity)
            return (T, Q + dQ), None

    elif on_unstable == "substep":

        def body(carry, _):
            T, Q = carry
            lim = jnp.min(explicit_stability_limit(T, grid, material, boundary, ghost_conductivity))
            n_sub = jnp.maximum(jnp.ceil(dt / (safety * lim)), 1.0)
            h = dt / n_sub

            def sub(i, c):
                T, Q = c
                T, dQ = explicit_step(T, h, grid, material, boundary, False, ghost_conductivity)
                return T, Q + dQ

            T, Q = jax.lax.fori_loop(0, n_sub.astype(jnp.int32), sub, (T, Q))
            return (T, Q), None

    Q0 = jnp.zeros(T0.shape[0])
    (T, Q), _ = jax.lax.scan(body, (T0, Q0), None, length=n_steps)
    return T, Q


# ----------------------------------------------------------------------------------------------
# implicit finite-volume theta scheme
# ----------------------------------------------------------------------------------------------


def _fv_divergence(T, G):
    """Net conductive inflow into each control volume, W. G: (N, n-1) face conductances."""
    flow = G * (T[:, 1:] - T[:, :-1])  # from i+1 into i
    zero = jnp.zeros_like(T[:, :1])
    return jnp.concatenate([flow, zero], axis=1) - jnp.concatenate([zero, flow], axis=1)


def _face_conductance(T, grid, material):
    lam = material.conductivity(T)
    lam_f = 0.5 * (lam[:, 1:] + lam[:, :-1])  # arithmetic mean, as [5.7] corrected
    return grid.face_area * lam_f / grid.dr[:, None]


def implicit_step(T, dt, grid, material, boundary, theta=1.0, newton_iters=2):
    """One unconditionally stable finite-volume theta step (module docstring).

    Control volumes of staltner-slag-particle.md section 3 (shell i = [(i-1) dr, i dr], node n
    the half shell [R - dr/2, R]), face conductance ``4 pi (i dr)^2 lam_f / dr`` with lam_f the
    arithmetic node mean ([5.7] corrected), surface flux ``4 pi R^2 q_out(T_n)``. Enthalpy form
    ``rho V [h(T') - h(T)] = dt [theta F(T') + (1 - theta) F(T)]`` solved by Newton with
    c_p(T*), lambda(T*) and ``q_out(T*) + q_out'(T*)(T_n' - T_n*)`` at the iterate T*.

    Parameters
    ----------
    T : (N, n) K. dt : s (any size). grid, material, boundary : as :func:`explicit_step`
        (:class:`FixedSurfaceTemperature` only with ``mode="surface"``).
    theta : 1 backward Euler (default, L-stable, monotone), 0.5 Crank-Nicolson.
    newton_iters : Newton iterations (1 is exact for constant c_p and a linear q_out).

    Returns
    -------
    T_new : (N, n) K. Q_out : (N,) heat out through the surface during the step, J (the flux
        actually used by the scheme, so ``stored_enthalpy`` + Q_out is conserved up to the
        Newton residual; Dirichlet: the decrease of stored enthalpy).
    """
    boundary = _as_boundary(boundary)
    T = jnp.asarray(T, dtype=jnp.float64)
    N, n = T.shape
    fixed = isinstance(boundary, FixedSurfaceTemperature)
    if fixed and boundary.mode != "surface":
        raise NotImplementedError(
            "implicit_step supports FixedSurfaceTemperature(mode='surface') only; the thesis' "
            "literal ghost-node Dirichlet mode is available in explicit_step."
        )
    rho = _col(material.density, T)
    rhoV = rho * grid.volume
    h_old = material.enthalpy(T)
    A = grid.surface_area
    is_n = (jnp.arange(n) == n - 1).astype(T.dtype)

    if theta < 1.0:
        F_old = _fv_divergence(T, _face_conductance(T, grid, material))
        if not fixed:
            q_old = boundary.flux(T[:, -1])
            F_old = F_old - is_n * (A * q_old)[:, None]
    else:
        F_old = jnp.zeros_like(T)
        q_old = jnp.zeros(N)

    Ts_star = T
    Q = jnp.zeros(N)
    for _ in range(int(newton_iters)):
        c = material.heat_capacity(Ts_star)
        G = _face_conductance(Ts_star, grid, material)
        zero = jnp.zeros((N, 1))
        Gm = jnp.concatenate([zero, G], axis=1)
        Gp = jnp.concatenate([G, zero], axis=1)
        C = rhoV * c / dt
        diag = C + theta * (Gm + Gp)
        lower = -theta * Gm
        upper = -theta * Gp
        rhs = C * Ts_star - rhoV * (material.enthalpy(Ts_star) - h_old) / dt + (1.0 - theta) * F_old
        if fixed:
            Tw = _wall_T(boundary, N)
            diag = diag.at[:, -1].set(1.0)
            lower = lower.at[:, -1].set(0.0)
            rhs = rhs.at[:, -1].set(Tw)
        else:
            q, dq = _flux_and_slope(boundary, Ts_star[:, -1])
            diag = diag.at[:, -1].add(theta * A * dq)
            rhs = rhs.at[:, -1].add(-theta * A * (q - dq * Ts_star[:, -1]))
        T_new = jax.lax.linalg.tridiagonal_solve(lower, diag, upper, rhs[..., None])[..., 0]
        if not fixed:
            q_used = q + dq * (T_new[:, -1] - Ts_star[:, -1])
            Q = dt * A * (theta * q_used + (1.0 - theta) * q_old)
        Ts_star = T_new
    if fixed:
        Q = stored_enthalpy(T, grid, material) - stored_enthalpy(T_new, grid, material)
    return T_new, Q


def implicit_integrate(T0, dt, n_steps, grid, material, boundary, theta=1.0, newton_iters=2):
    """Advance ``n_steps`` :func:`implicit_step` steps of size ``dt`` in one ``lax.scan``.

    Compiled once per shape/structure (``equinox.filter_jit``). Differentiable end to end (``jax.grad`` through the scan and the tridiagonal solves).

    Returns
    -------
    T : (N, n) final temperatures, K. Q_out : (N,) total heat out through the surface, J.
    """
    return _implicit_integrate_jit(
        jnp.asarray(T0, dtype=jnp.float64), jnp.asarray(dt, dtype=jnp.float64), int(n_steps),
        grid, material, _as_boundary(boundary), float(theta), int(newton_iters),
    )


@eqx.filter_jit
def _implicit_integrate_jit(T0, dt, n_steps, grid, material, boundary, theta, newton_iters):
    def body(carry, _):
        T, Q = carry
        T, dQ = implicit_step(T, dt, grid, material, boundary, theta, newton_iters)
        return (T, Q + dQ), None

    (T, Q), _ = jax.lax.scan(body, (T0, jnp.zeros(T0.shape[0])), None, length=n_steps)
    return T, Q
