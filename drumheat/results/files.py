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
import socket
import tempfile
import time
from pathlib import Path

import numpy as np

from drumheat.motion.npz_files import save_npz
from drumheat.motion.rows import stack_arrays

#: the manifest of a result folder: the names of the files and folders drumheat wrote into it
MANIFEST = ".drumheat-files.json"

#: what result folders written before the manifest existed hold (drumheat 0.1 and earlier):
#: a folder without a manifest counts as a drumheat result only if it holds ``summary.json``
#: and ``scene.toml`` and nothing that does not match these names
_LEGACY_OUTPUTS = ("timeseries.csv", "summary.json", "particles.npz", "scene.toml",
                   "contacts.npz", "phases.csv", "profiles.npz", "channel.json", "*.png",
                   "animation.gif", "animation.mp4", "vtk")


#: the lock file of a result folder that a run is writing into
RUN_LOCK = ".drumheat-run.lock"
#: the checkpoint of a run (drumheat.runner.checkpoint)
CHECKPOINT = "checkpoint.npz"
#: folder of a running result that holds its particle frames (drumheat.motion.rows.RowSpool)
FRAMES = ".frames"
#: folder of a running result where the motion model's log keeps its large arrays (the contact
#: recording of a DEM run, drumheat.motion.spooled_array.SpooledArray)
LOG = ".log"


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
    holder = running_pid(out)
    if holder is not None:
        raise ResultFolderError(f"output folder '{out}' is being written by a run that is still "
                                f"going (process {holder}); wait for it, or choose another --out")
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


def running_pid(folder: Path) -> int | None:
    """The process id of a run that is writing into ``folder`` now, or None (no lock, or the
    lock of a run that ended without removing it)."""
    try:
        info = json.loads((Path(folder) / RUN_LOCK).read_text())
    except (OSError, ValueError):
        return None
    pid = int(info.get("pid", -1))
    if info.get("host") != socket.gethostname() or pid <= 0 or pid == os.getpid():
        return None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return None
    except PermissionError:
        return pid
    return pid


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
    old = Path(tempfile.mkdtemp(prefix=f".{out.name}.drumheat-old-", dir=out.parent))
    old.rmdir()
    out.rename(old)
    try:
        tmp.rename(out)
    except BaseException:
        old.rename(out)
        raise
    shutil.rmtree(old, ignore_errors=True)


#: a temporary folder of drumheat's beside a result folder older than this (s) is left over
#: from a write that was killed (SIGKILL) and is removed
STALE_AFTER_S = 600.0


def clean_stale_temporaries(out: Path) -> list[Path]:
    """Remove drumheat's temporary folders beside ``out`` (``.<name>.drumheat-tmp-*``,
    ``.<name>.drumheat-old-*``) that a killed write left behind; returns those removed."""
    out = Path(out)
    removed = []
    if not out.parent.is_dir():
        return removed
    for p in out.parent.glob(f".{out.name}.drumheat-*"):
        try:
            if p.is_dir() and time.time() - p.stat().st_mtime > STALE_AFTER_S:
                shutil.rmtree(p)
                removed.append(p)
        except OSError:
            pass
    return removed


def write_folder(out: str | Path, fill) -> Path:
    """Write a folder of drumheat's own files atomically; returns it.

    ``fill(tmp)`` writes the files into a fresh temporary folder beside ``out``; the folder
    then gets its manifest and replaces ``out`` the way a result folder does (an empty folder
    or an earlier folder of drumheat's own files only; anything else is refused before
    ``fill`` runs, and nothing of the user's is deleted). The result folders of runs
    (:func:`write_results`) and ``drumheat validate --out`` are written so.

    Raises
    ------
    ResultFolderError
        If ``out`` holds something drumheat did not write (see :func:`check_out_dir`).
    """
    out = Path(out)
    check_out_dir(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_temporaries(out)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.drumheat-tmp-", dir=out.parent))
    try:
        tmp.chmod(0o777 & ~_umask())  # mkdtemp makes it 0700
        fill(tmp)
        _write_manifest(tmp, [p.name for p in tmp.iterdir()])
        place_folder(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def write_drum_wall(path, traj) -> None:
    """``wall.npz`` of a run with ``[heat.drum_wall]``: ``t`` (n_out,) s, ``T_wall`` (n_out,
    n_seg) K (segment k spans polar angles ``angle_edges[k]`` to ``angle_edges[k + 1]``, rad,
    in the drum's frame: from +x at t = 0), ``angle_edges`` (n_seg + 1,), ``capacity`` and
    ``area`` (n_seg,) J/K and m2, ``Q_outside`` and ``Q_gas`` (n_out,) J since t = 0."""
    w = traj.drum_wall
    n = w["T"].shape[1]
    np.savez_compressed(path, t=traj.t, T_wall=w["T"],
                        angle_edges=np.linspace(0.0, 2.0 * np.pi, n + 1),
                        capacity=w["capacity"], area=w["area"], Q_outside=w["Q_outside"],
                        Q_gas=w["Q_gas"])


def write_results(result, out_dir=None, figures: bool = True, figure_formats=("png",),
                  dpi: int = 120) -> Path:
    """Write a :class:`drumheat.runner.Result` to ``out_dir`` atomically; returns the folder.

    ``figure_formats`` and ``dpi`` go to :func:`drumheat.results.plot.save_figures`.

    Raises
    ------
    ResultFolderError
        If ``out_dir`` holds something drumheat did not write (see :func:`check_out_dir`).
    """
    out = Path(out_dir) if out_dir is not None else default_out_dir(result.scene.name)

    def fill(tmp: Path) -> None:
        result.timeseries.to_csv(tmp / "timeseries.csv", index=False, float_format="%.10g")
        (tmp / "summary.json").write_text(json.dumps(result.summary, indent=2) + "\n")
        traj = result.trajectory
        arrays = dict(t=traj.t, T=traj.T, group=traj.group, diameter=traj.diameter,
                      position=traj.position,
                      group_names=np.array([g.name for g in result.scene.groups]),
                      **traj.mechanics)
        save_npz(tmp / "particles.npz", arrays)  # the frames' pages given back as written
        (tmp / "scene.toml").write_text(result.scene.to_toml())
        if traj.drum_wall:  # segment temperatures of a drum wall with heat capacity
            write_drum_wall(tmp / "wall.npz", traj)
        for name, writer in traj.files.items():  # the motion model's own files
            writer(tmp / name)
        if figures:
            from drumheat.results import plot

            plot.save_figures(result, tmp, formats=figure_formats, dpi=dpi)

    return write_folder(out, fill)


# ---------------------------------------------------------------------------------------------
# a result folder written as the run goes
# ---------------------------------------------------------------------------------------------


class RunFolder:
    """The result folder of a run that writes as it goes (DESIGN.md, outside contracts).

    While the run goes, the folder holds ``scene.toml``, ``summary.json`` (``"complete":
    false``), ``timeseries.csv`` growing row by row (flushed; the columns every run has:
    ``t``, ``T_mean``, ``T_mean:<group>``, ``T_min``, ``T_max`` and the heat accounts), the
    latest ``checkpoint.npz``, the particle frames so far in ``.frames/`` (one ``.npy`` per
    frame and quantity: a long run never holds all its frames in memory), the contact
    recording so far in ``.log/`` (one file per recorded quantity; on the CPU also the start of
    the running chunk, :class:`drumheat.runner.spill.StartSpill`) and a lock (a second
    run into the same folder is refused). When the run completes, the complete result replaces
    all of it (:func:`write_results`). A run that stops early (Ctrl-C, an error) leaves what it
    has, marks the summary incomplete and keeps the checkpoint, from which ``drumheat run ...
    --resume`` continues.

    An earlier complete result at the output path is moved to ``<name>.previous`` beside it
    when a new run starts, and deleted when the new run completes: a run that fails never
    destroys an earlier result.

    Parameters
    ----------
    out : path
    scene : Scene
    resume : bool
        Continue the run whose checkpoint is in ``out`` (nothing is moved).
    mass, group : arrays (N,)
        Particle masses (kg) and group indices, for the streamed mean temperatures.
    """

    def __init__(self, out, scene, *, resume: bool = False, mass=None, group=None):
        self.out = Path(out)
        self.scene = scene
        self.mass = None if mass is None else np.asarray(mass, float)
        self.group = None if group is None else np.asarray(group)
        self.previous = self.out.with_name(self.out.name + ".previous")
        self._columns = None
        check_out_dir(self.out)
        if resume:
            if not (self.out / CHECKPOINT).is_file():
                raise ResultFolderError(f"there is no checkpoint to resume in '{self.out}' "
                                        f"({CHECKPOINT} is missing); run without --resume")
        else:
            self._clear()
        clean_stale_temporaries(self.out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.out.chmod(0o777 & ~_umask())
        (self.out / RUN_LOCK).write_text(json.dumps(dict(pid=os.getpid(),
                                                         host=socket.gethostname(),
                                                         started=time.time())))
        if not resume:
            (self.out / "scene.toml").write_text(scene.to_toml())
            self.summary({"complete": False, "status": "running"})
        self._register()

    def _clear(self):
        """Make room: an earlier complete result goes to ``<name>.previous`` (an older one
        there is deleted), an incomplete one (a run that stopped) is discarded."""
        if not self.out.is_dir() or not any(self.out.iterdir()):
            return
        complete = _read_json(self.out / "summary.json").get("complete", True)
        if complete:
            if self.previous.exists():
                if foreign_entries(self.previous) not in ([],):
                    raise ResultFolderError(f"'{self.previous}' (where drumheat keeps the "
                                            "earlier result while a new one runs) holds files "
                                            "drumheat did not write; move it away")
                shutil.rmtree(self.previous)
            self.out.rename(self.previous)
        else:
            shutil.rmtree(self.out)

    def _register(self):
        names = [p.name for p in self.out.iterdir() if p.name != MANIFEST]
        _write_manifest(self.out, names)

    # -- while running ------------------------------------------------------------------------
    def row(self, t: float, row: dict) -> None:
        """Append one output row to ``timeseries.csv`` (flushed)."""
        if self.mass is None or "T" not in row:
            return
        T = np.asarray(row["T"], float)
        cols = {"t": float(t), "T_mean": float(T @ self.mass / self.mass.sum())}
        for k, g in enumerate(self.scene.groups):
            m = self.group == k
            cols[f"T_mean:{g.name}"] = float(T[m] @ self.mass[m] / self.mass[m].sum())
        cols["T_min"], cols["T_max"] = float(T.min()), float(T.max())
        for a, q in sorted(row.get("Q", {}).items()):
            q = float(np.asarray(q))
            cols["Q_loss" if a == "gas" else f"Q_{a}"] = -q if a == "gas" else q
        path = self.out / "timeseries.csv"
        if self._columns is None:
            self._columns = list(cols)
            path.write_text(",".join(self._columns) + "\n")
            self._register()
        with open(path, "a") as fh:
            fh.write(",".join(f"{cols.get(c, float('nan')):.10g}" for c in self._columns)
                     + "\n")
            fh.flush()

    def rows(self, times, rows: list) -> None:
        """Start ``timeseries.csv`` anew with the rows so far (a resumed run)."""
        self._columns = None
        (self.out / "timeseries.csv").unlink(missing_ok=True)
        for t, r in zip(times, rows):
            self.row(t, r)

    def summary(self, data: dict) -> None:
        """Write ``summary.json`` (atomically)."""
        tmp = self.out / ".summary.json.writing"
        tmp.write_text(json.dumps(data, indent=2, default=_json_default) + "\n")
        tmp.replace(self.out / "summary.json")

    @property
    def checkpoint_path(self) -> Path:
        return self.out / CHECKPOINT

    @property
    def frames_dir(self) -> Path:
        """Where the run's particle frames are spooled while it runs
        (:class:`drumheat.motion.rows.RowSpool`)."""
        return self.out / FRAMES

    @property
    def log_dir(self) -> Path:
        """Where the motion model's log keeps its large arrays while the run goes (made by the
        log that uses it, e.g. :class:`drumheat.motion.dem.ContactRecorder`, before the first
        output row lists the folder's entries as drumheat's own)."""
        return self.out / LOG

    # -- the end ------------------------------------------------------------------------------
    def complete(self, result, figures: bool = True, **figure_options) -> Path:
        """Replace the running folder by the complete result; delete the earlier one
        (``figure_options``: ``figure_formats``, ``dpi`` of :func:`write_results`)."""
        self.checkpoint_path.unlink(missing_ok=True)
        (self.out / RUN_LOCK).unlink(missing_ok=True)
        self._register()
        try:
            write_results(result, self.out, figures=figures, **figure_options)
        except BaseException:
            self._release()
            raise
        if self.previous.is_dir() and foreign_entries(self.previous) == []:
            shutil.rmtree(self.previous, ignore_errors=True)
        return self.out

    def stop(self, summary: dict, times=None, rows=None) -> None:
        """A run that stopped early: what it has (the summary marked incomplete, the partial
        particle frames) stays, with its checkpoint; the lock goes."""
        try:
            self.summary(summary)
            if rows:
                _write_partial_particles(self.out / "particles.npz", times, rows, self.group,
                                         [g.name for g in self.scene.groups])
        finally:
            self._release()

    def discard(self) -> None:
        """Remove this run's folder (a run refused for bad input found while running) and put
        an earlier result back in its place."""
        shutil.rmtree(self.out, ignore_errors=True)
        if self.previous.is_dir() and not self.out.exists():
            self.previous.rename(self.out)

    def _release(self):
        (self.out / RUN_LOCK).unlink(missing_ok=True)
        self._register()


def _read_json(path: Path) -> dict:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return {}


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"{type(x).__name__} is not JSON serialisable")


def _write_partial_particles(path, times, rows, group, group_names):
    """``particles.npz`` of the rows a stopped run has (``t``, ``T``, ``position`` and the
    per-particle mechanics where every row has them)."""
    if not rows or any("T" not in r for r in rows):
        return
    arrays = dict(t=np.asarray(times[:len(rows)], float),
                  T=stack_arrays(rows, "T", (r["T"] for r in rows)), group=group,
                  group_names=np.array(group_names))
    if all("position" in r for r in rows):
        arrays["position"] = stack_arrays(rows, "position", (r["position"] for r in rows))
    if all("mechanics" in r for r in rows):
        for key in rows[0]["mechanics"]:
            arrays[key] = stack_arrays(rows, f"mechanics.{key}",
                                       (r["mechanics"][key] for r in rows))
    tmp = path.with_name(".particles.npz.writing")
    with open(tmp, "wb") as fh:
        save_npz(fh, arrays)
    os.replace(tmp, path)
