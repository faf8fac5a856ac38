"""Differentiable calibration: fit scene parameters to measured curves; alpha_pp -> lambda_bed.

Two tools (DESIGN.md, "fit model parameters ... to measured temperature curves with
gradients"):

:func:`fit`
    Least-squares fit of one or more scene parameters (any float leaf by dotted key:
    ``heat.loss.alphaA``, ``heat.contact.alpha``, ``heat.wall.alpha``,
    ``groups.0.temperature``, ...) to measured mean-temperature curves of one or more
    experiments. The residual Jacobian comes from ``jax.jacfwd`` through the whole simulation
    (``motion.solve(params)`` of the scene's motion model, built once with
    :func:`drumheat.runner.make_motion`; the adaptive solves run in diffrax ``ForwardMode``,
    which compiles several times faster than reverse mode and gives the full Jacobian of a few
    parameters in one pass). The optimiser is optax: L-BFGS directions
    (``optax.lbfgs(linesearch=None)``) with a backtracking Armijo line search evaluated on the
    host, or Adam (``optax.adam``). (optax's own zoom line search evaluates the objective inside
    ``lax.while_loop``, which would compile the whole multi-segment run into the loop.)
    Positive parameters are fitted in log space; bounds map through a logistic function.
    Reported: estimate, Gauss-Newton standard errors (``sigma^2 (J^T J)^-1`` with
    ``sigma^2 = SSR / (n - p)``), residuals, convergence history and
    :meth:`FitResult.plot`.

    **Measured times** need not lie on the scene's output grid: the motion object's output grid
    is replaced by ``{0} U {measured times}`` of each experiment, so the model is evaluated
    exactly at the measured times (no interpolation error); a dense grid is used only for the
    fitted curves in the figure.

:func:`calibrate_lambda_bed`
    The alpha_pp -> lambda_bed calibration line of weigler-thermal-dem.md section 10 (thesis
    Ch. 5.2, appendix A7, digest section 6.4) from wall-heating runs of one packing at two or
    more alpha_pp, and its inverse (alpha_pp for a target lambda_bed) by Newton's method on the
    differentiable map. See there for the conventions chosen.

Units: SI; temperatures in K, times in s.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pandas as pd

from drumheat.results import observe
from drumheat.assemble import group_index
from drumheat.scene import Scene, load_scene
from drumheat.motion import make_motion
from drumheat.runner.loop import trace

__all__ = [
    "CalibrationDataError",
    "Experiment",
    "read_measurements",
    "fit",
    "FitResult",
    "calibrate_lambda_bed",
    "LambdaBedCalibration",
    "LambdaBedPoint",
    "InverseResult",
]


class CalibrationDataError(ValueError):
    """Measured data or a parameter choice that a fit cannot use; the message says why and
    what to change."""


# ---------------------------------------------------------------------------------------------
# Measured data
# ---------------------------------------------------------------------------------------------

#: Below this every temperature of a column is taken as degrees Celsius given where K is
#: expected (no particle bed of interest here is colder than -123 degC).
CELSIUS_SUSPECT_K = 150.0


def _allowed_columns(scene: Scene) -> list[str]:
    return ["T_mean"] + [f"T_mean:{g.name}" for g in scene.groups]


def read_measurements(source: str | Path | pd.DataFrame, scene: Scene,
                      label: str = "data") -> pd.DataFrame:
    """Read and check a measured curve: column ``t`` (s) and temperature columns (K).

    Parameters
    ----------
    source : path or DataFrame
        CSV file (lines starting with ``#`` are comments) or a DataFrame.
    scene : Scene
        The scene the data belong to (its group names define the ``T_mean:<group>`` columns).
    label : str
        Name used in error messages.

    Returns
    -------
    pandas.DataFrame
        Columns ``t`` and one or more of ``T_mean``, ``T_mean:<group>``, float64.

    Raises
    ------
    CalibrationDataError
        Missing file or ``t`` column, unknown column or group, no temperature column, NaN or
        non-numeric values, negative or non-increasing times, temperatures <= 0 K or all
        below 150 K in a column (degrees Celsius where kelvin is expected).
    """
    if isinstance(source, pd.DataFrame):
        df = source.copy()
    else:
        path = Path(source)
        if not path.is_file():
            raise CalibrationDataError(f"{label}: no such file {str(path)!r}")
        label = f"{label} ({path.name})" if label == "data" else label
        try:
            df = pd.read_csv(path, comment="#", skipinitialspace=True)
        except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as err:
            raise CalibrationDataError(f"{label}: cannot be read as a CSV table with a header "
                                       f"row ({err})") from None
    df.columns = [str(c).strip() for c in df.columns]
    allowed = _allowed_columns(scene)
    if "t" not in df.columns:
        raise CalibrationDataError(f"{label}: no time column 't' (s); columns found: "
                                   f"{list(df.columns)}")
    for c in df.columns:
        if c == "t" or c in allowed:
            continue
        if c.startswith("T_mean:"):
            raise CalibrationDataError(
                f"{label}: column {c!r} names group {c[7:]!r}, which scene {scene.name!r} does "
                f"not have; its groups are {[g.name for g in scene.groups]}")
        raise CalibrationDataError(f"{label}: unknown column {c!r}; allowed: 't' (s) and "
                                   f"{allowed} (K)")
    temp = [c for c in df.columns if c != "t"]
    if not temp:
        raise CalibrationDataError(f"{label}: no temperature column; give one or more of "
                                   f"{allowed} (K)")
    for c in df.columns:
        values = pd.to_numeric(df[c], errors="coerce")
        bad = np.flatnonzero(~np.isfinite(values.to_numpy(dtype=float)))
        if bad.size:
            raise CalibrationDataError(
                f"{label}: column {c!r} has missing, NaN or non-numeric values in data rows "
                f"{(bad + 1).tolist()[:10]}; remove those rows or fill them in")
        df[c] = values.astype(float)
    t = df["t"].to_numpy()
    if len(t) == 0:
        raise CalibrationDataError(f"{label}: no data rows")
    if np.any(t < 0):
        raise CalibrationDataError(f"{label}: negative times in column 't'; times are s since "
                                   "the start of the simulated process (t = 0)")
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise CalibrationDataError(
            f"{label}: times must be strictly increasing; row {k + 2} (t = {t[k + 1]:g} s) "
            f"follows t = {t[k]:g} s. Sort the rows, and average or split repeated times into "
            "separate experiments")
    for c in temp:
        T = df[c].to_numpy()
        cold = np.flatnonzero(T < CELSIUS_SUSPECT_K)
        if cold.size:
            raise CalibrationDataError(
                f"{label}: column {c!r} has values below {CELSIUS_SUSPECT_K:g} K in data rows "
                f"{(cold + 1).tolist()[:10]} (e.g. {T[cold[0]]:g}); these look like degrees "
                "Celsius, but temperatures must be in kelvin: add 273.15 (to every row)")
        if np.any(T <= 0):
            raise CalibrationDataError(f"{label}: column {c!r} has temperatures <= 0 K")
    return df[["t"] + temp].reset_index(drop=True)


@dataclass
class Experiment:
    """One measured run: a scene and its measured curves.

    Attributes
    ----------
    scene : Scene or str
        Scene object, built-in name or file.
    data : path or DataFrame
        Measured curves (see :func:`read_measurements`).
    name : str, optional
        Label in results and figures (default: the scene name, numbered if repeated).
    overrides : dict, optional
        Fixed scene values of this experiment (validated dotted-key overrides), e.g. its own
        start temperature.
    """

    scene: Scene | str
    data: Any
    name: str | None = None
    overrides: dict | None = None


# ---------------------------------------------------------------------------------------------
# Parameters
# ---------------------------------------------------------------------------------------------


def _field_meta(scene: Scene, key: str):
    """(python type, metadata) declared for a dotted scene key, or raise KeyError."""
    cls: Any = type(scene)
    parts = key.split(".")
    meta: dict = {}
    tp: Any = cls
    for i, part in enumerate(parts):
        origin = typing.get_origin(tp)
        if origin is tuple:
            if not part.isdigit():
                raise KeyError(key)
            tp = typing.get_args(tp)[0]
            continue
        if not dataclasses.is_dataclass(tp):
            raise KeyError(key)
        hints = typing.get_type_hints(tp)
        fields = {f.name: f for f in dataclasses.fields(tp)}
        if part not in fields or fields[part].metadata.get("internal"):
            raise KeyError(key)
        meta = dict(fields[part].metadata)
        tp = hints[part]
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if typing.get_origin(tp) in (typing.Union, __import__("types").UnionType) and len(args) == 1:
            tp = args[0]
    return tp, meta


def check_parameter(scene: Scene, key: str) -> float:
    """Value of a fittable parameter in ``scene``; refuse unknown or non-float keys.

    Raises
    ------
    CalibrationDataError
        If ``key`` is not a scene key, not a float, or not set in this scene (e.g.
        ``heat.contact.alpha`` with ``model = "schluender"``, or a material property left to
        the library).
    """
    try:
        tp, meta = _field_meta(scene, key)
        try:
            value = scene.get(key)
        except AttributeError:  # a declared key inside an absent table, e.g. [heat.contact]
            value = None
    except (KeyError, AttributeError, IndexError, ValueError):
        raise CalibrationDataError(
            f"parameter {key!r} is not a key of scene {scene.name!r}; fittable parameters are "
            "float values by dotted key, e.g. heat.loss.alphaA, heat.contact.alpha, "
            "heat.wall.alpha, groups.0.temperature, gas.temperature") from None
    if tp is not float:
        raise CalibrationDataError(f"parameter {key!r} is not a float (it is "
                                   f"{getattr(tp, '__name__', tp)}); only float values can be "
                                   "fitted")
    if value is None:
        raise CalibrationDataError(f"parameter {key!r} is not set in scene {scene.name!r} "
                                   "(absent table, computed by a model, or a library value); "
                                   "set it in the scene to fit it")
    return float(value)


class _Transform:
    """theta = x0 * exp(u) (positive), lo + (hi - lo) sigmoid(u) (bounded), x0 + s u (free)."""

    def __init__(self, x0: float, kind: str, lo=None, hi=None):
        self.x0, self.kind, self.lo, self.hi = float(x0), kind, lo, hi
        self.scale = abs(self.x0) if self.x0 != 0 else 1.0

    def to_theta(self, u):
        if self.kind == "log":
            return self.x0 * jnp.exp(u)
        if self.kind == "bounded":
            return self.lo + (self.hi - self.lo) * jax.nn.sigmoid(u)
        return self.x0 + self.scale * u

    def to_u(self, theta: float) -> float:
        if self.kind == "log":
            return math.log(theta / self.x0)
        if self.kind == "bounded":
            p = (theta - self.lo) / (self.hi - self.lo)
            return math.log(p / (1 - p))
        return (theta - self.x0) / self.scale

    def dtheta_du(self, u: float) -> float:
        return float(jax.grad(lambda v: self.to_theta(v))(jnp.asarray(u, float)))


# ---------------------------------------------------------------------------------------------
# Fit result
# ---------------------------------------------------------------------------------------------


@dataclass
class FitResult:
    """Outcome of :func:`fit`.

    Attributes
    ----------
    names : list of str
        Fitted dotted keys.
    estimate, initial, stderr : dict
        Estimates, start values and Gauss-Newton standard errors (same units as the keys).
    covariance, correlation : ndarray (p, p)
        ``sigma^2 (J^T J)^-1`` with J = d model / d theta at the estimate, and its correlation.
    sigma : float
        Residual standard deviation ``sqrt(SSR / (n - p))``, K (or the given noise).
    n_data, dof : int
        Number of data points and ``n - p``.
    residuals : pandas.DataFrame
        Columns experiment, column, t (s), measured, model, residual (model - measured, K).
    history : pandas.DataFrame
        Per iteration: iteration, loss (mean squared residual / 2, K^2), step, and the
        parameter values.
    curves : dict
        ``{experiment: DataFrame}`` of model curves on a dense grid (for the figure).
    converged : bool
    message : str
    optimizer : str
    """

    names: list
    estimate: dict
    initial: dict
    stderr: dict
    covariance: np.ndarray
    correlation: np.ndarray
    sigma: float
    n_data: int
    dof: int
    residuals: pd.DataFrame
    history: pd.DataFrame
    curves: dict
    converged: bool
    message: str
    optimizer: str

    def table(self) -> pd.DataFrame:
        """Estimates with standard errors: columns initial, estimate, stderr, rel_stderr."""
        rows = [dict(parameter=k, initial=self.initial[k], estimate=self.estimate[k],
                     stderr=self.stderr[k],
                     rel_stderr=self.stderr[k] / abs(self.estimate[k]) if self.estimate[k]
                     else math.nan) for k in self.names]
        return pd.DataFrame(rows).set_index("parameter")

    def __str__(self) -> str:
        lines = [f"fit ({self.optimizer}): {self.message}; n = {self.n_data}, dof = {self.dof},"
                 f" residual sigma = {self.sigma:.4g} K, {len(self.history) - 1} iterations"]
        for k in self.names:
            lines.append(f"  {k} = {self.estimate[k]:.6g} +- {self.stderr[k]:.3g}"
                         f" (start {self.initial[k]:.6g})")
        return "\n".join(lines)

    def plot(self):
        """Figure of measured data (markers) and fitted model (lines), with residuals below.

        Returns
        -------
        matplotlib.figure.Figure
        """
        import matplotlib.pyplot as plt

        fig, (ax, axr) = plt.subplots(2, 1, figsize=(7, 6), sharex=True,
                                      gridspec_kw=dict(height_ratios=[3, 1]))
        colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
        k = 0
        for exp, df in self.residuals.groupby("experiment", sort=False):
            for col, d in df.groupby("column", sort=False):
                c = colors[k % len(colors)]
                k += 1
                label = exp if col == "T_mean" else f"{exp} {col}"
                ax.plot(d["t"], d["measured"], "o", color=c, ms=4, label=f"{label} (data)")
                curve = self.curves.get(exp)
                if curve is not None and col in curve:
                    ax.plot(curve["t"], curve[col], "-", color=c, lw=1.2)
                axr.plot(d["t"], d["residual"], "o", color=c, ms=3)
        axr.axhline(0, color="k", lw=0.8)
        ax.set_ylabel("mean temperature (K)")
        axr.set_ylabel("model - data (K)")
        axr.set_xlabel("t (s)")
        est = ", ".join(f"{n} = {self.estimate[n]:.4g} ± {self.stderr[n]:.2g}" for n in self.names)
        ax.set_title(est, fontsize=9)
        if k <= 12:
            ax.legend(fontsize=7)
        fig.tight_layout()
        return fig


# ---------------------------------------------------------------------------------------------
# The fit
# ---------------------------------------------------------------------------------------------


def _with_value(f):
    """``x -> (f(x), f(x))`` from one evaluation of ``f``: with ``jax.jacfwd(..., has_aux=True)``
    the Jacobian and the value come from the same forward pass."""
    def g(x):
        y = f(x)
        return y, y

    return g


@dataclass
class _Prepared:
    name: str
    scene: Scene
    motion: Any
    data: pd.DataFrame
    grid: np.ndarray
    columns: list
    rows: list = field(default_factory=list)


def _prepare(experiments, data, keys):
    if isinstance(experiments, (Scene, str, Path)):
        if data is None:
            raise CalibrationDataError("fit(scene, data, params): no data given")
        experiments = [Experiment(experiments, data)]
    elif isinstance(experiments, Experiment):
        experiments = [experiments]
    checked, names = [], {}
    for ex in experiments:
        scene = ex.scene if isinstance(ex.scene, Scene) else load_scene(ex.scene)
        if ex.overrides:
            scene = scene.with_overrides(ex.overrides)
        name = ex.name or scene.name
        if name in names:
            names[name] += 1
            name = f"{name}#{names[name]}"
        else:
            names[name] = 1
        for k in keys:
            check_parameter(scene, k)
        df = read_measurements(ex.data, scene, label=f"experiment {name!r}")
        checked.append((name, scene, df))
    n_data = sum(len(df) * (df.shape[1] - 1) for _, _, df in checked)
    if n_data < len(keys):
        raise CalibrationDataError(f"{n_data} data point(s) for {len(keys)} parameter(s): a fit "
                                   "needs at least as many points as parameters")
    prepared, motions = [], {}
    for name, scene, df in checked:  # packings and contacts are built once per scene
        key = scene.to_toml()
        if key not in motions:
            motion = make_motion(scene)
            if not motion.differentiable:
                raise CalibrationDataError(f"experiment {name!r}: motion model "
                                           f"{scene.motion.model!r} cannot be differentiated; "
                                           "fit with a static, random, replay or fluidized "
                                           "scene")
            motions[key] = motion.with_options(autodiff="forward")
        grid = np.unique(np.concatenate([[0.0], df["t"].to_numpy()]))
        prepared.append(_Prepared(name, scene, motions[key], df, grid,
                                  [c for c in df.columns if c != "t"]))
    return prepared


def _predict(p: _Prepared, params: dict, grid=None):
    """Model mean temperatures {column: (n_grid,)} of one experiment on ``grid``."""
    m = p.motion.with_options(times=p.grid if grid is None else grid)
    T, _ = trace(m, params)
    model, _ = m.model(params)
    mass = model.particles.mass
    group = group_index(p.scene)
    out = {}
    for c in p.columns:
        w = mass if c == "T_mean" else jnp.where(
            jnp.asarray(group == [g.name for g in p.scene.groups].index(c[7:])), mass, 0.0)
        out[c] = T @ w / jnp.sum(w)
    return out


def _transforms(scene, keys, x0, bounds, log) -> list:
    """How each fitted parameter is scaled (:class:`_Transform`): through a logistic map onto
    its ``bounds``, in log space, or free (see :func:`fit`'s ``bounds`` and ``log``)."""
    trans = []
    for k in keys:
        _, meta = _field_meta(scene, k)
        if not math.isfinite(x0[k]):
            raise CalibrationDataError(f"start value {k} = {x0[k]!r} is not a finite number")
        floor = next(((meta[c], c) for c in ("gt", "ge") if meta.get(c) is not None), None)
        if k in bounds:
            lo, hi = map(float, bounds[k])
            if floor is not None and (lo < floor[0] or (lo == floor[0] and floor[1] == "gt")):
                raise CalibrationDataError(
                    f"bounds of {k} = ({lo:g}, {hi:g}) reach values the scene does not allow "
                    f"(it must be {'>' if floor[1] == 'gt' else '>='} {floor[0]:g}): a fit must "
                    "not return a value the scene refuses; raise the lower bound")
            if not lo < x0[k] < hi:
                raise CalibrationDataError(f"start value {k} = {x0[k]:g} is outside its bounds "
                                           f"({lo:g}, {hi:g})")
            trans.append(_Transform(x0[k], "bounded", lo, hi))
            continue
        positive = (meta.get("gt") is not None and meta["gt"] >= 0) or (
            meta.get("ge") is not None and meta["ge"] >= 0)
        use_log = log.get(k, positive) if isinstance(log, dict) else (
            positive if log is None else bool(log))
        if use_log and x0[k] <= 0:
            raise CalibrationDataError(f"parameter {k} starts at {x0[k]:g}; log-space fitting "
                                       "needs a start value > 0")
        trans.append(_Transform(x0[k], "log" if use_log else "free"))
    return trans


def fit(experiments, data=None, params: Sequence[str] | dict | None = None, *,
        bounds: dict | None = None, log: bool | dict | None = None, optimizer: str = "lbfgs",
        max_iter: int = 100, learning_rate: float = 0.05, xtol: float = 1e-9,
        ftol: float = 1e-14, noise: float | None = None, dense: int = 121,
        verbose: bool = False) -> FitResult:
    """Fit scene parameters to measured mean-temperature curves, by gradients of the run.

    Parameters
    ----------
    experiments : Scene, str, Experiment or list of Experiment
        One scene (with ``data``) or several experiments sharing the fitted parameters (e.g.
        a heating and a cooling run, each with its own start temperature).
    data : path or DataFrame, optional
        Measured curves when ``experiments`` is a single scene (see :func:`read_measurements`:
        column ``t`` in s, ``T_mean`` and/or ``T_mean:<group>`` in K).
    params : list of str or dict
        Dotted keys to fit (float values of the scene), or ``{key: start value}``; by default
        the start is the (first) scene's value.
    bounds : dict, optional
        ``{key: (lo, hi)}``; the parameter is fitted through a logistic map onto (lo, hi).
    log : bool or dict, optional
        Fit in log space. Default: every parameter whose declared range is positive
        (``> 0`` or ``>= 0``, e.g. coefficients, temperatures) and whose start is > 0.
    optimizer : {"lbfgs", "adam"}
        ``"lbfgs"``: optax L-BFGS directions with a host-side Armijo backtracking line search
        (default); ``"adam"``: ``optax.adam`` on the (log-)scaled parameters with a cosine
        decay of ``learning_rate`` over ``max_iter`` (a constant step keeps oscillating).
    max_iter : int
        Maximum number of iterations.
    learning_rate : float
        Initial Adam step on the scaled parameters (0.05 = 5 % for log parameters).
    xtol, ftol : float
        Stop when the largest step on the scaled parameters is below ``xtol`` or the loss
        decreases by less than ``ftol`` times itself.
    noise : float, optional
        Known measurement standard deviation, K; default: estimated from the residuals.
    dense : int
        Points of the model curves kept for the figure.
    verbose : bool
        Print every iteration.

    Returns
    -------
    FitResult

    Raises
    ------
    CalibrationDataError
        Unusable data (see :func:`read_measurements`), fewer data points than parameters,
        unknown or non-float parameter keys, or a parameter the model does not depend on.
    """
    if params is None or len(params) == 0:
        raise CalibrationDataError("no parameters to fit; pass params=['heat.loss.alphaA', ...]")
    keys = list(params)
    if len(set(keys)) != len(keys):
        raise CalibrationDataError(f"parameter keys repeated: {keys}")
    prepared = _prepare(experiments, data, keys)
    n_data = sum(len(p.data) * len(p.columns) for p in prepared)
    y = np.concatenate([p.data[c].to_numpy() for p in prepared for c in p.columns])
    first = prepared[0].scene
    x0 = {k: float(params[k]) if isinstance(params, dict) else check_parameter(first, k)
          for k in keys}
    trans = _transforms(first, keys, x0, bounds or {}, log)

    def theta_of(u):
        return {k: tr.to_theta(u[i]) for i, (k, tr) in enumerate(zip(keys, trans))}

    def model_vector(u):
        th = theta_of(u)
        parts = []
        for p in prepared:
            pred = _predict(p, th)
            idx = np.searchsorted(p.grid, p.data["t"].to_numpy())
            parts += [pred[c][idx] for c in p.columns]
        return jnp.concatenate(parts)

    y_j = jnp.asarray(y)

    def residual(u):
        return model_vector(u) - y_j

    def res_and_jac(u):  # one model evaluation gives the residual and its Jacobian
        J, r = jax.jacfwd(_with_value(residual), has_aux=True)(u)
        return r, J

    def loss_of(r):
        return 0.5 * float(jnp.mean(r**2))

    u = jnp.zeros(len(keys))
    r, J = res_and_jac(u)
    if not np.all(np.isfinite(np.asarray(r))):
        raise CalibrationDataError("the model gives NaN/Inf at the start values; check the scene")
    dead = [k for i, k in enumerate(keys) if not np.any(np.asarray(J[:, i]) != 0)]
    if dead:
        raise CalibrationDataError(f"the simulated temperatures do not depend on {dead} (the "
                                   "packing and contact geometry are built once and are not "
                                   "fitted); choose thermal parameters")
    f = loss_of(r)
    hist = [dict(iteration=0, loss=f, step=0.0, **{k: x0[k] for k in keys})]
    converged, message = False, f"stopped after max_iter = {max_iter} iterations"
    opt = optax.lbfgs(linesearch=None) if optimizer == "lbfgs" else optax.adam(
        optax.cosine_decay_schedule(learning_rate, max_iter, alpha=1e-3))
    if optimizer not in ("lbfgs", "adam"):
        raise ValueError(f"optimizer must be 'lbfgs' or 'adam', got {optimizer!r}")
    state = opt.init(u)
    small = 0
    for it in range(1, max_iter + 1):
        g = J.T @ r / r.size
        if optimizer == "adam":
            upd, state = opt.update(g, state, u)
            u_new = u + upd
            r_new, J_new = res_and_jac(u_new)
            f_new = loss_of(r_new)
        else:
            d, state = opt.update(g, state, u)
            slope = float(g @ d)
            if not slope < 0:  # not a descent direction: restart the memory
                state = opt.init(u)
                d, state = opt.update(g, state, u)
                slope = float(g @ d)
            step, f_new = 1.0, math.inf
            big = float(jnp.max(jnp.abs(d)))
            if big > 1.0:  # at most a factor e per iteration in log space
                step = 1.0 / big
            for _ in range(40):
                r_try = residual(u + step * d)
                f_new = loss_of(r_try)
                if np.isfinite(f_new) and f_new <= f + 1e-4 * step * slope:
                    break
                step *= 0.5
            u_new = u + step * d
            r_new, J_new = res_and_jac(u_new)
        dx = float(jnp.max(jnp.abs(u_new - u)))
        decrease = f - f_new
        u, r, J, f_prev, f = u_new, r_new, J_new, f, f_new
        th = {k: float(v) for k, v in theta_of(u).items()}
        hist.append(dict(iteration=it, loss=f, step=dx, **th))
        if verbose:
            print(f"iter {it:3d}  loss {f:.6e}  step {dx:.2e}  " +
                  "  ".join(f"{k}={v:.6g}" for k, v in th.items()))
        if optimizer == "lbfgs":
            if dx < xtol:
                converged, message = True, f"converged: step below xtol = {xtol:g}"
                break
            if 0 <= decrease <= ftol * max(f_prev, 1e-300):
                small += 1
                if small >= 2:
                    converged, message = True, f"converged: loss change below ftol = {ftol:g}"
                    break
            else:
                small = 0
        elif dx < xtol:
            converged, message = True, f"converged: step below xtol = {xtol:g}"
            break

    # Gauss-Newton standard errors in the natural parameters
    est = {k: float(v) for k, v in theta_of(u).items()}
    scale = np.array([tr.dtheta_du(float(u[i])) for i, tr in enumerate(trans)])
    Jt = np.asarray(J) / scale[None, :]
    rr = np.asarray(r)
    p = len(keys)
    dof = n_data - p
    if noise is not None:
        sigma = float(noise)
    else:
        sigma = math.sqrt(float(rr @ rr) / dof) if dof > 0 else math.nan
    try:
        cov = sigma**2 * np.linalg.inv(Jt.T @ Jt)
    except np.linalg.LinAlgError:
        cov = np.full((p, p), np.inf)
        message += "; J^T J is singular (parameters not separately identifiable)"
    se = np.sqrt(np.abs(np.diag(cov)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)

    rows, curves = [], {}
    k0 = 0
    for pp in prepared:
        for c in pp.columns:
            n = len(pp.data)
            meas = pp.data[c].to_numpy()
            rows.append(pd.DataFrame(dict(experiment=pp.name, column=c, t=pp.data["t"].to_numpy(),
                                          measured=meas, model=meas + rr[k0:k0 + n],
                                          residual=rr[k0:k0 + n])))
            k0 += n
        t_dense = np.unique(np.concatenate([np.linspace(0.0, pp.grid[-1], dense), pp.grid]))
        pred = _predict(pp, {k: jnp.asarray(v) for k, v in est.items()}, grid=t_dense)
        curves[pp.name] = pd.DataFrame({"t": t_dense, **{c: np.asarray(v) for c, v in pred.items()}})
    return FitResult(names=keys, estimate=est, initial=x0, stderr=dict(zip(keys, se.tolist())),
                     covariance=cov, correlation=corr, sigma=sigma, n_data=n_data, dof=dof,
                     residuals=pd.concat(rows, ignore_index=True), history=pd.DataFrame(hist),
                     curves=curves, converged=converged, message=message, optimizer=optimizer)


# ---------------------------------------------------------------------------------------------
# Calibration line alpha_pp -> lambda_bed (weigler-thermal-dem.md sections 6.4, 10)
# ---------------------------------------------------------------------------------------------


@dataclass
class LambdaBedPoint:
    """One point of the calibration line: a wall-heating run at one alpha_pp.

    Attributes
    ----------
    alpha_pp : float
        W/(m2 K).
    lambda_bed : float
        lambda_bed read off at ``time``, W/(m K) (eq. [5.1]).
    time : float
        Read-off time, s.
    criterion : str
        "slope" (the log-log slope reaches -0.5) or "inflection" (extremum of the slope curve,
        the A7 fallback), see :func:`drumheat.results.observe.penetration_time`.
    slope_at_time : float
        Slope of the curve used at ``time``.
    alpha_overall, alpha_bed : float
        Overall and bed coefficients at ``time``, W/(m2 K).
    curves : pandas.DataFrame
        t, T_mean, alpha_overall, alpha_bed, slope, lambda_bed on the run's time grid.
    """

    alpha_pp: float
    lambda_bed: float
    time: float
    criterion: str
    slope_at_time: float
    alpha_overall: float
    alpha_bed: float
    curves: pd.DataFrame


@dataclass
class InverseResult:
    """alpha_pp for a target lambda_bed (:meth:`LambdaBedCalibration.alpha_pp`).

    Attributes
    ----------
    alpha_pp : float
        W/(m2 K).
    lambda_target : float
        W/(m K).
    lambda_achieved : float
        lambda_bed of a full calibration run at ``alpha_pp`` (read-off included), W/(m K).
    time, criterion : float, str
        Read-off time and criterion of that run.
    line_estimate : float
        The calibration line's answer, W/(m2 K).
    newton_steps : int
        Newton iterations in total (over all read-off time updates).
    """

    alpha_pp: float
    lambda_target: float
    lambda_achieved: float
    time: float
    criterion: str
    line_estimate: float
    newton_steps: int


@dataclass
class LambdaBedCalibration:
    """Calibration line alpha_pp -> lambda_bed and the runs behind it.

    Attributes
    ----------
    line : drumheat.results.observe.CalibrationLine
        ``lambda_bed = slope * alpha_pp + intercept``.
    points : list of LambdaBedPoint
    rho_bed, c_bed : float
        Bulk density (kg/m3) and heat capacity (J/(kg K)) of eq. [5.1].
    alpha_ws : float
        Wall coefficient subtracted in eq. [1.6], W/(m2 K).
    convention : str
        "A7" (alpha_ws = alpha_wp) or "phi" (alpha_ws = Phi alpha_wp).
    slope_of : str
        "overall" or "bed": which curve's log-log slope sets the read-off time.
    area : float
        A of eq. [1.10], ``d_p^2 x wall contacts``, m2.
    n_wall_contacts : int
    proportional : dict
        Check of linearity at a fixed read-off time: ``{"time": t, "ratio": ...}`` with
        ``lambda(a2, t) / lambda(a1, t) / (a2 / a1)`` for the first two points (1 = exactly
        proportional).
    """

    line: Any
    points: list
    rho_bed: float
    c_bed: float
    alpha_ws: float
    convention: str
    slope_of: str
    area: float
    n_wall_contacts: int
    proportional: dict
    _ctx: Any = field(repr=False, default=None)

    def table(self) -> pd.DataFrame:
        """alpha_pp, lambda_bed, time, criterion, slope_at_time, alpha_overall, alpha_bed."""
        return pd.DataFrame([dict(alpha_pp=p.alpha_pp, lambda_bed=p.lambda_bed, time=p.time,
                                  criterion=p.criterion, slope_at_time=p.slope_at_time,
                                  alpha_overall=p.alpha_overall, alpha_bed=p.alpha_bed)
                             for p in self.points])

    def lambda_bed(self, alpha_pp):
        """lambda_bed from the line, W/(m K)."""
        return float(self.line.lambda_bed(alpha_pp))

    def alpha_pp(self, lambda_target: float, method: str = "newton", tol: float = 1e-10,
                 max_outer: int = 8) -> InverseResult:
        """alpha_pp (W/(m2 K)) that gives ``lambda_target`` (W/(m K)).

        ``method="line"`` inverts the calibration line. ``method="newton"`` (default) solves
        ``lambda(alpha_pp; t_c) = lambda_target`` by Newton's method on the differentiable map
        (``jax.jacfwd`` through the run to the read-off time t_c), starting from the line;
        t_c is then re-read from a full run at the new alpha_pp, and the two steps repeat until
        t_c no longer changes (the read-off itself is a discrete choice, not differentiated).
        The map is not exactly linear (``proportional`` shows by how much), so the line and
        Newton answers differ.
        """
        a_line = float(self.line.alpha_pp(lambda_target))
        if method == "line":
            return InverseResult(a_line, lambda_target, math.nan, math.nan, "line", a_line, 0)
        ctx = self._ctx
        a = a_line
        nearest = min(self.points, key=lambda p: abs(p.alpha_pp - a))
        t_c, steps = nearest.time, 0
        pt = None
        for _ in range(max_outer):
            for _ in range(30):
                lam, dlam = ctx.lambda_at(a, t_c)
                da = (lam - lambda_target) / dlam
                a -= da
                steps += 1
                if abs(da) <= tol * abs(a):
                    break
            pt = ctx.point(a)
            if abs(pt.time - t_c) <= 1e-9 * t_c:
                break
            t_c = pt.time
        return InverseResult(a, lambda_target, pt.lambda_bed, pt.time, pt.criterion, a_line, steps)

    def plot(self):
        """Figure: alpha_overall(t) and slope curves of every run, and the calibration line."""
        import matplotlib.pyplot as plt

        fig, axs = plt.subplots(1, 3, figsize=(13, 4))
        for p in self.points:
            c = p.curves
            axs[0].loglog(c["t"], c["alpha_overall"], label=f"alpha_pp = {p.alpha_pp:g}")
            axs[1].semilogx(c["t"], c["slope"], label=f"alpha_pp = {p.alpha_pp:g}")
            axs[1].axvline(p.time, ls=":", color="gray")
        axs[1].axhline(-0.5, color="k", lw=0.8)
        axs[0].set(xlabel="t (s)", ylabel="alpha_overall (W/(m2 K))")
        axs[1].set(xlabel="t (s)", ylabel=f"d ln alpha_{self.slope_of} / d ln t")
        x = np.array([p.alpha_pp for p in self.points])
        xs = np.linspace(0, 1.2 * x.max(), 50)
        axs[2].plot(x, [p.lambda_bed for p in self.points], "o")
        axs[2].plot(xs, np.asarray(self.line.lambda_bed(xs)), "-")
        axs[2].set(xlabel="alpha_pp (W/(m2 K))", ylabel="lambda_bed (W/(m K))",
                   title=f"rho_bed = {self.rho_bed:g}, alpha_ws: {self.convention}")
        axs[0].legend(fontsize=8)
        fig.tight_layout()
        return fig


class _LambdaContext:
    """Runs of one packing at varying alpha_pp and the A7 post-processing."""

    def __init__(self, scene, rho_bed, c_bed, alpha_ws, slope_of, times, t_range, which,
                 smooth):
        self.scene = scene
        self.motion = make_motion(scene).with_options(autodiff="forward")
        d = np.asarray(self.motion.packing.diameter)
        self.n_wall = len(self.motion.wall_particles)
        self.area = float(np.sum(d[self.motion.wall_particles] ** 2))  # A7: d_p^2 N_w
        self.rho_bed, self.c_bed, self.alpha_ws = rho_bed, c_bed, alpha_ws
        self.slope_of, self.times, self.t_range = slope_of, times, t_range
        self.which, self.smooth = which, smooth
        self.T_w = float(scene.drum.wall_temperature)

    def _mean(self, a_pp, grid):
        m = self.motion.with_options(times=grid)
        params = {"heat.contact.alpha": a_pp}
        T, _ = trace(m, params)
        model, T0 = m.model(params)
        C = model.particles.capacity
        return T @ C / jnp.sum(C), jnp.sum(C), jnp.sum(C * T0) / jnp.sum(C)

    def _coefficients(self, t, Tm, C, T0):
        a = observe.alpha_overall(t, Tm, self.T_w, T0, C, self.area)
        ab = observe.alpha_bed_from_overall(a, self.alpha_ws)
        lam = observe.lambda_bed_curve(t, ab, self.rho_bed, self.c_bed)
        return a, ab, lam

    def point(self, a_pp) -> LambdaBedPoint:
        t = self.times
        Tm, C, T0 = self._mean(jnp.asarray(float(a_pp)), t)
        a, ab, lam = (np.asarray(v) for v in self._coefficients(t, Tm, C, T0))
        curve = a if self.slope_of == "overall" else ab
        pt = observe.penetration_time(t, curve, smooth=self.smooth, which=self.which,
                                      t_range=self.t_range)
        if not np.isfinite(pt.time):
            raise ValueError(f"alpha_pp = {a_pp:g}: the slope of alpha_{self.slope_of} neither "
                             "reaches -0.5 nor has an interior inflection point in the time "
                             "range; extend run.duration or t_range")
        # evaluate exactly at the read-off time (no interpolation of the curves)
        lam_t, _ = self.lambda_at(float(a_pp), pt.time, derivative=False)
        Tm_t, C_t, T0_t = self._mean(jnp.asarray(float(a_pp)), np.array([0.0, pt.time]))
        a_t, ab_t, _ = self._coefficients(np.array([0.0, pt.time]), Tm_t, C_t, T0_t)
        curves = pd.DataFrame(dict(t=t, T_mean=np.asarray(Tm), alpha_overall=a, alpha_bed=ab,
                                   slope=pt.slope, lambda_bed=lam))
        return LambdaBedPoint(float(a_pp), float(lam_t), float(pt.time), pt.criterion,
                              float(pt.slope_at_time), float(a_t[1]), float(ab_t[1]), curves)

    def lambda_at(self, a_pp, t_c, derivative=True):
        """lambda_bed at the fixed time t_c and d lambda / d alpha_pp (jax.jacfwd)."""
        grid = np.array([0.0, float(t_c)])

        def lam(a):
            Tm, C, T0 = self._mean(a, grid)
            return self._coefficients(grid, Tm, C, T0)[2][1]

        a = jnp.asarray(float(a_pp))
        if not derivative:
            return float(lam(a)), math.nan
        d, v = jax.jacfwd(_with_value(lam), has_aux=True)(a)
        return float(v), float(d)


def calibrate_lambda_bed(scene: Scene | str, alpha_pp_values: Sequence[float], *,
                         rho_bed: float = 1230.0, c_bed: float | None = None,
                         convention: str = "A7", phi: float = 0.8, slope_of: str = "overall",
                         n_times: int = 300, t_min: float = 1.0,
                         t_range: tuple | None = None, which: str = "first",
                         smooth: float | None = None,
                         through_origin: bool = False) -> LambdaBedCalibration:
    """Calibration line alpha_pp -> lambda_bed from wall-heating runs on one packing.

    The A7 procedure (weigler-thermal-dem.md sections 6.4 and 10): for each alpha_pp the
    resting packing of ``scene`` (same seed, so the same packing for every alpha_pp) is heated
    through the wall; then

    1. ``alpha_overall(t)`` from the capacity-weighted mean temperature, eq. [1.10], with the
       A7 area ``A = d_p^2 x (wall contacts)``;
    2. ``alpha_bed(t)`` from eq. [1.6], ``1/alpha_bed = 1/alpha_overall - 1/alpha_ws``;
    3. the log-log slope of ``alpha_overall`` (``slope_of="overall"``, the thesis text; the
       A7/A8 scripts take alpha_bed's, digest item 12.10), and the read-off time where it
       reaches -0.5, else its inflection point (:func:`drumheat.results.observe.penetration_time`);
    4. ``lambda_bed = alpha_bed^2 pi t / (4 rho_bed c_bed)`` (eq. [5.1]) at that time,
       evaluated by a run to exactly that time.

    Conventions (digest items 12.8-12.10), defaults chosen to reproduce how the thesis obtained
    lambda_bed = 0.9 W/(m K) (its A7 script):

    * ``convention="A7"``: ``alpha_ws = alpha_wp`` on ``A = d_p^2 N_w`` (the script); with
      ``"phi"``: ``alpha_ws = Phi alpha_wp`` (eq. [1.7], the text). In the DEM each wall
      contact conducts ``alpha_wp pi d_p^2 / 4`` per kelvin, i.e. ``(pi/4) alpha_wp ~ Phi
      alpha_wp`` on the A7 area, so ``"phi"`` is the physically consistent split and gives a
      larger lambda_bed (about 25 % at alpha_pp = 57); ``"A7"`` attributes part of the wall
      resistance to the bed.
    * ``slope_of="overall"``: the slope of alpha_bed depends at short times on the alpha_ws
      subtracted (it falls through -0.5 within seconds for ``"phi"`` as an artefact of the
      subtraction), while alpha_overall's slope does not depend on the convention at all.
    * ``rho_bed = 1230`` kg/m3, the value hard-coded in A7/A8 (Table 5-2 lists 1325-1375 for
      the packings, Ch. 5.4 uses 1274); lambda_bed scales with 1/rho_bed.

    Parameters
    ----------
    scene : Scene or str
        A wall-heating scene with ``[heat.contact]`` (model "constant") and ``[heat.wall]``,
        e.g. ``"weigler-glass-wall"``; ``run.duration`` sets the end of the time grid.
    alpha_pp_values : sequence of float
        Two or more alpha_pp, W/(m2 K).
    rho_bed : float
        Bulk density of eq. [5.1], kg/m3.
    c_bed : float, optional
        Heat capacity of eq. [5.1], J/(kg K); default: the particles' capacity-weighted mean c.
    convention : {"A7", "phi"}
    phi : float
        Phi of eq. [1.7] for ``convention="phi"``.
    slope_of : {"overall", "bed"}
    n_times : int
        Number of log-spaced times from ``t_min`` to ``run.duration`` (A7 uses log spacing;
        its 10 points are too coarse for a slope, digest item 12.13).
    t_min : float
        First time of the grid, s.
    t_range, which, smooth :
        Passed to :func:`drumheat.results.observe.penetration_time`.
    through_origin : bool
        Fit the line through the origin.

    Returns
    -------
    LambdaBedCalibration
        The line, the points (time used and criterion for each), the conventions used, a
        linearity check at fixed time, and the inverse :meth:`LambdaBedCalibration.alpha_pp`.
    """
    scene = scene if isinstance(scene, Scene) else load_scene(scene)
    if scene.heat.contact is None or scene.heat.contact.model != "constant":
        raise ValueError("calibrate_lambda_bed: the scene needs [heat.contact] with model = "
                         "'constant' (alpha_pp is varied)")
    if scene.heat.wall is None:
        raise ValueError("calibrate_lambda_bed: the scene needs [heat.wall] (wall heating)")
    if scene.motion.model != "static":
        raise ValueError("calibrate_lambda_bed: the A7 procedure heats a resting packing; use "
                         "motion.model = 'static'")
    values = [float(a) for a in alpha_pp_values]
    if len(values) < (1 if through_origin else 2):
        raise ValueError("calibrate_lambda_bed: a line needs two or more alpha_pp values")
    if convention not in ("A7", "phi") or slope_of not in ("overall", "bed"):
        raise ValueError("calibrate_lambda_bed: convention must be 'A7' or 'phi', slope_of "
                         "'overall' or 'bed'")
    a_wp = float(scene.heat.wall.alpha)
    alpha_ws = a_wp if convention == "A7" else phi * a_wp
    times = np.concatenate([[0.0], np.geomspace(t_min, scene.run.duration, n_times)])
    ctx = _LambdaContext(scene, rho_bed, None, alpha_ws, slope_of, times, t_range, which,
                         smooth)
    if c_bed is None:
        p = ctx.motion.model()[0].particles
        c_bed = float(jnp.sum(p.capacity) / jnp.sum(p.mass))
    ctx.c_bed = c_bed
    points = [ctx.point(a) for a in values]
    line = observe.calibration_line([p.alpha_pp for p in points],
                                    [p.lambda_bed for p in points], through_origin)
    prop = {}
    if len(points) >= 2:
        t_fix = points[0].time
        l1, _ = ctx.lambda_at(points[0].alpha_pp, t_fix, derivative=False)
        l2, _ = ctx.lambda_at(points[1].alpha_pp, t_fix, derivative=False)
        prop = dict(time=t_fix, ratio=(l2 / l1) / (points[1].alpha_pp / points[0].alpha_pp))
    return LambdaBedCalibration(line=line, points=points, rho_bed=rho_bed, c_bed=c_bed,
                                alpha_ws=alpha_ws, convention=convention, slope_of=slope_of,
                                area=ctx.area, n_wall_contacts=ctx.n_wall, proportional=prop,
                                _ctx=ctx)
