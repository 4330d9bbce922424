"""The options of `dynsplines animate` and `run-and-step` (also what `dynsplines bench` runs): the parser
arguments and the LeastChangeOptions they make."""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from runner.parser import nonnegative, positive
from runner.render import side_by_side
from runner.render.side_by_side import PANELS
from solver.errors import InputError
from solver.least_change import LeastChangeOptions
from solver.problem import forces_of


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
    lc = LeastChangeOptions()
    opt = p.add_argument_group("optimization: the least change to the plain spline that meets the constraints "
                               "(docs/design.md)")
    opt.add_argument("--terms", default=None, metavar="SET",
                     help="'default': the figure's constraints (penetration, planted feet, clearance, hinges, "
                          "range of motion, no jolts); 'all': also the force bounds (no wrench in flight, the "
                          "friction cone, the peak ground force) "
                          f"[{terms_help or 'the keyframe file’s, else default'}]")
    opt.add_argument("--tol", type=positive(float), default=None, metavar="X",
                     help="add variable frames until the decrease of the measure of change that refinement "
                          f"still predicts, relative to it, is at most X and every constraint holds [{lc.tol:g}]")
    opt.add_argument("--max-time", type=nonnegative(float), default=0.0, metavar="S",
                     help="stop optimizing after S seconds, keeping the best path so far [no limit]")
    opt.add_argument("--max-evals", type=nonnegative(int), default=0, metavar="N",
                     help="evaluations of the whole solve; when they are spent, keep the best path so far [no limit]")
    opt.add_argument("--rate", type=positive(float), default=lc.rate,
                     help="quadrature points per second [%(default)s]")


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
    """`ClipOptions` fields of the parsed arguments (`mocap`, `batch`, `bench corpus`): {"forces": whether
    --terms all, "solve": `solve_options`}, checked before any clip is read.

    Raises:
        InputError: a --terms other than default or all.
    """
    return {"forces": forces_of(args.terms, "--terms"), "solve": solve_options(args)}


def solve_options(args) -> LeastChangeOptions:
    """The solve options of the parsed `add_options` arguments (the command's and the benchmarks'
    settings): `LeastChangeOptions` with --tol, --max-time, --max-evals and --rate applied."""
    lc = LeastChangeOptions()
    tol = getattr(args, "tol", None)
    return replace(lc, tol=lc.tol if tol is None else tol, max_time_s=getattr(args, "max_time", 0.0) or 0.0,
                   max_evals=getattr(args, "max_evals", 0) or 0, rate=getattr(args, "rate", lc.rate))


def default_args() -> argparse.Namespace:
    """The options `animate` uses when none are given."""
    p = argparse.ArgumentParser()
    add_options(p)
    return p.parse_args([])
