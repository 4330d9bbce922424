"""`dynsplines keyframes-from-bvh CLIP --out FILE`: a keyframe file made from a BVH motion-capture clip.

Arguments: CLIP (a .bvh file), --out FILE (.keyframes.json), --every SECONDS (0.25), --scene MJCF
(models/run_and_step.xml), --model MJCF (the figure, default humanoid39.xml beside the scene).
The written file records the command in "source" (solver/keyframe_file.py format).
"""
from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path
from typing import Sequence

from runner.exit_codes import EXIT_INPUT, EXIT_OK
from runner.mocap.keyframes import keyframes_from_reference
from runner.mocap.reference import load_bvh_reference
from runner.parser import OneLineParser
from runner.paths import MODELS
from solver.errors import InputError
from solver.keyframe_file import write_keyframes
from solver.layout import StateLayout
from solver.model import check_scene, load_model

PROG = "dynsplines keyframes-from-bvh"
DEFAULT_SCENE = MODELS / "run_and_step.xml"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of the command (also used by `keyframes_from_bvh_main`)."""
    p.add_argument("clip", help="BVH clip (CMU skeleton), e.g. models/cmu/127_33.bvh")
    p.add_argument("--out", required=True, help="keyframe file to write (.keyframes.json)")
    p.add_argument("--every", type=float, default=0.25, help="keyframe spacing [s] (default 0.25)")
    p.add_argument("--scene", default=str(DEFAULT_SCENE), help="scene MJCF (figure + surfaces)")
    p.add_argument("--model", default=None, help="figure MJCF (default: humanoid39.xml beside the scene)")


def register(sub) -> None:
    """Add `keyframes-from-bvh` to the `dynsplines` parser."""
    p = sub.add_parser("keyframes-from-bvh", help="make a keyframe file from a BVH motion-capture clip",
                       description="Make a keyframe file from a CMU BVH clip retargeted onto the figure.")
    add_arguments(p)
    p.set_defaults(func=run)


def command_line(args) -> str:
    """The command that makes the same file, as recorded in its "source"."""
    words = [args.clip, "--out", args.out, "--every", f"{args.every:g}", "--scene", args.scene]
    if args.model:
        words += ["--model", args.model]
    return f"{PROG} {shlex.join(str(w) for w in words)}"


def run(args, command: str | None = None) -> int:
    """Run the command for parsed arguments. Returns 0; raises InputError on bad input.

    Args:
        args: parsed `add_arguments` arguments. command: the command recorded in the file's "source"
            [`command_line(args)`].
    """
    scene = Path(args.scene)
    figure = Path(args.model) if args.model else scene.parent / "humanoid39.xml"
    if not args.model and not figure.is_file():
        figure = MODELS / "humanoid39.xml"  # the scene includes the figure by another path
    model = load_model(scene)
    check_scene(model, scene)  # before the work, not when `animate` builds the penetration term
    reference = load_bvh_reference(args.clip, model)
    keyframes = keyframes_from_reference(reference, model, every=args.every)
    out = Path(args.out)
    source = {
        "clip": _relpath(Path(args.clip), out.parent),
        "command": command or command_line(args),
        "hand_edits": "none",
    }
    write_keyframes(out, keyframes, StateLayout.from_model(model), model=figure, scene=scene, source=source)
    print(
        f"wrote {args.out}: {keyframes.count} keyframes at {', '.join(f'{t:.3f}' for t in keyframes.times)} s "
        f"({int(keyframes.is_partial.sum())} partial) from {reference.count} frames of {args.clip}"
    )
    return EXIT_OK


def keyframes_from_bvh_main(argv: Sequence[str] | None = None, prog: str | None = None, debug: bool = False) -> int:
    """The command as a function (for scripts and tests): parse `argv`, run, map bad input to exit code 2.

    Args:
        argv: the arguments (without the program name); None = sys.argv[1:].
        prog: how the command was invoked, recorded (followed by the arguments) in the file [PROG].
        debug: re-raise an InputError (its traceback) instead of printing its message.
    Returns:
        0 on success, 2 on bad input (the message goes to stderr).
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = OneLineParser(prog=prog or PROG,
                       description="Make a keyframe file from a CMU BVH clip retargeted onto the figure.")
    add_arguments(ap)
    try:
        args = ap.parse_args(argv)
    except SystemExit as e:  # --help (0) or a usage error (2, its one-line message printed)
        return e.code if isinstance(e.code, int) else EXIT_INPUT
    try:
        return run(args, command=f"{prog or PROG} {shlex.join(argv)}")
    except InputError as e:
        if debug:
            raise
        print(f"dynsplines: error: {e}", file=sys.stderr)
        return EXIT_INPUT


def _relpath(path: Path, start: Path) -> str:
    return Path(os.path.relpath(path.resolve(), start.resolve())).as_posix()
