"""Figures (matplotlib): mean temperatures, temperature distributions, overall coefficient,
drum snapshots and contact networks.

Every ``plot_*`` function returns a :class:`matplotlib.figure.Figure` and takes an optional
``ax`` (one Axes, or a pair of Axes for the two-panel figures) so that figures can be composed
in a notebook. :func:`save_figures` writes a run's standard PNGs (what ``drumheat run`` puts
into the result folder).

The figures accept a :class:`drumheat.runner.Result`, and the snapshot and contact-network
figures also a result folder (path) or a :class:`ParticleFrames` read from one with
:func:`read_particles`, so a finished run can be drawn without re-running it.

Temperatures are shown in degC with kelvin on a secondary axis; times in s or min as the axis
label says; lengths in m.

Walls are drawn from plain *wall descriptions* (see :func:`draw_walls`): a circle for a
cylinder (drum shell, inner cylinder, tube) and a line segment for a plate. The drum shell of a
scene is :func:`scene_walls`; internals can be added to that list as they come.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import matplotlib

matplotlib.use("Agg") if matplotlib.get_backend().lower() == "agg" else None
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from drumheat.assemble import conduction_gaps  # noqa: E402
from drumheat.mechanics.analysis import PARTICLE_MECHANICS  # noqa: E402
from drumheat.results import observe  # noqa: E402

#: 0 degC in K.
C0 = 273.15

#: Colour map of particle temperatures (cold blue, warm red).
TEMPERATURE_CMAP = "coolwarm"


class ResultFolderError(FileNotFoundError):
    """A result folder is missing, or lacks the files or arrays a tool needs.

    A subclass of :class:`FileNotFoundError`, so the ``drumheat`` command reports it as bad
    input (exit code 2) with its one-paragraph message.
    """


# ---------------------------------------------------------------------------------------------
# Particle frames: a Result or a result folder, in one shape
# ---------------------------------------------------------------------------------------------


@dataclass
class ParticleFrames:
    """Particle data at the output times, from a result folder or a :class:`Result`.

    Attributes
    ----------
    t : ndarray (n_out,)
        Output times, s.
    T : ndarray (n_out, N)
        Particle temperatures, K.
    position : ndarray (n_out, N, dim)
        Particle centres, m (a resting bed's positions are repeated at every output).
    diameter : ndarray (N,)
        Particle diameters, m.
    group : ndarray of int (N,)
        Group index of every particle.
    group_names : list of str
        Group names, indexed by ``group``.
    scene : Scene or None
        The scene (from ``scene.toml``), None if the folder has none.
    name : str
        Scene name (or the folder name).
    mechanics : dict
        Per-particle mechanics at the output times where the run had a DEM (``velocity``,
        ``angular_velocity``, ``force``, ``coordination``, ``wall_contacts``, see
        :func:`drumheat.mechanics.analysis.particle_mechanics`; NaN at replayed outputs);
        empty otherwise.
    """

    t: np.ndarray
    T: np.ndarray
    position: np.ndarray
    diameter: np.ndarray
    group: np.ndarray
    group_names: list
    scene: Any = None
    name: str = ""
    mechanics: dict = field(default_factory=dict)

    @property
    def dim(self) -> int:
        """Spatial dimension of the positions (2 or 3)."""
        return int(self.position.shape[-1])

    @property
    def drum_diameter(self) -> float | None:
        """Inner drum diameter from the scene, m (None without a scene)."""
        if self.scene is None or self.scene.drum is None:
            return None
        return float(self.scene.drum.diameter)

    @classmethod
    def from_result(cls, result) -> "ParticleFrames":
        """The frames of a :class:`drumheat.runner.Result`."""
        traj = result.trajectory
        return cls(t=np.asarray(traj.t, float), T=np.asarray(traj.T, float),
                   position=_positions_per_frame(traj.position, len(traj.t)),
                   diameter=np.asarray(traj.diameter, float),
                   group=np.asarray(traj.group, int),
                   group_names=[g.name for g in result.scene.groups], scene=result.scene,
                   name=result.scene.name, mechanics=dict(traj.mechanics))


def _positions_per_frame(position, n_out) -> np.ndarray:
    position = np.asarray(position, float)
    if position.ndim == 2:  # one packing for all outputs
        position = position[None]
    if position.shape[0] == 1 and n_out > 1:
        position = np.broadcast_to(position, (n_out,) + position.shape[1:])
    if position.shape[0] != n_out:
        raise ResultFolderError(f"positions are given at {position.shape[0]} times but "
                                f"temperatures at {n_out}; write the results again")
    return position


def read_particles(result_dir) -> ParticleFrames:
    """Read ``particles.npz`` (and ``scene.toml``, if present) of a result folder.

    Parameters
    ----------
    result_dir : str or Path
        A folder written by ``drumheat run`` or :meth:`Result.save`.

    Returns
    -------
    ParticleFrames

    Raises
    ------
    ResultFolderError
        If the folder or ``particles.npz`` is missing, or the file lacks the arrays ``t``,
        ``T``, ``diameter`` and ``position``.
    """
    folder = Path(result_dir)
    what = ("a result folder written by 'drumheat run' (with particles.npz and scene.toml)")
    if not folder.is_dir():
        raise ResultFolderError(f"result folder '{folder}' does not exist; expected {what}")
    npz = folder / "particles.npz"
    if not npz.is_file():
        raise ResultFolderError(f"'{folder}' has no particles.npz; expected {what}. Run the "
                                "scene first, e.g. 'drumheat run weigler-static --out "
                                f"{folder}'")
    try:
        data = np.load(npz, allow_pickle=False)
        arrays = {k: data[k] for k in data.files}
    except Exception as err:  # zip or format errors
        raise ResultFolderError(f"'{npz}' cannot be read ({err}); write the results again") \
            from None
    missing = [k for k in ("t", "T", "diameter", "position") if k not in arrays]
    if missing:
        raise ResultFolderError(f"'{npz}' lacks the array(s) {', '.join(missing)}; it needs t, "
                                "T, diameter and position (write the results again with this "
                                "drumheat version)")
    t = np.atleast_1d(np.asarray(arrays["t"], float))
    scene = None
    if (folder / "scene.toml").is_file():
        import warnings

        from drumheat.scene import SceneError, load_scene

        try:
            scene = load_scene(folder / "scene.toml", check_files=False)
        except SceneError as err:  # e.g. written by another drumheat version
            warnings.warn(f"{folder / 'scene.toml'} is not a valid scene for this drumheat "
                          f"version ({err}); drawing without the drum walls", stacklevel=2)
    n = np.asarray(arrays["T"]).shape[-1]
    group = np.asarray(arrays.get("group", np.zeros(n, int)), int)
    if "group_names" in arrays:
        names = [str(s) for s in arrays["group_names"]]
    elif scene is not None:
        names = [g.name for g in scene.groups]
    else:
        names = [f"group {k}" for k in range(int(group.max()) + 1)]
    return ParticleFrames(t=t, T=np.atleast_2d(np.asarray(arrays["T"], float)),
                          position=_positions_per_frame(arrays["position"], len(t)),
                          diameter=np.asarray(arrays["diameter"], float), group=group,
                          group_names=names, scene=scene,
                          name=scene.name if scene is not None else folder.name,
                          mechanics={k: arrays[k] for k in PARTICLE_MECHANICS if k in arrays})


def as_frames(source) -> ParticleFrames:
    """:class:`ParticleFrames` from a Result, a result folder (path) or frames (unchanged)."""
    if isinstance(source, ParticleFrames):
        return source
    if isinstance(source, (str, Path)):
        return read_particles(source)
    if hasattr(source, "trajectory") and hasattr(source, "scene"):
        return ParticleFrames.from_result(source)
    raise TypeError(f"expected a Result, a result folder or ParticleFrames, got "
                    f"{type(source).__name__}")


# ---------------------------------------------------------------------------------------------
# Building blocks
# ---------------------------------------------------------------------------------------------


def _fig_ax(ax, figsize):
    if ax is not None:
        return ax.figure, ax
    return plt.subplots(figsize=figsize)


def _fig_axes2(ax, figsize, **kw):
    if ax is not None:
        axes = list(np.ravel(ax))
        if len(axes) != 2:
            raise ValueError(f"this figure has two panels; pass ax as a pair of Axes, got "
                             f"{len(axes)}")
        return axes[0].figure, axes
    fig, axes = plt.subplots(**kw, figsize=figsize)
    return fig, list(np.ravel(axes))


def _kelvin_axis(ax, which="y", side="right", label="K"):
    """A secondary axis in K beside an axis in degC."""
    funcs = (lambda c: c + C0, lambda k: k - C0)
    sec = (ax.secondary_yaxis(side, functions=funcs) if which == "y"
           else ax.secondary_xaxis(side, functions=funcs))
    sec.set_ylabel(label) if which == "y" else sec.set_xlabel(label)
    return sec


def scene_walls(scene, t: float = 0.0) -> list[dict]:
    """Wall descriptions of a scene's cross-section at time ``t`` (s), for :func:`draw_walls`.

    For now the drum shell: ``{"kind": "circle", "center": (0, 0), "radius": D/2}``. Internals
    (radial plates, inner cylinder, tubes) are appended here once the scene declares them.

    Parameters
    ----------
    scene : Scene or None
        None gives an empty list.
    t : float
        Time, s (for rotating internals).
    """
    if scene is None:
        return []
    if scene.drum is None and getattr(scene, "hopper", None) is not None:
        from drumheat.geometry.hopper import hopper_walls

        g = hopper_walls(scene.hopper)
        top = g.crest + scene.hopper.insertion_height
        xw = g.half_width
        out = [{"kind": "segment", "start": (sx * xw, scene.hopper.bottom_height),
                "end": (sx * xw, top)} for sx in (-1.0, 1.0)]
        return out + [wall_description(w) for w in g.walls[2:]]
    if scene.drum is None:
        return []
    return [{"kind": "circle", "center": (0.0, 0.0), "radius": 0.5 * float(scene.drum.diameter),
             "label": "drum shell"}]


def wall_description(wall, t: float = 0.0) -> dict:
    """Normalise one wall to a description dict (cross-section in the x-y plane).

    Accepted forms:

    * ``{"kind": "circle" | "cylinder" | "tube", "center": (x, y), "radius": r}``: a circle of
      radius ``r`` (m) about ``center`` (default the drum axis, (0, 0)).
    * ``{"kind": "segment" | "plate", "start": (x0, y0), "end": (x1, y1)}``: a line segment, m.
    * A wall object of :mod:`drumheat.geometry.walls` (``DrumShell``, ``InnerCylinder``,
      ``FixedCylinder``, ``RadialPlate`` at angle ``phase + omega t``); walls without a
      cross-section line (``EndPlate``, ``Plane``, ``Box``) are not drawn.

    Returns
    -------
    dict
        ``{"kind": "circle", "center", "radius"}`` or ``{"kind": "segment", "start", "end"}``,
        plus the optional ``"label"``; or ``{"kind": "none"}`` for a wall with no line to draw.
    """
    if isinstance(wall, dict):
        kind = str(wall.get("kind", "")).lower()
        label = wall.get("label")
        if kind in ("circle", "cylinder", "tube", "shell", "drum"):
            out = {"kind": "circle", "center": tuple(map(float, wall.get("center", (0.0, 0.0)))),
                   "radius": float(wall["radius"])}
        elif kind in ("segment", "plate", "line"):
            out = {"kind": "segment", "start": tuple(map(float, wall["start"])),
                   "end": tuple(map(float, wall["end"]))}
        else:
            raise ValueError(f"wall description {wall!r}: kind must be 'circle' (cylinder, "
                             "tube) or 'segment' (plate)")
        if label:
            out["label"] = label
        return out
    name = type(wall).__name__
    if name in ("DrumShell", "InnerCylinder"):
        return {"kind": "circle", "center": (0.0, 0.0), "radius": float(wall.radius)}
    if name == "FixedCylinder":
        return {"kind": "circle", "center": tuple(map(float, np.asarray(wall.center)[:2])),
                "radius": float(wall.radius)}
    if name == "Segment":
        return {"kind": "segment", "start": tuple(map(float, wall.a)),
                "end": tuple(map(float, wall.b))}
    if name == "RadialPlate":
        phi = float(wall.angle(t))
        e = np.array([np.cos(phi), np.sin(phi)])
        return {"kind": "segment", "start": tuple(float(wall.r_inner) * e),
                "end": tuple(float(wall.r_outer) * e)}
    return {"kind": "none"}


def draw_walls(ax, walls: Sequence, t: float = 0.0, color="0.25", lw=2.0, **kw) -> list:
    """Draw walls into a cross-section: a circle per cylinder, a line per plate.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    walls : sequence of dict or wall objects
        Wall descriptions as accepted by :func:`wall_description`, e.g.
        ``[{"kind": "circle", "radius": 0.025},
        {"kind": "segment", "start": (0.01, 0), "end": (0.025, 0)}]`` (m).
    t : float
        Time, s, for rotating wall objects.
    color, lw, **kw
        Line style passed to matplotlib.

    Returns
    -------
    list of matplotlib artists, one per drawn wall.
    """
    from matplotlib.patches import Circle

    artists = []
    for w in walls:
        d = wall_description(w, t)
        if d["kind"] == "circle":
            patch = Circle(d["center"], d["radius"], fill=False, color=color, lw=lw,
                           label=d.get("label"), **kw)
            ax.add_patch(patch)
            artists.append(patch)
        elif d["kind"] == "segment":
            (x0, y0), (x1, y1) = d["start"], d["end"]
            (line,) = ax.plot([x0, x1], [y0, y1], color=color, lw=lw, solid_capstyle="butt",
                              label=d.get("label"), **kw)
            artists.append(line)
    return artists


def _walls_extent(walls) -> float:
    r = 0.0
    for w in walls:
        d = wall_description(w)
        if d["kind"] == "circle":
            r = max(r, np.hypot(*d["center"]) + d["radius"])
        elif d["kind"] == "segment":
            r = max(r, np.hypot(*d["start"]), np.hypot(*d["end"]))
    return r


def draw_particles(ax, position, diameter, values=None, cmap=TEMPERATURE_CMAP, vmin=None,
                   vmax=None, edgecolor="k", linewidth=0.3, **kw):
    """Particles as discs to scale (diameter in data units), coloured by ``values``.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Should have an equal aspect ratio for round discs.
    position : array_like (N, >=2)
        Centres, m; x and y are used (a 3D bed is projected along the drum axis).
    diameter : array_like (N,)
        m.
    values : array_like (N,), optional
        Colour values (e.g. temperature in degC).
    vmin, vmax : float, optional
        Colour limits.

    Returns
    -------
    matplotlib.collections.EllipseCollection
        Update a frame with ``coll.set_offsets(xy)`` and ``coll.set_array(values)``.
    """
    from matplotlib.collections import EllipseCollection

    position = np.asarray(position, float)
    diameter = np.asarray(diameter, float)
    coll = EllipseCollection(diameter, diameter, np.zeros_like(diameter), units="xy",
                             offsets=position[:, :2], offset_transform=ax.transData,
                             cmap=cmap, edgecolors=edgecolor, linewidths=linewidth, **kw)
    if values is not None:
        coll.set_array(np.asarray(values, float))
        coll.set_clim(vmin, vmax)
    ax.add_collection(coll)
    return coll


def temperature_colorbar(fig, mappable, ax, label="temperature", **kw):
    """Colour bar in degC (right side, labelled) with a kelvin scale on its left side.

    The mappable must hold values in degC; a translucent mappable gets an opaque bar. Returns
    the colour bar; its kelvin axis is ``cb.kelvin_axis``.
    """
    from matplotlib.cm import ScalarMappable

    kw.setdefault("pad", 0.16)
    kw.setdefault("fraction", 0.05)
    if mappable.get_alpha() not in (None, 1.0):
        mappable = ScalarMappable(norm=mappable.norm, cmap=mappable.cmap)
    cb = fig.colorbar(mappable, ax=ax, **kw)
    cb.set_label(f"{label} / °C")
    kelvin = cb.ax.secondary_yaxis("left", functions=(lambda c: c + C0, lambda k: k - C0))
    kelvin.set_ylabel("K", labelpad=2)
    kelvin.tick_params(labelsize="small")
    cb.ax.tick_params(labelsize="small")
    cb.kelvin_axis = kelvin
    return cb


def _mm_formatter():
    from matplotlib.ticker import FuncFormatter

    return FuncFormatter(lambda v, _: f"{v * 1e3:g}")


def _plain_log_axis(axis):
    """Plain numbers (20, 50, 100) instead of powers of ten on a log axis."""
    from matplotlib.ticker import FuncFormatter, LogLocator

    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    lo, hi = axis.get_view_interval()
    if lo > 0 and np.log10(hi / lo) < 2.5:
        axis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
        axis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:g}"))


def _setup_cross_section(ax, walls, frames_position, diameter):
    ax.set_aspect("equal")
    R = _walls_extent(walls)
    if R == 0:
        p = np.asarray(frames_position)[..., :2]
        R = float(np.max(np.abs(p)) + np.max(diameter))
    ax.set_xlim(-1.04 * R, 1.04 * R)
    ax.set_ylim(-1.04 * R, 1.04 * R)
    ax.xaxis.set_major_formatter(_mm_formatter())
    ax.yaxis.set_major_formatter(_mm_formatter())
    ax.set_xlabel("x / mm")
    ax.set_ylabel("y / mm")


def format_clock(t: float) -> str:
    """Process time as ``t = 1234.5 s (20:34.5 min)``; under a minute as ``t = 12.3 s``."""
    if t < 60:
        return f"t = {t:.1f} s"
    m, s = divmod(t, 60.0)
    if m < 60:
        return f"t = {t:.0f} s ({int(m)}:{s:04.1f} min)"
    h, m = divmod(m, 60.0)
    return f"t = {t:.0f} s ({int(h)}:{int(m):02d}:{s:02.0f} h)"


# ---------------------------------------------------------------------------------------------
# Time series
# ---------------------------------------------------------------------------------------------


def _group_columns(ts):
    return [c for c in ts.columns if c.startswith("T_mean:")]


def _measured_frame(data):
    if data is None:
        return None
    if isinstance(data, (str, Path)):
        import pandas as pd

        return pd.read_csv(data)
    return data


def plot_mean_temperatures(result, ax=None, data=None):
    """Mean bed and group temperatures over time, with measured points overlaid.

    Lines are the simulation (bed mean black, groups in colour); open circles of the same
    colour are the measurement. The left axis is in degC, the right one in K.

    Parameters
    ----------
    result : Result
    ax : matplotlib.axes.Axes, optional
    data : pandas.DataFrame or path of a CSV file, optional
        Measured points: column ``t`` (s) and any of the time-series columns in K
        (``T_mean``, ``T_mean:<group>``), as :func:`drumheat.experiments.thermochromic.fraction_means`
        writes them.

    Returns
    -------
    matplotlib.figure.Figure
    """
    ts = result.timeseries
    data = _measured_frame(data)
    fig, ax = _fig_ax(ax, (6.4, 4.2))
    t_min = ts["t"] / 60.0
    ax.plot(t_min, ts["T_mean"] - C0, "k-", lw=2, label="all particles")
    n_measured = 0
    for k, col in enumerate(_group_columns(ts)):
        ax.plot(t_min, ts[col] - C0, f"C{k}-", lw=1.5, label=col.split(":", 1)[1])
        if data is not None and col in data:
            ax.plot(data["t"] / 60.0, data[col] - C0, f"C{k}o", mfc="none", ms=5)
            n_measured += 1
    if data is not None and "T_mean" in data:
        ax.plot(data["t"] / 60.0, data["T_mean"] - C0, "ko", mfc="none", ms=5)
        n_measured += 1
    if n_measured:
        ax.plot([], [], "o", color="0.4", mfc="none", label="measured")
    ax.set_xlabel("time / min")
    ax.set_ylabel("temperature / °C")
    ax.set_title(f"{result.scene.name}: mean temperatures")
    _kelvin_axis(ax)
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    fig.tight_layout()
    return fig


def pick_times(t, n=4):
    """``n`` output indices spread over a run (first, log-spaced middle ones, last)."""
    t = np.asarray(t)
    if len(t) <= n:
        return list(range(len(t)))
    targets = np.geomspace(max(t[1], 1e-9), t[-1], n - 1)
    idx = [0] + [int(np.argmin(np.abs(t - x))) for x in targets]
    return sorted(set(idx))


def nearest_indices(t, times) -> list[int]:
    """Indices of the outputs nearest to the requested ``times`` (s), in the order given."""
    t = np.asarray(t, float)
    return [int(np.argmin(np.abs(t - float(x)))) for x in np.atleast_1d(times)]


def plot_distributions(result, times_index=None, width=1.0, times=None, ax=None):
    """Number-density q0 and cumulative Q0 particle-temperature distributions at chosen times.

    Classes of ``width`` K (1 K as in the thesis, weigler-thermal-dem.md section 8) on whole
    degC; q0 (1/K) as steps on the left, Q0 (-) at the class edges on the right.

    Parameters
    ----------
    result : Result
    times_index : sequence of int, optional
        Output indices; default :func:`pick_times` (first, log-spaced, last).
    width : float
        Class width, K.
    times : sequence of float, optional
        Times, s, instead of ``times_index`` (the nearest outputs are used).
    ax : pair of Axes, optional
        (q0 axes, Q0 axes).

    Returns
    -------
    matplotlib.figure.Figure
    """
    traj = result.trajectory
    if times is not None:
        idx = nearest_indices(traj.t, times)
    else:
        idx = pick_times(traj.t) if times_index is None else list(times_index)
    T = np.asarray(traj.T)[idx] - C0
    dist = observe.temperature_distribution(T, width=width)
    edges = np.asarray(dist.edges)
    fig, (a0, a1) = _fig_axes2(ax, (10, 4), ncols=2)
    for k, i in enumerate(idx):
        label = f"t = {traj.t[i] / 60:.3g} min"
        a0.stairs(np.asarray(dist.q0)[k], edges, color=f"C{k}", lw=1.5, label=label)
        a1.plot(edges, np.asarray(dist.Q0)[k], color=f"C{k}", marker=".", ms=3, label=label)
    a0.set_xlabel("temperature class / °C")
    a0.set_ylabel(f"q0 / (1/K)   ({width:g} K classes)")
    a1.set_xlabel("temperature / °C")
    a1.set_ylabel("Q0 / -")
    a1.set_ylim(-0.02, 1.02)
    for a in (a0, a1):
        a.grid(alpha=0.3)
        a.legend(fontsize="small")
    fig.suptitle(f"{result.scene.name}: particle temperature distributions")
    fig.tight_layout()
    return fig


def plot_alpha_overall(result, ax=None, smooth=None):
    """Overall wall-to-bed coefficient (weigler eq. [1.10]) and its log-log slope over time.

    Top: alpha_overall, W/(m2 K), on log-log axes. Bottom: ``d ln alpha / d ln t``
    (:func:`drumheat.results.observe.log_slope`) on a log time axis, with the ideal penetration
    regime -0.5 marked.

    Parameters
    ----------
    result : Result
        Needs the ``alpha_overall`` column (scenes with ``[heat.wall]``).
    ax : pair of Axes, optional
    smooth : float, optional
        Smoothing width of the slope, decades of t.

    Returns
    -------
    matplotlib.figure.Figure
    """
    ts = result.timeseries
    if "alpha_overall" not in ts:
        raise ValueError(f"{result.scene.name}: no alpha_overall in the time series; it needs "
                         "a heated wall ([heat.wall] and drum.wall_temperature)")
    t, a = ts["t"].to_numpy(), ts["alpha_overall"].to_numpy()
    ok = (t > 0) & np.isfinite(a) & (a > 0)
    fig, (a0, a1) = _fig_axes2(ax, (6.4, 6), nrows=2, sharex=True)
    a0.loglog(t[ok], a[ok], "C0-", marker=".", ms=3)
    a0.set_ylabel("alpha_overall / (W/(m² K))")
    a0.grid(alpha=0.3, which="both")
    a1.set_xscale("log")
    if ok.sum() > 2:
        slope = np.asarray(observe.log_slope(t[ok], a[ok], smooth=smooth))
        a1.plot(t[ok], slope, "C1-", marker=".", ms=3, label="slope")
    a1.axhline(-0.5, color="k", ls=":", lw=1, label="penetration regime (-0.5)")
    if ok.sum() > 4:
        pt = observe.penetration_time(t[ok], a[ok], smooth=smooth)
        if np.isfinite(pt.time):
            for a_ in (a0, a1):
                a_.axvline(pt.time, color="C2", ls="--", lw=1)
            a1.plot([], [], "C2--", lw=1,
                    label=f"read-off ({pt.criterion}): t = {pt.time:.3g} s")
    a1.legend(fontsize="small")
    a1.set_ylabel("d ln alpha / d ln t")
    a1.set_xlabel("time / s")
    a1.grid(alpha=0.3, which="both")
    _plain_log_axis(a0.yaxis)
    _plain_log_axis(a1.xaxis)
    fig.suptitle(f"{result.scene.name}: overall heat-transfer coefficient")
    fig.tight_layout()
    return fig


def plot_drum_wall(result, times=None, ax=None):
    """The drum wall's segment temperatures (``[heat.drum_wall]``).

    Left: temperature of every segment against its angle in the drum's own frame (segment k
    spans ``[k, k + 1) x 360/n_seg`` degrees from +x at t = 0) at a few times
    (:func:`pick_times`, or the outputs nearest to ``times``, s). Right: the segments' mean,
    minimum and maximum and the bed's mean temperature over time.

    Returns
    -------
    matplotlib.figure.Figure
    """
    w = result.trajectory.drum_wall
    if not w:
        raise ValueError(f"{result.scene.name}: no drum wall with heat capacity in this run; "
                         "it needs [heat.drum_wall]")
    t, Tw = result.t, np.asarray(w["T"])
    n = Tw.shape[1]
    idx = pick_times(t) if times is None else nearest_indices(t, times)
    fig, (a0, a1) = _fig_axes2(ax, (11, 4.2), ncols=2)
    centre = (np.arange(n) + 0.5) * 360.0 / n
    for k, i in enumerate(idx):
        a0.step(np.append(centre - 180.0 / n, 360.0), np.append(Tw[i], Tw[i][-1]), where="post",
                color=f"C{k % 10}", label=format_clock(t[i]))
    a0.set_xlabel("segment angle in the drum frame / deg")
    a0.set_ylabel("wall temperature / K")
    a0.set_xlim(0, 360)
    a0.legend(fontsize="small")
    a0.grid(alpha=0.3)
    ts = result.timeseries
    a1.plot(t, ts["T_wall_mean"], "C3-", label="wall, mean of segments")
    a1.fill_between(t, ts["T_wall_min"], ts["T_wall_max"], color="C3", alpha=0.2,
                    label="wall, min-max of segments")
    a1.plot(t, ts["T_mean"], "C0-", label="bed, mean")
    a1.set_xlabel("time / s")
    a1.set_ylabel("temperature / K")
    a1.legend(fontsize="small")
    a1.grid(alpha=0.3)
    fig.suptitle(f"{result.scene.name}: drum wall ({n} segments)")
    fig.tight_layout()
    return fig


# ---------------------------------------------------------------------------------------------
# Cross-sections
# ---------------------------------------------------------------------------------------------


def cross_section(frames: ParticleFrames, index: int):
    """The particles a cross-section figure draws at output ``index``: ``(xy (M, 2) m,
    diameter (M,) m, temperature (M,) degC, note)``. In 2D all particles (note ""); in 3D the
    slice through the middle of the drum's depth, the particles whose centres lie within half
    a diameter of the mid-plane (those the plane cuts), with a note saying how many. After
    ``dem.replay_after`` the note says that the positions are those of the replayed recording
    (the bed then moves through the recorded cycle again; the temperatures are the frame's)."""
    pos, d = np.asarray(frames.position[index]), np.asarray(frames.diameter)
    T_C = np.asarray(frames.T[index]) - C0
    replay = _replay_note(frames, float(frames.t[index]))
    if pos.shape[1] != 3:
        return pos, d, T_C, replay
    z = pos[:, 2]
    depth = getattr(getattr(frames.scene, "drum", None), "depth", None)
    z_mid = 0.5 * depth if depth else 0.5 * (z.min() + z.max())
    cut = np.abs(z - z_mid) <= 0.5 * d
    note = f"slice at mid-depth: {int(np.sum(cut))} of {len(cut)} particles"
    return pos[cut][:, :2], d[cut], T_C[cut], note + (f"\n{replay}" if replay else "")


def _replay_note(frames: ParticleFrames, t: float) -> str:
    """What a frame's positions are after ``dem.replay_after``: those of the replayed cycle of
    the recording (the temperatures are the frame's own), or "" before it / without replay."""
    dem = frames.scene.dem if frames.scene is not None else None
    if dem is None or dem.replay_after is None or t <= dem.replay_after + 1e-9:
        return ""
    after = dem.replay_after
    return f"positions replayed from {after - dem.replayed_cycle:.3g}-{after:.3g} s"


def plot_snapshot(result, index=-1, ax=None, vmin=None, vmax=None, walls=None, colorbar=True):
    """The drum cross-section with particles to scale, coloured by temperature (degC and K).

    A 3D result shows the slice through the middle of the drum's depth: the particles whose
    centres lie within half a diameter of the mid-plane (those the plane cuts), so that the
    bed's inside is seen rather than a projection of all particles on top of each other.

    Parameters
    ----------
    result : Result, result folder or ParticleFrames
    index : int
        Output index.
    ax : matplotlib.axes.Axes, optional
    vmin, vmax : float, optional
        Colour limits, degC; default the range over the whole run (comparable snapshots).
    walls : sequence, optional
        Wall descriptions (:func:`draw_walls`); default :func:`scene_walls` (the drum shell).
    colorbar : bool
        Add the temperature colour bar.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fr = as_frames(result)
    fig, ax = _fig_ax(ax, (6.0, 5.0))
    walls = scene_walls(fr.scene, fr.t[index]) if walls is None else list(walls)
    T_C = fr.T - C0
    vmin = float(np.min(T_C)) if vmin is None else vmin
    vmax = float(np.max(T_C)) if vmax is None else vmax
    if vmax <= vmin:
        vmin, vmax = vmin - 0.5, vmax + 0.5
    pos, d, T_i, note = cross_section(fr, index)
    title = f"{fr.name}, {format_clock(float(fr.t[index]))}" + (f"\n{note}" if note else "")
    coll = draw_particles(ax, pos, d, T_i, vmin=vmin, vmax=vmax)
    draw_walls(ax, walls, t=float(fr.t[index]))
    _setup_cross_section(ax, walls, pos, d)
    ax.set_title(title)
    if colorbar:
        temperature_colorbar(fig, coll, ax)
    return fig


def contact_heat_flows(frames, pairs, index=-1, alpha_pp=None):
    """Heat flow through every particle-particle contact, W (weigler eq. [2.7]).

    ``Q_ij = alpha_pp A_p (T_i - T_j)`` from i to j, with ``A_p = pi d^2 / 4`` of the smaller
    particle (as :func:`drumheat.thermal.contact.pair_area`).

    Parameters
    ----------
    frames : ParticleFrames, Result or result folder
    pairs : array_like (P, 2)
    index : int
        Output index.
    alpha_pp : float, optional
        W/(m2 K); default from the scene's ``[heat.contact]`` (0 without that effect).

    Returns
    -------
    ndarray (P,)
    """
    fr = as_frames(frames)
    pairs = np.asarray(pairs, int).reshape(-1, 2)
    if alpha_pp is None:
        alpha_pp = contact_alpha(fr.scene)
    T = fr.T[index]
    i, j = pairs.T
    area = 0.25 * np.pi * np.minimum(fr.diameter[i], fr.diameter[j]) ** 2
    return alpha_pp * area * (T[i] - T[j])


def contact_alpha(scene) -> float:
    """alpha_pp of a scene, W/(m2 K): the constant, the Schluender value, or 0 without
    ``[heat.contact]``."""
    cfg = None if scene is None else scene.heat.contact
    if cfg is None:
        return 0.0
    if cfg.model == "constant":
        return float(cfg.alpha)
    from drumheat.materials import gas
    from drumheat.models import schluender

    n = sum(g.count for g in scene.groups)
    d = sum(g.count * g.diameter for g in scene.groups) / n
    if scene.gas is not None:
        g = gas(scene.gas.material)
        T, p = scene.gas.temperature, scene.gas.pressure
        lam = scene.gas.conductivity or g.conductivity
    else:
        g, T, p = gas("air"), 303.15, 101325.0
        lam = g.conductivity
    _, a_pp = schluender.contact_coefficients(d, T=T, p=p, conductivity=lam,
                                              heat_capacity=g.heat_capacity,
                                              molar_mass=g.molar_mass,
                                              C=g.accommodation_constant)
    return float(a_pp)


def plot_contact_network(result, index=-1, pairs=None, color_by="heat_flow", ax=None,
                         alpha_pp=None, tolerance=None, walls=None, cmap="viridis"):
    """The contact network: particles (by temperature) and a segment per contact.

    Each segment joins two touching centres and is coloured by the magnitude of the heat flow
    through it (``color_by="heat_flow"``, W; weigler eq. [2.7]) or of the temperature
    difference across it (``color_by="dT"``, K). Contacts come from
    :func:`drumheat.thermal.network.find_contacts_2d_drum` at the chosen output (with the
    scene's ``heat.contact.gap_tolerance``) unless ``pairs`` are given.

    Parameters
    ----------
    result : Result, result folder or ParticleFrames
    index : int
        Output index.
    pairs : array_like (P, 2), optional
        Particle index pairs of the contacts.
    color_by : {"heat_flow", "dT"}
    ax : matplotlib.axes.Axes, optional
    alpha_pp : float, optional
        W/(m2 K) for the heat flows; default from the scene.
    tolerance : float, optional
        Gap tolerance for finding contacts (fraction of the smaller diameter).
    walls : sequence, optional
        Wall descriptions; default the drum shell.
    cmap : str
        Colour map of the segments.

    Returns
    -------
    matplotlib.figure.Figure
        ``fig.contact_pairs`` holds the pairs drawn.
    """
    from matplotlib.collections import LineCollection

    if color_by not in ("heat_flow", "dT"):
        raise ValueError(f"color_by = {color_by!r}; allowed: 'heat_flow', 'dT'")
    fr = as_frames(result)
    pos = fr.position[index]
    if pairs is None:
        from drumheat.thermal.network import find_contacts_2d_drum

        if fr.drum_diameter is None:
            raise ValueError("no scene to find contacts in; pass pairs=")
        tol = tolerance if tolerance is not None else conduction_gaps(fr.scene)[0]
        pairs, _ = find_contacts_2d_drum(pos, fr.diameter, fr.drum_diameter, tol)
    pairs = np.asarray(pairs, int).reshape(-1, 2)
    fig, ax = _fig_ax(ax, (6.2, 6.2))
    walls = scene_walls(fr.scene, fr.t[index]) if walls is None else list(walls)
    T_C = fr.T - C0
    coll = draw_particles(ax, pos, fr.diameter, T_C[index], vmin=float(T_C.min()),
                          vmax=max(float(T_C.max()), float(T_C.min()) + 1e-9), alpha=0.45,
                          linewidth=0.2)
    draw_walls(ax, walls, t=float(fr.t[index]))
    i, j = pairs.T
    if color_by == "heat_flow":
        values = np.abs(contact_heat_flows(fr, pairs, index, alpha_pp))
        label = "|heat flow| per contact / W"
    else:
        values = np.abs(fr.T[index][i] - fr.T[index][j])
        label = "|temperature difference| / K"
    segs = np.stack([pos[i, :2], pos[j, :2]], axis=1) if len(pairs) else np.zeros((0, 2, 2))
    lw = 2.0 if len(fr.diameter) <= 150 else 1.2
    lines = LineCollection(segs, cmap=cmap, linewidths=lw, capstyle="round")
    lines.set_array(values)
    if len(values):
        lines.set_clim(0.0, max(float(values.max()), 1e-12))
    ax.add_collection(lines)
    _setup_cross_section(ax, walls, fr.position, fr.diameter)
    ax.set_title(f"{fr.name}: {len(pairs)} contacts, {format_clock(float(fr.t[index]))}")
    cb = fig.colorbar(lines, ax=ax, location="bottom", pad=0.13, fraction=0.05, aspect=40)
    cb.set_label(label)
    cb.formatter.set_powerlimits((-2, 3))
    cb.ax.tick_params(labelsize="small")
    temperature_colorbar(fig, coll, ax, label="particle temperature")
    fig.contact_pairs = pairs
    return fig


# ---------------------------------------------------------------------------------------------
# The standard set
# ---------------------------------------------------------------------------------------------

#: the figures :func:`plot` draws, by name
FIGURES = {
    "mean_temperatures": plot_mean_temperatures,
    "distributions": plot_distributions,
    "alpha_overall": plot_alpha_overall,
    "snapshot": plot_snapshot,
    "contact_network": plot_contact_network,
    "drum_wall": plot_drum_wall,
}


def plot(result, kind: str = "mean_temperatures", **kwargs):
    """A figure of a run: ``drumheat.plot(result)``, ``drumheat.plot(result, "snapshot")``.

    Parameters
    ----------
    result : Result, or a result folder (path) for ``"snapshot"`` and ``"contact_network"``
    kind : str
        One of ``"mean_temperatures"`` (default), ``"distributions"``, ``"alpha_overall"``,
        ``"snapshot"``, ``"contact_network"``, ``"drum_wall"`` (:data:`FIGURES`).
    **kwargs
        Passed to the ``plot_<kind>`` function (e.g. ``ax``, ``index``, ``data``).

    Returns
    -------
    matplotlib.figure.Figure
    """
    if kind not in FIGURES:
        import difflib

        close = difflib.get_close_matches(kind, FIGURES, n=1)
        raise ValueError(f"unknown figure {kind!r}" + (f" (did you mean {close[0]!r}?)" if close
                                                        else "") + "; figures: "
                         + ", ".join(FIGURES))
    return FIGURES[kind](result, **kwargs)


#: file formats :func:`save_figures` writes (matplotlib's savefig formats)
FIGURE_FORMATS = ("png", "pdf", "svg")


def save_figures(result, folder, formats=("png",), dpi: int = 120) -> list[Path]:
    """Write the standard figures of a run into ``folder``.

    Parameters
    ----------
    result : Result
    folder : path
    formats : sequence of str
        Any of :data:`FIGURE_FORMATS`; PDF and SVG are vector formats for papers.
    dpi : int
        Resolution of the PNG files (300 for print).
    """
    bad = [f for f in formats if f not in FIGURE_FORMATS]
    if bad or not formats:
        raise ValueError(f"figure formats must be among {FIGURE_FORMATS}, got {list(formats)}")
    folder = Path(folder)
    out = []
    # each figure is drawn, written and closed before the next: one figure in memory at a time
    figs = {"mean_temperatures": plot_mean_temperatures,
            "temperature_distributions": plot_distributions}
    if "alpha_overall" in result.timeseries:
        figs["alpha_overall"] = plot_alpha_overall
    if result.trajectory.drum_wall:
        figs["drum_wall"] = plot_drum_wall
    if result.scene.dim == 2 or (result.scene.drum is not None
                                 and result.scene.motion.model in ("dem", "replay")):
        figs["snapshot_final"] = lambda r: plot_snapshot(r, -1)  # 3D: the mid-depth slice
    for name, draw in figs.items():
        fig = draw(result)
        for fmt in formats:
            fig.savefig(folder / f"{name}.{fmt}", dpi=dpi, bbox_inches="tight")  # long titles
            out.append(folder / f"{name}.{fmt}")
        plt.close(fig)
    return out
