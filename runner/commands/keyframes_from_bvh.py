"""`dynsplines keyframes-from-bvh CLIP --out FILE`: a keyframe file made from a BVH motion-capture clip.

Arguments: CLIP (a .bvh file), --out FILE (.keyframes.json), --every SECONDS (0.25), --keys every|contacts,
--scene auto|MJCF (auto: a floor and boxes fitted to the clip, written next to --out), --figure
subject|default|MJCF (default: the subject's own figure, written next to --out as NAME.figure.xml),
--mass KG, --skeleton-map FILE, --partial, --no-root-extremes.
The written file records the command in "source" and the clip's contacts in "contacts"
(solver/keyframe_file.py format).
"""
from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

from runner.capture.capture_keys import KEY_CHOICES
from runner.capture.figure_choice import SUBJECT
from runner.capture.gaps import clip_gaps, gaps_line
from runner.capture.glitches import glitches_line
from runner.capture.reference_motion import ROOT_SCALE_LEGS
from runner.commands.mocap import (
    add_figure_arguments,
    add_key_frames_argument,
    add_root_scale_argument,
    add_scene_arguments,
)
from runner.exit_codes import EXIT_INPUT, EXIT_OK
from runner.parser import OneLineParser
from runner.pipeline import CLIP_STAGES, ClipKeys, write_clip_keyframes
from runner.progress import Steps
from solver.errors import InputError

PROG = "dynsplines keyframes-from-bvh"


def fitted_scene_path(out: Path) -> Path:
    """Where `--scene auto` writes the fitted scene: next to `out`, `<name>.scene.xml`."""
    name = out.name
    for suffix in (".keyframes.json", ".json"):
        if name.endswith(suffix):
            name = name[: -len(suffix)]
            break
    return out.parent / f"{name}.scene.xml"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of the command (also used by `keyframes_from_bvh_main`)."""
    p.add_argument("clip", help="BVH clip (a human skeleton of any common convention), e.g. models/cmu/127_33.bvh")
    p.add_argument("--out", required=True, help="keyframe file to write (.keyframes.json)")
    p.add_argument("--every", type=float, default=None,
                   help="keyframe spacing [s] (default 0.25); with --keys contacts the largest gap (default none)")
    p.add_argument("--keys", choices=KEY_CHOICES, default="every",
                   help="every: evenly spaced keys plus the root's highest and lowest frames; contacts: keys at "
                        "touch-downs and lift-offs, the ends and the root's extremes [%(default)s]")
    add_scene_arguments(p, written="next to --out as NAME.scene.xml")
    add_figure_arguments(p)
    p.add_argument("--partial", action="store_true",
                   help="make the middle keyframe partial: it fixes only the root and the legs (torso and arms "
                        "free for the optimizer); default: full keyframes")
    add_key_frames_argument(p)
    p.add_argument("--no-root-extremes", action="store_true",
                   help="with --keys every: do not add keys at the root's highest and lowest frames")
    p.add_argument("--quiet", action="store_true", help="no progress bar; the 'wrote ...' line is still printed")
    add_root_scale_argument(p)


def register(sub) -> None:
    """Add `keyframes-from-bvh` to the `dynsplines` parser."""
    p = sub.add_parser("keyframes-from-bvh", help="make a keyframe file from a BVH motion-capture clip",
                       description="Make a keyframe file from a BVH clip retargeted onto the figure. "
                                   "Without --scene, the scene is fitted to the clip (--scene auto).")
    add_arguments(p)
    p.set_defaults(func=run)


def command_line(args) -> str:
    """The command that makes the same file, as recorded in its "source"."""
    words = [args.clip, "--out", args.out]
    if args.every is not None:
        words += ["--every", f"{args.every:g}"]
    words += ["--keys", args.keys, "--scene", args.scene]
    if args.boxes is not None:
        words += ["--boxes", args.boxes]
    if str(args.figure) != SUBJECT:
        words += ["--figure", args.figure]
    if args.mass is not None:
        words += ["--mass", f"{args.mass:g}"]
    if args.skeleton_map is not None:
        words += ["--skeleton-map", args.skeleton_map]
    words += ["--partial"] * bool(args.partial) + ["--no-root-extremes"] * bool(args.no_root_extremes)
    if args.root_scale != ROOT_SCALE_LEGS:
        words += ["--root-scale", f"{args.root_scale:g}"]
    if args.key_frames is not None:
        words += ["--key-frames", ",".join(str(f) for f in args.key_frames)]
    if args.key_joints is not None:
        words += ["--key-joints", args.key_joints]
    return f"{PROG} {shlex.join(str(w) for w in words)}"


def run(args, command: str | None = None) -> int:
    """Run the command for parsed arguments. Returns 0; raises InputError on bad input.

    Args:
        args: parsed `add_arguments` arguments. command: the command recorded in the file's "source"
            [`command_line(args)`].
    """
    out = Path(args.out)
    if not out.parent.is_dir():
        raise InputError(f"--out {out}: the folder {out.parent} does not exist; create it first")
    k = ClipKeys(scene=args.scene, figure=args.figure, mass=args.mass, root_scale=args.root_scale,
                 skeleton_map=args.skeleton_map,
                 keys=args.keys, every=args.every, partial=args.partial, extremes=not args.no_root_extremes,
                 key_frames=args.key_frames, key_joints=args.key_joints, boxes=args.boxes,
                 command=command or command_line(args))
    with Steps(f"keyframes from {Path(args.clip).name}", len(CLIP_STAGES), args.quiet, unit=" stages") as bar:
        cs, contacts, keyframes = write_clip_keyframes(Path(args.clip), out, k, fitted_scene_path(out),
                                                       progress=lambda i, stage: bar.update(i, note=stage))
    reference = cs.reference
    scene_note = f"fitted scene {cs.scene_path}" if cs.fitted is not None else f"scene {cs.scene_path}"
    print(
        f"wrote {args.out}: {keyframes.count} keyframes at {', '.join(f'{t:.3f}' for t in keyframes.times)} s "
        f"({int(keyframes.is_partial.sum())} partial), {len(contacts)} contacts, from {reference.count} frames "
        f"of {args.clip}; {scene_note}"
    )
    if cs.fitted is not None or reference.captured_root:
        from runner.capture.root_height import feet_line

        print(f"  retargeted clip: {feet_line(reference, cs.model)}")
    if (glitch := glitches_line(reference.glitches)) is not None:
        print(f"  {glitch}")
    if (gap := gaps_line(clip_gaps(reference))) is not None:
        print(f"  {gap}")
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
                       description="Make a keyframe file from a BVH clip retargeted onto the figure.")
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
