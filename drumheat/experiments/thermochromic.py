"""Thermochromic temperature measurement: intensity -> temperature for particle images.

This module is the measurement chain of Weigler (2012) for users who have measured the mean HSI
intensity of every particle in their own images (one circular region of interest per sphere,
identical pixel counts, as with Olympus AnalySiS; digest ``reference/weigler-thermal-dem.md``,
section 8). It turns those intensities into particle temperatures, fraction means over time and
temperature distributions, exactly as the thesis did, and ships the thesis's calibration data.
It needs numpy, scipy and pandas only (matplotlib for :func:`plot_calibration`); no JAX.

The chain
---------
1. **Calibration** (digest section 8, App. A1): :func:`fit_calibration` fits temperature as a
   function of intensity, ``T = f(I)`` (the thesis swapped the axes in ``polyfit`` the same way).
   Three branches are shipped (:func:`calibration_table`, :func:`calibration`):

   * ``"heating"``  - Table A1.1, box heated from 23 to 54 degC;
   * ``"cooling"``  - Table A1.2, box cooled from 54 to 23 degC;
   * ``"combined"`` - Table A1.3, the hysteresis-free curve of Sec. 3.6.2: heating branch below
     36 degC, cooling branch from 36 degC up. All thesis results use it.

   The pigments show hysteresis: at the same temperature a cooling particle is brighter than a
   heating one (up to about 15 intensity units, i.e. up to about 6 K read on the wrong branch).

   The polynomial coefficients printed in the thesis are *not* used: they are printed garbled
   and, read correctly (Matlab ``polyfit`` order, highest power first), the degree-12 combined
   polynomial has terms of order 1e12 that cancel to a result of order 1e1, so the six printed
   significant digits leave errors of hundreds to hundreds of thousands of kelvin (digest
   section 8 and section 12, item 17; ``tests/test_thermochromic.py`` computes it). We refit
   from the tables instead: by default with a monotone piecewise-cubic (PCHIP) interpolant,
   optionally with a centred and scaled least-squares polynomial
   (:meth:`numpy.polynomial.Polynomial.fit`).

2. **Temperature assignment** (digest section 8, thesis Sec. 3.5, App. A10):
   :func:`assign_temperatures` decides per particle and frame whether it belongs to the heating
   (initially cold) or the cooling (initially warm) fraction, with

   * method 1, *position-based*: the fraction of every particle is known (from where it was put);
   * method 2, *mean threshold*: particles darker than the frame's mean intensity are heating;
   * method 3, *sorting* (chosen in the thesis): the ``n_heating`` darkest particles are heating.

   The temperature then comes from the combined curve (``curves="combined"``, thesis default) or
   from the branch of the particle's fraction (``curves="branches"``).

3. **Evaluation** (digest section 8, "Temperature classes"): fraction means over time
   (:func:`fraction_means`) and the number density ``q0`` and cumulative number distribution
   ``Q0`` in 1 K classes between 25 and 50 degC (:func:`temperature_distribution`).
   :func:`evaluate` runs the whole chain on a CSV file in the long format documented in
   :func:`read_intensity_csv`.

Conventions
-----------
Intensities are HSI intensities on the 0..255 scale of the calibration; temperatures in this
module are in degrees Celsius (suffix ``_C``), as in the thesis tables. :func:`fraction_means`
also gives kelvin columns named like a simulation's ``timeseries.csv`` (``T_mean``,
``T_mean:cold``, ``T_mean:warm``) so a measurement can be overlaid on a drumheat run directly.
Your own images must be taken with the same camera settings, lighting and lacquer as the
calibration (control strip at about 129, digest section 7.1); otherwise calibrate anew and pass
your own points to :func:`fit_calibration`.

Example
-------
>>> from drumheat.experiments import thermochromic as tc
>>> cal = tc.calibration("combined")          # PCHIP through Table A1.3
>>> float(cal(101.0))                         # a table point: 40 degC
40.0
>>> ev = tc.evaluate("my_run.csv", method=3, n_heating=35)    # doctest: +SKIP
>>> ev.means[["t", "T_mean_C:cold", "T_mean_C:warm"]]        # doctest: +SKIP
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from importlib import resources
from os import PathLike
from typing import Callable, Mapping, Sequence

import numpy as np
import pandas as pd
from numpy.polynomial import Polynomial
from scipy.interpolate import PchipInterpolator

__all__ = [
    "CalibrationRangeWarning",
    "Calibration",
    "calibration_table",
    "fit_calibration",
    "calibration",
    "calibrations",
    "PRINTED_COEFFICIENTS",
    "printed_polynomial",
    "Assignment",
    "assign_temperatures",
    "DEFAULT_CLASS_EDGES_C",
    "Distribution",
    "temperature_distribution",
    "fraction_means",
    "IntensityData",
    "read_intensity_csv",
    "write_intensity_csv",
    "Evaluation",
    "evaluate",
    "image_times",
    "EVALUATED_IMAGES_RESTING",
    "EVALUATED_IMAGES_MIXED",
    "plot_calibration",
]

BRANCHES = ("heating", "cooling", "combined")
_COMBINED_FILE = "weigler_thermochromic_calibration.csv"
_BRANCHES_FILE = "weigler_thermochromic_branches.csv"

#: Default temperature classes (degC): 1 K classes from 25 to 50 degC, i.e. **25** classes.
#: The thesis text says "50 classes of 1 degC between 25 and 50 degC", which is inconsistent
#: (digest section 8 and section 12, item 15); 1 K bins over 25 K give 25 classes.
DEFAULT_CLASS_EDGES_C = np.arange(25.0, 51.0, 1.0)

#: Image numbers evaluated in the thesis at 1, 2, 4, 6, 11, 16, 21, 31 min after filling
#: (Tables 3-5 and 3-6, digest section 7.2): resting beds (30 s interval), mixed beds (5 s).
EVALUATED_IMAGES_RESTING = (1, 3, 7, 11, 21, 31, 41, 61)
EVALUATED_IMAGES_MIXED = (1, 13, 37, 61, 121, 181, 241, 361)

#: The polynomial coefficients as printed in the thesis (digest section 8), in Matlab
#: ``polyfit`` order: highest power first, ending with the constant; x = intensity, f = T in
#: degC. Degree 9 for the branches, degree 12 for the combined curve. Kept for documentation
#: only: they are numerically useless (see :func:`printed_polynomial`), and the heating and
#: cooling lists may be swapped (digest section 12, item 17).
PRINTED_COEFFICIENTS = {
    "heating": (2.22e-12, -1.8e-9, 6.77e-7, -0.00014, 0.019521, -1.75053, 103.7872,
                -3922.56, 85745.11, -825926.0),
    "cooling": (3.13e-12, -2.5e-9, 8.84e-7, -0.00018, 0.023546, -2.02904, 115.5935,
                -4197.24, 88125.02, -815016.0),
    "combined": (-1.79193e-15, 1.90366e-12, -9.21324e-10, 2.68573e-7, -5.25137e-5,
                 0.007254804, -0.726047895, 53.03126976, -2805.527818, 104833.4,
                 -2626261.417, 39603581.99, -271866479.9),
}


class CalibrationRangeWarning(UserWarning):
    """Intensities outside the calibrated range were met (their temperature is NaN)."""


# --------------------------------------------------------------------------------------------
# Calibration data and fitting
# --------------------------------------------------------------------------------------------


def _data_path(name: str):
    return resources.files("drumheat") / "data" / name


def calibration_table() -> pd.DataFrame:
    """The thermochromic calibration points shipped with drumheat (Weigler 2012, App. A1).

    Returns
    -------
    pandas.DataFrame
        One row per calibration temperature, columns

        * ``T_C``: temperature, degC (23 to 54 degC);
        * ``intensity_heating``: mean ROI intensity on the heating branch (Table A1.1);
        * ``intensity_cooling``: mean ROI intensity on the cooling branch (Table A1.2);
        * ``intensity_combined``: the hysteresis-free combined curve (Table A1.3): heating
          branch below 36 degC, cooling branch from 36 degC up (Sec. 3.6.2);
        * ``control_intensity``: control-strip intensity of Table A1.3 (about 129-130).

        Intensities are HSI intensities (0..255). As printed, Table A1.3 has 95.50 at 38 degC
        where Table A1.2 has 95.00 (digest section 12, item 16); both are kept unchanged.
    """
    with _data_path(_BRANCHES_FILE).open() as fh:
        branches = pd.read_csv(fh, comment="#")
    with _data_path(_COMBINED_FILE).open() as fh:
        combined = pd.read_csv(fh, comment="#")
    table = branches.merge(combined, on="T_C", how="outer", validate="one_to_one")
    table = table.rename(columns={"intensity": "intensity_combined"})
    return table.sort_values("T_C").reset_index(drop=True)[
        ["T_C", "intensity_heating", "intensity_cooling", "intensity_combined",
         "control_intensity"]]


class Calibration:
    """A fitted intensity -> temperature calibration ``T = f(I)``.

    Made by :func:`fit_calibration` (or :func:`calibration` for the shipped thesis data); not
    meant to be constructed directly.

    Attributes
    ----------
    branch : str
        Label of the data set (``"heating"``, ``"cooling"``, ``"combined"`` or user-given).
    method : str
        ``"pchip"`` (monotone piecewise-cubic interpolation) or ``"poly"`` (centred and scaled
        least-squares polynomial).
    degree : int or None
        Polynomial degree (``None`` for PCHIP).
    intensity, temperature_C : numpy.ndarray
        The calibration points, sorted by intensity (intensity 0..255, temperature degC).
    domain : tuple of float
        ``(I_min, I_max)``: the calibrated intensity range, the smallest and largest calibration
        intensity. Outside it the calibration is not defined (see ``out_of_range``).
    temperature_range_C : tuple of float
        ``(f(I_min), f(I_max))`` in degC.
    residuals_K : numpy.ndarray
        ``f(I_k) - T_k`` at the calibration points, K (exactly zero for PCHIP, which
        interpolates).
    rms_K : float
        Root-mean-square of ``residuals_K``, K.
    loo_rms_K : float
        Leave-one-out RMS error, K: each interior point is left out in turn, the same method is
        refitted to the others and evaluated at the left-out intensity. An honest estimate of the
        calibration error *between* the points (for PCHIP, whose ``rms_K`` is zero trivially).
    monotone : bool
        Whether ``f`` increases strictly over ``domain`` (checked on 4001 points). A calibration
        that is not monotone cannot be inverted and may rank particles wrongly.
    out_of_range : str
        Default treatment of intensities outside ``domain`` in :meth:`__call__`:
        ``"nan"`` (temperature NaN and a :class:`CalibrationRangeWarning`), ``"clip"`` (clip the
        intensity to the domain, no warning) or ``"raise"`` (``ValueError``).
    """

    def __init__(self, branch: str, method: str, degree: int | None, intensity: np.ndarray,
                 temperature_C: np.ndarray, func: Callable[[np.ndarray], np.ndarray],
                 deriv: Callable[[np.ndarray], np.ndarray], loo_rms_K: float,
                 out_of_range: str = "nan"):
        _check_out_of_range(out_of_range)
        self.branch = branch
        self.method = method
        self.degree = degree
        self.intensity = intensity
        self.temperature_C = temperature_C
        self._f = func
        self._df = deriv
        self.domain = (float(intensity[0]), float(intensity[-1]))
        self.temperature_range_C = (float(func(intensity[0])), float(func(intensity[-1])))
        self.residuals_K = func(intensity) - temperature_C
        self.rms_K = float(np.sqrt(np.mean(self.residuals_K ** 2)))
        self.loo_rms_K = float(loo_rms_K)
        grid = np.linspace(*self.domain, 4001)
        self.monotone = bool(np.all(np.diff(func(grid)) > 0.0))
        self.out_of_range = out_of_range

    def __repr__(self) -> str:
        deg = "" if self.degree is None else f", degree={self.degree}"
        return (f"Calibration(branch={self.branch!r}, method={self.method!r}{deg}, "
                f"domain=({self.domain[0]:g}, {self.domain[1]:g}), rms_K={self.rms_K:.3g}, "
                f"loo_rms_K={self.loo_rms_K:.3g}, monotone={self.monotone})")

    def __call__(self, intensity, out_of_range: str | None = None) -> np.ndarray:
        """Temperature in degC for HSI intensities (any shape).

        Parameters
        ----------
        intensity : array_like
            Mean ROI intensities (0..255). NaN stays NaN (a missing particle).
        out_of_range : {"nan", "clip", "raise"}, optional
            Treatment of finite intensities outside :attr:`domain`; defaults to the
            calibration's :attr:`out_of_range`. With ``"nan"`` their temperature is NaN and one
            :class:`CalibrationRangeWarning` per call says how many there were.

        Returns
        -------
        numpy.ndarray
            Temperatures, degC, same shape as ``intensity``.
        """
        mode = self.out_of_range if out_of_range is None else out_of_range
        _check_out_of_range(mode)
        x = np.asarray(intensity, dtype=float)
        lo, hi = self.domain
        outside = np.isfinite(x) & ((x < lo) | (x > hi))
        n_out = int(np.count_nonzero(outside))
        if n_out and mode == "raise":
            raise ValueError(
                f"{n_out} intensities lie outside the calibrated range [{lo:g}, {hi:g}] of the "
                f"{self.branch!r} calibration (e.g. {x[outside].flat[0]:g}); use "
                "out_of_range='nan' or 'clip', or extend the calibration")
        xc = np.clip(x, lo, hi)
        T = np.asarray(self._f(xc), dtype=float)
        T = np.where(np.isnan(x), np.nan, T)
        if n_out and mode == "nan":
            T = np.where(outside, np.nan, T)
            warnings.warn(
                f"{n_out} of {x.size} intensities lie outside the calibrated range "
                f"[{lo:g}, {hi:g}] of the {self.branch!r} calibration; their temperature is "
                "NaN (pass out_of_range='clip' to clip them to the range ends)",
                CalibrationRangeWarning, stacklevel=2)
        return T

    def derivative(self, intensity) -> np.ndarray:
        """Slope ``dT/dI`` of the calibration, K per intensity unit (NaN outside the domain).

        Multiply an intensity uncertainty by it to get the temperature uncertainty.
        """
        x = np.asarray(intensity, dtype=float)
        lo, hi = self.domain
        d = np.asarray(self._df(np.clip(x, lo, hi)), dtype=float)
        return np.where((x >= lo) & (x <= hi), d, np.nan)

    def inverse(self, temperature_C, tol: float = 1e-10) -> np.ndarray:
        """Intensity that the calibration maps to ``temperature_C`` (degC), any shape.

        Exact numerical inverse of :meth:`__call__` by vectorised bisection over
        :attr:`domain`; NaN for temperatures outside :attr:`temperature_range_C`. Useful to
        generate synthetic intensities from simulated temperatures. Requires a monotone
        calibration.

        Parameters
        ----------
        temperature_C : array_like
            Temperatures, degC.
        tol : float
            Bisection tolerance on the intensity.

        Returns
        -------
        numpy.ndarray
            Intensities (0..255 scale), same shape as ``temperature_C``.
        """
        if not self.monotone:
            raise ValueError(f"the {self.branch!r} calibration is not monotone over its "
                             "domain and has no unique inverse; use method='pchip' or a "
                             "lower polynomial degree")
        T = np.asarray(temperature_C, dtype=float)
        lo_T, hi_T = self.temperature_range_C
        a = np.full(T.shape, self.domain[0])
        b = np.full(T.shape, self.domain[1])
        n_iter = int(np.ceil(np.log2((self.domain[1] - self.domain[0]) / tol))) + 1
        for _ in range(n_iter):
            m = 0.5 * (a + b)
            below = self._f(m) < T
            a = np.where(below, m, a)
            b = np.where(below, b, m)
        I = 0.5 * (a + b)
        return np.where((T >= lo_T) & (T <= hi_T), I, np.nan)


def _check_out_of_range(mode: str) -> None:
    if mode not in ("nan", "clip", "raise"):
        raise ValueError(f"out_of_range={mode!r}; allowed are 'nan', 'clip', 'raise'")


def _fit_function(I: np.ndarray, T: np.ndarray, method: str, degree: int | None):
    if method == "pchip":
        f = PchipInterpolator(I, T, extrapolate=True)
        return f, f.derivative()
    p = Polynomial.fit(I, T, degree)   # maps [I_min, I_max] onto [-1, 1] before fitting
    return p, p.deriv()


def fit_calibration(intensity, temperature, method: str = "pchip", degree: int | None = None,
                    branch: str = "custom", out_of_range: str = "nan") -> Calibration:
    """Fit temperature as a function of intensity, ``T = f(I)`` (digest section 8).

    Parameters
    ----------
    intensity : array_like, shape (n,)
        Mean ROI intensities (HSI, 0..255) of the calibration images.
    temperature : array_like, shape (n,)
        The matching temperatures, degC.
    method : {"pchip", "poly"}
        ``"pchip"`` (default): monotone piecewise-cubic Hermite interpolation
        (:class:`scipy.interpolate.PchipInterpolator`) through the points; it is monotone
        wherever the data are and does not oscillate. ``"poly"``: least-squares polynomial of
        ``degree`` in the intensity mapped onto [-1, 1] (:meth:`numpy.polynomial.Polynomial.fit`),
        which avoids the ill-conditioning of the thesis's raw-power ``polyfit``.
    degree : int, optional
        Polynomial degree for ``method="poly"`` (default 5: on the thesis data the highest degree
        whose fit is monotone on all three branches; degrees 6-12 wiggle on the combined curve).
        Must be ``None`` for PCHIP.
    branch : str
        Label stored on the result (e.g. ``"heating"``).
    out_of_range : {"nan", "clip", "raise"}
        Default treatment of intensities outside the calibrated range (see
        :meth:`Calibration.__call__`). The default gives NaN and a warning: no extrapolation.

    Returns
    -------
    Calibration
        Callable ``cal(I) -> T_C`` with residuals (``rms_K``, ``loo_rms_K``), ``domain`` and
        ``monotone``.

    Raises
    ------
    ValueError
        Mismatched or non-finite inputs, fewer than 3 points (``degree + 2`` for ``"poly"``),
        repeated intensities, or an unknown method.

    Warns
    -----
    UserWarning
        If the fitted curve is not monotone over the calibrated range.
    """
    if method not in ("pchip", "poly"):
        raise ValueError(f"method={method!r}; allowed are 'pchip' and 'poly'")
    if method == "pchip" and degree is not None:
        raise ValueError("degree applies to method='poly' only")
    if method == "poly":
        degree = 5 if degree is None else int(degree)
        if degree < 1:
            raise ValueError(f"degree={degree}; must be at least 1")
    I = np.asarray(intensity, dtype=float).ravel()
    T = np.asarray(temperature, dtype=float).ravel()
    if I.shape != T.shape:
        raise ValueError(f"intensity has {I.size} values but temperature has {T.size}")
    if not (np.all(np.isfinite(I)) and np.all(np.isfinite(T))):
        raise ValueError("calibration points must be finite")
    n_min = 3 if method == "pchip" else degree + 2
    if I.size < n_min:
        raise ValueError(f"{I.size} calibration points; method={method!r}"
                         f"{'' if degree is None else f' of degree {degree}'} needs at least "
                         f"{n_min}")
    order = np.argsort(I, kind="stable")
    I, T = I[order], T[order]
    if np.any(np.diff(I) <= 0.0):
        raise ValueError("repeated calibration intensities; average the points first")
    _check_out_of_range(out_of_range)

    f, df = _fit_function(I, T, method, degree)
    loo = []
    for k in range(1, I.size - 1):          # interior points only: no extrapolation
        keep = np.arange(I.size) != k
        if method == "poly" and keep.sum() < degree + 1:
            break
        fk, _ = _fit_function(I[keep], T[keep], method, degree)
        loo.append(float(fk(I[k])) - T[k])
    loo_rms = float(np.sqrt(np.mean(np.square(loo)))) if loo else float("nan")

    cal = Calibration(branch, method, degree, I, T, f, df, loo_rms, out_of_range)
    if not cal.monotone:
        warnings.warn(f"the fitted {branch!r} calibration ({method}"
                      f"{'' if degree is None else f', degree {degree}'}) is not monotone "
                      f"over [{cal.domain[0]:g}, {cal.domain[1]:g}]; temperatures may be "
                      "ambiguous (try method='pchip' or a lower degree)", stacklevel=2)
    return cal


def calibration(branch: str = "combined", method: str = "pchip", degree: int | None = None,
                out_of_range: str = "nan") -> Calibration:
    """The thesis calibration of one branch, refitted from the shipped tables (App. A1).

    Parameters
    ----------
    branch : {"combined", "heating", "cooling"}
        Table A1.3 (hysteresis-free, used for all thesis results), A1.1 or A1.2.
    method, degree, out_of_range
        As in :func:`fit_calibration`.

    Returns
    -------
    Calibration
    """
    if branch not in BRANCHES:
        raise ValueError(f"branch={branch!r}; allowed are {', '.join(map(repr, BRANCHES))}")
    table = calibration_table()
    return fit_calibration(table[f"intensity_{branch}"], table["T_C"], method=method,
                           degree=degree, branch=branch, out_of_range=out_of_range)


def calibrations(method: str = "pchip", degree: int | None = None,
                 out_of_range: str = "nan") -> dict[str, Calibration]:
    """All three thesis calibrations: ``{"heating": ..., "cooling": ..., "combined": ...}``."""
    return {b: calibration(b, method, degree, out_of_range) for b in BRANCHES}


def printed_polynomial(branch: str = "combined") -> Callable[[np.ndarray], np.ndarray]:
    """The thesis polynomial as printed, ``T = polyval(p, I)`` (documentation only).

    Evaluates :data:`PRINTED_COEFFICIENTS` in Matlab ``polyfit`` order (highest power first).
    For the combined curve the individual terms reach about 2.5e12 at I = 119 while the sum
    should be about 50; the coefficients carry only about 6 significant digits, so the rounding
    alone leaves errors of order 1e2 to 1e5 K. Do not use it for measurements; it exists so that
    a test can show why drumheat refits (digest section 8 and section 12, item 17).
    """
    coeffs = np.asarray(PRINTED_COEFFICIENTS[branch], dtype=float)
    return lambda intensity: np.polyval(coeffs, np.asarray(intensity, dtype=float))


# --------------------------------------------------------------------------------------------
# Temperature assignment (methods 1-3)
# --------------------------------------------------------------------------------------------


@dataclass
class Assignment:
    """Per particle and frame: fraction, calibration branch and temperature.

    Attributes
    ----------
    heating : numpy.ndarray of bool, shape (n_frames, n_particles)
        True where the particle is assigned to the heating fraction (the initially cold
        spheres), False for the cooling fraction (initially warm). False where the intensity is
        missing (NaN).
    branch : numpy.ndarray of str, shape (n_frames, n_particles)
        Calibration curve used: ``"heating"`` or ``"cooling"`` (``curves="branches"``), or
        ``"combined"``; ``""`` where the intensity is missing.
    T_C : numpy.ndarray, shape (n_frames, n_particles)
        Particle temperatures, degC; NaN for missing intensities and (with the default
        ``out_of_range="nan"``) for intensities outside the calibrated range.
    valid : numpy.ndarray of bool, shape (n_frames, n_particles)
        Finite intensity present.
    method : int
        Assignment method (1, 2 or 3).
    curves : str
        ``"combined"`` or ``"branches"``.
    """

    heating: np.ndarray
    branch: np.ndarray
    T_C: np.ndarray
    valid: np.ndarray
    method: int
    curves: str


def _as_frames(intensity) -> np.ndarray:
    x = np.asarray(intensity, dtype=float)
    if x.ndim == 1:
        x = x[None, :]
    if x.ndim != 2:
        raise ValueError(f"intensity must have shape (n_frames, n_particles); got {x.shape}")
    return x


def assign_temperatures(intensity, method: int = 3, n_heating: int | None = None,
                        fraction=None, curves: str = "combined",
                        cals: Mapping[str, Calibration] | None = None,
                        out_of_range: str | None = None) -> Assignment:
    """Assign each particle in each frame to a fraction and a temperature (digest section 8).

    Parameters
    ----------
    intensity : array_like, shape (n_frames, n_particles) or (n_particles,)
        Mean ROI intensity of each particle in each frame (HSI, 0..255); NaN marks a particle
        not measured in that frame.
    method : {1, 2, 3}
        1, *position-based*: ``fraction`` gives each particle's fraction (known from the filling
        positions of a resting bed). Most accurate, not for moving beds.
        2, *mean threshold*: in each frame, particles with an intensity below the mean of all
        measured particles are heating, the others cooling. The split may drift from the true
        fraction sizes.
        3, *sorting* (thesis choice): in each frame the ``n_heating`` lowest intensities are the
        heating fraction, the rest cooling. Fixed split; noise can swap particles near the
        boundary. With missing particles in a frame, the split is scaled:
        ``round(n_heating * n_measured / n_particles)``.
    n_heating : int, optional
        Size of the heating (initially cold) fraction for method 3. Default: the number of
        heating particles in ``fraction`` if given, otherwise half the particles (the thesis
        used 35 of 70); an odd particle count then needs it explicitly.
    fraction : array_like of bool or str, shape (n_particles,), optional
        The true fraction of each particle: True / ``"cold"`` / ``"heating"`` for the heating
        fraction, False / ``"warm"`` / ``"cooling"`` for the cooling fraction. Required for
        method 1.
    curves : {"combined", "branches"}
        ``"combined"`` (default, as all thesis results): every particle's temperature from the
        hysteresis-free combined curve; the assignment then only decides fraction membership.
        ``"branches"``: heating particles read on the heating branch, cooling particles on the
        cooling branch.
    cals : mapping, optional
        Calibrations with keys ``"combined"`` or ``"heating"`` and ``"cooling"``; default
        :func:`calibrations` (PCHIP through the thesis tables).
    out_of_range : {"nan", "clip", "raise"}, optional
        Passed to :meth:`Calibration.__call__`.

    Returns
    -------
    Assignment
    """
    x = _as_frames(intensity)
    n_frames, n_p = x.shape
    valid = np.isfinite(x)
    truth = None if fraction is None else _heating_mask(fraction, n_p)

    if method == 1:
        if truth is None:
            raise ValueError("method 1 (position-based) needs the fraction of every particle "
                             "(argument fraction, or a 'fraction' column in the CSV)")
        heating = np.broadcast_to(truth, x.shape) & valid
    elif method == 2:
        n_valid = valid.sum(axis=1, keepdims=True)
        mean = np.where(n_valid > 0, np.nansum(x, axis=1, keepdims=True) / np.maximum(n_valid, 1),
                        np.nan)
        heating = valid & (x < mean)
    elif method == 3:
        if n_heating is None:
            if truth is not None:
                n_heating = int(truth.sum())
            elif n_p % 2 == 0:
                n_heating = n_p // 2
            else:
                raise ValueError(f"{n_p} particles (odd): give n_heating, the size of the "
                                 "heating (initially cold) fraction, for method 3")
        n_heating = int(n_heating)
        if not 0 <= n_heating <= n_p:
            raise ValueError(f"n_heating={n_heating}; must lie between 0 and {n_p}")
        heating = np.zeros(x.shape, dtype=bool)
        for f in range(n_frames):
            idx = np.flatnonzero(valid[f])
            k = int(round(n_heating * idx.size / n_p)) if idx.size < n_p else n_heating
            darkest = idx[np.argsort(x[f, idx], kind="stable")[:k]]
            heating[f, darkest] = True
    else:
        raise ValueError(f"method={method!r}; allowed are 1 (position-based), "
                         "2 (mean threshold), 3 (sorting)")

    if cals is None:
        cals = calibrations()
    if curves == "combined":
        T = cals["combined"](x, out_of_range=out_of_range)
        branch = np.where(valid, "combined", "")
    elif curves == "branches":
        T = np.full(x.shape, np.nan)
        cold, warm = heating & valid, ~heating & valid
        T[cold] = cals["heating"](x[cold], out_of_range=out_of_range)
        T[warm] = cals["cooling"](x[warm], out_of_range=out_of_range)
        branch = np.where(valid, np.where(heating, "heating", "cooling"), "")
    else:
        raise ValueError(f"curves={curves!r}; allowed are 'combined' and 'branches'")
    return Assignment(heating=np.array(heating), branch=branch, T_C=np.asarray(T, float),
                      valid=valid, method=int(method), curves=curves)


_HEATING_WORDS = {"cold", "heating", "kalt", "1", "true"}
_COOLING_WORDS = {"warm", "cooling", "0", "false"}


def _heating_mask(fraction, n_p: int | None = None) -> np.ndarray:
    arr = np.asarray(fraction)
    if arr.dtype == bool:
        out = arr.copy()
    elif arr.dtype.kind in "iuf":
        if not np.all(np.isin(arr, (0, 1))):
            raise ValueError("numeric fraction values must be 1 (heating/cold) or 0 "
                             "(cooling/warm)")
        out = arr.astype(bool)
    else:
        words = np.char.lower(np.char.strip(arr.astype(str)))
        bad = ~np.isin(words, list(_HEATING_WORDS | _COOLING_WORDS))
        if bad.any():
            raise ValueError(f"unknown fraction label {arr[bad][0]!r}; use 'cold' (heating) "
                             "or 'warm' (cooling)")
        out = np.isin(words, list(_HEATING_WORDS))
    if n_p is not None and out.shape != (n_p,):
        raise ValueError(f"fraction has shape {out.shape}; expected ({n_p},)")
    return out


# --------------------------------------------------------------------------------------------
# Distributions and fraction means
# --------------------------------------------------------------------------------------------


@dataclass
class Distribution:
    """Number distribution of particle temperatures in classes (digest section 8).

    Attributes
    ----------
    edges_C : numpy.ndarray, shape (n_classes + 1,)
        Class edges, degC. Classes are ``[e_k, e_k+1)``, the last one closed.
    counts : numpy.ndarray of int, shape (n_frames, n_classes)
        Particles per class.
    q0 : numpy.ndarray, shape (n_frames, n_classes)
        Number density, 1/K: ``counts / (n_valid * class width)``; ``sum(q0 * width) = 1``.
    Q0 : numpy.ndarray, shape (n_frames, n_classes)
        Cumulative number distribution at the *upper* edge of each class, ``cumsum(counts) /
        n_valid``; the last value is 1.
    n_valid : numpy.ndarray of int, shape (n_frames,)
        Particles with a finite temperature (the normalisation).
    n_below, n_above : numpy.ndarray of int, shape (n_frames,)
        Particles below the first / above the last edge. With ``outside="clip"`` they are
        counted in the first / last class, so ``Q0`` at every upper edge except the last is the
        true fraction of particles below that edge; with ``"exclude"`` they are left out of the
        counts and of ``n_valid``.
    """

    edges_C: np.ndarray
    counts: np.ndarray
    q0: np.ndarray
    Q0: np.ndarray
    n_valid: np.ndarray
    n_below: np.ndarray
    n_above: np.ndarray

    @property
    def centres_C(self) -> np.ndarray:
        """Class centres, degC."""
        return 0.5 * (self.edges_C[1:] + self.edges_C[:-1])

    @property
    def widths_K(self) -> np.ndarray:
        """Class widths, K."""
        return np.diff(self.edges_C)


def temperature_distribution(T_C, edges_C=None, outside: str = "clip") -> Distribution:
    """Number density q0 and cumulative distribution Q0 of particle temperatures.

    The thesis bins particle temperatures into 1 K classes between 25 and 50 degC (digest
    section 8). Its text says "50 classes", which 1 K classes over 25 K cannot give (section 12,
    item 15); the default here is the 25 classes of 1 K. Pass ``edges_C`` for other classes.

    Parameters
    ----------
    T_C : array_like, shape (n_frames, n_particles) or (n_particles,)
        Particle temperatures, degC. NaN (unmeasured or out of calibrated range) is ignored.
    edges_C : array_like, optional
        Increasing class edges, degC; default :data:`DEFAULT_CLASS_EDGES_C` (25, 26, ..., 50).
    outside : {"clip", "exclude"}
        Particles outside the classes: counted in the first/last class (default) or dropped.

    Returns
    -------
    Distribution
        Arrays with a leading frame axis (length 1 for 1-D input).
    """
    T = _as_frames(T_C)
    edges = DEFAULT_CLASS_EDGES_C if edges_C is None else np.asarray(edges_C, dtype=float)
    if edges.ndim != 1 or edges.size < 2 or np.any(np.diff(edges) <= 0):
        raise ValueError("edges_C must be at least two strictly increasing temperatures")
    if outside not in ("clip", "exclude"):
        raise ValueError(f"outside={outside!r}; allowed are 'clip' and 'exclude'")
    finite = np.isfinite(T)
    below = finite & (T < edges[0])
    above = finite & (T > edges[-1])
    n_cls = edges.size - 1
    counts = np.zeros((T.shape[0], n_cls), dtype=int)
    for f in range(T.shape[0]):
        counts[f], _ = np.histogram(T[f, finite[f]], bins=edges)
    n_below, n_above = below.sum(axis=1), above.sum(axis=1)
    if outside == "clip":
        counts[:, 0] += n_below
        counts[:, -1] += n_above
    n_valid = counts.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = counts / n_valid[:, None]
    q0 = share / np.diff(edges)[None, :]
    Q0 = np.cumsum(share, axis=1)
    return Distribution(edges_C=edges, counts=counts, q0=q0, Q0=Q0, n_valid=n_valid,
                        n_below=n_below, n_above=n_above)


def fraction_means(T_C, heating, time_s=None, frames=None) -> pd.DataFrame:
    """Mean temperature of the heating (cold) fraction, cooling (warm) fraction and all.

    Parameters
    ----------
    T_C : array_like, shape (n_frames, n_particles)
        Particle temperatures, degC (NaN ignored).
    heating : array_like of bool, shape (n_frames, n_particles) or (n_particles,)
        Heating-fraction membership (e.g. :attr:`Assignment.heating`).
    time_s : array_like, shape (n_frames,), optional
        Frame times, s (default: NaN).
    frames : array_like, shape (n_frames,), optional
        Frame numbers (default 0, 1, ...).

    Returns
    -------
    pandas.DataFrame
        One row per frame: ``frame``, ``t`` (s); ``T_mean``, ``T_mean:cold``, ``T_mean:warm``
        in K (named as in a simulation's ``timeseries.csv``, with the thesis groups "cold" =
        heating fraction and "warm" = cooling fraction); the same in degC as ``T_mean_C``,
        ``T_mean_C:cold``, ``T_mean_C:warm``; ``n:cold``, ``n:warm`` (particles with a finite
        temperature in each fraction) and ``n_invalid`` (NaN temperatures). Means are unweighted
        number means, which for equal spheres equal the mass-weighted means.
    """
    T = _as_frames(T_C)
    h = np.broadcast_to(np.asarray(heating, dtype=bool), T.shape)
    fin = np.isfinite(T)

    def _mean(mask):
        n = mask.sum(axis=1)
        s = np.where(mask, T, 0.0).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(n > 0, s / n, np.nan), n

    m_all, _ = _mean(fin)
    m_cold, n_cold = _mean(fin & h)
    m_warm, n_warm = _mean(fin & ~h)
    n_frames = T.shape[0]
    frames = np.arange(n_frames) if frames is None else np.asarray(frames)
    time_s = np.full(n_frames, np.nan) if time_s is None else np.asarray(time_s, dtype=float)
    return pd.DataFrame({
        "frame": frames, "t": time_s,
        "T_mean": m_all + 273.15, "T_mean:cold": m_cold + 273.15, "T_mean:warm": m_warm + 273.15,
        "T_mean_C": m_all, "T_mean_C:cold": m_cold, "T_mean_C:warm": m_warm,
        "n:cold": n_cold, "n:warm": n_warm, "n_invalid": (~fin).sum(axis=1),
    })


# --------------------------------------------------------------------------------------------
# CSV input and the whole chain
# --------------------------------------------------------------------------------------------


@dataclass
class IntensityData:
    """Particle intensities per frame, as read by :func:`read_intensity_csv`.

    Attributes
    ----------
    frames : numpy.ndarray of int, shape (n_frames,)
        Frame (image) numbers, increasing.
    time_s : numpy.ndarray, shape (n_frames,)
        Time of each frame, s.
    particles : numpy.ndarray, shape (n_particles,)
        Particle ids (as in the file, sorted).
    intensity : numpy.ndarray, shape (n_frames, n_particles)
        Mean ROI intensity (HSI, 0..255); NaN where a particle has no row for a frame.
    fraction : numpy.ndarray of bool, shape (n_particles,), or None
        True for the heating (initially cold) fraction; None if the file has no fraction column.
    """

    frames: np.ndarray
    time_s: np.ndarray
    particles: np.ndarray
    intensity: np.ndarray
    fraction: np.ndarray | None = None


def read_intensity_csv(path: str | PathLike) -> IntensityData:
    """Read particle intensities from a long-format CSV file.

    File format (one header row; lines starting with ``#`` are comments)::

        frame,time_s,particle,intensity,fraction
        1,60,1,64.2,cold
        1,60,2,112.9,warm
        ...

    * ``frame`` (int): image number; ``time_s`` (float): its time in s (e.g. since the start of
      filling, see :func:`image_times`); every row of a frame must carry the same time.
    * ``particle``: particle id (int or string), the same sphere across frames.
    * ``intensity`` (float): mean HSI intensity (0..255) of the particle's ROI in that image.
    * ``fraction`` (optional): the particle's true fraction, ``cold`` (heating, also accepted:
      ``heating``, ``1``) or ``warm`` (cooling, also: ``cooling``, ``0``); constant per particle.
      Needed for method 1; with methods 2 and 3 it is used to count misassignments.

    One row per particle and frame; a particle missing from a frame gets NaN there.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    IntensityData

    Raises
    ------
    ValueError
        Missing columns, duplicate (frame, particle) rows, differing times within a frame,
        a particle with two fractions, non-numeric or negative intensities.
    """
    df = pd.read_csv(path, comment="#", skipinitialspace=True)
    df.columns = [c.strip() for c in df.columns]
    need = ["frame", "time_s", "particle", "intensity"]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise ValueError(f"{path}: missing column(s) {missing}; expected "
                         "frame,time_s,particle,intensity[,fraction]")
    if df.duplicated(["frame", "particle"]).any():
        row = df[df.duplicated(["frame", "particle"])].iloc[0]
        raise ValueError(f"{path}: particle {row['particle']!r} appears twice in frame "
                         f"{row['frame']!r}")
    try:
        intensity = pd.to_numeric(df["intensity"]).to_numpy(float)
        time = pd.to_numeric(df["time_s"]).to_numpy(float)
        frame = pd.to_numeric(df["frame"], downcast="integer").to_numpy()
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{path}: frame, time_s and intensity must be numeric ({exc})") from None
    if np.any(intensity < 0):
        raise ValueError(f"{path}: negative intensity {intensity[intensity < 0][0]:g}")
    frames, f_idx = np.unique(frame, return_inverse=True)
    particles, p_idx = np.unique(df["particle"].to_numpy(), return_inverse=True)
    n_times = pd.Series(time).groupby(f_idx).nunique(dropna=False)
    if (n_times > 1).any():
        raise ValueError(f"{path}: frame {frames[n_times.idxmax()]} has rows with different "
                         "time_s")
    time_s = np.full(frames.size, np.nan)
    time_s[f_idx] = time
    I = np.full((frames.size, particles.size), np.nan)
    I[f_idx, p_idx] = intensity
    fraction = None
    if "fraction" in df.columns:
        mask = _heating_mask(df["fraction"].to_numpy())
        fraction = np.zeros(particles.size, dtype=bool)
        fraction[p_idx] = mask
        if np.any(fraction[p_idx] != mask):
            bad = particles[p_idx[fraction[p_idx] != mask][0]]
            raise ValueError(f"{path}: particle {bad!r} is given both fractions")
    return IntensityData(frames=frames, time_s=time_s, particles=particles, intensity=I,
                         fraction=fraction)


def write_intensity_csv(path: str | PathLike, intensity, time_s, frames=None, particles=None,
                        fraction=None) -> None:
    """Write particle intensities in the long format of :func:`read_intensity_csv`.

    Parameters
    ----------
    path : str or path-like
    intensity : array_like, shape (n_frames, n_particles)
        HSI intensities; NaN entries are left out (particle not measured in that frame).
    time_s : array_like, shape (n_frames,)
        Frame times, s.
    frames : array_like, shape (n_frames,), optional
        Frame numbers (default 1, 2, ...).
    particles : array_like, shape (n_particles,), optional
        Particle ids (default 1, 2, ...).
    fraction : array_like of bool or str, shape (n_particles,), optional
        True / "cold" for the heating fraction; written as ``cold`` / ``warm``.
    """
    I = _as_frames(intensity)
    n_f, n_p = I.shape
    frames = np.arange(1, n_f + 1) if frames is None else np.asarray(frames)
    particles = np.arange(1, n_p + 1) if particles is None else np.asarray(particles)
    time_s = np.asarray(time_s, dtype=float)
    if frames.shape != (n_f,) or time_s.shape != (n_f,) or particles.shape != (n_p,):
        raise ValueError("frames and time_s need one entry per frame, particles one per "
                         "particle")
    ff, pp = np.meshgrid(np.arange(n_f), np.arange(n_p), indexing="ij")
    keep = np.isfinite(I)
    out = pd.DataFrame({"frame": frames[ff[keep]], "time_s": time_s[ff[keep]],
                        "particle": particles[pp[keep]], "intensity": I[keep]})
    if fraction is not None:
        h = _heating_mask(fraction, n_p)
        out["fraction"] = np.where(h, "cold", "warm")[pp[keep]]
    out.to_csv(path, index=False, float_format="%.17g")


@dataclass
class Evaluation:
    """Result of :func:`evaluate`.

    Attributes
    ----------
    means : pandas.DataFrame
        Fraction means over time (see :func:`fraction_means`), plus ``n_misassigned`` (particles
        whose assigned fraction differs from the file's ``fraction`` column, if present).
    distributions : pandas.DataFrame
        Long format, one row per frame and class: ``frame``, ``t`` (s), ``T_lo_C``,
        ``T_hi_C``, ``T_mid_C`` (degC), ``count``, ``q0`` (1/K), ``Q0`` (at ``T_hi_C``).
    distribution : Distribution
        The same as arrays.
    assignment : Assignment
        Per particle and frame: fraction, branch and temperature.
    data : IntensityData
        What was read.
    """

    means: pd.DataFrame
    distributions: pd.DataFrame
    distribution: Distribution
    assignment: Assignment
    data: IntensityData = field(repr=False)


def evaluate(csv_path: str | PathLike, method: int = 3, n_heating: int | None = None,
             curves: str = "combined", calibration_method: str = "pchip",
             degree: int | None = None, edges_C=None, outside: str = "clip",
             cals: Mapping[str, Calibration] | None = None) -> Evaluation:
    """Thermochromic evaluation of a CSV file of particle intensities, as in the thesis.

    Reads the file (:func:`read_intensity_csv`), assigns fractions and temperatures
    (:func:`assign_temperatures`), and computes fraction means over time
    (:func:`fraction_means`) and q0/Q0 distributions per frame
    (:func:`temperature_distribution`). Digest section 8.

    Parameters
    ----------
    csv_path : str or path-like
        Long-format CSV ``frame,time_s,particle,intensity[,fraction]``.
    method : {1, 2, 3}
        Assignment method; 3 (sorting) is the thesis choice. 1 needs the ``fraction`` column.
    n_heating : int, optional
        Heating-fraction size for method 3 (default: from the ``fraction`` column, else half).
    curves : {"combined", "branches"}
        Calibration curve(s), see :func:`assign_temperatures`.
    calibration_method, degree
        Fit of the shipped calibration tables (:func:`calibrations`); ignored if ``cals`` given.
    edges_C, outside
        Temperature classes, see :func:`temperature_distribution` (default 1 K from 25 to
        50 degC).
    cals : mapping, optional
        Your own calibrations (keys ``"combined"``, or ``"heating"`` and ``"cooling"``).

    Returns
    -------
    Evaluation
        ``.means`` (DataFrame of fraction means over time) and ``.distributions`` (DataFrame of
        q0 and Q0 per frame and class), plus the arrays behind them.
    """
    data = read_intensity_csv(csv_path)
    if cals is None:
        cals = calibrations(calibration_method, degree)
    asg = assign_temperatures(data.intensity, method=method, n_heating=n_heating,
                              fraction=data.fraction, curves=curves, cals=cals)
    means = fraction_means(asg.T_C, asg.heating, data.time_s, data.frames)
    if data.fraction is not None:
        wrong = asg.valid & (asg.heating != data.fraction[None, :])
        means["n_misassigned"] = wrong.sum(axis=1)
    dist = temperature_distribution(asg.T_C, edges_C, outside)
    n_f, n_c = dist.counts.shape
    lo, hi = dist.edges_C[:-1], dist.edges_C[1:]
    distributions = pd.DataFrame({
        "frame": np.repeat(data.frames, n_c), "t": np.repeat(data.time_s, n_c),
        "T_lo_C": np.tile(lo, n_f), "T_hi_C": np.tile(hi, n_f),
        "T_mid_C": np.tile(0.5 * (lo + hi), n_f),
        "count": dist.counts.ravel(), "q0": dist.q0.ravel(), "Q0": dist.Q0.ravel(),
    })
    return Evaluation(means=means, distributions=distributions, distribution=dist,
                      assignment=asg, data=data)


def image_times(image_numbers: Sequence[int] | np.ndarray, interval_s: float,
                t_first_s: float = 60.0) -> np.ndarray:
    """Times of interval-mode images, counted from the start of filling (digest section 7.2).

    Image k is taken at ``t_first_s + (k - 1) * interval_s``: the first image about 60 s after
    the filling started; interval 30 s for resting beds, 5 s for mixed beds.

    Parameters
    ----------
    image_numbers : array_like of int
        1-based image numbers, e.g. :data:`EVALUATED_IMAGES_RESTING`.
    interval_s : float
        Recording interval, s.
    t_first_s : float
        Time of image 1, s.

    Returns
    -------
    numpy.ndarray
        Times, s.
    """
    k = np.asarray(image_numbers, dtype=float)
    return t_first_s + (k - 1.0) * float(interval_s)


# --------------------------------------------------------------------------------------------
# Plot
# --------------------------------------------------------------------------------------------


def plot_calibration(cals: Mapping[str, Calibration] | None = None, method: str = "pchip",
                     degree: int | None = None, ax=None, show_points: bool = True):
    """Plot the calibration points of all three branches and the fitted curves T(I).

    Parameters
    ----------
    cals : mapping, optional
        Calibrations to draw (default :func:`calibrations` with ``method`` and ``degree``).
    method, degree
        Fit of the shipped tables when ``cals`` is not given.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into (default: a new figure).
    show_points : bool
        Draw the table points (App. A1.1-A1.3) of each branch.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    if cals is None:
        cals = calibrations(method, degree)
    if ax is None:
        fig, ax = plt.subplots(figsize=(6.0, 4.5), layout="constrained")
    else:
        fig = ax.figure
    style = {"heating": ("tab:red", "v", "--"), "cooling": ("tab:blue", "^", "--"),
             "combined": ("black", "o", "-")}
    for name, cal in cals.items():
        colour, marker, ls = style.get(name, ("tab:green", "s", "-."))
        grid = np.linspace(*cal.domain, 400)
        deg = "" if cal.degree is None else f" deg {cal.degree}"
        ax.plot(grid, cal(grid), color=colour, ls=ls,
                label=f"{name}: {cal.method}{deg} (LOO RMS {cal.loo_rms_K:.2f} K)")
        if show_points:
            ax.plot(cal.intensity, cal.temperature_C, ls="none", marker=marker,
                    mfc="none" if name == "combined" else colour, mec=colour, ms=6 if
                    name == "combined" else 4)
    ax.set_xlabel("HSI intensity (mean ROI)")
    ax.set_ylabel("temperature (°C)")
    ax.set_title("Thermochromic calibration (Weigler 2012, App. A1)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    return fig
