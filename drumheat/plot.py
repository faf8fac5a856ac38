"""Figures (matplotlib): mean temperatures, temperature distributions, overall coefficient,
drum snapshots. Every function returns a Figure; :func:`save_figures` writes a run's PNGs.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg") if matplotlib.get_backend().lower() == "agg" else None
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from drumheat import observe  # noqa: E402

C0 = 273.15


def _group_columns(ts):
    return [c for c in ts.columns if c.startswith("T_mean:")]


def plot_mean_temperatures(result, ax=None, data=None):
    """Mean bed and group temperatures over time (degC, with K on the right axis).

    Parameters
    ----------
    result : Result
    data : pandas.DataFrame, optional
        Measured points to overlay: column ``t`` and any of the time-series columns.
    """
    ts = result.timeseries
    fig, ax = (ax.figure, ax) if ax is not None else plt.subplots(figsize=(6.4, 4.2))
    t_min = ts["t"] / 60.0
    ax.plot(t_min, ts["T_mean"] - C0, "k-", lw=2, label="all particles")
    for k, col in enumerate(_group_columns(ts)):
        ax.plot(t_min, ts[col] - C0, f"C{k}-", lw=1.5, label=col.split(":", 1)[1])
        if data is not None and col in data:
            ax.plot(data["t"] / 60.0, data[col] - C0, f"C{k}o", mfc="none")
    if data is not None and "T_mean" in data:
        ax.plot(data["t"] / 60.0, data["T_mean"] - C0, "ko", mfc="none", label="measured")
    ax.set_xlabel("time / min")
    ax.set_ylabel("temperature / °C")
    ax.set_title(f"{result.scene.name}: mean temperatures")
    sec = ax.secondary_yaxis("right", functions=(lambda c: c + C0, lambda k: k - C0))
    sec.set_ylabel("K")
    ax.grid(alpha=0.3)
    ax.legend()
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


def plot_distributions(result, times_index=None, width=1.0):
    """Number-density q0 and cumulative Q0 temperature distributions (1 K classes, as in the
    thesis, weigler-thermal-dem.md section 8) at a few output times."""
    traj = result.trajectory
    idx = pick_times(traj.t) if times_index is None else list(times_index)
    T = traj.T[idx] - C0
    dist = observe.temperature_distribution(T, width=width)
    edges = np.asarray(dist.edges)
    fig, (a0, a1) = plt.subplots(1, 2, figsize=(10, 4))
    for k, i in enumerate(idx):
        label = f"t = {traj.t[i] / 60:.3g} min"
        a0.stairs(np.asarray(dist.q0)[k], edges, color=f"C{k}", label=label)
        a1.plot(edges, np.asarray(dist.Q0)[k], color=f"C{k}", label=label)
    a0.set_xlabel("temperature class / °C")
    a0.set_ylabel(f"q0 / (1/K), {width:g} K classes")
    a1.set_xlabel("temperature / °C")
    a1.set_ylabel("Q0")
    for a in (a0, a1):
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"{result.scene.name}: particle temperature distributions")
    fig.tight_layout()
    return fig


def plot_alpha_overall(result):
    """Overall wall-to-bed coefficient (eq. [1.10]) and its log-log slope over time."""
    ts = result.timeseries
    t, a = ts["t"].to_numpy(), ts["alpha_overall"].to_numpy()
    ok = (t > 0) & np.isfinite(a) & (a > 0)
    fig, (a0, a1) = plt.subplots(2, 1, figsize=(6.4, 6), sharex=True)
    a0.loglog(t[ok], a[ok], "C0-")
    a0.set_ylabel("alpha_overall / W/(m² K)")
    a0.grid(alpha=0.3, which="both")
    if ok.sum() > 4:
        slope = np.asarray(observe.log_slope(t[ok], a[ok]))
        a1.semilogx(t[ok], slope, "C1-")
        a1.axhline(-0.5, color="k", ls=":", lw=1, label="penetration regime (-0.5)")
        a1.legend()
    a1.set_ylabel("d ln alpha / d ln t")
    a1.set_xlabel("time / s")
    a1.grid(alpha=0.3, which="both")
    fig.suptitle(f"{result.scene.name}: overall heat-transfer coefficient")
    fig.tight_layout()
    return fig


def plot_snapshot(result, index=-1, ax=None, vmin=None, vmax=None):
    """The drum cross-section with particles to scale, coloured by temperature (°C and K)."""
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle

    traj = result.trajectory
    pos = traj.position[index]
    T = traj.T[index] - C0
    fig, ax = (ax.figure, ax) if ax is not None else plt.subplots(figsize=(5.6, 5))
    R = 0.5 * result.scene.drum.diameter
    patches = [Circle((x, y), 0.5 * d) for (x, y), d in zip(pos[:, :2], traj.diameter)]
    vmin = np.min(traj.T - C0) if vmin is None else vmin
    vmax = np.max(traj.T - C0) if vmax is None else vmax
    coll = PatchCollection(patches, cmap="coolwarm", edgecolor="k", linewidth=0.2)
    coll.set_array(T)
    coll.set_clim(vmin, vmax)
    ax.add_collection(coll)
    ax.add_patch(Circle((0, 0), R, fill=False, lw=2, color="0.3"))
    ax.set_xlim(-1.05 * R, 1.05 * R)
    ax.set_ylim(-1.05 * R, 1.05 * R)
    ax.set_aspect("equal")
    ax.set_xlabel("x / m")
    ax.set_ylabel("y / m")
    ax.set_title(f"{result.scene.name}, t = {traj.t[index]:.4g} s")
    cb = fig.colorbar(coll, ax=ax, pad=0.16)
    cb.set_label("temperature / °C")
    kelvin = cb.ax.secondary_yaxis("left", functions=(lambda c: c + C0, lambda k: k - C0))
    kelvin.set_ylabel("K")
    fig.tight_layout()
    return fig


def save_figures(result, folder) -> list[Path]:
    """Write the standard figures of a run as PNG files into ``folder``."""
    folder = Path(folder)
    out = []
    figs = {"mean_temperatures.png": plot_mean_temperatures(result),
            "temperature_distributions.png": plot_distributions(result)}
    if "alpha_overall" in result.timeseries:
        figs["alpha_overall.png"] = plot_alpha_overall(result)
    if result.scene.dim == 2:
        figs["snapshot_final.png"] = plot_snapshot(result, -1)
    for name, fig in figs.items():
        fig.savefig(folder / name, dpi=120)
        plt.close(fig)
        out.append(folder / name)
    return out
