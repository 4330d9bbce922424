"""The options of `dynsplines animate` and `run-and-step` (also what `dynsplines bench` runs): the parser
arguments and the SolveOptions they make."""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from runner.parser import nonnegative, positive
from runner.render import side_by_side
from runner.render.side_by_side import PANELS
from solver.animate import DEFAULT_RATE, default_options
from solver.errors import InputError
from solver.optimize import ALGORITHMS
from solver.problem import parse_terms, term_names
from solver.solve import SCORES, SUBDIVISIONS, SolveOptions

#: the library's settings (`solver.default_options`): the command's defaults are these, not its own
_LIB = default_options({})


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 960x540") from None
    if w <= 0 or h <= 0 or w > 3840 or h > 2160:
        raise argparse.ArgumentTypeError(f"--size {text!r}: width and height must be 1..3840 x 1..2160")
    return w, h




def _panels(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    bad = [n for n in names if n not in PANELS]
    if bad or not names or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(
            f"--panels {text!r}: expected a comma-separated list of distinct panels from {', '.join(PANELS)}, "
            "e.g. plain,optimized,reference")
    return names


def _camera(text: str) -> float:
    try:
        return side_by_side.parse_camera(text)
    except InputError as e:
        raise argparse.ArgumentTypeError(str(e).removeprefix(f"--camera {text!r}: ")) from None


def _weight(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"--weight {text!r}: expected NAME=VALUE, e.g. torque=0.1")
    try:
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--weight {text!r}: {value!r} is not a number") from None


def add_options(p: argparse.ArgumentParser, *, defaults: dict | None = None) -> None:
    """The options shared by `animate` and `run-and-step`."""
    d = defaults or {}
    out = p.add_argument_group("outputs")
    out.add_argument("--out", type=Path, default=d.get("out"),
                     help="video file (.mp4) [%(default)s]" if d.get("out") is not None else
                     "video file (.mp4) [renders/<keyframe file name>.mp4, e.g. renders/walk.mp4 for "
                     "walk.keyframes.json]")
    out.add_argument("--save-path", type=Path, default=d.get("save_path"),
                     help="optimized path (.npz; see README) [%(default)s]")
    out.add_argument("--no-render", action="store_true", help="skip the video")
    out.add_argument("--fps", type=positive(float), default=30.0, help="video frames per second [%(default)s]")
    out.add_argument("--size", type=_size, default=(960, 540), metavar="WxH", help="video size [960x540]")
    out.add_argument("--panels", type=_panels, default=("plain", "optimized"), metavar="LIST",
                     help="video panels, left to right, from plain,optimized,reference (the motion capture "
                          "the keyframes were made from) [plain,optimized]")
    out.add_argument("--reference-panel", dest="panels", action="store_const",
                     const=("plain", "optimized", "reference"),
                     help="the same as --panels plain,optimized,reference")
    out.add_argument("--speed", type=positive(float), default=0.5, help="playback speed [%(default)s x real time]")
    out.add_argument("--camera", type=_camera, default="side", metavar="SIDE|DEG", help=side_by_side.CAMERA_HELP)
    out.add_argument("--plot", type=Path, default=None, metavar="DIR", help="write plots (PNG) to DIR")
    out.add_argument("--export", type=Path, action="append", default=[], metavar="FILE",
                     help="also write the optimized path as FILE.bvh (BVH on the figure's skeleton) or FILE.glb "
                          "(animated glTF with the scene), after the path is saved; repeatable")
    add_solve_arguments(p)
    p.add_argument("--quiet", action="store_true",
                   help="no progress (bars or lines); results (summary, 'wrote ...') are still printed")
    p.add_argument("--no-summary", action="store_true", help="do not print the summary table")


def add_solve_arguments(p: argparse.ArgumentParser) -> None:
    """The "optimization" options of `add_options` (what `solve_options` reads); also `dynsplines batch`'s."""
    opt = p.add_argument_group("optimization")
    opt.add_argument("--terms", default=None,
                     help=f"objective terms: 'all' or a list from {','.join(term_names())} "
                          "[the keyframe file's, else penetration,unit,bending,smooth]")
    opt.add_argument("--weight", type=_weight, action="append", default=[], metavar="NAME=VALUE",
                     help="weight of a term (repeatable), e.g. --weight torque=0.1")
    opt.add_argument("--max-time", type=nonnegative(float), default=_LIB.max_time_s, metavar="S",
                     help="stop optimizing after S seconds, keeping the best path so far [no limit]")
    opt.add_argument("--subdivision", choices=SUBDIVISIONS, default=_LIB.subdivision,
                     help="where to add variable frames [%(default)s]")
    opt.add_argument("--per-segment", type=nonnegative(int), default=_LIB.per_segment,
                     help="variable frames per keyframe interval to start with [%(default)s]")
    opt.add_argument("--rounds", type=nonnegative(int), default=None,
                     help="a fixed number of adaptive subdivision rounds instead of the tolerance (ignored if "
                          "--tol is given too) [rounds until --tol]")
    opt.add_argument("--tol", type=positive(float), default=None, metavar="X",
                     help="refine adaptively until the decrease of E that refinement still predicts, relative "
                          "to E, is at most X, or the frame budget (--max-frames, else 10 per keyframe "
                          f"interval) or --max-time runs out [{_LIB.tol:g}]")
    opt.add_argument("--max-frames", type=nonnegative(int), default=_LIB.max_frames, metavar="N",
                     help="at most N variable frames in total (0 = no limit; with --tol 10 per keyframe "
                          "interval) [%(default)s]")
    opt.add_argument("--algorithm", choices=list(ALGORITHMS), default=_LIB.algorithm, help="nlopt algorithm [%(default)s]")
    opt.add_argument("--ftol", type=nonnegative(float), default=_LIB.ftol_rel, help="relative objective tolerance [%(default)s]")
    opt.add_argument("--max-evals", type=nonnegative(int), default=_LIB.max_evals, help="evaluations per round [no limit]")
    opt.add_argument("--rate", type=positive(float), default=DEFAULT_RATE,
                     help="quadrature points per second [%(default)s]")
    opt.add_argument("--score", choices=SCORES, default=_LIB.score,
                     help="how adaptive subdivision ranks segments: the decrease of E a midpoint frame "
                          "predicts, or the raw weak-form Euler-Lagrange gradient [%(default)s]")
    opt.add_argument("--no-precondition", action="store_true",
                     help="optimize the frame values directly instead of in the spline-acceleration metric")
    opt.add_argument("--no-renormalize", action="store_true",
                     help="use the weights as they are instead of dividing each term by its initial value (eq. 7)")


def clip_terms(args) -> dict:
    """`ClipOptions` fields for the objective of clips whose contacts are not known yet (`mocap`,
    `batch`): {"terms": the --terms spec, "weights": the --weight overrides, "solve": solve_options}.
    The spec is checked here (a bad name or weight is an InputError before any clip is read) as if a
    contact schedule were known; `process_clip` chooses the terms with the clip's own contacts."""
    weights = parse_terms(args.terms, dict(args.weight), contacts=(None,))
    return {"terms": args.terms, "weights": dict(args.weight), "solve": solve_options(args, weights)}


def solve_options(args, weights: dict) -> SolveOptions:
    """`solver.default_options(weights)` with the parsed `add_options` arguments applied (the command's
    and the benchmark's settings)."""
    if getattr(args, "tol", None) and args.subdivision != "adaptive":
        raise InputError(f"--tol {args.tol:g} refines adaptively; it does not go with --subdivision "
                         f"{args.subdivision}")
    return replace(
        default_options(weights),
        subdivision=args.subdivision, per_segment=args.per_segment,
        renormalize=not args.no_renormalize, algorithm=args.algorithm, ftol_rel=args.ftol,
        max_evals=args.max_evals, max_time_s=args.max_time, precondition=not args.no_precondition,
        score=args.score, max_frames=args.max_frames,
        tol=args.tol if args.tol is not None else 0.0 if args.rounds is not None else _LIB.tol,
        rounds=_LIB.rounds if args.rounds is None else args.rounds,
    )


def default_args() -> argparse.Namespace:
    """The options `animate` uses when none are given."""
    p = argparse.ArgumentParser()
    add_options(p)
    return p.parse_args([])
