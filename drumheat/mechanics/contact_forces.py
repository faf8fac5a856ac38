"""Soft-sphere contact laws: linear spring-dashpot normal force, Cundall-Strack tangential spring
with Coulomb limit and history, optional rolling resistance.

References (cite by file and equation):

* ``reference/weigler-thermal-dem.md`` (the "Weigler digest"): sec. 4 [2.1] critical time step
  ``t_crit = 2 sqrt(m/k_n)``; [2.3] stiffness ``k_n = E A_p / d_p`` with ``A_p = pi d_p^2/4``
  and ``k_s = k_n``; [2.4] overlap ``eps = R_i + R_j - |r_i - r_j|``; sec. 5: friction 0.9
  (particle-particle) and 0.6 (particle-wall), viscous damping ratio 0.3 normal and shear,
  linear contact law (PFC2D, Cundall-Strack).
* ``peers/liggghts/README.md``: LIGGGHTS ``hooke`` with ``tangential history`` (incremental
  tangential spring, Coulomb cap ``mu |F_n|``, tangential damping only while sticking,
  ``gamma = sqrt(4 m* k / (1 + (pi/ln e)^2))``).

Model (per contact, partners A and B, unit normal n from A to B, overlap delta > 0):

* normal:      ``F_n = max(0, k_n delta + gamma_n d(delta)/dt)``,
  ``gamma_n = 2 zeta_n sqrt(m* k_n)``, never attractive (total normal force clipped at 0);
* tangential:  spring ``xi`` (m) carried per contact: each step it is rotated onto the current
  tangent plane keeping its length, then incremented by ``v_t dt``; trial force
  ``F_s = -k_t xi``. If ``|F_s| > mu F_n`` the contact slides: ``F_s`` is scaled to
  ``mu F_n`` and ``xi = -F_s / k_t`` (the spring is stored at the Coulomb limit) and no
  tangential dashpot acts; otherwise ``F_t = F_s - gamma_t v_t`` with
  ``gamma_t = 2 zeta_t sqrt(m* k_t)`` (LIGGGHTS hooke/history and PFC behave the same way);
* rolling resistance (optional): constant directional torque (Ai et al. 2011, "model A")
  ``M_r = -mu_r R* F_n w_rel/|w_rel|``, capped at the torque that would stop the relative
  rolling ``w_rel`` within one step, so it cannot reverse it (no chatter at rest).

``m* = m_A m_B / (m_A + m_B)`` for two particles and ``m* = m`` against a wall.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from drumheat.devices import to_device
from drumheat.models.soft_sphere import (  # noqa: F401
    critical_time_step, dashpot_time_step, normal_stiffness_from_youngs)

__all__ = [
    "ContactParams",
    "contact_params",
    "normal_stiffness_from_youngs",
    "damping_ratio_from_restitution",
    "restitution_from_damping_ratio",
    "damping_coefficient",
    "critical_time_step",
    "contact_law",
    "ContactResult",
    "cross_w_a",
    "cross_a_f",
    "rolling_torque",
    "rolling_loss",
]


# ---------------------------------------------------------------------------------------------
# parameter helpers (k_n from E and the critical step are closed-form: drumheat.models.soft_sphere)
# ---------------------------------------------------------------------------------------------


def restitution_from_damping_ratio(zeta, model="no_attraction"):
    """Normal restitution coefficient of the linear spring-dashpot with damping ratio zeta.

    ``zeta = gamma / (2 sqrt(m* k))``.

    * ``model="linear"``: the classical result for a contact that ends when the overlap returns
      to zero (the dashpot may pull): ``e = exp(-pi zeta / sqrt(1 - zeta^2))``; inverse of the
      LIGGGHTS formula ``gamma = sqrt(4 m* k / (1 + (pi/ln e)^2))`` (peers/liggghts/README.md).
    * ``model="no_attraction"``: the contact ends when the total normal force reaches zero,
      which is what this code does (the force is clipped at 0). The particles then separate
      with the velocity they have at that instant (Schwager & Poeschel, Phys. Rev. E 78,
      051304 (2008), linear model):
      ``e = exp(-a (pi - 2 arctan a))``, ``a = zeta/sqrt(1 - zeta^2)`` for zeta < 1, and
      ``e = exp(-b ln((zeta + s)/(zeta - s)))``, ``s = sqrt(zeta^2 - 1)``, ``b = zeta/s`` for
      zeta > 1. It is larger than the "linear" value for the same zeta.
    """
    z = float(zeta)
    if z < 0:
        raise ValueError(f"damping ratio must be >= 0, got {z}")
    if z == 0:
        return 1.0
    if model == "linear":
        if z >= 1:
            return 0.0
        return math.exp(-math.pi * z / math.sqrt(1 - z * z))
    if model != "no_attraction":
        raise ValueError(f"model must be 'no_attraction' or 'linear', got {model!r}")
    if abs(z - 1.0) < 1e-12:
        return math.exp(-2.0)
    if z < 1:
        a = z / math.sqrt(1 - z * z)
        return math.exp(-a * (math.pi - 2.0 * math.atan(a)))
    s = math.sqrt(z * z - 1)
    return math.exp(-(z / s) * math.log((z + s) / (z - s)))


def damping_ratio_from_restitution(e, model="no_attraction"):
    """Damping ratio ``zeta`` (dimensionless) giving normal restitution coefficient ``e``.

    ``model="linear"``: ``zeta = -ln e / sqrt(pi^2 + ln^2 e)``, i.e. the brief's / LIGGGHTS'
    ``gamma_n = 2 sqrt(m* k_n) (-ln e)/sqrt(pi^2 + ln^2 e)``; exact only if the normal force
    may become attractive. ``model="no_attraction"`` (default): exact for this code's clipped
    normal force, by inverting :func:`restitution_from_damping_ratio` (bisection, monotone).
    """
    e = float(e)
    if not 0.0 < e <= 1.0:
        raise ValueError(f"restitution coefficient must be in (0, 1], got {e}")
    if e == 1.0:
        return 0.0
    if model == "linear":
        le = math.log(e)
        return -le / math.sqrt(math.pi**2 + le * le)
    lo, hi = 0.0, 1.0
    while restitution_from_damping_ratio(hi, model) > e:
        hi *= 2.0
        if hi > 1e6:
            raise ValueError(f"restitution {e} is not reachable")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if restitution_from_damping_ratio(mid, model) > e:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def damping_coefficient(zeta, m_eff, k):
    """Viscous damping coefficient ``gamma = 2 zeta sqrt(m* k)`` (N s/m).

    zeta is the fraction of critical damping (PFC "viscous damping", 0.3 in the thesis;
    Weigler digest sec. 5).
    """
    return 2.0 * zeta * jnp.sqrt(m_eff * k)


class ContactParams(eqx.Module):
    """Contact parameters per material pair (array leaves, fittable / vmappable).

    Particle-particle tables have shape (T, T) (T particle material types, symmetric);
    particle-wall tables have shape (T, W) or (T, 1) (broadcast over the W wall primitives).

    Fields (SI): ``kn, kt`` stiffness (N/m); ``zeta_n, zeta_t`` damping ratios (fraction of
    critical, dimensionless); ``mu`` Coulomb friction; ``mu_roll`` rolling-resistance
    coefficient (dimensionless, 0 = off). Suffix ``_pp`` particle-particle, ``_pw`` wall.
    """

    kn_pp: jax.Array
    kt_pp: jax.Array
    zeta_n_pp: jax.Array
    zeta_t_pp: jax.Array
    mu_pp: jax.Array
    mu_roll_pp: jax.Array
    kn_pw: jax.Array
    kt_pw: jax.Array
    zeta_n_pw: jax.Array
    zeta_t_pw: jax.Array
    mu_pw: jax.Array
    mu_roll_pw: jax.Array

    @property
    def n_types(self):
        return self.kn_pp.shape[0]

    def k_max(self):
        """Largest stiffness of all tables (N/m), for the critical time step."""
        return float(max(np.max(np.asarray(getattr(self, f)))
                         for f in ("kn_pp", "kt_pp", "kn_pw", "kt_pw")))

    def dashpot_time_step(self, m_min: float) -> float:
        """The explicit limit of the tangential dashpots on the spin of the lightest particle
        (mass ``m_min``, kg), :func:`drumheat.models.soft_sphere.dashpot_time_step`, with the
        largest tangential damping of the contacts that can stick (friction > 0), s."""

        def gamma(zeta, kt, mu, m_eff):
            zeta, kt, mu = np.broadcast_arrays(*(np.asarray(a, float) for a in (zeta, kt, mu)))
            g = np.where(mu > 0, 2.0 * zeta * np.sqrt(m_eff * kt), 0.0)
            return float(np.max(g)) if g.size else 0.0

        return dashpot_time_step(m_min, gamma(self.zeta_t_pp, self.kt_pp, self.mu_pp, m_min / 2),
                                 gamma(self.zeta_t_pw, self.kt_pw, self.mu_pw, m_min))

    def uses_rolling(self):
        return bool(np.any(np.asarray(self.mu_roll_pp) > 0)
                    or np.any(np.asarray(self.mu_roll_pw) > 0))


def contact_params(
    kn,
    *,
    kt=None,
    kn_wall=None,
    kt_wall=None,
    restitution=None,
    wall_restitution=None,
    damping_ratio=None,
    wall_damping_ratio=None,
    tangential_damping_ratio=None,
    wall_tangential_damping_ratio=None,
    friction=0.9,
    wall_friction=0.6,
    rolling_friction=0.0,
    wall_rolling_friction=None,
    n_types=1,
    restitution_model="no_attraction",
):
    """Build :class:`ContactParams` from scalars or tables.

    Defaults follow the Weigler digest sec. 5: ``kt = kn`` ([2.3]: k_s = k_n), wall stiffness
    = particle stiffness, friction 0.9 / wall friction 0.6. Damping is given either as a
    restitution coefficient (converted with :func:`damping_ratio_from_restitution`,
    ``restitution_model`` chooses the convention) or directly as a damping ratio (PFC viscous
    damping, 0.3 in the thesis); tangential damping ratios default to the normal ones
    (LIGGGHTS: gamma_t = gamma_n with kt = kn; PFC: 0.3 normal and shear). No damping given
    means none (elastic contacts).
    """
    T = int(n_types)

    def pp(v):
        a = np.asarray(v, dtype=float)
        return to_device(np.broadcast_to(a, (T, T)).copy())

    def pw(v):
        a = np.asarray(v, dtype=float)
        if a.ndim == 2:
            return to_device(np.broadcast_to(a, (T, a.shape[1])).copy())
        if a.ndim == 1:  # per wall
            return to_device(np.broadcast_to(a[None, :], (T, a.size)).copy())
        return to_device(np.full((T, 1), float(a)))

    def zeta_of(e, z):
        if e is not None and z is not None:
            raise ValueError("give either a restitution coefficient or a damping ratio, not both")
        if e is not None:
            return np.vectorize(lambda x: damping_ratio_from_restitution(x, restitution_model))(
                np.asarray(e, dtype=float))
        return 0.0 if z is None else z

    kt = kn if kt is None else kt
    kn_wall = kn if kn_wall is None else kn_wall
    kt_wall = kn_wall if kt_wall is None else kt_wall
    zn_pp = zeta_of(restitution, damping_ratio)
    if wall_restitution is None and wall_damping_ratio is None:
        wall_restitution, wall_damping_ratio = restitution, damping_ratio
    zn_pw = zeta_of(wall_restitution, wall_damping_ratio)
    zt_pp = zn_pp if tangential_damping_ratio is None else tangential_damping_ratio
    zt_pw = zn_pw if wall_tangential_damping_ratio is None else wall_tangential_damping_ratio
    wall_rolling_friction = (rolling_friction if wall_rolling_friction is None
                             else wall_rolling_friction)
    return ContactParams(
        kn_pp=pp(kn), kt_pp=pp(kt), zeta_n_pp=pp(zn_pp), zeta_t_pp=pp(zt_pp),
        mu_pp=pp(friction), mu_roll_pp=pp(rolling_friction),
        kn_pw=pw(kn_wall), kt_pw=pw(kt_wall), zeta_n_pw=pw(zn_pw), zeta_t_pw=pw(zt_pw),
        mu_pw=pw(wall_friction), mu_roll_pw=pw(wall_rolling_friction),
    )


# ---------------------------------------------------------------------------------------------
# kernels
# ---------------------------------------------------------------------------------------------


def cross_w_a(w, a):
    """``w x a`` for an angular velocity w and a lever a.

    3D: ordinary cross product. 2D: w is the z component (scalar per item), a is in-plane:
    ``w e_z x a = w (-a_y, a_x)``.
    """
    if a.shape[-1] == 3:
        return jnp.cross(w, a)
    return w[..., None] * jnp.stack([-a[..., 1], a[..., 0]], axis=-1)


def cross_a_f(a, f):
    """Torque ``a x f``: a 3-vector in 3D, the z component (scalar per item) in 2D."""
    if a.shape[-1] == 3:
        return jnp.cross(a, f)
    return a[..., 0] * f[..., 1] - a[..., 1] * f[..., 0]


def _norm(v):
    return jnp.sqrt(jnp.sum(v * v, axis=-1))


class ContactResult(NamedTuple):
    force: jax.Array  # (..., dim) force on partner B (N)
    normal_force: jax.Array  # (...,) clipped normal force magnitude (N)
    spring: jax.Array  # (..., dim) updated tangential spring xi (m)
    sliding: jax.Array  # (...,) bool: Coulomb limit reached
    # with ``dissipation=True`` (else None): mechanical energy the contact dissipated in this
    # step (J, >= 0), :func:`contact_law`
    damping_loss: jax.Array | None = None  # (...,) in the normal and tangential dashpots
    slip_loss: jax.Array | None = None  # (...,) by the Coulomb limit (sliding, release)


def contact_law(n, overlap, v_rel, m_eff, kn, kt, zeta_n, zeta_t, mu, spring, dt, active,
                dissipation: bool = False):
    """Linear spring-dashpot contact with Cundall-Strack tangential history (one step).

    Args (arrays broadcast over contacts, vectors have a trailing dim axis):
      n: unit normal from partner A to partner B.
      overlap: ``delta = R_A + R_B - distance`` (m) (Weigler digest [2.4]).
      v_rel: velocity of B's contact point relative to A's (m/s) at the force evaluation time
        (used by the dashpots and, times dt, as the tangential spring increment).
      m_eff: effective mass m* (kg). kn, kt (N/m), zeta_n, zeta_t (-), mu (-).
      spring: tangential spring xi from the previous step (m).
      dt: time step (s). active: bool, the contact exists (delta > 0 and a valid pair).
      dissipation: also return the mechanical energy the contact dissipated in the step (J),
        split as the heat sources of friction heating (:mod:`drumheat.mechanics.dissipation`):

        * ``damping_loss``: the dashpots, ``(k_n delta - F_n) v_n dt`` (``gamma_n v_n^2 dt``
          while the normal force is not clipped; while it is clipped at zero the dashpot
          cancels the spring and takes the spring's release ``k_n delta v_n dt``) plus
          ``gamma_t |v_t|^2 dt`` while the contact sticks;
        * ``slip_loss``: while the contact slides, the Coulomb force times the slip of the
          step, ``mu F_n |xi_trial - xi|`` (the part of the tangential displacement the spring
          does not take); when the contact opens, the energy left in its tangential spring,
          ``k_t |xi_old|^2 / 2``, which the model discards.

        These are the rates of the continuous law (PFC's dashpot and slip energies, Itasca PFC
        manual, "energy partitions") at the step's velocities; the exact loss of the discrete
        step is :func:`drumheat.mechanics.dissipation.step_heat`.

    Returns a :class:`ContactResult` with the force acting on B (A receives the opposite).
    See the module docstring for the equations.
    """
    vn = jnp.sum(v_rel * n, axis=-1)  # > 0: separating; d(delta)/dt = -vn
    gn = damping_coefficient(zeta_n, m_eff, kn)
    fn = jnp.maximum(kn * overlap - gn * vn, 0.0)
    fn = jnp.where(active, fn, 0.0)
    vt = v_rel - vn[..., None] * n
    # rotate the stored spring onto the current tangent plane, keeping its length
    xi_n = jnp.sum(spring * n, axis=-1)
    xi_p = spring - xi_n[..., None] * n
    len_old = _norm(spring)
    len_p = _norm(xi_p)
    scale = jnp.where(len_p > 0, len_old / jnp.where(len_p > 0, len_p, 1.0), 1.0)
    xi = xi_p * scale[..., None] + vt * dt
    xi_trial = xi
    fs = -kt[..., None] * xi if jnp.ndim(kt) else -kt * xi
    fs_len = _norm(fs)
    f_coul = mu * fn
    slide = fs_len > f_coul
    ratio = f_coul / jnp.where(slide, fs_len, 1.0)
    fs_lim = jnp.where(slide[..., None], fs * ratio[..., None], fs)
    kt_b = kt[..., None] if jnp.ndim(kt) else kt
    xi = jnp.where(slide[..., None], -fs_lim / kt_b, xi)
    gt = damping_coefficient(zeta_t, m_eff, kt)
    gt_b = gt[..., None] if jnp.ndim(gt) else gt
    ft = jnp.where(slide[..., None], fs_lim, fs - gt_b * vt)
    act = active[..., None]
    ft = jnp.where(act, ft, 0.0)
    xi_new = jnp.where(act, xi, 0.0)
    force = fn[..., None] * n + ft
    if not dissipation:
        return ContactResult(force, fn, xi_new, slide & active)
    damping = ((kn * overlap - fn) * vn
               + jnp.where(slide, 0.0, gt * jnp.sum(vt * vt, axis=-1))) * dt
    slip = jnp.where(slide, f_coul * _norm(xi_trial - xi), 0.0)
    release = 0.5 * jnp.broadcast_to(kt, fn.shape) * jnp.sum(spring * spring, axis=-1)
    return ContactResult(force, fn, xi_new, slide & active, jnp.where(active, damping, 0.0),
                         jnp.where(active, slip, release))


def rolling_torque(w_rel, fn, r_eff, mu_r, inertia_eff, dt):
    """Rolling-resistance torque on partner B (constant directional torque, capped).

    ``M = -min(mu_r R* F_n, I* |w_rel| / dt) w_rel/|w_rel|`` with ``w_rel = w_B - w_A``
    (rad/s; scalar z component in 2D). The cap stops the relative rolling in at most one step
    instead of reversing it. Known artefact of this capped model: on a slope that rolling
    resistance should hold (tan(theta) < mu_r) the particle creeps at
    ``|w| = M_needed dt / I`` (first order in dt, e.g. ~3e-3 rad/s for a 4 mm aluminium sphere
    near the bottom of a 100 mm drum at dt = 8e-6 s); an elastic-plastic rolling spring
    (Ai et al. 2011, model C) would remove it.
    """
    if w_rel.ndim == fn.ndim:  # 2D: scalar
        mag = jnp.abs(w_rel)
        cap = jnp.minimum(mu_r * r_eff * fn, inertia_eff * mag / dt)
        return -cap * jnp.sign(w_rel)
    mag = _norm(w_rel)
    cap = jnp.minimum(mu_r * r_eff * fn, inertia_eff * mag / dt)
    safe = jnp.where(mag > 0, mag, 1.0)
    return -(cap / safe)[..., None] * w_rel


def rolling_loss(m_r, w_rel, inertia_eff, dt, vector: bool):
    """Energy (J, >= 0) the rolling-resistance torque ``m_r`` of :func:`rolling_torque` takes
    from the relative rolling ``w_rel`` in one step.

    A torque of constant magnitude ``M`` against the relative rotation of effective inertia
    ``I*`` slows it from ``|w|`` to ``|w| - M dt / I*``; the kinetic energy of the relative
    rotation drops by ``M dt (|w| - M dt / (2 I*))`` (which is ``I* w^2 / 2`` when the cap stops
    the rolling within the step). ``vector``: 3-vectors (3D) on a trailing axis, else scalars
    (the z components in 2D), as in :func:`rolling_torque`.
    """
    if vector:
        mag_m, mag_w = _norm(m_r), _norm(w_rel)
    else:
        mag_m, mag_w = jnp.abs(m_r), jnp.abs(w_rel)
    return mag_m * dt * jnp.maximum(mag_w - 0.5 * mag_m * dt / inertia_eff, 0.0)
