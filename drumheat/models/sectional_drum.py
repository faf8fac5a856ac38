"""Transverse bed geometry of a rotary drum with sectional internals (Herz 2024).

The drum cross-section (shell radius ``R1``, inner cylinder radius ``R2``) is divided by radial
plates into annular sections of angle ``alpha`` (eight sections of 45 degrees in the source).
Every section carries the same filling degree ``fill`` of its own area. At each rotation angle
``delta`` the bed in a section is the part of the section lying below a straight free surface
inclined at the kinetic angle of repose ``gamma`` (constant over the revolution), and the
surface's offset is fixed by the bed area. The model returns the contact lengths per unit drum
length (reference: ``reference/herz-sectional-drum.md``, cited below as *Herz digest*):

=========  ==========================================================
``P1``     bed on plate 1 (``B1C1``, the leading plate at ``phi1``)
``P2``     bed on plate 2 (``B2C2``, at ``phi2 = phi1 - alpha``)
``Wo``     bed on the shell arc ``C1C2``
``Wi``     bed on the inner-cylinder arc ``B1B2``
``l_SG``   free surface (solid-gas contact), chord ``DE``
=========  ==========================================================

Conventions (Herz digest, Sec. 1, eq. 17): origin on the drum axis, ``x`` horizontal, ``y`` up.
The drum turns clockwise; ``delta`` is the direction of ``OC1`` measured clockwise from the
negative ``x`` half-axis, so plate 1 lies at the counter-clockwise polar angle
``phi1 = pi - delta`` and plate 2 at ``phi2 = pi - delta - alpha``. The free surface has slope
``-tan(gamma)``: it falls towards ``+x``.

Formulation
-----------
We use the general half-plane formulation of the Herz digest, Sec. 3 (our reformulation there,
not the source's case-by-case method): the bed is ``S ∩ {s(x) <= c}`` with
``s(x) = x sin(gamma) + y cos(gamma)``. All lengths and the area follow in closed form from ``c``,
and ``c`` is found by bisection (``A(c)`` is monotone, ``dA/dc = l_SG``) followed by one Newton
step, so that ``jax.grad`` through the solution gives the implicit-function derivative. This
needs no case table and no root selection. The source's region-by-region construction (Herz
digest, Sec. 2.3, eqs. 14, 21-25, 31-34, 43-45) is reproduced independently in the tests and
agrees to round-off. Region labels 1-8 (Sec. 2.2) are derived from the none/part/all pattern of
``P1, P2, Wo, Wi``; a pattern outside the source's table gets label 0.

Angles in the public API are in degrees (as in the source); lengths in metres (any consistent
length unit works: every length scales with ``R1``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.devices import round_length

__all__ = [
    "ContactLengths",
    "RegionBoundary",
    "REGION_PATTERNS",
    "section_area",
    "bed_area",
    "contact_lengths",
    "region_label",
    "drum_contact_lengths",
    "region_boundaries",
    "cycle_means",
    "contact_length_rates",
    "delta_at_time",
    "bed_polygon",
    "section_polygon",
    "plot_contact_lengths",
    "plot_bed",
]

_TWO_PI = 2.0 * math.pi
_N_BISECT = 64  # halvings of [-R1, R1]: 2 R1 / 2**64 is below float64 resolution of c

# Region topologies, Herz digest Sec. 2.2: state of (P1, P2, Wo, Wi) with
# 0 = not touched, 1 = partly wetted, 2 = fully wetted.
REGION_PATTERNS: dict[int, tuple[int, int, int, int]] = {
    1: (1, 0, 1, 0),  # plate 1 part (from C1), shell part
    2: (2, 0, 1, 1),  # plate 1 all, shell part, inner arc part (from B1)
    3: (2, 1, 1, 2),  # plate 1 all, inner arc all, plate 2 part (from B2), shell part
    4: (1, 1, 0, 2),  # inner arc all, plate 1 part, plate 2 part
    5: (1, 2, 1, 2),  # plate 2 all, inner arc all, plate 1 part, shell part (from C2)
    6: (0, 2, 1, 1),  # plate 2 all, shell part, inner arc part (from B2)
    7: (0, 1, 1, 0),  # plate 2 part (from C2), shell part
    8: (1, 1, 2, 0),  # shell all, plate 1 part, plate 2 part
}
_CODE_TO_REGION = np.zeros(81, dtype=np.int32)
for _reg, (_a, _b, _c, _d) in REGION_PATTERNS.items():
    _CODE_TO_REGION[_a + 3 * _b + 9 * _c + 27 * _d] = _reg


class ContactLengths(NamedTuple):
    """Contact lengths of the bed in one section (per unit drum length).

    All fields have the shape of the ``delta`` input (NumPy arrays for concrete inputs, JAX
    arrays when traced). Lengths in the unit of ``R1`` (m).

    Attributes
    ----------
    P1, P2 : bed contact with plate 1 (``B1C1``) and plate 2 (``B2C2``), m.
    Wo : bed contact with the shell arc ``C1C2``, m.
    Wi : bed contact with the inner-cylinder arc ``B1B2``, m.
    l_SG : free-surface length (solid-gas contact), m.
    c : offset of the free-surface line ``x sin(gamma) + y cos(gamma) = c``, m.
    region : region label 1-8 of Herz digest Sec. 2.2 (0: topology outside that table, or a
        point exactly on a region boundary within the classification tolerance).
    """

    P1: jax.Array
    P2: jax.Array
    Wo: jax.Array
    Wi: jax.Array
    l_SG: jax.Array
    c: jax.Array
    region: jax.Array


class RegionBoundary(NamedTuple):
    """A change of bed topology at rotation angle ``delta_deg`` (degrees, in [0, 360))."""

    delta_deg: float
    region_before: int
    region_after: int


# --------------------------------------------------------------------------------------------
# closed-form pieces (radians inside)
# --------------------------------------------------------------------------------------------


def section_area(R1, R2, alpha_deg=45.0):
    """Area of one annular section, ``A_section = (alpha/2)(R1^2 - R2^2)``.

    Herz digest, eq. (1).

    Parameters
    ----------
    R1, R2 : float
        Shell and inner-cylinder radius, m.
    alpha_deg : float
        Section angle, degrees (45 for eight sections).

    Returns
    -------
    float
        Section area per unit drum length, m^2.
    """
    return 0.5 * jnp.deg2rad(alpha_deg) * (R1**2 - R2**2)


def _safe_div(num, den, eps=1e-300):
    ok = jnp.abs(den) > eps
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0), ok


def _arc_measure(R, c, psi_a, alpha):
    """Measure of ``{psi in [psi_a, psi_a + alpha] : R sin(psi) <= c}`` (rad).

    ``psi = phi + gamma``; this is ``Phi_R(c)`` of Herz digest Sec. 3. ``R > 0`` is assumed by
    the caller (``R = 0`` contributes nothing because it is multiplied by ``R``).
    """
    R_safe = jnp.where(R > 0, R, 1.0)
    u = c / R_safe
    inside = jnp.abs(u) < 1.0
    # double-where keeps gradients finite where arcsin' is infinite (|u| >= 1)
    p = jnp.where(inside, jnp.arcsin(jnp.where(inside, u, 0.0)), jnp.sign(u) * (0.5 * jnp.pi))
    q = jnp.pi - p  # R sin(psi) > c on (p, q) + 2 pi k
    a0 = jnp.mod(psi_a, _TWO_PI)
    b0 = a0 + alpha
    over = 0.0
    for k in (0, 1):  # alpha < pi and a0 in [0, 2 pi): only these two copies can overlap
        lo = jnp.maximum(a0, p + _TWO_PI * k)
        hi = jnp.minimum(b0, q + _TWO_PI * k)
        over = over + jnp.maximum(0.0, hi - lo)
    return jnp.clip(alpha - over, 0.0, alpha)


def _chord_interval(R, c, gamma, phi1, phi2):
    """Parameter interval ``[t_lo, t_hi]`` of the chord of ``s = c`` across the sector of radius R.

    Points on the line are ``X(t) = c n + t tau`` with ``n = (sin g, cos g)`` and
    ``tau = (-cos g, sin g)`` (the traversal direction of Herz digest Sec. 3). The sector
    (``r <= R``, polar angle in ``[phi2, phi1]``, opening below pi) is the intersection of the
    disc with two half-planes through the origin, each of which bounds ``t`` linearly.
    Returns ``(t_lo, t_hi)``; the chord is empty when ``t_hi <= t_lo``.
    """
    h2 = R * R - c * c
    h = jnp.where(h2 > 0, jnp.sqrt(jnp.where(h2 > 0, h2, 1.0)), 0.0)  # NaN-free gradient
    t_lo = -h
    t_hi = h
    big = 1e300
    # cross(u2, X) >= 0:  c cos(phi2+g) + t sin(phi2+g) >= 0
    # cross(X, u1) >= 0: -c cos(phi1+g) - t sin(phi1+g) >= 0
    for A, B in (
        (c * jnp.cos(phi2 + gamma), jnp.sin(phi2 + gamma)),
        (-c * jnp.cos(phi1 + gamma), -jnp.sin(phi1 + gamma)),
    ):
        t_star, ok = _safe_div(-A, B, 1e-14)
        lower = jnp.where(ok & (B > 0), t_star, jnp.where(ok | (A >= 0), -big, big))
        upper = jnp.where(ok & (B < 0), t_star, jnp.where(ok | (A >= 0), big, -big))
        t_lo = jnp.maximum(t_lo, lower)
        t_hi = jnp.minimum(t_hi, upper)
    return t_lo, t_hi


def _sector_terms(R, c, gamma, phi1, phi2, alpha):
    """Area ``G(R, c)``, chord length ``L(R, c)`` and arc measure of the clipped sector."""
    Phi = _arc_measure(R, c, phi2 + gamma, alpha)
    t_lo, t_hi = _chord_interval(R, c, gamma, phi1, phi2)
    L = jnp.maximum(t_hi - t_lo, 0.0)
    # Green's theorem: radial edges contribute nothing, the arc 1/2 R^2 Phi, and the chord
    # P->Q (traversed along tau) 1/2 (P x Q) = 1/2 c L because n x tau = 1.
    G = 0.5 * R * R * Phi + 0.5 * c * L
    return G, L, Phi


def _plate_length(c, phi, gamma, R1, R2):
    """Wetted length of the plate at polar angle ``phi``: ``{t in [R2,R1]: t sin(phi+g) <= c}``."""
    sig = jnp.sin(phi + gamma)
    t_star, ok = _safe_div(c, sig, 1e-14)
    t_cl = jnp.clip(t_star, R2, R1)
    length = jnp.where(sig > 0, t_cl - R2, R1 - t_cl)
    return jnp.where(ok, length, jnp.where(c >= 0, R1 - R2, 0.0))


def _area_and_surface(c, R1, R2, gamma, phi1, phi2, alpha):
    G1, L1, _ = _sector_terms(R1, c, gamma, phi1, phi2, alpha)
    G2, L2, _ = _sector_terms(R2, c, gamma, phi1, phi2, alpha)
    return G1 - G2, L1 - L2


def _state(x, full, tol):
    return jnp.where(x <= tol, 0, jnp.where((full > tol) & (x >= full - tol), 2, 1))


def _section_scalar(delta, R1, R2, fill, gamma, alpha):
    """Contact lengths at one rotation angle (all angles in radians)."""
    phi1 = jnp.pi - delta
    phi2 = phi1 - alpha
    A_bed = fill * 0.5 * alpha * (R1**2 - R2**2)  # Herz digest eq. (1)

    def body(_, lohi):
        lo, hi = lohi
        mid = 0.5 * (lo + hi)
        A, _ = _area_and_surface(mid, R1, R2, gamma, phi1, phi2, alpha)
        below = A < A_bed
        return (jnp.where(below, mid, lo), jnp.where(below, hi, mid))

    # |s(x)| <= |x| <= R1, so A(-R1) = 0 and A(R1) = A_section bracket every filling.
    lo, hi = jax.lax.fori_loop(0, _N_BISECT, body, (-R1 * jnp.ones_like(delta), R1 * jnp.ones_like(delta)))
    c0 = jax.lax.stop_gradient(0.5 * (lo + hi))
    # one Newton step, dA/dc = l_SG (Herz digest Sec. 3): a no-op in value at convergence, but
    # it carries the implicit-function derivative dc/dtheta = -(dA/dtheta - dA_bed/dtheta)/l_SG
    A0, L0 = _area_and_surface(c0, R1, R2, gamma, phi1, phi2, alpha)
    step, _ = _safe_div(A0 - A_bed, L0, 1e-300)
    c = c0 - step

    _, L1, Phi1 = _sector_terms(R1, c, gamma, phi1, phi2, alpha)
    _, L2, Phi2 = _sector_terms(R2, c, gamma, phi1, phi2, alpha)
    l_SG = L1 - L2
    Wo = R1 * Phi1
    Wi = R2 * Phi2
    P1 = _plate_length(c, phi1, gamma, R1, R2)
    P2 = _plate_length(c, phi2, gamma, R1, R2)

    tol = 1e-12 * R1
    code = (
        _state(P1, R1 - R2, tol)
        + 3 * _state(P2, R1 - R2, tol)
        + 9 * _state(Wo, R1 * alpha, tol)
        + 27 * _state(Wi, R2 * alpha, tol)
    )
    region = jnp.asarray(_CODE_TO_REGION)[code]
    return P1, P2, Wo, Wi, l_SG, c, region, code


_section_vmapped_jit = jax.jit(jax.vmap(_section_scalar, in_axes=(0, None, None, None, None, None)))


_CHUNK = 256


def _section_vmapped(delta, *params):
    """Evaluate on a flat array of angles in chunks of one fixed length, so that one compiled
    executable serves every call (compiling costs seconds, a chunk well under a millisecond).
    With concrete inputs, padding and joining are done in NumPy (no per-shape compiles either)."""
    traced = any(isinstance(v, jax.core.Tracer) for v in (delta, *params))
    xp = jnp if traced else np
    n = delta.shape[0]
    m = round_length(max(n, 1), _CHUNK)
    padded = xp.concatenate([delta, xp.zeros(m - n, delta.dtype)]) if m > n else delta
    parts = [_section_vmapped_jit(padded[i:i + _CHUNK], *params) for i in range(0, m, _CHUNK)]
    if not traced:
        parts = [tuple(np.asarray(o) for o in p) for p in parts]
    return tuple(xp.concatenate([p[k] for p in parts])[:n] for k in range(len(parts[0])))


def _check_inputs(R1, R2, fill, gamma_deg, alpha_deg):
    """Validate concrete inputs; traced values (inside jit/grad) are passed through."""
    try:
        R1f, R2f, ff, gf, af = (float(v) for v in (R1, R2, fill, gamma_deg, alpha_deg))
    except (TypeError, jax.errors.ConcretizationTypeError):
        return
    if not R1f > 0:
        raise ValueError(f"R1 = {R1f!r}: the shell radius must be positive.")
    if not 0 <= R2f < R1f:
        raise ValueError(f"R2 = {R2f!r}: the inner radius must satisfy 0 <= R2 < R1 = {R1f}.")
    if not 0 < ff < 1:
        raise ValueError(f"fill = {ff!r}: the filling degree of a section must lie in (0, 1).")
    if not -90 < gf < 90:
        raise ValueError(f"gamma_deg = {gf!r}: the angle of repose must lie in (-90, 90) degrees.")
    if not 0 < af < 180:
        raise ValueError(f"alpha_deg = {af!r}: the section angle must lie in (0, 180) degrees.")


def contact_lengths(delta_deg, *, R1, R2, fill, gamma_deg, alpha_deg=45.0) -> ContactLengths:
    """Contact lengths of the bed in one section as functions of the rotation angle.

    Half-plane formulation of Herz digest Sec. 3 (equivalent to the region-wise construction of
    Sec. 2.3, eqs. 14, 21-25, 31-34, 43-46 with the errata of Sec. 2.5 applied):

    - area ``A(c) = G(R1, c) - G(R2, c)``, ``G(R, c) = 1/2 R^2 Phi_R(c) + 1/2 c L_R(c)``;
    - ``l_SG = L_R1(c) - L_R2(c)``, ``Wo = R1 Phi_R1(c)``, ``Wi = R2 Phi_R2(c)``;
    - ``P_j = length{t in [R2, R1] : t sin(phi_j + gamma) <= c}``;
    - ``c`` solves ``A(c) = fill * A_section`` (eq. 1).

    Parameters
    ----------
    delta_deg : float or array_like
        Rotation angle of the section (direction of ``OC1``, clockwise from the negative x
        half-axis, Herz digest eq. 17), degrees. Any shape; any real value (taken mod 360).
    R1, R2 : float
        Shell and inner-cylinder radius, m (``0 <= R2 < R1``).
    fill : float
        Filling degree of the section (bed area / section area), in (0, 1).
    gamma_deg : float
        Kinetic angle of repose, degrees; the free surface falls towards ``+x``.
    alpha_deg : float, optional
        Section angle, degrees (default 45: eight sections).

    Returns
    -------
    ContactLengths
        ``P1, P2, Wo, Wi, l_SG, c`` (m) and the region label, each with the shape of
        ``delta_deg``.
    """
    _check_inputs(R1, R2, fill, gamma_deg, alpha_deg)
    xp = jnp if isinstance(delta_deg, jax.core.Tracer) else np
    d = xp.asarray(delta_deg, dtype=xp.float64)
    shape = d.shape
    out = _section_vmapped(
        xp.deg2rad(d.reshape(-1)),
        *(_as_param(v) for v in (R1, R2, fill)),
        _as_param(gamma_deg, deg=True),
        _as_param(alpha_deg, deg=True),
    )
    return ContactLengths(*(o.reshape(shape) for o in out[:7]))


def _as_param(v, deg=False):
    if isinstance(v, jax.core.Tracer):
        return jnp.deg2rad(v) if deg else v
    v = np.float64(v)
    return np.deg2rad(v) if deg else v


def _pattern_code(delta_deg, R1, R2, fill, gamma_deg, alpha_deg):
    d = np.asarray(delta_deg, dtype=np.float64).reshape(-1)
    out = _section_vmapped(
        np.deg2rad(d), *(_as_param(v) for v in (R1, R2, fill)),
        _as_param(gamma_deg, deg=True), _as_param(alpha_deg, deg=True),
    )
    return np.asarray(out[7])


def region_label(delta_deg, *, R1, R2, fill, gamma_deg, alpha_deg=45.0):
    """Region label (1-8, Herz digest Sec. 2.2) at rotation angle(s) ``delta_deg`` (degrees).

    0 means a topology outside the source's table (or a point on a boundary within the
    classification tolerance of 1e-12 R1).
    """
    return contact_lengths(
        delta_deg, R1=R1, R2=R2, fill=fill, gamma_deg=gamma_deg, alpha_deg=alpha_deg
    ).region


def bed_area(delta_deg, c, *, R1, R2, gamma_deg, alpha_deg=45.0):
    """Area of the section below the line ``x sin(gamma) + y cos(gamma) = c``, m^2.

    Herz digest Sec. 3, ``A(c) = G(R1, c) - G(R2, c)``. Used to check the area closure.
    """
    delta = jnp.deg2rad(jnp.asarray(delta_deg, jnp.float64))
    alpha = jnp.deg2rad(alpha_deg)
    phi1 = jnp.pi - delta
    A, _ = _area_and_surface(
        jnp.asarray(c, jnp.float64), R1, R2, jnp.deg2rad(gamma_deg), phi1, phi1 - alpha, alpha
    )
    return A


def delta_at_time(t, *, rpm, delta0_deg=0.0):
    """Rotation angle of a section at time ``t``: ``delta = delta0 + 6 n t`` (degrees).

    Herz digest Sec. 3 ("Whole drum"); ``n`` in rpm (clockwise positive), ``t`` in s.
    """
    return delta0_deg + 6.0 * rpm * jnp.asarray(t)


def drum_contact_lengths(delta_deg, *, R1, R2, fill, gamma_deg, alpha_deg=45.0) -> dict:
    """Contact lengths summed over all sections of the drum, m.

    The sections sit at ``delta_j = delta + j alpha`` (``j = 0 .. 360/alpha - 1``), Herz digest
    Sec. 3 ("Whole drum"). ``alpha_deg`` must divide 360.

    Returns
    -------
    dict
        ``P1, P2, Wo, Wi, l_SG`` summed over the sections (shape of ``delta_deg``), plus the
        surface variants of Herz digest Sec. 5: ``plates = P1 + P2`` and ``walls = Wi + Wo``
        (variant a) and ``all_walls = P1 + P2 + Wi + Wo`` (variant b).
    """
    n_sec = 360.0 / alpha_deg
    if abs(n_sec - round(n_sec)) > 1e-9:
        raise ValueError(f"alpha_deg = {alpha_deg}: must divide 360 for a whole drum.")
    n_sec = int(round(n_sec))
    xp = jnp if isinstance(delta_deg, jax.core.Tracer) else np
    d = xp.asarray(delta_deg, xp.float64)
    dd = d[..., None] + alpha_deg * xp.arange(n_sec)
    cl = contact_lengths(dd, R1=R1, R2=R2, fill=fill, gamma_deg=gamma_deg, alpha_deg=alpha_deg)
    out = {k: getattr(cl, k).sum(axis=-1) for k in ("P1", "P2", "Wo", "Wi", "l_SG")}
    return _with_variants(out)


def _with_variants(d: dict) -> dict:
    d = dict(d)
    d["plates"] = d["P1"] + d["P2"]
    d["walls"] = d["Wi"] + d["Wo"]
    d["all_walls"] = d["P1"] + d["P2"] + d["Wi"] + d["Wo"]
    return d


# --------------------------------------------------------------------------------------------
# region boundaries, cycle means, rates
# --------------------------------------------------------------------------------------------


def region_boundaries(
    *, R1, R2, fill, gamma_deg, alpha_deg=45.0, n_scan=1440, tol_deg=1e-10
) -> list[RegionBoundary]:
    """Rotation angles at which the bed topology changes (region boundaries), degrees.

    Herz digest Sec. 2.4: each transition is an event where one contact length reaches 0 or
    its full value (1->2: ``P1 = R1 - R2``; 2->3: ``Wi = R2 alpha``; 3->4: ``Wo = 0``; 4->5:
    ``P2 = R1 - R2``; 5->6: ``P1 = 0``; 6->7: ``Wi = 0``; 7->8: ``Wo = R1 alpha``; 8->1:
    ``P2 = 0``). They are found as changes of the none/part/all pattern of ``(P1, P2, Wo, Wi)``
    on a scan of ``n_scan`` angles, each refined by bisection to ``tol_deg``. This also finds
    transitions of topologies outside the source's table (label 0).

    Parameters
    ----------
    R1, R2, fill, gamma_deg, alpha_deg
        As in :func:`contact_lengths`.
    n_scan : int
        Scan points over one revolution; two transitions closer than ``360/n_scan`` degrees can
        be missed.
    tol_deg : float
        Bisection tolerance, degrees.

    Returns
    -------
    list of RegionBoundary
        Sorted by ``delta_deg`` in ``[0, 360)``; ``region_before``/``region_after`` are the labels
        (0 for a topology outside the table) just below and above the boundary.
    """
    _check_inputs(R1, R2, fill, gamma_deg, alpha_deg)
    args = (R1, R2, fill, gamma_deg, alpha_deg)
    grid = np.linspace(0.0, 360.0, n_scan + 1)
    codes = _pattern_code(grid, *args)
    idx = np.nonzero(codes[1:] != codes[:-1])[0]
    if idx.size == 0:
        return []
    lo = grid[idx].copy()
    hi = grid[idx + 1].copy()
    code_lo = codes[idx]
    while np.max(hi - lo) > tol_deg:
        mid = 0.5 * (lo + hi)
        same = _pattern_code(mid, *args) == code_lo
        lo = np.where(same, mid, lo)
        hi = np.where(same, hi, mid)
    eps = 1e-6
    before = _CODE_TO_REGION[_pattern_code(lo - eps, *args)]
    after = _CODE_TO_REGION[_pattern_code(hi + eps, *args)]
    out = [
        RegionBoundary(float(np.mod(0.5 * (a + b), 360.0)), int(r0), int(r1))
        for a, b, r0, r1 in zip(lo, hi, before, after)
    ]
    return sorted(out, key=lambda b: b.delta_deg)


def cycle_means(*, R1, R2, fill, gamma_deg, alpha_deg=45.0, n_gauss=24) -> dict:
    """Revolution means of the contact lengths of one section, m.

    ``mean_delta(l) = (1/360) * integral_0^360 l(delta) d delta`` (the numerator of Herz digest
    eq. 48 as read in Sec. 5). Integrated piecewise between the region boundaries (where the
    lengths have kinks) with ``n_gauss``-point Gauss-Legendre rules, so the result is accurate to
    round-off for smooth pieces.

    Returns
    -------
    dict
        Means of ``P1, P2, Wo, Wi, l_SG`` and of the variants ``plates = P1 + P2``,
        ``walls = Wi + Wo``, ``all_walls`` (Herz digest Sec. 5).
    """
    bnds = [b.delta_deg for b in region_boundaries(
        R1=R1, R2=R2, fill=fill, gamma_deg=gamma_deg, alpha_deg=alpha_deg)]
    edges = np.unique(np.concatenate([[0.0], bnds, [360.0]]))
    x, w = np.polynomial.legendre.leggauss(n_gauss)
    a, b = edges[:-1, None], edges[1:, None]
    nodes = (0.5 * (b - a) * x + 0.5 * (a + b)).ravel()
    weights = (0.5 * (b - a) * w).ravel()
    cl = contact_lengths(nodes, R1=R1, R2=R2, fill=fill, gamma_deg=gamma_deg, alpha_deg=alpha_deg)
    means = {k: float(np.sum(weights * np.asarray(getattr(cl, k))) / 360.0)
             for k in ("P1", "P2", "Wo", "Wi", "l_SG")}
    return _with_variants(means)


def contact_length_rates(means: dict, rpm: float) -> dict:
    """Mean contact-length rates ``l_dot = mean_delta(l) * n / 60`` (m/s per metre of drum).

    Herz digest Sec. 5, eq. (48). As printed, eq. (48) reads
    ``[(1/n) sum_{delta=0}^{360} l] / (60/n)``; we implement the consistent reading given in the
    digest: the bracket is the revolution-mean length (the printed ``1/n`` is a sample average
    over the evaluated angles, not the speed) and ``60/n`` is the period in seconds. The result
    is the contact surface renewed per second per metre of drum length for one section; apply it
    to :func:`drum_contact_lengths`-style sums by passing their means.

    Parameters
    ----------
    means : dict
        Revolution-mean lengths, m (e.g. from :func:`cycle_means`).
    rpm : float
        Drum speed ``n``, revolutions per minute.

    Returns
    -------
    dict
        Same keys as ``means``, values in m/s.
    """
    return {k: v * rpm / 60.0 for k, v in means.items()}


# --------------------------------------------------------------------------------------------
# shapes for plotting
# --------------------------------------------------------------------------------------------


def section_polygon(delta_deg, *, R1, R2, alpha_deg=45.0, n_arc=200, extra_angles=()) -> np.ndarray:
    """Vertices (counter-clockwise) of the annular section ``B1 B2 C2 C1`` with sampled arcs, m.

    Herz digest eq. (17). Returns the shell arc from ``C2`` to ``C1`` (``n_arc`` points plus any
    ``extra_angles``, polar angles in rad that fall inside the section), then the inner arc from
    ``B1`` back to ``B2``.
    """
    phi1 = math.pi - math.radians(delta_deg)
    phi2 = phi1 - math.radians(alpha_deg)
    extra = [phi2 + (e - phi2) % _TWO_PI for e in extra_angles]
    extra = [e for e in extra if phi2 < e < phi1]
    t = np.unique(np.concatenate([np.linspace(phi2, phi1, n_arc), extra]))
    outer = R1 * np.column_stack([np.cos(t), np.sin(t)])
    inner = R2 * np.column_stack([np.cos(t[::-1]), np.sin(t[::-1])])
    if R2 == 0:
        inner = inner[:1]
    return np.vstack([outer, inner])


def _clip_halfplane(poly: np.ndarray, nvec: np.ndarray, c: float) -> np.ndarray:
    """Sutherland-Hodgman clip of a polygon by the half-plane ``n . x <= c``."""
    out = []
    m = len(poly)
    s = poly @ nvec - c
    s[np.abs(s) < 1e-13 * np.max(np.abs(poly))] = 0.0  # vertices placed on the line stay on it
    for i in range(m):
        p, q = poly[i], poly[(i + 1) % m]
        sp, sq = s[i], s[(i + 1) % m]
        if sp <= 0:
            out.append(p)
        if (sp < 0 < sq) or (sq < 0 < sp):
            out.append(p + (q - p) * (sp / (sp - sq)))
    return np.array(out).reshape(-1, 2)


def bed_polygon(delta_deg, *, R1, R2, fill, gamma_deg, alpha_deg=45.0, n_arc=200) -> np.ndarray:
    """Vertices of the bed in one section at rotation angle ``delta_deg``, m (for plotting).

    The annular section (arcs sampled with ``n_arc`` points) is clipped by the half-plane below
    the free surface (Sutherland-Hodgman, Herz digest Sec. 3, "robust fallback"), with the
    surface offset ``c`` from :func:`contact_lengths`. The polar angles where the surface line
    meets the two circles are inserted into the arc samples, so the chord end points are exact;
    the arcs are polygonal, so the polygon area approaches the bed area as ``O(n_arc^-2)``.

    Returns
    -------
    numpy.ndarray
        ``(M, 2)`` counter-clockwise vertices ``(x, y)``.
    """
    cl = contact_lengths(delta_deg, R1=R1, R2=R2, fill=fill, gamma_deg=gamma_deg, alpha_deg=alpha_deg)
    g = math.radians(gamma_deg)
    c = float(cl.c)
    extra = []
    for R in (R1, R2):
        if R > abs(c):  # R sin(phi + g) = c
            a = math.asin(c / R)
            extra += [a - g, math.pi - a - g]
    poly = section_polygon(delta_deg, R1=R1, R2=R2, alpha_deg=alpha_deg, n_arc=n_arc,
                           extra_angles=extra)
    return _clip_halfplane(poly, np.array([math.sin(g), math.cos(g)]), c)


def plot_bed(delta_deg, *, R1, R2, fill, gamma_deg, alpha_deg=45.0, ax=None, all_sections=True):
    """Draw the drum cross-section with the bed of each section at rotation angle ``delta_deg``.

    Returns the matplotlib Figure.
    """
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(figsize=(5, 5))
    else:
        fig = ax.figure
    n_sec = int(round(360.0 / alpha_deg)) if all_sections else 1
    for j in range(n_sec):
        dj = delta_deg + j * alpha_deg
        sec = section_polygon(dj, R1=R1, R2=R2, alpha_deg=alpha_deg)
        ax.fill(sec[:, 0], sec[:, 1], facecolor="none", edgecolor="0.3", lw=0.8)
        bed = bed_polygon(dj, R1=R1, R2=R2, fill=fill, gamma_deg=gamma_deg, alpha_deg=alpha_deg)
        if len(bed):
            ax.fill(bed[:, 0], bed[:, 1], color="tab:orange" if j == 0 else "tab:brown", alpha=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"delta = {delta_deg:g} deg")
    return fig


def plot_contact_lengths(
    *, R1, R2, fill, gamma_deg, alpha_deg=45.0, n=1441, ax=None, normalize=False, show_regions=True
):
    """Figure of the contact lengths ``P1, P2, Wo, Wi, l_SG`` of one section over one revolution.

    Herz digest Sec. 2-3. Region boundaries (Sec. 2.4) are drawn as dotted lines with the region
    numbers between them.

    Parameters
    ----------
    R1, R2, fill, gamma_deg, alpha_deg
        As in :func:`contact_lengths`.
    n : int
        Number of rotation angles over [0, 360] degrees.
    ax : matplotlib Axes, optional
        Axes to draw into; a new figure is made when omitted.
    normalize : bool
        Plot lengths divided by ``R1`` instead of in metres.
    show_regions : bool
        Mark region boundaries and labels.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(figsize=(8, 4.5))
    else:
        fig = ax.figure
    d = np.linspace(0.0, 360.0, n)
    cl = contact_lengths(d, R1=R1, R2=R2, fill=fill, gamma_deg=gamma_deg, alpha_deg=alpha_deg)
    scale = 1.0 / R1 if normalize else 1.0
    labels = {"P1": "P1 (plate 1)", "P2": "P2 (plate 2)", "Wo": "Wo (shell)",
              "Wi": "Wi (inner cylinder)", "l_SG": "l_SG (free surface)"}
    for k, lab in labels.items():
        ax.plot(d, scale * np.asarray(getattr(cl, k)), label=lab)
    if show_regions:
        bnds = region_boundaries(R1=R1, R2=R2, fill=fill, gamma_deg=gamma_deg, alpha_deg=alpha_deg)
        ymax = ax.get_ylim()[1]
        for b in bnds:
            ax.axvline(b.delta_deg, color="0.5", ls=":", lw=0.8)
        edges = [0.0] + [b.delta_deg for b in bnds] + [360.0]
        for a, b in zip(edges[:-1], edges[1:]):
            if b - a > 4.0:
                r = int(region_label(0.5 * (a + b), R1=R1, R2=R2, fill=fill,
                                     gamma_deg=gamma_deg, alpha_deg=alpha_deg))
                ax.text(0.5 * (a + b), 0.97 * ymax, str(r) if r else "?", ha="center", va="top",
                        fontsize=9, color="0.3")
    ax.set_xlim(0.0, 360.0)
    ax.set_xlabel("rotation angle delta (deg)")
    ax.set_ylabel("contact length / R1 (-)" if normalize else "contact length (m)")
    ax.set_title(f"Sectional drum: f = {fill:g}, R2/R1 = {R2 / R1:.3g}, gamma = {gamma_deg:g} deg")
    ax.legend(loc="center right", fontsize=8)
    return fig
