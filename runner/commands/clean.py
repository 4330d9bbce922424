"""`dynsplines clean CLIP.bvh`: the clip cleaned, its performance kept (the work is
`runner.clean.process_clean`; this module is argument glue)."""
from __future__ import annotations

import shlex
import sys
from pathlib import Path

from runner.exit_codes import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from runner.parser import positive

PROG = "dynsplines clean"


def _times(text: str) -> tuple:
    """--pin T1,T2,... [s], or a keyframe file (.json) whose keyframes' times are the pins (`_keyframe_times`)."""
    import argparse

    if text.lower().endswith(".json"):
        return _keyframe_times(text)
    try:
        return tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of times in seconds, e.g. 0.5,1.25") from None


def _keyframe_times(path: str) -> tuple:
    """The times [s] of a keyframe file's keyframes (its "keyframes", each with its "time", on the clip's own
    timeline: the keys `mocap` chose for the clip, or an animator's): the frames a clean keeps as captured.

    Raises:
        argparse.ArgumentTypeError: the file cannot be read as JSON, or has no keyframe with a finite time (the
            message names the file and the fix, one line).
    """
    import argparse
    import math

    from solver.errors import InputError
    from solver.keyframe_file import read_document

    try:
        doc = read_document(path)
    except InputError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    keys = doc.get("keyframes") if isinstance(doc, dict) else None
    times = [k.get("time") for k in keys if isinstance(k, dict)] if isinstance(keys, list) else []
    if not times or not all(isinstance(t, int | float) and not isinstance(t, bool) and math.isfinite(t) for t in times):
        raise argparse.ArgumentTypeError(f"{path}: no keyframe times to pin (its \"keyframes\", each with a finite "
                                         "\"time\" [s]); give a keyframe file as mocap writes it, or times: --pin 0.5,1.25")
    return tuple(float(t) for t in times)


def add_pin_arguments(p, each: str = "") -> None:
    """`--pin T1,T2` (repeatable) and `--pin-ends` (`clean`; `batch --mode clean`, with `each` saying that
    every clip takes the same pins)."""
    p.add_argument("--pin", type=_times, action="append", default=[], metavar="T1,T2",
                   help="times [s] where the clip is kept exactly as captured (each on the nearest frame), or a "
                        "keyframe file (.json) whose keyframes' times are pinned, e.g. the keys mocap chose; may be "
                        f"repeated{each} [none]")
    p.add_argument("--pin-ends", action="store_true",
                   help="keep the clip's first and last frame exactly as captured too (to join it to other clips); "
                        "a contact that runs into them is then fixed only where it can be")


def pins_of(args) -> tuple:
    """The times [s] of every --pin given, in order."""
    return tuple(t for group in args.pin for t in group)


def add_newton_argument(p) -> None:
    """--gauss-newton (`LeastChangeOptions.newton`), for `clean` and the clean mode of `batch` and `bench corpus`."""
    p.add_argument("--gauss-newton", action="store_true",
                   help="the multipliers' rounds first, preconditioned by the constraints' curvature too, then the "
                        "least violation where they stall (the default searches first, which is cheaper; docs/solvers.md)")


def register(sub) -> None:
    """Add `clean` to the `dynsplines` parser."""
    from runner.capture.scene import AUTO
    from runner.commands.mocap import add_figure_arguments, add_root_scale_argument

    p = sub.add_parser(
        "clean", help="a motion-capture clip in, the same clip with its feet fixed out (the performance kept)",
        description="Clean a BVH clip: the capture plus the least displacement that keeps the feet out of the floor, "
                    "planted in contact and clear in flight, knees and elbows on their hinges, no new jolts "
                    "(motion displacement mapping; docs/mocap.md \"Cleaning a clip\"). Where nothing must change the "
                    "capture comes back exactly. Outputs go to renders/<clip stem>/ unless given: <stem>.clean.npz, "
                    "<stem>.clean.bvh (on the source skeleton), <stem>.clean.glb, <stem>.clean.metrics.json, <stem>.clean.mp4, "
                    "<stem>.contacts.json (the contacts cleaned with: edit them and give them back with --contacts).")
    p.add_argument("clip", type=Path, help="BVH clip, e.g. models/cmu/16_23.bvh")
    add_pin_arguments(p)
    p.add_argument("--feet", choices=("planted", "captured"), default="planted",  # solver.displacement.FEET
                   help="a foot in contact: planted (slides no more than the pins force) or as captured "
                        "(only penetration, float and flight cleaned) [%(default)s]")
    p.add_argument("--contacts", type=Path, default=None, metavar="FILE.json",
                   help="the contacts to clean with instead of those detected: the <stem>.contacts.json a clean wrote, "
                        "edited (a slow step detected as a planted foot: split or delete its contact), or a keyframe "
                        "file of the clip with contacts [detected]")
    p.add_argument("--out-dir", type=Path, default=None, help="output folder [renders/<clip stem>/ in the current folder]")
    p.add_argument("--scene", default=AUTO,
                   help="scene MJCF, or 'auto' (default): a floor and boxes fitted to where the clip's feet rest")
    add_figure_arguments(p)
    add_root_scale_argument(p)
    p.add_argument("--no-render", action="store_true", help="skip the video")
    p.add_argument("--fps", type=positive(float), default=30.0, help="video frames per second [%(default)s]")
    p.add_argument("--max-time", type=positive(float), default=None, metavar="S", help="stop the solve after S seconds")
    add_newton_argument(p)
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--no-summary", action="store_true", help="do not print the summary")
    p.set_defaults(func=run)


def run(args) -> int:
    from runner.clean import CleanOptions, process_clean
    from solver.least_change import LeastChangeOptions

    solve = LeastChangeOptions(max_time_s=args.max_time or 0.0, newton=args.gauss_newton) \
        if args.max_time or args.gauss_newton else None
    o = CleanOptions(pins=pins_of(args), pin_ends=args.pin_ends, feet=args.feet, scene=args.scene, figure=args.figure,
                     mass=args.mass, root_scale=args.root_scale, skeleton_map=args.skeleton_map, solve=solve, contacts=args.contacts,
                     render=not args.no_render, fps=args.fps, quiet=args.quiet, summary=not args.no_summary,
                     command=shlex.join(["dynsplines", "clean", *sys.argv[2:]]))
    result = process_clean(args.clip, args.out_dir, o)
    return {"ok": EXIT_OK, "interrupted": EXIT_INTERRUPTED}.get(result["exit"], EXIT_FAILED)
