"""Result files: ``timeseries.csv``, ``summary.json``, ``particles.npz`` and figures.

Written into a temporary folder beside the target and moved into place only when complete, so
a failed run leaves nothing half-written behind (DESIGN.md, outside contracts).

**A run never deletes a folder it did not write.** Every result folder holds a small manifest,
``.drumheat-files.json``, listing the files drumheat wrote into it (the run's files, and the
animation and ParaView files written later from it). An existing folder at the output path is
replaced only when it is empty or is a drumheat result folder holding nothing but drumheat's
own files; anything else (a folder of the user's own files, the current folder, a regular
file, a symbolic link) is refused with :class:`ResultFolderError` before anything is written,
and the earlier result stays in place until the new one is complete.
"""

from __future__ import annotations

import fnmatch
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

#: the manifest of a result folder: the names of the files and folders drumheat wrote into it
MANIFEST = ".drumheat-files.json"

#: what result folders written before the manifest existed hold (drumheat 0.1 and earlier):
#: a folder without a manifest counts as a drumheat result only if it holds ``summary.json``
#: and ``scene.toml`` and nothing that does not match these names
_LEGACY_OUTPUTS = ("timeseries.csv", "summary.json", "particles.npz", "scene.toml",
                   "contacts.npz", "phases.csv", "profiles.npz", "channel.json", "*.png",
                   "animation.gif", "animation.mp4", "vtk")


class ResultFolderError(ValueError):
    """The output path cannot take a result folder (it holds files drumheat did not write,
    is a regular file or a link, or cannot be written); nothing was written or deleted."""


def default_out_dir(scene_name: str) -> Path:
    """``results/<scene>`` in the current directory."""
    return Path("results") / scene_name


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _manifest(folder: Path) -> list[str] | None:
    """The names listed in a folder's manifest, or None if it has none (or an unreadable one)."""
    try:
        data = json.loads((folder / MANIFEST).read_text())
        return [str(x) for x in data["files"]]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def foreign_entries(folder: Path) -> list[str] | None:
    """Entries of an existing result folder that drumheat did not write.

    Returns None if ``folder`` is not a drumheat result folder at all (no manifest and not an
    older result folder), else the sorted names of the entries not written by drumheat (empty
    when it holds only drumheat's files).
    """
    entries = sorted(p.name for p in folder.iterdir())
    listed = _manifest(folder)
    if listed is None:
        if not {"summary.json", "scene.toml"} <= set(entries):
            return None
        return [e for e in entries
                if not any(fnmatch.fnmatch(e, pat) for pat in _LEGACY_OUTPUTS)]
    ours = set(listed) | {MANIFEST}
    return [e for e in entries if e not in ours]


def check_out_dir(out: str | Path) -> Path:
    """Check that ``out`` can take a result folder, before a run starts; returns it.

    Accepted: a path that does not exist yet (in a folder that can be written), an empty
    folder, or a drumheat result folder that holds only drumheat's own files (it will be
    replaced when the new result is complete).

    Raises
    ------
    ResultFolderError
        Naming the path and what is in the way; nothing is written or deleted.
    """
    out = Path(out)
    if str(out).strip() == "":
        raise ResultFolderError("the output folder must not be an empty path")
    if out.is_symlink():
        raise ResultFolderError(f"output folder '{out}' is a symbolic link"
                                + ("" if out.exists() else " to nothing")
                                + "; give the real folder (or a new name)")
    if out.exists() and not out.is_dir():
        raise ResultFolderError(f"output folder '{out}' is a file, not a folder; choose "
                                "another --out")
    here = Path.cwd().resolve()
    target = out.resolve()
    if target == here or target in here.parents:
        raise ResultFolderError(f"output folder '{out}' is the current folder (or holds it); "
                                "results go into a folder of their own, e.g. --out results/run1")
    if out.is_dir() and any(out.iterdir()):
        foreign = foreign_entries(out)
        if foreign is None:
            shown = sorted(p.name for p in out.iterdir())
            raise ResultFolderError(
                f"output folder '{out}' is not empty and is not a drumheat result folder "
                f"(it holds {_list(shown)}); drumheat never replaces a folder it did not "
                "write: choose a new or empty folder with --out")
        if foreign:
            raise ResultFolderError(
                f"output folder '{out}' holds an earlier drumheat result together with files "
                f"drumheat did not write ({_list(foreign)}); move those away or choose "
                "another --out, so that replacing the result loses nothing of yours")
    parent = target.parent
    while not parent.exists():
        parent = parent.parent
    if not os.access(parent, os.W_OK | os.X_OK) or (out.is_dir() and not os.access(
            target, os.W_OK | os.X_OK)):
        raise ResultFolderError(f"output folder '{out}' cannot be written (no permission in "
                                f"'{parent}'); choose another --out")
    return out


def _list(names: list[str], k: int = 5) -> str:
    shown = ", ".join(f"'{n}'" for n in names[:k])
    return shown + (f" and {len(names) - k} more" if len(names) > k else "")


def register_outputs(folder: str | Path, names) -> None:
    """Add ``names`` (files or folders drumheat wrote into a result folder, e.g. an animation)
    to the folder's manifest, so that replacing the result later may remove them too."""
    folder = Path(folder)
    listed = _manifest(folder)
    if listed is None:
        if foreign_entries(folder) is None:  # not a result folder: nothing to register
            return
        listed = [p.name for p in folder.iterdir() if p.name != MANIFEST]
    names = sorted(set(listed) | {str(n) for n in names})
    _write_manifest(folder, names)


def _write_manifest(folder: Path, names) -> None:
    from drumheat._version import __version__

    tmp = folder / f"{MANIFEST}.tmp"
    tmp.write_text(json.dumps({"drumheat": __version__, "files": sorted(names)}, indent=1)
                   + "\n")
    tmp.replace(folder / MANIFEST)


def place_folder(tmp: Path, out: Path) -> None:
    """Move the complete folder ``tmp`` to ``out``, replacing an earlier result folder there.

    The earlier folder is moved aside first and deleted only after the new one is in place;
    if that fails it is moved back.
    """
    check_out_dir(out)
    if out.is_dir() and not any(out.iterdir()):
        out.rmdir()
    if not out.exists():
        tmp.rename(out)
        return
    old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old.", dir=out.parent))
    old.rmdir()
    out.rename(old)
    try:
        tmp.rename(out)
    except BaseException:
        old.rename(out)
        raise
    shutil.rmtree(old, ignore_errors=True)


def write_results(result, out_dir=None, figures: bool = True) -> Path:
    """Write a :class:`drumheat.runner.Result` to ``out_dir`` atomically; returns the folder.

    Raises
    ------
    ResultFolderError
        If ``out_dir`` holds something drumheat did not write (see :func:`check_out_dir`).
    """
    out = Path(out_dir) if out_dir is not None else default_out_dir(result.scene.name)
    check_out_dir(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        tmp.chmod(0o777 & ~_umask())  # mkdtemp makes it 0700
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
            from drumheat.results import plot

            plot.save_figures(result, tmp)
        _write_manifest(tmp, [p.name for p in tmp.iterdir()])
        place_folder(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
