"""Per-particle results as a pandas DataFrame, and the heat flow into each particle.

``particle_table(result_or_folder)`` gives one row per particle and output time, ready for
``groupby``, ``query`` and seaborn; :func:`heat_rates` the mean heat flow into each particle over
each output interval, which the ParaView export writes too.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from drumheat.results.plot import ParticleFrames, as_frames

__all__ = ["particle_table", "heat_rates", "particle_capacities"]


def particle_capacities(frames: ParticleFrames) -> np.ndarray | None:
    """Heat capacity of each particle, J/K (``m c``, weigler-thermal-dem.md section 4), from
    the frames' scene; None without a scene, where the scene does not describe these
    particles (another count or other diameters), or where a particle's temperature is not its
    whole heat content (``[heat.internal]``: radial shells)."""
    scene = frames.scene
    if scene is None or scene.heat.internal is not None:
        return None
    from drumheat.assemble import scene_values, thermal_particles

    particles = thermal_particles(scene, scene_values(scene))
    d = np.asarray(particles.diameter, float)
    cap = np.asarray(particles.capacity, float)
    if cap.shape != frames.diameter.shape or (
            not np.allclose(d, frames.diameter, rtol=1e-9)):
        return None
    return cap


def heat_rates(frames: ParticleFrames) -> np.ndarray | None:
    """Mean heat flow into each particle over the output interval ending at each output, W,
    ``C_i (T_i(t_k) - T_i(t_{k-1})) / (t_k - t_{k-1})`` (n_out, N); NaN at the first output.
    None where :func:`particle_capacities` is None. A sum over particles is the heat the bed
    takes up from walls, gas and sources in that interval."""
    cap = particle_capacities(frames)
    if cap is None:
        return None
    q = np.full(frames.T.shape, np.nan)
    if len(frames.t) > 1:
        dt = np.diff(frames.t)[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            q[1:] = cap[None, :] * np.diff(frames.T, axis=0) / dt
    return q


def particle_table(source, every: int = 1) -> pd.DataFrame:
    """One row per particle and output time.

    Main arguments:
      source: a :class:`~drumheat.Result`, or a result folder written by ``drumheat run``.
      every: keep every k-th output time (default all).

    Returns:
      DataFrame with columns ``t`` (s), ``particle`` (index), ``group`` (name, categorical),
      ``diameter`` (m), ``T`` (K), ``x``, ``y`` (and ``z`` in 3D; m) and, for lumped particles
      with a scene at hand, ``heat_rate`` (W, :func:`heat_rates`; NaN at the first output).
      Where the run had a DEM also ``vx``, ``vy`` (``vz``; m/s), ``omega_z`` (2D) or
      ``omega_x``, ``omega_y``, ``omega_z`` (3D; rad/s), ``fx``, ``fy`` (``fz``; N, the force
      without the weight), ``coordination`` and ``wall_contacts`` (overlapping contacts;
      :func:`drumheat.mechanics.analysis.particle_mechanics`), NaN at replayed outputs.
      Rows are ordered by time, then particle.

    Example::

        df = drumheat.particle_table("results/weigler-mixed")
        df.groupby(["t", "group"])["T"].std()        # spread within each group over time
    """
    frames = as_frames(source)
    every = int(every)
    if every < 1:
        raise ValueError(f"every must be a positive integer, got {every}")
    keep = np.arange(0, len(frames.t), every)
    n_out, n = len(keep), frames.T.shape[1]
    names = np.asarray(frames.group_names, dtype=object)
    cols = {"t": np.repeat(frames.t[keep], n),
            "particle": np.tile(np.arange(n), n_out),
            "group": pd.Categorical(np.tile(names[frames.group], n_out),
                                    categories=list(frames.group_names)),
            "diameter": np.tile(frames.diameter, n_out),
            "T": frames.T[keep].reshape(-1)}
    pos = frames.position[keep]
    for k, axis in enumerate("xyz"[:pos.shape[-1]]):
        cols[axis] = pos[..., k].reshape(-1)
    q = heat_rates(frames)
    if q is not None:
        cols["heat_rate"] = q[keep].reshape(-1)
    cols.update(_mechanics_columns(frames, keep))
    return pd.DataFrame(cols)


#: column prefixes of the vector quantities of ParticleFrames.mechanics
_VECTOR_COLUMNS = {"velocity": "v", "angular_velocity": "omega_", "force": "f"}


def _mechanics_columns(frames: ParticleFrames, keep) -> dict:
    """The per-particle mechanics as flat columns (vector components split by axis)."""
    cols = {}
    for key, values in frames.mechanics.items():
        values = np.asarray(values)[keep]
        if key not in _VECTOR_COLUMNS:
            cols[key] = values.reshape(-1)
        elif values.ndim == 2:  # a 2D spin: its z component
            cols[_VECTOR_COLUMNS[key] + "z"] = values.reshape(-1)
        else:
            for k, axis in enumerate("xyz"[:values.shape[-1]]):
                cols[_VECTOR_COLUMNS[key] + axis] = values[..., k].reshape(-1)
    return cols
