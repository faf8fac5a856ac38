"""Result files: ``timeseries.csv``, ``summary.json``, ``particles.npz`` and figures.

Written into a temporary folder beside the target and moved into place only when complete, so
a failed run leaves nothing half-written behind (DESIGN.md, outside contracts).
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

import numpy as np


def default_out_dir(scene_name: str) -> Path:
    """``results/<scene>`` in the current directory."""
    return Path("results") / scene_name


def write_results(result, out_dir=None, figures: bool = True) -> Path:
    """Write a :class:`drumheat.runner.Result` to ``out_dir`` atomically; returns the folder."""
    out = Path(out_dir) if out_dir is not None else default_out_dir(result.scene.name)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        result.timeseries.to_csv(tmp / "timeseries.csv", index=False, float_format="%.10g")
        (tmp / "summary.json").write_text(json.dumps(result.summary, indent=2) + "\n")
        traj = result.trajectory
        arrays = dict(t=traj.t, T=traj.T, group=traj.group, diameter=traj.diameter,
                      position=traj.position,
                      group_names=np.array([g.name for g in result.scene.groups]))
        np.savez_compressed(tmp / "particles.npz", **arrays)
        (tmp / "scene.toml").write_text(result.scene.to_toml())
        for name, writer in traj.files.items():  # the motion model's own files
            writer(tmp / name)
        if figures:
            from drumheat import plot

            plot.save_figures(result, tmp)
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
