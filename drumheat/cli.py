"""The ``drumheat`` command (DESIGN.md, command line).

``drumheat scenes`` lists the built-in scenes; ``drumheat run SCENE [--out DIR] [--set K=V]``
runs one; ``drumheat validate [--quick] [--out DIR]`` runs the validation suite
(:mod:`drumheat.analysis.validation`; exit code 1 when a comparison is outside its
tolerance). Bad input gives a one-paragraph message naming the key, the value and what is
allowed, and exit code 2; nothing half-written is left behind.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from pathlib import Path


def _cmd_scenes(args) -> int:
    from drumheat.scene import builtin_scenes

    scenes = builtin_scenes()
    width = max(map(len, scenes)) if scenes else 0
    for name, desc in scenes.items():
        print(f"{name:<{width}}  {desc}")
    return 0


def _cmd_run(args) -> int:
    from drumheat.results.files import default_out_dir
    from drumheat.runner.loop import run
    from drumheat.scene import load_scene

    scene = load_scene(args.scene, args.set)
    out = Path(args.out) if args.out is not None else default_out_dir(scene.name)
    result = run(scene, out=out, progress=not args.quiet, resume=args.resume,
                 figure_formats=tuple(args.figure_formats or ("png",)), dpi=args.dpi,
                 allow_long=args.yes)
    s = result.summary
    print(f"{scene.name}: {s['n_particles']} particles, {s['duration_s']:g} s simulated in "
          f"{s['wall_time_s']:.1f} s wall time; energy balance error "
          f"{s['energy_balance_rel_error']:.2e}")
    for col in result.timeseries.columns:
        if col.startswith("T_mean"):
            print(f"  final {col:<20} {s[col]:.3f} K ({s[col] - 273.15:.3f} degC)")
    if "outlet" in s:  # an open apparatus: T_mean includes the particles queued at the feeder
        o = s["outlet"]
        for name, key in (("particles out", "T_particle_out"), ("gas out", "T_gas_out")):
            print(f"  {name:<26} {o[key]:.3f} K ({o[key] - 273.15:.3f} degC)")
        print(f"  {'Q_2 (slice / channel)':<26} {o['Q_2']:.2f} W / {o['Q_2_channel']:.1f} W")
    print(f"results in {out}/")
    return 0


def _cmd_new(args) -> int:
    from drumheat.scene.template import write_new_scene

    try:
        path = write_new_scene(args.file, args.template, args.set, force=args.force)
    except FileExistsError as err:
        return _fail(str(err))
    print(f"wrote {path} (from {args.template}). Next:\n"
          f"  drumheat estimate {path}    steps and wall time, before you commit to a run\n"
          f"  drumheat explain {path}     which heat-transfer effects matter\n"
          f"  drumheat run {path}         run it (results in results/{path.stem}/)")
    return 0


def _cmd_estimate(args) -> int:
    from drumheat.motion import make_motion
    from drumheat.runner.loop import estimate
    from drumheat.scene import load_scene

    scene = load_scene(args.scene, args.set)
    print(f"{scene.name}: preparing (packing the bed, compiling, timing a warm-up) ...",
          file=sys.stderr, flush=True)
    cost = estimate(make_motion(scene))
    if cost is None:
        print(f"{scene.name}: motion model {scene.motion.model!r} makes no estimate; its runs "
              "take seconds to minutes")
        return 0
    print(cost["text"])
    if cost.get("cheaper"):
        print(f"cheaper: {cost['cheaper']}")
    return 0


def _cmd_explain(args) -> int:
    from drumheat.analysis.advisor import explain
    from drumheat.scene import load_scene

    print(explain(load_scene(args.scene, args.set)).text())
    return 0


def _cmd_animate(args) -> int:
    from drumheat.results.animate import AnimationError, animate

    try:
        out = animate(args.result_dir, out=args.out, fps=args.fps, fmt=args.format,
                      every=args.every)
    except AnimationError as err:
        return _fail(str(err))
    print(f"animation in {out}")
    return 0


def _cmd_export_vtk(args) -> int:
    from drumheat.results.vtk import export_vtk

    pvd = export_vtk(args.result_dir, out_dir=args.out, binary=not args.ascii)
    print(f"ParaView files in {pvd.parent}/ (open {pvd.name}; walls in walls.vtp)")
    return 0


def _cmd_validate(args) -> int:
    from drumheat.analysis.validation import format_table, run_validation, write_validation
    from drumheat.results.files import check_out_dir

    if args.out is not None:
        check_out_dir(args.out)  # refuse a folder of the user's before the work, not after
    try:
        rows, figures = run_validation(quick=args.quick, cases=args.case or None,
                                       progress=lambda line: print(line, file=sys.stderr,
                                                                   flush=True))
    except ValueError as err:
        return _fail(str(err))
    print(format_table(rows))
    if args.out is not None:
        out = write_validation(rows, figures, args.out)
        print(f"validation.csv, validation.md and {len(figures)} figures in {out}/")
    failed = [r for r in rows if r.status == "FAIL"]
    if failed:
        print(f"{len(failed)} of {len(rows)} comparisons outside their tolerance",
              file=sys.stderr)
        return 1
    return 0


def _scene_command(sub, name: str, func, help: str):
    """A subcommand that takes a scene (built-in name or file) and ``--set`` overrides."""
    c = sub.add_parser(name, help=help)
    c.add_argument("scene", help="built-in scene name or path to a .toml scene file")
    c.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value by its dotted key (repeatable)")
    c.set_defaults(func=func)
    return c


def build_parser() -> argparse.ArgumentParser:
    from drumheat._version import __version__

    p = argparse.ArgumentParser(prog="drumheat", description="Thermal DEM of particle beds.")
    p.add_argument("--version", action="version", version=f"drumheat {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("scenes", help="list the built-in scenes")
    s.set_defaults(func=_cmd_scenes)
    r = sub.add_parser("run", help="run a built-in scene (by name) or a scene file (by path)")
    r.add_argument("scene", help="built-in scene name or path to a .toml scene file")
    r.add_argument("--out", help="result folder (default results/<scene>)")
    r.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value by its dotted key, e.g. run.duration=600 or "
                        "groups.0.temperature=300 (repeatable)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--yes", action="store_true",
                   help="run even if the estimate made before the run is above an hour")
    r.add_argument("--figure-format", action="append", choices=("png", "pdf", "svg"),
                   dest="figure_formats", metavar="FORMAT",
                   help="figure file format, png (default), pdf or svg; repeat for several")
    r.add_argument("--dpi", type=int, default=120, help="resolution of PNG figures (default "
                                                        "120; 300 for print)")
    r.add_argument("--resume", action="store_true",
                   help="continue the run whose checkpoint is in the result folder (the same "
                        "scene and overrides)")
    r.set_defaults(func=_cmd_run)
    n = sub.add_parser("new", help="write a new scene file from a built-in scene (comments "
                                   "kept), with changes")
    n.add_argument("file", metavar="FILE", help="the new scene file, e.g. my-drum.toml (its "
                                                "name is the file's stem)")
    n.add_argument("--from", dest="template", default="glass-drum-3d", metavar="SCENE",
                   help="built-in scene or scene file to start from (default glass-drum-3d, "
                        "a heated 3D turning drum); 'drumheat scenes' lists them")
    n.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="change a value by its dotted key, e.g. groups.0.count=3000 "
                        "(repeatable); checked before the file is written")
    n.add_argument("--force", action="store_true", help="overwrite an existing file")
    n.set_defaults(func=_cmd_new)
    _scene_command(sub, "estimate", _cmd_estimate, "what a run will cost before it starts: "
                   "steps and estimated wall time (packs the bed, times a warm-up)")
    _scene_command(sub, "explain", _cmd_explain, "size of each heat-transfer effect in a scene, "
                   "and which to drop or add")
    val = sub.add_parser("validate", help="run the validation suite: drumheat against closed "
                                          "forms, the penetration model and the thesis' data")
    val.add_argument("--quick", action="store_true",
                     help="the quick cases only (under a minute); default: the full suite")
    val.add_argument("--out", help="folder for validation.csv, validation.md and the figures")
    val.add_argument("--case", action="append", metavar="NAME",
                     help="run only this case (repeatable): chain, lattice, drum-pm, thesis")
    val.set_defaults(func=_cmd_validate)
    a = sub.add_parser("animate", help="animate a result folder: the drum coloured by "
                                       "temperature, with a clock (GIF or MP4)")
    a.add_argument("result_dir", metavar="RESULT_DIR",
                   help="result folder written by 'drumheat run' (particles.npz, scene.toml)")
    a.add_argument("--out", help="output file (default RESULT_DIR/animation.gif); a .mp4 "
                                 "name writes MP4 (needs imageio-ffmpeg)")
    a.add_argument("--fps", type=float, default=10.0, help="frames per second (default 10)")
    a.add_argument("--every", type=int, default=1, help="use every k-th output (default 1)")
    a.add_argument("--format", choices=("gif", "mp4"), default=None,
                   help="file format (default: from the --out suffix, else gif)")
    a.set_defaults(func=_cmd_animate)
    v = sub.add_parser("export-vtk", help="write a result folder as ParaView files (.vtp "
                                          "series, .pvd, walls.vtp)")
    v.add_argument("result_dir", metavar="RESULT_DIR",
                   help="result folder written by 'drumheat run' (particles.npz, scene.toml)")
    v.add_argument("--out", help="output folder (default RESULT_DIR/vtk)")
    v.add_argument("--ascii", action="store_true", help="ASCII instead of base64 binary data")
    v.set_defaults(func=_cmd_export_vtk)
    return p


#: exit code of a run stopped early (Ctrl-C) with its results so far and a checkpoint
EXIT_STOPPED = 3


def _fail(message: str) -> int:
    print(textwrap.fill(f"drumheat: error: {message}", width=100, break_on_hyphens=False,
                        break_long_words=False), file=sys.stderr)
    return 2


def main(argv=None) -> int:
    """Entry point of the ``drumheat`` command; returns the exit code."""
    from drumheat.mechanics import DEMError
    from drumheat.results.files import ResultFolderError
    from drumheat.runner.checkpoint import CheckpointError
    from drumheat.runner.loop import LongRunError, RunStopped
    from drumheat.scene import SceneError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (SceneError, ResultFolderError, CheckpointError, LongRunError) as err:
        return _fail(str(err))
    except RunStopped as err:
        print(textwrap.fill(f"drumheat: {err}", width=100, break_on_hyphens=False,
                            break_long_words=False), file=sys.stderr)
        return EXIT_STOPPED
    except DEMError as err:
        return _fail(f"the DEM run failed: {err}")
    except (FileNotFoundError, IsADirectoryError, PermissionError) as err:
        return _fail(str(err))
    except KeyboardInterrupt:
        print("interrupted (a run that was writing into a result folder left what it had and "
              "a checkpoint there)", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
