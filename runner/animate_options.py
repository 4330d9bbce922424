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
from solver.least_change import LeastChangeOptions
from solver.optimize import ALGORITHMS
from solver.problem import parse_terms, term_names
from solver.solve import SCORES, SUBDIVISIONS, SolveOptions

#: the solve methods of --method (docs/design.md)
METHODS = ("least-change", "penalty")
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
                     help=f"video file (.mp4) [{d.get('out_help') or '%(default)s'}]")
    out.add_argument("--save-path", type=Path, default=d.get("save_path"),
                     help=f"optimized path (.npz; docs/saved-path.md) [{d.get('save_path_help') or '%(default)s'}]")
    out.add_argument("--no-render", action="store_true", help="skip the video")
    out.add_argument("--fps", type=positive(float), default=30.0, help="video frames per second [%(default)s]")
    out.add_argument("--size", type=_size, default=(960, 540), metavar="WxH", help="video size [960x540]")
    panels = d.get("panels", ("plain", "optimized"))
    out.add_argument("--panels", type=_panels, default=panels, metavar="LIST",
                     help="video panels, left to right, from plain,optimized,reference (the motion capture "
                          f"the keyframes were made from) [{','.join(panels)}]")
    out.add_argument("--reference-panel", dest="panels", action="store_const",
                     const=("plain", "optimized", "reference"),
                     help="the same as --panels plain,optimized,reference")
    out.add_argument("--speed", type=positive(float), default=0.5, help="playback speed [%(default)s x real time]")
    out.add_argument("--camera", type=_camera, default="side", metavar="SIDE|DEG", help=side_by_side.CAMERA_HELP)
    out.add_argument("--plot", type=Path, default=None, metavar="DIR", help="write plots (PNG) to DIR")
    out.add_argument("--export", type=Path, action="append", default=[], metavar="FILE",
                     help="also write the optimized path as FILE.bvh (BVH on the figure's skeleton) or FILE.glb "
                          "(animated glTF with the scene), after the path is saved; repeatable")
    add_solve_arguments(p, terms_help=d.get("terms_help"))
    p.add_argument("--quiet", action="store_true",
                   help="no progress (bars or lines); results (summary, 'wrote ...') are still printed")
    p.add_argument("--no-summary", action="store_true", help="do not print the summary table")


def add_solve_arguments(p: argparse.ArgumentParser, terms_help: str | None = None) -> None:
    """The "optimization" options of `add_options` (what `solve_options` reads); also `dynsplines batch`'s.
    `terms_help`: what --terms defaults to for this command (its help's [default])."""
    opt = p.add_argument_group("optimization")
    opt.add_argument("--method", choices=METHODS, default=None,
                     help="least-change: the least change to the plain spline that meets the constraints "
                          "(docs/design.md; with --tol, --max-time, --max-evals); penalty: the weighted terms "
                          "of paper eq. 1 (every other option below) [least-change; penalty when an option "
                          "only it has is given]")
    opt.add_argument("--terms", default=None,
                     help="'all': the least change with the force bounds too (ballistic flights, the friction "
                          "cone, the peak ground force; docs/design.md); a list of terms from "
                          f"{','.join(term_names())}: the penalty method "
                          f"[{terms_help or 'the keyframe file’s, else the default terms; with its contacts also planted,clearance'}]")
    opt.add_argument("--weight", type=_weight, action="append", default=[], metavar="NAME=VALUE",
                     help="weight of a term (repeatable), e.g. --weight torque=0.1")
    opt.add_argument("--max-time", type=nonnegative(float), default=_LIB.max_time_s, metavar="S",
                     help="stop optimizing after S seconds, keeping the best path so far [no limit]")
    opt.add_argument("--subdivision", choices=SUBDIVISIONS, default=_LIB.subdivision,
                     help="where to add variable frames [%(default)s]")
    opt.add_argument("--per-segment", type=nonnegative(int), default=_LIB.per_segment,
                     help="variable frames per keyframe interval to start with [%(default)s]")
    opt.add_argument("--rounds", type=nonnegative(int), default=None,
                     help="refine for N fixed adaptive subdivision rounds instead of to a tolerance (not "
                          "with --tol) [rounds until --tol]")
    opt.add_argument("--tol", type=positive(float), default=None, metavar="X",
                     help="refine adaptively until the decrease of E that refinement still predicts, relative "
                          "to E, is at most X (not with --rounds), or the frame budget (--max-frames, else 10 per keyframe "
                          f"interval) or --max-time runs out [{_LIB.tol:g}]")
    opt.add_argument("--max-frames", type=nonnegative(int), default=_LIB.max_frames, metavar="N",
                     help="at most N variable frames in total (0 = no limit; with --tol 10 per keyframe "
                          "interval) [%(default)s]")
    opt.add_argument("--algorithm", choices=list(ALGORITHMS), default=_LIB.algorithm,
                     help="nlopt algorithm of each round [%(default)s]")
    opt.add_argument("--ftol", type=nonnegative(float), default=_LIB.ftol_rel, help="relative objective tolerance [%(default)s]")
    opt.add_argument("--max-evals", type=nonnegative(int), default=_LIB.max_evals, help="evaluations per round [no limit]")
    opt.add_argument("--rate", type=positive(float), default=DEFAULT_RATE,
                     help="quadrature points per second [%(default)s; least-change: "
                          f"{LeastChangeOptions().rate:g}]")
    opt.add_argument("--score", choices=SCORES, default=_LIB.score,
                     help="how adaptive subdivision ranks segments: the decrease of E a midpoint frame "
                          "predicts, or the raw weak-form Euler-Lagrange gradient [%(default)s]")
    opt.add_argument("--no-precondition", action="store_true",
                     help="optimize the frame values directly instead of in the spline-acceleration metric")
    opt.add_argument("--no-renormalize", action="store_true",
                     help="use the weights as they are instead of dividing each term by its initial value (eq. 7)")


def outputs_from_args(args, default_video: Path | None = None, **fields):
    """`runner.run.Outputs` from the parsed `add_options` arguments, each checked before the optimization
    (a writable folder, a video name and size, export names): a bad one is an InputError now, not after
    minutes of solving. `default_video` is the video when --out is not given; `fields` are the
    command's own (e.g. metrics_json).

    Raises:
        InputError: an output that cannot be written (names the option and the file).
    """
    from runner.files import check_writable_dir
    from runner.render.side_by_side import VideoOptions, check_video_out
    from runner.run import Outputs, check_exports

    video = None if args.no_render else (args.out if args.out is not None else default_video)
    for path, option in ((video, "--out"), (args.save_path, "--save-path"), (fields.get("metrics_json"), "--metrics")):
        if path is not None:
            check_writable_dir(path, option)
    if video is not None:
        check_video_out(video, args.size)
    if args.plot is not None:
        check_writable_dir(Path(args.plot) / "plot.png", "--plot")
    check_exports(args.export)
    return Outputs(save_path=args.save_path, exports=tuple(args.export), plot_dir=args.plot, video=video,
                   video_options=VideoOptions.from_args(args),
                   summary=not args.no_summary, quiet=args.quiet,
                   command={k: v for k, v in vars(args).items() if k != "func"}, **fields)


def clip_terms(args) -> dict:
    """`ClipOptions` fields for the objective of clips whose contacts are not known yet (`mocap`,
    `batch`): {"terms": the --terms spec, "weights": the --weight overrides, "solve": solve_options}.
    The spec is checked here (a bad name or weight is an InputError before any clip is read) as if a
    contact schedule were known; `process_clip` chooses the terms with the clip's own contacts."""
    weights = parse_terms(args.terms, dict(args.weight), assume_schedule=True)
    return {"terms": args.terms, "weights": dict(args.weight), "solve": solve_options(args, weights)}


#: the options only the penalty method has, with their defaults (one of them given chooses it)
PENALTY_ONLY = {"terms": None, "weight": [], "subdivision": _LIB.subdivision, "per_segment": _LIB.per_segment,
                "rounds": None, "max_frames": _LIB.max_frames, "algorithm": _LIB.algorithm,
                "score": _LIB.score, "no_precondition": False, "no_renormalize": False}


def method(args) -> str:
    """The solve method of the parsed arguments: --method, else penalty when an option only the penalty
    method has is given (--terms other than all, --weight, --subdivision, --rounds, ...: `PENALTY_ONLY`),
    else least-change."""
    chosen = getattr(args, "method", None)
    if chosen is not None:
        return chosen
    return "penalty" if _penalty_options(args) else "least-change"


def _penalty_options(args) -> list[str]:
    """The `PENALTY_ONLY` options given; `--terms all` is not one of them: the least change with every
    constraint, the force bounds too (`solver.constraints.forces`)."""
    return [k for k, default in PENALTY_ONLY.items() if getattr(args, k, default) != default
            and not (k == "terms" and getattr(args, k) == "all")]


def solve_options(args, weights: dict) -> SolveOptions | LeastChangeOptions:
    """The solve options of the parsed `add_options` arguments (the command's and the benchmark's
    settings). least-change (`method`): `LeastChangeOptions` with --tol and --max-time. penalty:
    `solver.default_options(weights)` with the arguments applied; `--rounds N` selects N fixed adaptive
    rounds (`SolveOptions.refine` "rounds"), `--tol X` (or neither: the default tolerance) refinement to
    a tolerance ("tol").

    Raises:
        InputError: both --rounds and --tol; --tol with a subdivision other than adaptive; --terms or
            --weight with --method least-change.
    """
    tol, rounds = getattr(args, "tol", None), getattr(args, "rounds", None)
    if method(args) == "least-change":
        given = _penalty_options(args)
        if given:
            flags = ", ".join("--" + k.replace("_", "-") for k in given)
            raise InputError(f"{flags}: options of the penalty method; drop them, or use --method penalty")
        lc = LeastChangeOptions()
        rate = getattr(args, "rate", DEFAULT_RATE)
        return replace(lc, tol=lc.tol if tol is None else tol, max_time_s=getattr(args, "max_time", 0.0) or 0.0,
                       max_evals=getattr(args, "max_evals", 0) or 0, rate=lc.rate if rate == DEFAULT_RATE else rate)
    if tol is not None and rounds is not None:
        raise InputError(f"--rounds {rounds} and --tol {tol:g} are two ways to end adaptive refinement; give "
                         "one: --rounds N for N fixed rounds, or --tol X to refine until the estimate is at most X")
    if tol and args.subdivision != "adaptive":
        raise InputError(f"--tol {tol:g} refines adaptively; it does not go with --subdivision "
                         f"{args.subdivision}")
    mode = (dict(refine="rounds", rounds=rounds, tol=0.0) if rounds is not None
            else dict(refine="tol", rounds=None, tol=_LIB.tol if tol is None else tol))
    return replace(
        default_options(weights),
        subdivision=args.subdivision, per_segment=args.per_segment,
        renormalize=not args.no_renormalize, algorithm=args.algorithm, ftol_rel=args.ftol,
        max_evals=args.max_evals, max_time_s=args.max_time, precondition=not args.no_precondition,
        score=args.score, max_frames=args.max_frames, **mode,
    )


def default_args(method: str | None = None) -> argparse.Namespace:
    """The options `animate` uses when none are given; `method` as --method (the benchmarks of term
    sets choose "penalty": a term set is what `animate --terms` solves)."""
    p = argparse.ArgumentParser()
    add_options(p)
    return p.parse_args([] if method is None else ["--method", method])
