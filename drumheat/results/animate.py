"""Animations of a finished run: the drum cross-section coloured by temperature, with a clock.

Made from a result folder (``particles.npz`` and ``scene.toml``, as ``drumheat run`` writes
them), one frame per output time::

    from drumheat.results.animate import animate
    animate("results/weigler-static")                      # -> results/weigler-static/animation.gif
    animate("results/weigler-static", "eq.mp4", fps=20)    # MP4 needs imageio-ffmpeg

or on the command line: ``drumheat animate results/weigler-static --fps 20``.

GIF files are written with Pillow (always available with matplotlib). MP4 files need an
``ffmpeg`` executable: the one shipped by the ``imageio-ffmpeg`` package
(``pip install imageio-ffmpeg``, or ``pip install drumheat[video]``) or one on the PATH.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

FORMATS = ("gif", "mp4")


class AnimationError(RuntimeError):
    """An animation cannot be written (unknown format, no ffmpeg for MP4)."""


def _ffmpeg_path() -> str:
    try:
        import imageio_ffmpeg
    except ImportError:
        exe = shutil.which("ffmpeg")
        if exe:
            return exe
        raise AnimationError("MP4 output needs ffmpeg, which was not found: install it with "
                             "'pip install imageio-ffmpeg' (or 'pip install drumheat[video]'), "
                             "or write a GIF instead (fmt='gif', or --out FILE.gif on the "
                             "command line)") from None
    return imageio_ffmpeg.get_ffmpeg_exe()


def _format(out, fmt) -> str:
    suffix = Path(out).suffix.lower().lstrip(".") if out is not None else ""
    if fmt is None:
        fmt = suffix if suffix else "gif"
    fmt = str(fmt).lower().lstrip(".")
    if fmt not in FORMATS:
        raise AnimationError(f"animation format {fmt!r} is not supported; allowed: "
                             + ", ".join(repr(f) for f in FORMATS))
    if suffix and suffix != fmt:
        raise AnimationError(f"output file '{out}' does not end in .{fmt}; name it *.{fmt} or "
                             f"ask for format {suffix!r}")
    return fmt


def _register(result_dir, path: Path) -> None:
    """Record ``path`` in the result folder's manifest when it lies directly inside it."""
    from drumheat.results.files import register_outputs

    if Path(path).resolve().parent == Path(result_dir).resolve():
        register_outputs(result_dir, [Path(path).name])


def animate(result_dir, out=None, fps: float = 10, fmt: str | None = None, dpi: int = 100,
            every: int = 1, vmin: float | None = None, vmax: float | None = None) -> Path:
    """Write an animation of a run: particles to scale, coloured by temperature, and a clock.

    Parameters
    ----------
    result_dir : str or Path
        Result folder with ``particles.npz`` (``t``, ``T``, ``diameter``, ``position``) and
        ``scene.toml`` (for the drum diameter; without it the view is fitted to the particles
        and no shell is drawn).
    out : str or Path, optional
        Output file; default ``<result_dir>/animation.<fmt>``.
    fps : float
        Frames per second; one frame per output time.
    fmt : {"gif", "mp4"}, optional
        File format; default from the suffix of ``out``, else ``"gif"``.
    dpi : int
        Resolution of the frames, dots per inch (a 6 x 5 inch figure).
    every : int
        Use every ``every``-th output time (1 = all).
    vmin, vmax : float, optional
        Colour limits, degC; default the temperature range of the whole run (fixed over
        the frames).

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    drumheat.results.plot.ResultFolderError
        Missing folder, ``particles.npz`` or arrays (a :class:`FileNotFoundError`).
    AnimationError
        Unknown format, or MP4 requested without ffmpeg.
    """
    import matplotlib

    matplotlib.use("Agg") if matplotlib.get_backend().lower() == "agg" else None
    import matplotlib.pyplot as plt
    from matplotlib import animation

    from drumheat.results import plot

    frames = plot.read_particles(result_dir)
    fmt = _format(out, fmt)
    if not fps > 0:
        raise AnimationError(f"fps = {fps!r}; must be a number > 0")
    if int(every) < 1:
        raise AnimationError(f"every = {every!r}; must be an integer >= 1")
    out = Path(out) if out is not None else Path(result_dir) / f"animation.{fmt}"
    if fmt == "mp4":
        writer = animation.FFMpegWriter(fps=fps, codec="libx264",
                                        extra_args=["-pix_fmt", "yuv420p"])
        matplotlib.rcParams["animation.ffmpeg_path"] = _ffmpeg_path()
    else:
        writer = animation.PillowWriter(fps=fps)

    idx = np.arange(0, len(frames.t), int(every))
    fig = plot.plot_snapshot(frames, index=int(idx[0]), vmin=vmin, vmax=vmax)
    ax = fig.axes[0]
    coll = next(c for c in ax.collections if hasattr(c, "set_offsets"))
    title = ax.title
    clock = ax.text(0.02, 0.97, "", transform=ax.transAxes, ha="left", va="top",
                    family="monospace", fontsize="medium",
                    bbox=dict(boxstyle="round", fc="white", ec="0.6", alpha=0.85))
    title.set_text(frames.name)

    three_d = frames.position.shape[-1] == 3
    if three_d:
        vmin = float(np.min(frames.T) - plot.C0) if vmin is None else vmin
        vmax = float(np.max(frames.T) - plot.C0) if vmax is None else vmax

    def draw(k):
        nonlocal coll
        i = int(idx[k])
        pos, d, T_C, note = plot.cross_section(frames, i)
        if three_d:  # the mid-depth slice: which particles it cuts changes from frame to frame
            coll.remove()
            coll = plot.draw_particles(ax, pos, d, T_C, vmin=vmin, vmax=vmax)
        else:
            coll.set_offsets(pos)
            coll.set_array(T_C)
        title.set_text(f"{frames.name}\n{note}" if note else frames.name)
        clock.set_text(plot.format_clock(float(frames.t[i])))

    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.stem}.partial{out.suffix}")
    try:
        with writer.saving(fig, str(tmp), dpi):
            for k in range(len(idx)):
                draw(k)
                writer.grab_frame()
        tmp.replace(out)
        _register(result_dir, out)
    except FileNotFoundError as err:  # ffmpeg executable vanished
        raise AnimationError(f"could not run ffmpeg ({err}); write a GIF instead") from None
    finally:
        tmp.unlink(missing_ok=True)
        plt.close(fig)
    return out
