"""Calibration line alpha_pp -> lambda_bed (Weigler ch. 5.2, appendix A7).

Runs the resting wall-heating scene (default ``weigler-glass-wall``: 370 glass spheres 8 mm in
a 250 mm drum, alpha_wp = 114 W/(m2 K)) at two or more alpha_pp on the same packing, reads
lambda_bed off each run (slope -0.5 of alpha_overall, else its inflection point) and prints
the line, the time and criterion used for each point, a linearity check, and the alpha_pp for
a target lambda_bed (Newton's method on the differentiable map).

Usage::

    python scripts/calibrate_lambda_bed.py [--scene weigler-glass-wall] [--alpha-pp 57 114]
        [--rho-bed 1230] [--convention A7|phi] [--target 0.9] [--seeds 1 2 3] [--figure F.png]
"""

from __future__ import annotations

import argparse

import drumheat as dh
from drumheat.analysis.calibrate import calibrate_lambda_bed


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="weigler-glass-wall")
    ap.add_argument("--alpha-pp", type=float, nargs="+", default=[57.0, 114.0])
    ap.add_argument("--rho-bed", type=float, default=1230.0)
    ap.add_argument("--convention", default="A7", choices=("A7", "phi"))
    ap.add_argument("--slope-of", default="overall", choices=("overall", "bed"))
    ap.add_argument("--target", type=float, default=0.9, help="lambda_bed to invert, W/(m K)")
    ap.add_argument("--seeds", type=int, nargs="+", default=None,
                    help="packings (run.seed values); default: the scene's")
    ap.add_argument("--figure", default=None)
    args = ap.parse_args(argv)
    seeds = args.seeds or [None]
    out = []
    for seed in seeds:
        scene = dh.load_scene(args.scene, {"run.seed": seed} if seed is not None else None)
        cal = calibrate_lambda_bed(scene, args.alpha_pp, rho_bed=args.rho_bed,
                                   convention=args.convention, slope_of=args.slope_of)
        print(f"\npacking seed {scene.run.seed}: {cal.n_wall_contacts} wall contacts, "
              f"A = {cal.area:.5g} m2, rho_bed = {cal.rho_bed:g} kg/m3, c = {cal.c_bed:g}, "
              f"alpha_ws = {cal.alpha_ws:g} ({cal.convention}), slope of alpha_{cal.slope_of}")
        print(cal.table().to_string())
        print(f"line: lambda_bed = {float(cal.line.slope):.6g} * alpha_pp + "
              f"{float(cal.line.intercept):.6g}")
        print(f"fixed-time proportionality check at t = {cal.proportional['time']:.1f} s: "
              f"(lambda2/lambda1)/(a2/a1) = {cal.proportional['ratio']:.6f}")
        inv = cal.alpha_pp(args.target)
        print(f"alpha_pp for lambda_bed = {args.target:g}: Newton {inv.alpha_pp:.6g} "
              f"(read-off {inv.time:.1f} s, {inv.criterion}; achieved {inv.lambda_achieved:.6g}),"
              f" line {inv.line_estimate:.6g}")
        out.append(cal)
        if args.figure:
            cal.plot().savefig(args.figure if len(seeds) == 1 else
                               args.figure.replace(".png", f"-seed{scene.run.seed}.png"), dpi=120)
    return out


if __name__ == "__main__":
    main()
