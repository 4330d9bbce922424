"""`dynsplines orient KEYFRAMES.json --out PATH.npz`: covariant interpolation of one orientation (sec. 3).

Reads keyframe quaternions, optimizes the path (solver.orient), writes it (.npz) and prints a summary;
`--plot` adds the figure-10 comparison of Euler-Lagrange deviations for these keyframes (runner.fig10).

Keyframe file (JSON):
    {"times": [0, 0.8, ...], "quaternions": [[w, x, y, z], ...]}
times in seconds, strictly increasing; quaternions need not be unit (they are normalized, as MuJoCo does).

Output (.npz): frame_times (m,) [s], frames (m, 4) - the path is the natural cubic spline through them -,
keyframe_times (k,), keyframes (k, 4) (normalized, hemisphere-aligned), wall_time_s, objective_trace,
and the summary numbers (form, energy [1/s^3], max_norm_deviation).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from runner.argtypes import nonnegative, positive
from solver.errors import InputError
from solver.solve import SUBDIVISIONS


def register(sub) -> None:
    """Add the `orient` subcommand to the `dynsplines` parser."""
    from solver.orient import FORMS

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
    p.add_argument("--rounds", type=nonnegative(int), default=None, metavar="N",
                   help="adaptive subdivision rounds [2; 3 with --form paper]")
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


def read_keyframes(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read an orientation keyframe file.

    Args:
        path: JSON file {"times": [k numbers], "quaternions": [k lists of 4 numbers (w x y z)]}.
    Returns:
        times (k,) [s], quaternions (k, 4) as given (validated by `solver.orient.check_keyframes`).
    Raises:
        InputError: missing or unreadable file, invalid JSON, missing or malformed field; the message
            names the file, the field and the value.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"keyframe file {path} does not exist")
    try:
        data = json.loads(path.read_text())
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file; expected JSON") from None
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: invalid JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
    if not isinstance(data, dict):
        raise InputError(f'{path}: expected a JSON object {{"times": [...], "quaternions": [...]}}, '
                         f"got {type(data).__name__}")
    for key in ("times", "quaternions"):
        if key not in data:
            raise InputError(f"{path}: missing field {key!r}; the file needs \"times\" and \"quaternions\" "
                             f"(it has: {', '.join(map(repr, data)) or 'nothing'})")
    times, quats = data["times"], data["quaternions"]
    if not isinstance(times, list) or not all(_is_number(t) for t in times):
        raise InputError(f"{path}: field 'times' must be a list of numbers [s], got {_short(times)}")
    if not isinstance(quats, list):
        raise InputError(f"{path}: field 'quaternions' must be a list of [w, x, y, z], got {_short(quats)}")
    for i, q in enumerate(quats):
        if not isinstance(q, list) or len(q) != 4 or not all(_is_number(c) for c in q):
            raise InputError(f"{path}: quaternions[{i}] is {_short(q)}; expected 4 numbers [w, x, y, z]")
    if len(times) != len(quats):
        raise InputError(f"{path}: {len(times)} times but {len(quats)} quaternions; give one time per quaternion")
    return np.asarray(times, dtype=float), np.asarray(quats, dtype=float).reshape(-1, 4)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _short(v) -> str:
    s = json.dumps(v)
    return s if len(s) <= 60 else s[:57] + "..."


def write_result(path: str | Path, result) -> None:
    """Write an OrientResult as .npz atomically (temporary file in the same folder, then rename)."""
    from runner.files import atomic_output

    fr = result.frames
    with atomic_output(path, suffix=".npz") as tmp:
        np.savez(
            tmp,
            frame_times=fr.times,
            frames=fr.values,
            keyframe_times=result.keyframe_times,
            keyframes=result.keyframes,
            is_keyframe=fr.is_keyframe,
            wall_time_s=np.float64(result.wall_time_s),
            objective_trace=result.objective_trace,
            form=np.str_(result.form),
            weights=np.asarray(result.weights),
            energy=np.float64(result.energy),
            energy_initial=np.float64(result.energy_initial),
            max_norm_deviation=np.float64(result.max_norm_deviation),
        )


def run(args) -> int:
    """The `orient` subcommand. Returns 0; raises InputError on bad input."""
    from runner.files import check_writable_dir
    from solver.orient import default_options, orient

    out = Path(args.out)
    if out.suffix != ".npz":
        raise InputError(f"--out {out}: the output is a NumPy archive; give a file name ending in .npz")
    check_writable_dir(out)
    if args.plot:
        plot = Path(args.plot)
        if plot.suffix.lower() != ".png":
            raise InputError(f"--plot {plot}: give a file name ending in .png")
        check_writable_dir(plot, option="--plot")
    times, quats = read_keyframes(args.keyframes)
    changes = dict(subdivision=args.subdivision, per_segment=args.per_segment, max_frames=args.max_frames)
    if args.rounds is not None:
        changes["rounds"] = args.rounds
    result = orient(times, quats, form=args.form, options=default_options(args.form, **changes), rate=args.rate,
                    source=str(args.keyframes))
    write_result(out, result)
    if not args.quiet:
        print(summary(result, out))
    if args.plot:
        from runner.fig10 import figure10

        rows = figure10(times, quats, args.plot, result=result, source=str(args.keyframes))
        if not args.quiet:
            print(f"figure 10 (Euler-Lagrange deviation by tenths of the path): {args.plot}")
            for name, dev in rows.items():
                print(f"  {name:<28} total {dev.sum():9.4g}  max tenth {dev.max():9.4g}")
    return 0


def summary(result, out=None) -> str:
    """A few lines: objective, energy, max |1 - |q||, frames, time."""
    sol = result.solution
    lines = [
        f"orient: {len(result.keyframe_times)} keyframes, {result.n_variable} variable frames "
        f"({result.form} form, {len(sol.rounds)} round(s), {sol.n_evals} evaluations, {sol.message})",
        f"  objective            {sol.E_initial:.6g} -> {sol.E_final:.6g}",
        f"  angular accel. E     {result.energy_initial:.6g} -> {result.energy:.6g} 1/s^3 "
        "(integral |cov. acc. of q/|q||^2 dt)",
        f"  max |1 - |q||        {result.max_norm_deviation:.3g}",
        f"  keyframes met to     {result.keyframe_error:.1e}",
        f"  time                 {result.wall_time_s * 1e3:.1f} ms",
    ]
    if out is not None:
        lines.append(f"  wrote                {out}")
    return "\n".join(lines)
