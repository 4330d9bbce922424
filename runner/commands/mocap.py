"""`dynsplines mocap CLIP.bvh`: one command from a motion-capture clip to a video, a saved path and a
metrics report (the work is `runner.pipeline.process_clip`; this module is argument glue)."""
from __future__ import annotations

import shlex
import sys
from pathlib import Path

from runner.animate_options import add_options, clip_terms
from runner.capture.capture_keys import KEY_CHOICES
from runner.capture.reference_motion import ROOT_SCALE_LEGS
from runner.capture.scene import AUTO
from runner.exit_codes import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from runner.parser import positive, positive_or
from runner.pipeline import ClipOptions, default_out_dir, process_clip

PROG = "dynsplines mocap"


def register(sub) -> None:
    """Add `mocap` to the `dynsplines` parser."""
    p = sub.add_parser(
        "mocap", help="a motion-capture clip in, an optimized path, a video and metrics out",
        description="Retarget a BVH clip (a human skeleton of any common convention) onto the figure, fit the scene to where its feet rest, "
                    "pick keyframes, optimize the in-betweens and compare the plain spline and the optimized path "
                    "with the clip (motion metrics). Outputs go to renders/<clip stem>/ unless given: "
                    "<stem>.keyframes.json (rerun or edit it with `dynsplines animate`), <stem>.scene.xml (with "
                    "--scene auto), <stem>.npz, <stem>.metrics.json, <stem>.mp4.")
    p.add_argument("clip", type=Path, help="BVH clip, e.g. models/cmu/127_33.bvh")
    p.add_argument("--out-dir", type=Path, default=None,
                   help="output folder [renders/<clip stem>/ in the current folder]")
    add_clip_arguments(p)
    p.add_argument("--metrics", type=Path, default=None, metavar="FILE.json",
                   help="motion metrics and acceptance figures as JSON [<out-dir>/<stem>.metrics.json]")
    add_options(p, defaults={"out_help": "<out-dir>/<stem>.mp4", "save_path_help": "<out-dir>/<stem>.npz",
                             "terms_help": "default"})
    p.set_defaults(func=run)


def add_clip_arguments(p) -> None:
    """The options of a clip's keyframes, scene and figure (`mocap` and `batch`)."""
    keys = p.add_argument_group("keyframes")
    keys.add_argument("--keys", choices=KEY_CHOICES, default="every",
                      help="every: evenly spaced keys plus the root's highest and lowest frames; contacts: keys at "
                           "touch-downs and lift-offs, the ends and the root's extremes [%(default)s]")
    keys.add_argument("--every", type=positive(float), default=None, metavar="S",
                      help="key spacing [s] (0.25); with --keys contacts: at most S s between keys [no limit]")
    keys.add_argument("--partial", action="store_true",
                      help="the middle keyframe fixes only the root and the legs (torso and arms free)")
    add_key_frames_argument(keys)
    add_scene_arguments(p)
    add_figure_arguments(p)
    add_root_scale_argument(p)


def add_scene_arguments(p, written: str = "next to the outputs as <stem>.scene.xml") -> None:
    """`--scene auto|floor|FILE` and `--boxes FILE` (`mocap`, `batch`, `keyframes-from-bvh`)."""
    p.add_argument("--scene", default=AUTO,
                   help="scene MJCF; 'auto' (default): a floor and boxes fitted to where the clip's feet rest; or "
                        "'floor': a level floor at the clip's own height 0 (a DCC's ground plane) and the --boxes; "
                        f"auto and floor are written {written}")
    p.add_argument("--boxes", type=Path, default=None, metavar="FILE.json",
                   help="with --scene floor: boxes in the clip's coordinates (its axes and unit), "
                        "[{\"min\": [x, y, z], \"max\": [x, y, z]}, ...] [none]")


def key_frames(text: str) -> tuple[int, ...]:
    """`--key-frames` "0,30,61": the frame numbers (checked against the clip by `given_indices`)."""
    import argparse

    try:
        return tuple(int(w) for w in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of frame numbers, e.g. 0,30,61") from None


def add_key_frames_argument(p) -> None:
    """`--key-frames F,F,...` (`mocap`, `batch`, `keyframes-from-bvh`)."""
    p.add_argument("--key-frames", type=key_frames, default=None, metavar="F,F,...",
                   help="the clip's frames an animator keyed (0 = its first frame after a rest frame; at least two, "
                        "increasing): they are the keyframes, with the clip's own values (feet not planted), instead "
                        "of --keys and --every; the Blender add-on's in-between [picked by --keys]")
    p.add_argument("--key-joints", type=Path, default=None, metavar="FILE.json",
                   help="with --key-frames: the joints keyed at the partial ones, e.g. {\"30\": [\"LeftUpLeg\", "
                        "\"LeftLeg\"]}: they fix the figure joints those joints drive, the rest is free "
                        "(docs/mocap.md) [every key full]")


def add_skeleton_map_argument(p) -> None:
    """`--skeleton-map FILE` (`mocap`, `batch`, `keyframes-from-bvh`)."""
    p.add_argument("--skeleton-map", type=Path, default=None, metavar="FILE.json",
                   help="a JSON file naming the joint of each role the recogniser cannot find, and optionally the "
                        "unit and up axis, e.g. {\"hips\": \"pelvis\", \"l_foot\": \"foot_l\", \"unit\": \"cm\"} "
                        "(docs/mocap.md, \"Skeleton map\") [none: every role recognised]")


def add_figure_arguments(p) -> None:
    """`--figure subject|default|FILE.xml` (with its older name `--model FILE.xml`), `--mass KG` and
    `--skeleton-map FILE` (`mocap`, `batch`, `keyframes-from-bvh`)."""
    from runner.capture.figure_choice import SUBJECT

    p.add_argument("--figure", "--model", dest="figure", default=SUBJECT, metavar="subject|default|FILE.xml",
                   help="the figure the clip is retargeted onto: 'subject' (default) the subject's own, made from "
                        "the clip's skeleton and written next to the outputs as <stem>.figure.xml (no loss, the root "
                        "path as captured); 'default' the shipped figure (models/humanoid39.xml, fixed proportions); "
                        "or a figure MJCF file (--model FILE is the older name)")
    p.add_argument("--mass", type=positive(float), default=None, metavar="KG",
                   help="body mass of the subject's figure [kg] [from the stature: 22.9 kg/m^2 x stature^2]")
    add_skeleton_map_argument(p)


def add_root_scale_argument(p) -> None:
    """`--root-scale legs|X` (`mocap`, `batch`, `keyframes-from-bvh`)."""
    p.add_argument("--root-scale", type=positive_or(ROOT_SCALE_LEGS), default=ROOT_SCALE_LEGS, metavar="legs|X",
                   help="scale of the captured root path: 'legs' (default) the figure's leg length over the "
                        "subject's, so that its strides cover the subject's ground (1 on the subject's own figure); "
                        "a number, e.g. 1 for the path as captured (a scene built around the capture's coordinates)")


def clip_options(args, prog: str, **fields) -> ClipOptions:
    """`ClipOptions` from the parsed `add_clip_arguments` and solve options (`mocap`, `batch`), with the
    command line recorded as `prog` plus its arguments; `fields` are the command's own (outputs, render)."""
    name = prog.split()[-1]
    return ClipOptions(
        keys=args.keys, every=args.every, partial=args.partial, scene=args.scene, figure=args.figure,
        mass=args.mass, root_scale=args.root_scale, skeleton_map=args.skeleton_map, key_frames=args.key_frames,
        key_joints=args.key_joints, boxes=args.boxes,
        **clip_terms(args),
        command=f"{prog} {shlex.join(sys.argv[2:])}" if sys.argv[1:2] == [name] else prog, **fields,
    )


def run(args) -> int:
    """Run `mocap`. Returns the exit code; raises InputError on bad input."""
    options = clip_options(args, PROG, out=args.out, save_path=args.save_path, metrics=args.metrics, plot=args.plot,
                           render=not args.no_render, fps=args.fps, size=args.size, speed=args.speed, camera=args.camera,
                           quiet=args.quiet, exports=tuple(args.export), panels=tuple(args.panels),
                           summary=not args.no_summary)
    out_dir = args.out_dir if args.out_dir is not None else default_out_dir(args.clip)
    result = process_clip(args.clip, out_dir, options, say=print)  # --quiet: no progress bars; results printed
    if result["exit"] == "failed":
        print(f"dynsplines: warning: the optimization failed ({result['status']}); the best path before that "
              "(it meets every keyframe) is reported and written", file=sys.stderr)
    return {"ok": EXIT_OK, "failed": EXIT_FAILED, "interrupted": EXIT_INTERRUPTED}[result["exit"]]
