"""`dynsplines orient KEYFRAMES.json --out PATH.npz`: covariant interpolation of one orientation (sec. 3).

Reads keyframe quaternions, optimizes the path (solver.paper.orient), writes it (.npz) and prints a summary;
`--plot` adds the figure-10 comparison of Euler-Lagrange deviations for these keyframes (runner.figure10).

The keyframe file and the output: runner/orient_file.py.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from runner.figure10 import figure10
from runner.files import check_writable_dir
from runner.orient_file import read_keyframes, write_result
from runner.parser import nonnegative, positive
from solver.errors import InputError
from solver.paper.orient import FORMS, default_options, orient
from solver.paper.solve import SUBDIVISIONS


def register(sub) -> None:
    """Add the `orient` subcommand to the `dynsplines` parser."""
    p = sub.add_parser(
        "orient",
        help="smooth orientation path through keyframe quaternions (paper sec. 3)",
        description="Optimize a smooth orientation path through keyframe quaternions by minimizing "
        "covariant angular acceleration (Ramamoorthi, Ball & Barr sec. 3).",
    )
    p.add_argument("keyframes", metavar="KEYFRAMES.json",
                   help='keyframe file: {"times": [...], "quaternions": [[w, x, y, z], ...]}')
    p.add_argument("--out", required=True, metavar="PATH.npz", help="where to write the optimized path")
    p.add_argument("--subdivision", choices=SUBDIVISIONS, default="adaptive",
                   help="where variable frames go: none, global (N per keyframe interval), adaptive "
                   "(N per interval, then where the Euler-Lagrange score is largest) [adaptive]")
    p.add_argument("--per-segment", type=nonnegative(int), default=1, metavar="N",
                   help="variable frames per keyframe interval (global), or to start with (adaptive) [1]")
    p.add_argument("--tol", type=positive(), default=None, metavar="GAP",
                   help="refine adaptively until the estimated relative gap (E - E*)/E* to the exact optimum "
                   "is at most GAP, or the frame budget (--max-frames, else 40 per keyframe interval) runs "
                   "out (normalized form only) [1e-3 unless --rounds is given]")
    p.add_argument("--rounds", type=nonnegative(int), default=None, metavar="N",
                   help="a fixed number of adaptive subdivision rounds instead of a tolerance (not with "
                   "--tol) [normalized form: rounds until the estimated gap is at most --tol; "
                   "3 with --form paper]")
    p.add_argument("--max-frames", type=nonnegative(int), default=0, metavar="N",
                   help="at most N variable frames in total (0 = no limit) [0]")
    p.add_argument("--form", choices=FORMS, default="normalized",
                   help="objective: normalized (covariant acceleration of q/|q|) or paper (eq. 9 on q, "
                   "renormalized 2:5 on the paper's starting path, docs/orient.md) [normalized]")
    p.add_argument("--rate", type=positive(), default=None, metavar="HZ",
                   help="uniform quadrature (the paper's midpoint rule) at HZ points per second, instead of "
                   "the default Gauss-Legendre rule with 4 nodes on every spline segment")
    p.add_argument("--plot", metavar="FILE.png", default=None,
                   help="also plot the figure-10 comparison of Euler-Lagrange deviations for these keyframes")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(func=run)


def run(args) -> int:
    """The `orient` subcommand. Returns 0; raises InputError on bad input."""
    out = Path(args.out)
    if out.suffix != ".npz":
        raise InputError(f"--out {out}: the output is a NumPy archive; give a file name ending in .npz")
    check_writable_dir(out)
    if args.plot:
        plot = Path(args.plot)
        if plot.suffix.lower() != ".png":
            raise InputError(f"--plot {plot}: give a file name ending in .png")
        check_writable_dir(plot, option="--plot")
    if args.rounds is not None and args.tol is not None:
        raise InputError(f"--rounds {args.rounds} and --tol {args.tol:g}: give one: --rounds for a fixed number of "
                         "adaptive rounds, --tol for rounds until the estimated gap is at most GAP")
    times, quats = read_keyframes(args.keyframes)
    changes = dict(subdivision=args.subdivision, per_segment=args.per_segment, max_frames=args.max_frames)
    if args.rounds is not None:
        changes["rounds"] = args.rounds
    if args.tol is not None:
        if args.form != "normalized":
            raise InputError(f"--tol {args.tol:g}: the estimated gap is to the exact-unit optimum, which only "
                             "the normalized form has; with --form paper give --rounds")
        changes["tol"] = args.tol
    result = orient(times, quats, form=args.form, options=default_options(args.form, **changes), rate=args.rate,
                    source=str(args.keyframes))
    write_result(out, result)
    if not args.quiet:
        print(summary(result, out))
    if args.plot:
        rows = figure10(times, quats, args.plot, result=result, source=str(args.keyframes))
        if not args.quiet:
            print(f"figure 10 (Euler-Lagrange deviation by tenths of the path): {args.plot}")
            for name, dev in rows.items():
                print(f"  {name:<28} total {dev.sum():9.4g}  max tenth {dev.max():9.4g}")
    return 0


def accuracy_line(result) -> str:
    """The estimated gap reached and, with a tolerance, whether it was met (else which budget ran out)."""
    est = result.estimated_gap
    if not np.isfinite(est):
        return "not estimated (the paper form's optimum is not the exact-unit one)"
    text = f"{est:.2g} (relative, (E - E*)/E*)"
    if result.converged_to_tol is None:
        return text + "; fixed rounds, no tolerance"
    if result.converged_to_tol:
        return text + f"; tolerance {result.tol:g} met"
    return text + f"; tolerance {result.tol:g} NOT met: {result.solution.message}"


def summary(result, out=None) -> str:
    """A few lines: objective, energy, estimated gap, max |1 - |q||, frames, time."""
    sol = result.solution
    lines = [
        f"orient: {len(result.keyframe_times)} keyframes, {result.n_variable} variable frames "
        f"({result.form} form, {len(sol.rounds)} round(s), {sol.n_evals} evaluations, {sol.message})",
        f"  objective            {sol.E_initial:.6g} -> {sol.E_final:.6g}",
        f"  angular accel. E     {result.energy_initial:.6g} -> {result.energy:.6g} 1/s^3 "
        "(integral |cov. acc. of q/|q||^2 dt)",
        f"  estimated gap        {accuracy_line(result)}",
        f"  max |1 - |q||        {result.max_norm_deviation:.3g}",
        f"  keyframes met to     {result.keyframe_error:.1e}",
        f"  time                 {result.wall_time_s * 1e3:.1f} ms",
    ]
    if out is not None:
        lines.append(f"  wrote                {out}")
    return "\n".join(lines)

