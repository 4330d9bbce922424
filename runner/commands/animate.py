"""`dynsplines animate KEYFRAMES --scene SCENE` and its showcase shortcut `dynsplines run-and-step`:
argument glue around `runner.run.execute` (solve, summary, saved path, exports, plots, video)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from runner.animate_options import add_options, outputs_from_args, solve_options
from runner.paths import display_path
from runner.problem_file import RUN_AND_STEP_KEYFRAMES, file_problem
from runner.run import execute
from solver.errors import InputError

#: where the commands write when no output is named: relative to the current folder
OUTPUT_DIR = Path("renders")


# ----------------------------------------------------------------------------------------- arguments
def register(sub) -> None:
    """Add `animate` and `run-and-step` to the `dynsplines` parser."""
    p = sub.add_parser("animate", help="optimize the in-betweens of a keyframe file and render them",
                       description="Optimize the in-betweens of KEYFRAMES (a dynsplines keyframe file) in a "
                                   "scene, print a summary, save the path and render a video. Files go to "
                                   "renders/ in the current folder unless named.")
    p.add_argument("keyframes", type=Path, help="keyframe file (.json, see docs/keyframe-format.md)")
    p.add_argument("--scene", type=Path, default=None, help="scene MJCF [the keyframe file's 'scene']")
    add_options(p, defaults={"out": None, "out_help": "renders/<keyframe file name>.mp4, e.g. renders/walk.mp4 "
                                                      "for walk.keyframes.json"})
    p.set_defaults(func=run_animate)

    q = sub.add_parser("run-and-step", help="the showcase: run and step onto a box, from CMU motion capture",
                       description="Shortcut for: dynsplines animate <the shipped run_and_step.keyframes.json> "
                                   "--out renders/run_and_step.mp4 --save-path renders/run_and_step.npz (in the "
                                   "current folder)")
    add_options(q, defaults={"out": OUTPUT_DIR / "run_and_step.mp4", "save_path": OUTPUT_DIR / "run_and_step.npz"})
    q.set_defaults(func=run_animate, keyframes=RUN_AND_STEP_KEYFRAMES, scene=None)


# -------------------------------------------------------------------------------------------- run


def default_video(keyframes) -> Path:
    """renders/<name>.mp4 (in the current folder) for keyframe file <name>.keyframes.json (or <name>.json)."""
    name = Path(keyframes).name
    for suffix in (".json", ".keyframes"):
        name = name.removesuffix(suffix)
    return OUTPUT_DIR / f"{name or 'animation'}.mp4"


def run_animate(args) -> int:
    """Run `animate` / `run-and-step`. Returns the exit code."""
    outputs = outputs_from_args(args, default_video=default_video(args.keyframes))  # checked before solving
    problem, source = file_problem(args.keyframes, args.scene, args.terms, quiet=args.quiet)
    if "reference" in outputs.video_options.panels and outputs.video is not None and source.reference is None:
        raise InputError(f"--panels reference: {args.keyframes} names no motion-capture clip that is there "
                         "(its \"source\": {\"clip\": ...}, relative to the file); drop the reference panel")
    options = solve_options(args)
    _warn_penetrating_keyframes(problem)
    kf = problem.keyframes
    print(f"dynsplines: {display_path(args.keyframes)} -> {kf.count} keyframes ({int(kf.is_partial.sum())} partial) "
          f"over {kf.times[-1] - kf.times[0]:.2f} s, scene {display_path(source.scene_path)}")
    print("  the least change to the plain spline that meets the constraints"
          f"{' and the force bounds' if problem.forces else ''} (docs/design.md)")
    return execute(problem, options, source, outputs).exit_code


def _warn_penetrating_keyframes(problem) -> None:
    """Keyframes are hard constraints: a contact site a keyframe puts inside a surface stays there.
    Say so before optimizing (the optimizer can only fix the in-betweens)."""
    from solver.terms.penetration import Penetration

    model, keyframes, initial = problem.model, problem.keyframes, problem.initial
    depth = Penetration(model, problem.figure.contact_sites, margin=0.0).depths(initial.values[initial.is_keyframe])
    for k, row in enumerate(depth):
        if row.max() > 0.001:
            site = problem.figure.contact_sites[int(np.argmax(row))]
            print(f"dynsplines: warning: {keyframes.source}: keyframe {k} (t={keyframes.times[k]:g} s) puts "
                  f"{site} {1000 * row.max():.1f} mm inside a surface; keyframes are met exactly, so that "
                  "stays - raise the keyframe's root or bend its leg to fix it", file=sys.stderr)
