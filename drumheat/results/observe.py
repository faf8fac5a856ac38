"""Observables and the heat-transfer analysis of Weigler's appendices A7/A8/A9.

Pure functions on NumPy or JAX arrays. The thesis does this analysis by hand in Matlab after
every run; here it is a library that the runner (:mod:`drumheat.run`), the calibration
(:mod:`drumheat.analysis.calibrate`) and users in notebooks share.

Two kinds of functions live here:

* **Formula observables** (:func:`alpha_overall`, :func:`alpha_bed_from_overall`,
  :func:`lambda_bed_curve`, :func:`thermal_mixing_time`, :func:`group_means`,
  :func:`count_interfraction_contacts`, :meth:`CalibrationLine.lambda_bed`, ...) are written
  in ``jax.numpy``: they broadcast, return ``jax.Array`` and can be differentiated and jitted.
* **Read-off procedures** (:func:`log_slope`, :func:`penetration_time`,
  :func:`temperature_distribution`, :func:`mixing_index`, :func:`mechanical_mixing_time`)
  make discrete choices (which point crosses, which class a particle falls in, a nonlinear
  least-squares fit); they are written in NumPy/SciPy, take array-likes (JAX arrays are
  converted) and are **not** differentiable.

Units are SI throughout: s, K, m, kg, J/(kg K), W/(m^2 K), W/(m K).

The typical A7 pipeline (digest ``reference/weigler-thermal-dem.md``, section 6.4)::

    alpha = alpha_overall(t, T_mean, T_w, T_0, mass_heat_capacity=sum(m_i c_i),
                          area=d_p**2 * n_wall_contacts)           # eq. [1.10]
    a_bed = alpha_bed_from_overall(alpha, alpha_ws)                 # eq. [1.6]
    lam = lambda_bed_curve(t, a_bed, rho_bed, c_bed)                # eq. [5.1]
    pt = penetration_time(t, alpha)                                 # slope -0.5 / inflection
    lam_at = np.interp(pt.time, t, lam)
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from drumheat.models import penetration as _pm
from drumheat.mechanics.analysis import count_interfraction_contacts  # noqa: F401

__all__ = [
    "alpha_overall",
    "alpha_bed_from_overall",
    "lambda_bed_curve",
    "thermal_mixing_time",
    "log_slope",
    "PenetrationTime",
    "penetration_time",
    "CalibrationLine",
    "calibration_line",
    "group_means",
    "TemperatureDistribution",
    "temperature_distribution",
    "mixing_index",
    "count_interfraction_contacts",
    "MixingTimeFit",
    "mechanical_mixing_time",
    "mixing_time_horizontal",
    "HorizontalTrend",
]


# ---------------------------------------------------------------------------------------------
# Heat-transfer coefficients from mean-temperature curves
# ---------------------------------------------------------------------------------------------


def alpha_overall(t, T_mean, T_wall, T_0, mass_heat_capacity, area):
    """Time-averaged overall wall-to-bed coefficient from a mean-temperature curve.

    weigler-thermal-dem.md, eq. [1.10] (and A7 post-processing, section 6.4):
    ``alpha(t) = m c / (A t) * ln[(T_w - T_0) / (T_w - T_mean(t))]``.

    For a constant coefficient this inverts :func:`drumheat.models.penetration.mean_temperature`
    exactly. It works for heating and cooling (T_w < T_0).

    Parameters
    ----------
    t : array_like
        Times since the start of wall heat transfer, s.
    T_mean : array_like
        Heat-capacity-weighted mean bed temperature at ``t``, K (same shape as ``t``, or
        broadcastable).
    T_wall : array_like
        Wall temperature T_w, K.
    T_0 : array_like
        Initial mean bed temperature, K.
    mass_heat_capacity : array_like
        Total heat capacity of the bed ``m c = sum_i m_i c_i``, J/K.
    area : array_like
        Heat-transfer area A, m^2. The runner follows the A7 convention
        ``area = d_p**2 * n_wall_contacts`` (a 2D slice of depth d_p; digest item 12.9).

    Returns
    -------
    jax.Array
        alpha(t), W/(m^2 K). **t <= 0 gives NaN** (the formula is 0/0 at t = 0, the A7 listing
        divides by zero there, digest item 12.13). A mean temperature at or beyond the wall
        temperature gives inf / NaN (the logarithm's argument is infinite / negative).

    Notes
    -----
    Conditioning: the relative error of alpha is about
    ``eps * |T_w| / (|T_w - T_mean| * ln[(T_w - T_0)/(T_w - T_mean)])`` (eps = 2.2e-16), so
    it is ~1e-13 while T_w - T_mean is kelvins, ~1e-5 once the bed is within 1e-9 K of the
    wall (about 25 time constants m c/(alpha A) in float64) and meaningless beyond; read alpha
    off before the bed has fully reached the wall temperature.

    Differentiable with :func:`jax.grad`; the t <= 0 entries are masked with ``jnp.where`` on
    a safe denominator so that they do not poison the gradient of the other entries.
    """
    t = jnp.asarray(t, float)
    T_mean = jnp.asarray(T_mean, float)
    T_wall = jnp.asarray(T_wall, float)
    positive = t > 0
    t_safe = jnp.where(positive, t, 1.0)
    log_ratio = jnp.log((T_wall - jnp.asarray(T_0, float)) / (T_wall - T_mean))
    value = jnp.asarray(mass_heat_capacity, float) / (jnp.asarray(area, float) * t_safe) * log_ratio
    return jnp.where(positive, value, jnp.nan)


def alpha_bed_from_overall(alpha, alpha_ws):
    """Back-calculate the bed (penetration) coefficient from the overall one.

    weigler-thermal-dem.md, eq. [1.6] solved for alpha_bed:
    ``1/alpha_bed = 1/alpha - 1/alpha_ws``.

    Which wall coefficient to subtract (digest item 12.9):

    * the text (eq. [1.7], sections 11.1/11.2) uses ``alpha_ws = Phi * alpha_wp`` with
      Phi = 0.8 (:func:`drumheat.models.penetration.alpha_wall_bed`);
    * the A7/A8 scripts subtract ``1/alpha_pw`` itself (alpha_ws = alpha_wp) while defining
      alpha on the area ``A = d_p**2 * n_wall_contacts``.

    In a DEM run each wall contact transfers alpha_wp * pi d_p^2/4 per kelvin, which on the
    area d_p^2 per contact is an effective wall coefficient (pi/4) alpha_wp ~ 0.785 alpha_wp ~
    Phi alpha_wp. So with the A7 area, ``alpha_ws = Phi * alpha_wp`` is the consistent choice;
    subtracting 1/alpha_wp (A7) attributes part of the wall resistance to the bed and gives a
    smaller alpha_bed. Pass the alpha_ws of the convention you want and report it.

    Parameters
    ----------
    alpha : array_like
        Overall coefficient, W/(m^2 K) (e.g. from :func:`alpha_overall`).
    alpha_ws : array_like
        Wall-to-bed coefficient, W/(m^2 K).

    Returns
    -------
    jax.Array
        alpha_bed, W/(m^2 K). NaN where ``alpha >= alpha_ws`` (no positive bed resistance
        left: the overall coefficient cannot exceed the wall coefficient in the series model)
        or where alpha is NaN.
    """
    alpha = jnp.asarray(alpha, float)
    alpha_ws = jnp.asarray(alpha_ws, float)
    resistance = 1.0 / alpha - 1.0 / alpha_ws
    ok = resistance > 0
    return jnp.where(ok, 1.0 / jnp.where(ok, resistance, 1.0), jnp.nan)


def lambda_bed_curve(t, alpha_bed, rho_bed, c_bed):
    """Bed conductivity curve lambda_bed(t) from a bed coefficient curve.

    weigler-thermal-dem.md, eq. [5.1] (A7 post-processing, section 6.4):
    ``lambda_bed(t) = alpha_bed(t)^2 pi t / (4 rho_bed c_bed)``.
    Same formula as :func:`drumheat.models.penetration.lambda_bed_from_alpha_bed`, with the
    argument order of a time series.

    Note (digest item 12.8): lambda_bed scales with 1/rho_bed, and the thesis uses three
    different bulk densities (1230 in A7/A8, 1274 in Ch. 5.4, 1325-1375 in Table 5-2). Report
    the rho_bed used.

    Parameters
    ----------
    t : array_like
        Times, s.
    alpha_bed : array_like
        Bed coefficient at ``t``, W/(m^2 K) (NaN propagates).
    rho_bed : array_like
        Bulk density, kg/m^3.
    c_bed : array_like
        Bed heat capacity, J/(kg K).

    Returns
    -------
    jax.Array
        lambda_bed(t), W/(m K).
    """
    return _pm.lambda_bed_from_alpha_bed(alpha_bed, t, rho_bed, c_bed)


def thermal_mixing_time(alpha_bed, rho_bed, c_bed, lambda_bed):
    """Thermal mixing time ``t_th = 4 (rho c lambda)_bed / (pi alpha_bed^2)``.

    weigler-thermal-dem.md, eq. [5.3]; wrapper of
    :func:`drumheat.models.penetration.thermal_mixing_time` (see there for units).
    """
    return _pm.thermal_mixing_time(alpha_bed, rho_bed, c_bed, lambda_bed)


# ---------------------------------------------------------------------------------------------
# Log-log slope and the penetration read-off time
# ---------------------------------------------------------------------------------------------


def _local_linear_slope(x, f, width):
    """Gaussian-weighted local linear regression slope df/dx at every x (O(n^2) in chunks)."""
    n = x.size
    out = np.empty(n)
    chunk = max(1, 2_000_000 // max(n, 1))
    for start in range(0, n, chunk):
        xi = x[start : start + chunk, None]
        w = np.exp(-0.5 * ((x[None, :] - xi) / width) ** 2)
        sw = w.sum(axis=1, keepdims=True)
        xm = (w * x[None, :]).sum(axis=1, keepdims=True) / sw
        fm = (w * f[None, :]).sum(axis=1, keepdims=True) / sw
        dx = x[None, :] - xm
        out[start : start + chunk] = (w * dx * (f[None, :] - fm)).sum(axis=1) / (w * dx**2).sum(axis=1)
    return out


def log_slope(t, y, smooth=None):
    """Logarithmic slope ``d ln y / d ln t`` on a (possibly non-uniform) time grid.

    The slope of the overall coefficient in a log-log plot is the read-off criterion of the A7
    calibration (weigler-thermal-dem.md, section 10, step 3; A7 uses
    ``diff(ln alpha)/diff(ln t)``, section 6.4). Here it is computed more robustly:

    * ``smooth=None``: second-order central differences in log space on the non-uniform grid
      x = ln t (``numpy.gradient`` with coordinates, second-order one-sided at the ends). Exact
      for power laws and for ln y quadratic in ln t.
    * ``smooth=w`` (float, in **decades** of t): local linear least squares of ln y against
      ln t with Gaussian weights of standard deviation ``w`` decades around each point. Also
      exact for a power law; use it for noisy or saw-tooth curves (semi-discrete PM,
      digest section 11.1), e.g. ``smooth=0.1``.

    Points with t <= 0, y <= 0 or non-finite values (e.g. alpha at t = 0, which is NaN) are
    left out of the computation and get NaN in the output, so they do not spoil their
    neighbours.

    Parameters
    ----------
    t : array_like, shape (n,)
        Strictly increasing times, s (the valid ones must be strictly increasing).
    y : array_like, shape (n,)
        Positive quantity, e.g. alpha(t) in W/(m^2 K).
    smooth : float or None, optional
        Gaussian smoothing width in decades of t (see above).

    Returns
    -------
    numpy.ndarray, shape (n,)
        The slope, dimensionless; NaN at invalid points (and everywhere if fewer than 3 valid
        points remain).
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if t.shape != y.shape or t.ndim != 1:
        raise ValueError(f"log_slope: t and y must be 1-D of equal length, got {t.shape} and {y.shape}")
    valid = np.isfinite(t) & np.isfinite(y) & (t > 0) & (y > 0)
    out = np.full(t.shape, np.nan)
    if valid.sum() < 3:
        return out
    x = np.log(t[valid])
    if np.any(np.diff(x) <= 0):
        raise ValueError("log_slope: the valid times must be strictly increasing")
    f = np.log(y[valid])
    if smooth is None:
        out[valid] = np.gradient(f, x, edge_order=2)
    else:
        if not smooth > 0:
            raise ValueError(f"log_slope: smooth must be a positive width in decades, got {smooth!r}")
        out[valid] = _local_linear_slope(x, f, float(smooth) * math.log(10.0))
    return out


class PenetrationTime(NamedTuple):
    """Result of :func:`penetration_time`.

    Attributes
    ----------
    time : float
        Read-off time, s (NaN if neither criterion applies).
    criterion : str
        ``"slope"`` (the slope reaches ``target``), ``"inflection"`` (extremum of the slope
        curve, the fallback of A7) or ``"none"``.
    slope : numpy.ndarray
        The slope curve d ln alpha / d ln t on the input grid (NaN at invalid points).
    slope_at_time : float
        Slope at ``time`` (= target for the slope criterion), dimensionless.
    target : float
        The target slope that was searched for.
    """

    time: float
    criterion: str
    slope: np.ndarray
    slope_at_time: float
    target: float


def penetration_time(t, alpha, target=-0.5, smooth=None, which="first", fallback=True, t_range=None):
    """Read-off time of the A7 calibration: slope -0.5, else the log-log inflection point.

    weigler-thermal-dem.md, section 10, steps 3-4 (A7): lambda_bed is tied to alpha_pp at the
    time where ``d ln alpha / d ln t = -0.5`` (ideal penetration regime alpha ~ t^(-1/2)). If
    the slope never reaches -0.5 (the cylinder packings of the thesis), the inflection point of
    alpha(t) in the log-log plot is used: the point where the slope curve changes direction,
    i.e. the interior extremum of the slope (the steepest point; about 700 s in the thesis).

    Ambiguity (digest item 12.10): the text takes the slope of the *overall* alpha, the A7/A8
    scripts that of *alpha_bed*. This function takes whichever curve is passed as ``alpha``.
    Mind that the early-time slope of an alpha_bed curve depends on the alpha_ws subtracted: in
    a resting DEM bed alpha(t -> 0) = (pi/4) alpha_wp on the A7 area, so subtracting
    exactly that gives alpha_bed ~ 1/t (slope -1) at short times, Phi = 0.8 gives a slope
    falling through -0.5 within seconds, and alpha_wp (A7) may never reach -0.5. The first
    crossing can then be an early-time artefact; restrict the search with ``t_range`` or use
    ``which="last"`` and report the choice.

    Details of the read-off:

    * Slope criterion: the crossing of ``target`` is located between grid points and
      interpolated linearly in (ln t, slope). ``which="first"`` (default) takes the first
      crossing in time (the slope falling through the target); ``"last"`` the last one (the
      slope returning through it when the finite bed saturates).
    * Inflection criterion: the interior grid point of largest |slope| (the extremum of the
      slope curve), refined by a parabola through it and its two neighbours in (ln t, slope).
      An extremum at the first or last valid point is not an inflection point (criterion
      ``"none"``). On noisy curves pass ``smooth`` (see :func:`log_slope`).

    Parameters
    ----------
    t : array_like, shape (n,)
        Times, s (t = 0 and NaN alpha are ignored).
    alpha : array_like, shape (n,)
        Coefficient curve, W/(m^2 K).
    target : float, optional
        Target slope (default -0.5).
    smooth : float or None, optional
        Smoothing width for :func:`log_slope`, decades.
    which : {"first", "last"}, optional
        Which crossing of the target to report.
    fallback : bool, optional
        Use the inflection point when the target is not reached (default True).
    t_range : tuple (t_min, t_max), optional
        Only points with t_min <= t <= t_max are searched (the slope is still computed on the
        whole curve and returned in full).

    Returns
    -------
    PenetrationTime
        ``(time, criterion, slope, slope_at_time, target)``.
    """
    if which not in ("first", "last"):
        raise ValueError(f"penetration_time: which must be 'first' or 'last', got {which!r}")
    t = np.asarray(t, dtype=float)
    s = log_slope(t, alpha, smooth=smooth)
    keep = np.isfinite(s)
    if t_range is not None:
        keep &= (t >= t_range[0]) & (t <= t_range[1])
    idx = np.flatnonzero(keep)
    if idx.size < 3:
        return PenetrationTime(math.nan, "none", s, math.nan, float(target))
    x = np.log(t[idx])
    sv = s[idx]
    d = sv - target
    # a crossing between k and k+1: sign change, or landing exactly on the target
    cross = np.flatnonzero((d[:-1] * d[1:] < 0) | ((d[1:] == 0) & (d[:-1] != 0)))
    if d[0] == 0:
        cross = np.concatenate([[-1], cross])
    if cross.size:
        k = cross[0] if which == "first" else cross[-1]
        if k < 0:
            return PenetrationTime(float(t[idx[0]]), "slope", s, float(target), float(target))
        frac = (target - sv[k]) / (sv[k + 1] - sv[k])
        xt = x[k] + frac * (x[k + 1] - x[k])
        return PenetrationTime(float(np.exp(xt)), "slope", s, float(target), float(target))
    if not fallback:
        return PenetrationTime(math.nan, "none", s, math.nan, float(target))
    k = int(np.argmax(np.abs(sv)))
    if k == 0 or k == sv.size - 1:
        return PenetrationTime(math.nan, "none", s, math.nan, float(target))
    # parabola through (x[k-1..k+1], s[k-1..k+1]); vertex in ln t
    xs, ys = x[k - 1 : k + 2], sv[k - 1 : k + 2]
    a2, a1, a0 = np.polyfit(xs - xs[1], ys, 2)
    if a2 != 0:
        xv = -a1 / (2 * a2)
        xv = min(max(xv, xs[0] - xs[1]), xs[2] - xs[1])  # stay inside the bracket
        sval = a0 + a1 * xv + a2 * xv**2
    else:
        xv, sval = 0.0, ys[1]
    return PenetrationTime(float(np.exp(xs[1] + xv)), "inflection", s, float(sval), float(target))


# ---------------------------------------------------------------------------------------------
# Calibration line alpha_pp -> lambda_bed
# ---------------------------------------------------------------------------------------------


class CalibrationLine(eqx.Module):
    """Straight calibration line ``lambda_bed = slope * alpha_pp + intercept``.

    weigler-thermal-dem.md, section 10 ("Calibration line", Fig. 5.11): maps a DEM contact
    coefficient alpha_pp (W/(m^2 K)) to the PM bed conductivity lambda_bed (W/(m K)) so that a
    DEM run and a PM run can be set up consistently. An equinox module, hence a PyTree: its
    methods are differentiable in both the line parameters and the argument.

    Attributes
    ----------
    slope : jax.Array
        d lambda_bed / d alpha_pp, W/(m K) per W/(m^2 K), i.e. m.
    intercept : jax.Array
        lambda_bed at alpha_pp = 0, W/(m K) (0 for a line through the origin).
    """

    slope: jnp.ndarray
    intercept: jnp.ndarray

    def lambda_bed(self, alpha_pp):
        """lambda_bed (W/(m K)) for a contact coefficient alpha_pp (W/(m^2 K))."""
        return self.slope * jnp.asarray(alpha_pp, float) + self.intercept

    def alpha_pp(self, lambda_bed):
        """Inverse: alpha_pp (W/(m^2 K)) that gives lambda_bed (W/(m K))."""
        return (jnp.asarray(lambda_bed, float) - self.intercept) / self.slope


def calibration_line(alpha_pp_values, lambda_bed_values, through_origin=False):
    """Least-squares calibration line lambda_bed = a * alpha_pp + b.

    weigler-thermal-dem.md, section 10: the thesis draws the line through two
    (alpha_pp, lambda_bed) points; with more points this is the least-squares line. The digest
    note there: a pure contact-conduction network scales linearly in alpha_pp, so
    ``through_origin=True`` (b = 0, a = sum(x y)/sum(x^2)) is a sanity check and a one-point
    calibration.

    Parameters
    ----------
    alpha_pp_values : array_like, shape (k,)
        Particle-particle contact coefficients, W/(m^2 K).
    lambda_bed_values : array_like, shape (k,)
        Bed conductivities read off at the penetration time, W/(m K).
    through_origin : bool, optional
        Force the intercept to zero.

    Returns
    -------
    CalibrationLine
        With ``slope``, ``intercept``, ``lambda_bed(alpha_pp)`` and ``alpha_pp(lambda_bed)``.
    """
    x = jnp.atleast_1d(jnp.asarray(alpha_pp_values, float))
    y = jnp.atleast_1d(jnp.asarray(lambda_bed_values, float))
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(
            f"calibration_line: need two 1-D arrays of equal length, got {x.shape} and {y.shape}"
        )
    need = 1 if through_origin else 2
    if x.size < need:
        raise ValueError(
            f"calibration_line: {x.size} point(s) given, a line "
            f"{'through the origin ' if through_origin else ''}needs at least {need}"
        )
    if through_origin:
        return CalibrationLine(slope=jnp.sum(x * y) / jnp.sum(x * x), intercept=jnp.zeros(()))
    xm, ym = jnp.mean(x), jnp.mean(y)
    slope = jnp.sum((x - xm) * (y - ym)) / jnp.sum((x - xm) ** 2)
    return CalibrationLine(slope=slope, intercept=ym - slope * xm)


# ---------------------------------------------------------------------------------------------
# Group means and temperature distributions (thesis section 8 / digest section 8)
# ---------------------------------------------------------------------------------------------


def group_means(T, masses_or_heat_capacities, groups, n_groups=None):
    """Weighted mean temperature per particle group.

    ``T_mean_g = sum_{i in g} w_i T_i / sum_{i in g} w_i``. With w_i = m_i this is the
    mass-weighted mean of the result files (DESIGN.md, ``T_mean:<group>``); with
    w_i = m_i c_i it is the caloric mean (eq. [4.1] of the digest's section 7.2 for equal
    masses). For one material both are the same.

    Parameters
    ----------
    T : array_like, shape (..., N)
        Particle temperatures, K (leading axes, e.g. time, are kept).
    masses_or_heat_capacities : array_like, shape (N,)
        Weights w_i, kg or J/K.
    groups : array_like of int, shape (N,)
        Group label 0..G-1 of every particle.
    n_groups : int, optional
        G; default ``max(groups) + 1`` (must be given when ``groups`` is traced under jit).

    Returns
    -------
    jax.Array, shape (..., G)
        Weighted mean per group, K; NaN for an empty group. Differentiable in T and w.
    """
    T = jnp.asarray(T, float)
    w = jnp.asarray(masses_or_heat_capacities, float)
    groups = jnp.asarray(groups)
    if n_groups is None:
        n_groups = int(np.max(np.asarray(groups))) + 1
    onehot = (groups[:, None] == jnp.arange(n_groups)[None, :]).astype(T.dtype)  # (N, G)
    wg = w[:, None] * onehot
    return (T @ wg) / jnp.sum(wg, axis=0)


class TemperatureDistribution(NamedTuple):
    """Number distribution of particle temperatures in classes (see
    :func:`temperature_distribution`).

    Attributes
    ----------
    edges : numpy.ndarray, shape (k+1,)
        Class edges, K.
    centres : numpy.ndarray, shape (k,)
        Class centres, K.
    q0 : numpy.ndarray, shape (m, k) or (k,)
        Number density, fraction of particles per K, 1/K.
    Q0 : numpy.ndarray, shape (m, k+1) or (k+1,)
        Cumulative number fraction below each edge, dimensionless.
    counts : numpy.ndarray, shape (m, k) or (k,)
        Number of particles per class.
    t_index : numpy.ndarray or int or None
        The selected rows of T.
    """

    edges: np.ndarray
    centres: np.ndarray
    q0: np.ndarray
    Q0: np.ndarray
    counts: np.ndarray
    t_index: object


def temperature_distribution(T, t_index=None, width=1.0, T_lo=None, T_hi=None):
    """Number distribution q0 and cumulative distribution Q0 of particle temperatures.

    weigler-thermal-dem.md, section 8 ("Temperature classes"): temperatures are binned into
    1 K classes (the thesis uses 25-50 degC, i.e. 298.15-323.15 K; the text's "50 classes" is
    inconsistent with 1 K bins, digest item 12.15, so the classes here are defined by their
    width).

    Definitions (standard particle-size-distribution conventions, with temperature as the
    property): classes are left-closed ``[e_k, e_{k+1})``;
    ``Q0(e) = (number of particles with T < e) / N`` at every edge;
    ``q0_k = (Q0(e_{k+1}) - Q0(e_k)) / width = counts_k / (N width)`` in 1/K. N counts all
    finite temperatures of the row, so particles outside [T_lo, T_hi) show up as
    Q0(T_lo) > 0 or Q0(T_hi) < 1.

    Parameters
    ----------
    T : array_like, shape (n_out, N) or (N,)
        Particle temperatures, K.
    t_index : int, sequence of int or None, optional
        Rows of T to evaluate (an int gives 1-D outputs); None: all rows.
    width : float, optional
        Class width, K (default 1 K).
    T_lo, T_hi : float, optional
        Range of the classes, K. Defaults: ``floor(min T / width) * width`` and the smallest
        ``T_lo + k width`` above the maximum, over the selected rows, so that every particle
        falls in a class and all rows share the classes.

    Returns
    -------
    TemperatureDistribution
        ``(edges, centres, q0, Q0, counts, t_index)``.
    """
    T = np.asarray(T, dtype=float)
    if not width > 0:
        raise ValueError(f"temperature_distribution: width must be > 0 K, got {width!r}")
    scalar = False
    if T.ndim == 1:
        rows = T[None, :]
        scalar = True
    elif T.ndim == 2:
        if t_index is None:
            rows = T
        elif np.ndim(t_index) == 0:
            rows = T[[int(t_index)]]
            scalar = True
        else:
            rows = T[np.asarray(t_index, dtype=int)]
    else:
        raise ValueError(f"temperature_distribution: T must be (N,) or (n_out, N), got {T.shape}")
    finite = rows[np.isfinite(rows)]
    if finite.size == 0:
        raise ValueError("temperature_distribution: no finite temperatures")
    lo = math.floor(finite.min() / width) * width if T_lo is None else float(T_lo)
    if T_hi is None:
        n_cls = int(math.floor((finite.max() - lo) / width)) + 1
    else:
        n_cls = int(round((float(T_hi) - lo) / width))
        if n_cls < 1 or not math.isclose(lo + n_cls * width, float(T_hi), rel_tol=0, abs_tol=1e-9 * max(1.0, abs(T_hi))):
            raise ValueError(
                f"temperature_distribution: T_hi - T_lo = {float(T_hi) - lo} K is not a positive "
                f"multiple of width = {width} K"
            )
    edges = lo + width * np.arange(n_cls + 1)
    n = np.isfinite(rows).sum(axis=1, keepdims=True).astype(float)
    # number of particles with T < e at every edge (NaN sorts last and is never counted)
    srt = np.sort(rows, axis=1)
    below = np.stack(
        [np.minimum(np.searchsorted(r, edges, side="left"), k) for r, k in zip(srt, n[:, 0].astype(int))]
    )
    Q0 = below / n
    counts = np.diff(below, axis=1)
    q0 = counts / (n * width)
    if scalar:
        Q0, counts, q0 = Q0[0], counts[0], q0[0]
    return TemperatureDistribution(edges, 0.5 * (edges[:-1] + edges[1:]), q0, Q0, counts, t_index)


# ---------------------------------------------------------------------------------------------
# Mechanical mixing: Lacey index, inter-fraction contacts, mixing time
# ---------------------------------------------------------------------------------------------


def mixing_index(positions, is_tracer, cell_size, origin=None, min_per_cell=1):
    """Lacey mixing index of two coloured fractions on a grid of cells.

    Definition (Lacey 1954, in the particle-number-weighted form common in DEM studies):

    * the domain is divided into square/cubic cells of edge ``cell_size`` starting at
      ``origin``; only cells holding at least ``min_per_cell`` particles are used;
    * p = tracer fraction of all particles in the used cells; x_c = tracer fraction of cell c,
      n_c its particle count, N = sum n_c, N_c the number of used cells;
    * ``S^2 = sum_c n_c (x_c - p)^2 / N`` (measured variance);
    * ``sigma_0^2 = p (1 - p)`` (completely segregated: every cell one colour);
    * ``sigma_R^2 = p (1 - p) / n_bar`` with ``n_bar = N / N_c`` (random mixture: the expected
      S^2 for binomially filled cells);
    * ``M = (sigma_0^2 - S^2) / (sigma_0^2 - sigma_R^2)``.

    M = 0 for a segregated bed and M ~ 1 for a random mixture; an ordered arrangement that is
    more uniform than random gives M slightly above 1. The index depends on the cell size
    (cells of a few particle diameters are usual). This index is not in the thesis, which
    counts inter-fraction contacts instead (:func:`count_interfraction_contacts`,
    digest section 11.2).

    Parameters
    ----------
    positions : array_like, shape (N, dim) or (n_out, N, dim)
        Particle centres, m.
    is_tracer : array_like of bool, shape (N,)
        True for the particles of one colour (e.g. ``group == 1``).
    cell_size : float
        Cell edge length, m.
    origin : array_like, shape (dim,), optional
        Grid origin, m; default the minimum corner of the positions (per frame).
    min_per_cell : int, optional
        Cells with fewer particles are left out (default 1).

    Returns
    -------
    float or numpy.ndarray, shape (n_out,)
        The Lacey index M (NaN if fewer than 2 used cells or only one colour present, or if
        every used cell holds a single particle, where sigma_0 = sigma_R).
    """
    pos = np.asarray(positions, dtype=float)
    tracer = np.asarray(is_tracer).astype(bool)
    if not cell_size > 0:
        raise ValueError(f"mixing_index: cell_size must be > 0 m, got {cell_size!r}")
    if pos.ndim == 3:
        return np.array([mixing_index(p, tracer, cell_size, origin, min_per_cell) for p in pos])
    if pos.ndim != 2 or pos.shape[0] != tracer.shape[0]:
        raise ValueError(f"mixing_index: positions {pos.shape} do not match is_tracer {tracer.shape}")
    o = pos.min(axis=0) if origin is None else np.asarray(origin, dtype=float)
    cells = np.floor((pos - o) / cell_size).astype(np.int64)
    _, inverse, n_c = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    k_c = np.bincount(inverse, weights=tracer.astype(float), minlength=n_c.size)
    used = n_c >= min_per_cell
    n_c, k_c = n_c[used].astype(float), k_c[used]
    if n_c.size < 2:
        return math.nan
    N = n_c.sum()
    p = k_c.sum() / N
    sigma0 = p * (1.0 - p)
    sigmaR = sigma0 * n_c.size / N
    if sigma0 == 0 or sigma0 == sigmaR:
        return math.nan
    S2 = np.sum(n_c * (k_c / n_c - p) ** 2) / N
    return float((sigma0 - S2) / (sigma0 - sigmaR))


class MixingTimeFit(NamedTuple):
    """Result of :func:`mechanical_mixing_time`.

    Attributes
    ----------
    time : float
        Mechanical mixing time t_mech, s: where the fitted trend reaches ``plateau_fraction``
        of its rise, ``tau * ln(1 / (1 - plateau_fraction))`` (3.0 tau for 0.95).
    tau : float
        Fitted time constant, s.
    c_inf : float
        Fitted plateau (counts).
    c_0 : float
        Fitted value at t = 0 (counts).
    tau_std, c_inf_std, c_0_std : float
        Standard errors from the fit covariance.
    plateau_fraction : float
        The fraction used.
    within_record : bool
        False if ``time`` lies beyond the last sample (extrapolated; run longer).
    """

    time: float
    tau: float
    c_inf: float
    c_0: float
    tau_std: float
    c_inf_std: float
    c_0_std: float
    plateau_fraction: float
    within_record: bool

    def trend(self, t):
        """The fitted trend c(t) = c_inf - (c_inf - c_0) exp(-t/tau) (numpy)."""
        t = np.asarray(t, dtype=float)
        return self.c_inf - (self.c_inf - self.c_0) * np.exp(-t / self.tau)


def _saturating(t, c_inf, c_0, tau):
    return c_inf - (c_inf - c_0) * np.exp(-t / tau)


def mechanical_mixing_time(t, counts, plateau_fraction=0.95, p0=None):
    """Mechanical mixing time from inter-fraction contact counts.

    weigler-thermal-dem.md, section 11.2: t_mech is where a trend line through the white-red
    contact counts "becomes horizontal". The thesis does not give the trend form; following the
    digest's suggestion, a saturating exponential

        c(t) = c_inf - (c_inf - c_0) exp(-t / tau)

    is fitted (``scipy.optimize.curve_fit``, not differentiable) and t_mech is the time where
    the trend has covered ``plateau_fraction`` of its rise from c_0 to c_inf:
    ``t_mech = tau ln(1 / (1 - plateau_fraction))`` (= 3.0 tau for the default 0.95). An
    exponential never becomes exactly horizontal, so the plateau fraction is a choice; report
    it with the result.

    Parameters
    ----------
    t : array_like, shape (n,)
        Times since the start of rotation (t = 0 is the segregated start), s.
    counts : array_like, shape (n,)
        Inter-fraction contact counts (see :func:`count_interfraction_contacts`).
    plateau_fraction : float, optional
        Fraction of the rise that defines t_mech, in (0, 1) (default 0.95).
    p0 : tuple (c_inf, c_0, tau), optional
        Initial guess; default from the data (first and last fifth of the record, and the
        first time the counts cover 63 % of the rise).

    Returns
    -------
    MixingTimeFit
        t_mech, the fit parameters with standard errors, and ``trend(t)``.
    """
    if not 0 < plateau_fraction < 1:
        raise ValueError(f"mechanical_mixing_time: plateau_fraction must be in (0, 1), got {plateau_fraction!r}")
    from scipy.optimize import curve_fit

    t = np.asarray(t, dtype=float)
    c = np.asarray(counts, dtype=float)
    ok = np.isfinite(t) & np.isfinite(c)
    t, c = t[ok], c[ok]
    if t.size < 4:
        raise ValueError(f"mechanical_mixing_time: need at least 4 samples, got {t.size}")
    span = t.max() - t.min()
    if p0 is None:
        m = max(1, t.size // 5)
        c0_g, cinf_g = float(np.mean(c[:m])), float(np.mean(c[-m:]))
        rise = cinf_g - c0_g
        reached = np.flatnonzero((c - c0_g) * np.sign(rise) >= 0.632 * abs(rise)) if rise != 0 else []
        tau_g = float(t[reached[0]] - min(t.min(), 0.0)) if len(reached) else span / 3.0
        p0 = (cinf_g, c0_g, max(tau_g, span * 1e-3))
    popt, pcov = curve_fit(
        _saturating, t, c, p0=p0,
        bounds=([-np.inf, -np.inf, span * 1e-6], [np.inf, np.inf, np.inf]),
        maxfev=20000,
    )
    c_inf, c_0, tau = (float(v) for v in popt)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        std = np.sqrt(np.diag(pcov))
    t_mech = tau * math.log(1.0 / (1.0 - plateau_fraction))
    return MixingTimeFit(
        time=t_mech, tau=tau, c_inf=c_inf, c_0=c_0,
        tau_std=float(std[2]), c_inf_std=float(std[0]), c_0_std=float(std[1]),
        plateau_fraction=float(plateau_fraction), within_record=bool(t_mech <= t.max()),
    )



class HorizontalTrend(NamedTuple):
    """Result of :func:`mixing_time_horizontal`: a rising straight trend line that becomes
    horizontal at ``time``.

    Attributes
    ----------
    time : float
        Where the trend line becomes horizontal (the break point), s.
    plateau : float
        The horizontal level (counts).
    slope : float
        Slope of the rising part, counts/s.
    residual : float
        Root-mean-square deviation of the counts from the trend line.
    within_record : bool
        False if the break lies at the last sample (no horizontal part seen; run longer).
    """

    time: float
    plateau: float
    slope: float
    residual: float
    within_record: bool

    def trend(self, t):
        """The trend line ``plateau - slope max(time - t, 0)`` (numpy)."""
        t = np.asarray(t, dtype=float)
        return self.plateau - self.slope * np.maximum(self.time - t, 0.0)


def mixing_time_horizontal(t, counts) -> HorizontalTrend:
    """Mechanical mixing time as the time at which a trend line through the inter-fraction
    contact counts becomes horizontal, read literally (weigler-thermal-dem.md section 11.2).

    The trend line is a straight rise followed by a horizontal line,
    ``c(t) = plateau - slope max(t_b - t, 0)``, fitted by least squares: for every break
    ``t_b`` on the sample times the two linear coefficients follow in closed form, and the
    break with the smallest squared deviation is taken (no starting guess, no iteration).
    Unlike the plateau fraction of :func:`mechanical_mixing_time`, the break needs no
    threshold; it does need a record that reaches well into the plateau.

    Parameters
    ----------
    t : array_like, shape (n,)
        Times since the start of rotation, s.
    counts : array_like, shape (n,)
        Inter-fraction contact counts.
    """
    t = np.asarray(t, dtype=float)
    c = np.asarray(counts, dtype=float)
    ok = np.isfinite(t) & np.isfinite(c)
    t, c = t[ok], c[ok]
    if t.size < 4:
        raise ValueError(f"mixing_time_horizontal: need at least 4 samples, got {t.size}")
    best = None
    for tb in t[1:]:
        x = -np.maximum(tb - t, 0.0)  # c = plateau + slope * x
        A = np.stack([np.ones_like(t), x], axis=1)
        coef, *_ = np.linalg.lstsq(A, c, rcond=None)
        sse = float(np.sum((A @ coef - c) ** 2))
        if best is None or sse < best[0]:
            best = (sse, tb, coef)
    sse, tb, (plateau, slope) = best
    return HorizontalTrend(time=float(tb), plateau=float(plateau), slope=float(slope),
                           residual=math.sqrt(sse / t.size), within_record=bool(tb < t[-1]))
