"""`dynsplines animate KEYFRAMES --scene SCENE` and its showcase shortcut `dynsplines run-and-step`.

Reads keyframes, optimizes the in-betweens (solver.solve), prints progress and a summary of what the
optimization bought (plain spline vs optimized), saves the path (.npz) and renders a side-by-side video.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from runner.console import Progress, StopRequest, summary_table
from runner.exit_codes import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from runner.files import check_writable_dir
from runner.parser import nonnegative, positive
from runner.paths import MODELS, RENDERS, display_path as _rel
from runner.saved_path import save_path_npz
from solver.errors import InputError
from solver.frames import FrameSet
from solver.keyframe_file import read_document, read_keyframes
from solver.layout import CONTACT_SITES, StateLayout
from solver.metrics import path_metrics, sample_times
from solver.model import load_model
from solver.optimize import ALGORITHMS, Status
from solver.problem import default_limits, figure_objective, parse_terms, term_names
from solver.solve import SUBDIVISIONS, SolveOptions, solve

RUN_AND_STEP_KEYFRAMES = MODELS / "run_and_step.keyframes.json"


# ----------------------------------------------------------------------------------------- arguments
def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 960x540") from None
    if w <= 0 or h <= 0 or w > 3840 or h > 2160:
        raise argparse.ArgumentTypeError(f"--size {text!r}: width and height must be 1..3840 x 1..2160")
    return w, h


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
    out.add_argument("--out", type=Path, default=d.get("out"), help="video file (.mp4) [%(default)s]")
    out.add_argument("--save-path", type=Path, default=d.get("save_path"),
                     help="optimized path (.npz; see README) [%(default)s]")
    out.add_argument("--no-render", action="store_true", help="skip the video")
    out.add_argument("--fps", type=positive(float), default=30.0, help="video frames per second [%(default)s]")
    out.add_argument("--size", type=_size, default=(960, 540), metavar="WxH", help="video size [960x540]")
    out.add_argument("--speed", type=positive(float), default=0.5, help="playback speed [%(default)s x real time]")
    out.add_argument("--plot", type=Path, default=None, metavar="DIR", help="write plots (PNG) to DIR")
    opt = p.add_argument_group("optimization")
    opt.add_argument("--terms", default=None,
                     help=f"objective terms: 'all' or a list from {','.join(term_names())} "
                          "[the keyframe file's, else penetration,unit,bending,smooth]")
    opt.add_argument("--weight", type=_weight, action="append", default=[], metavar="NAME=VALUE",
                     help="weight of a term (repeatable), e.g. --weight torque=0.1")
    opt.add_argument("--max-time", type=nonnegative(float), default=0.0, metavar="S",
                     help="stop optimizing after S seconds, keeping the best path so far [no limit]")
    opt.add_argument("--subdivision", choices=SUBDIVISIONS, default="adaptive",
                     help="where to add variable frames [%(default)s]")
    opt.add_argument("--per-segment", type=nonnegative(int), default=1,
                     help="variable frames per keyframe interval to start with [%(default)s]")
    opt.add_argument("--rounds", type=nonnegative(int), default=2, help="adaptive subdivision rounds [%(default)s]")
    opt.add_argument("--algorithm", choices=list(ALGORITHMS), default="lbfgs", help="nlopt algorithm [%(default)s]")
    opt.add_argument("--ftol", type=nonnegative(float), default=1e-6, help="relative objective tolerance [%(default)s]")
    opt.add_argument("--max-evals", type=nonnegative(int), default=0, help="evaluations per round [no limit]")
    opt.add_argument("--rate", type=positive(float), default=400.0,
                     help="quadrature points per second [%(default)s]")
    opt.add_argument("--score", choices=("decrease", "gradient"), default="decrease",
                     help="how adaptive subdivision ranks segments: the decrease of E a midpoint frame "
                          "predicts, or the raw weak-form Euler-Lagrange gradient [%(default)s]")
    opt.add_argument("--no-precondition", action="store_true",
                     help="optimize the frame values directly instead of in the spline-acceleration metric")
    opt.add_argument("--no-renormalize", action="store_true",
                     help="use the weights as they are instead of dividing each term by its initial value (eq. 7)")
    p.add_argument("--quiet", action="store_true", help="no progress output")


def register(sub) -> None:
    p = sub.add_parser("animate", help="optimize the in-betweens of a keyframe file and render them",
                       description="Optimize the in-betweens of KEYFRAMES (a dynsplines keyframe file) in a "
                                   "scene, print a summary, save the path and render a video.")
    p.add_argument("keyframes", type=Path, help="keyframe file (.json, see models/README.md)")
    p.add_argument("--scene", type=Path, default=None, help="scene MJCF [the keyframe file's 'scene']")
    add_options(p)
    p.set_defaults(func=run_animate)

    q = sub.add_parser("run-and-step", help="the showcase: run and step onto a box, from CMU motion capture",
                       description="Shortcut for: dynsplines animate models/run_and_step.keyframes.json "
                                   "--out renders/run_and_step.mp4 --save-path renders/run_and_step.npz")
    add_options(q, defaults={"out": RENDERS / "run_and_step.mp4", "save_path": RENDERS / "run_and_step.npz"})
    q.set_defaults(func=run_animate, keyframes=RUN_AND_STEP_KEYFRAMES, scene=None)


# ------------------------------------------------------------------------------------------ loading
def load_problem(keyframes_path: Path, scene: Path | None):
    """(keyframes, info, model, layout) for a keyframe file and an optional scene override."""
    import mujoco

    keyframes_path = Path(keyframes_path)
    head = _peek_scene(keyframes_path)  # also reports a missing, unreadable or malformed file
    scene_path = Path(scene) if scene is not None else head
    if scene_path is None:
        raise InputError(f"{keyframes_path}: no 'scene' in the file; give one with --scene SCENE.xml")
    model = load_model(scene_path)
    layout = StateLayout.from_model(model)
    if not any(j.kind == "free" for j in layout.joints):
        raise InputError(f"scene {scene_path} has no free joint: does it include the figure (humanoid39.xml)?")
    sites = CONTACT_SITES
    missing = [s for s in sites if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s) < 0]
    if missing:
        raise InputError(f"scene {scene_path} has no contact site(s) {', '.join(map(repr, missing))} (the "
                         f"figure's feet need {', '.join(sites)}): does it include the figure (humanoid39.xml)?")
    keyframes, info = read_keyframes(keyframes_path, layout)
    return keyframes, info, model, layout, scene_path


def _peek_scene(path: Path) -> Path | None:
    data = read_document(path)  # InputError naming the file for anything unreadable
    scene = data.get("scene") if isinstance(data, dict) else None
    if isinstance(scene, str) and "\x00" in scene:
        raise InputError(f"{path}: field 'scene' is {scene!r}; give a path relative to the keyframe file")
    return (path.parent / scene).resolve() if isinstance(scene, str) and scene else None


# -------------------------------------------------------------------------------------------- run
def solve_options(args, weights: dict) -> SolveOptions:
    """SolveOptions from parsed `add_options` arguments (the command's and the benchmark's)."""
    return SolveOptions(
        subdivision=args.subdivision, per_segment=args.per_segment, rounds=args.rounds,
        renormalize=not args.no_renormalize, algorithm=args.algorithm, ftol_rel=args.ftol,
        max_evals=args.max_evals, max_time_s=args.max_time, limits=default_limits(weights),
        precondition=not args.no_precondition, score=args.score,
    )


def default_args() -> argparse.Namespace:
    """The options `animate` uses when none are given."""
    p = argparse.ArgumentParser()
    add_options(p)
    return p.parse_args([])


def run_animate(args) -> int:
    """Run `animate` / `run-and-step`. Returns the exit code."""
    for out, option in ((args.out, "--out"), (args.save_path, "--save-path")):
        if out is not None:
            check_writable_dir(out, option)
    if args.out is not None and not args.no_render:
        _check_video_out(args.out, args.size)  # before the optimization, not after it
    if args.plot is not None:
        check_writable_dir(Path(args.plot) / "plot.png", "--plot")
    keyframes, info, model, layout, scene_path = load_problem(args.keyframes, args.scene)
    file_terms = dict(getattr(info, "terms", None) or {})
    weights_in = dict(args.weight)
    if args.terms is None and file_terms:
        try:
            parse_terms(",".join(file_terms), file_terms)
        except InputError as e:
            raise InputError(f"{args.keyframes}: field 'terms': {e}; fix the file, or choose with --terms") from None
        weights = parse_terms(",".join(file_terms), {**file_terms, **weights_in})
    else:
        weights = parse_terms(args.terms, weights_in)
    objective = figure_objective(model, weights, keyframes.times[0], keyframes.times[-1], rate=args.rate)
    options = solve_options(args, weights)
    initial = FrameSet.from_keyframes(keyframes, layout.quat_slots)
    _warn_penetrating_keyframes(model, keyframes, initial)
    say = (lambda *a: None) if args.quiet else print
    say(f"dynsplines: {args.keyframes} -> {keyframes.count} keyframes "
        f"({int(keyframes.is_partial.sum())} partial) over {keyframes.times[-1] - keyframes.times[0]:.2f} s, "
        f"scene {_rel(scene_path)}")
    say(f"  terms: {', '.join(f'{n}={w:g}' for n, w in weights.items())}"
        f"{' (renormalized, eq. 7)' if options.renormalize else ''}; subdivision {options.subdivision}; "
        f"nlopt {options.algorithm}")
    progress = Progress(args.quiet)
    with StopRequest(args.quiet) as stop:
        solution = solve(objective, initial, options, should_stop=stop, progress=progress)
        progress.done()
        failed = solution.status in (Status.NONFINITE, Status.FAILED)
        why = "interrupted (Ctrl-C), best path so far kept" if stop.requested else solution.message
        say(f"  stopped: {why}; {solution.n_evals} evaluations, {solution.wall_time_s:.2f} s")
        if failed:
            print(f"dynsplines: warning: the optimization failed ({solution.message}); the best path before "
                  "that (it meets every keyframe) is reported and written", file=sys.stderr)

        reference = _reference(info, model)
        plain_m = path_metrics(model, initial.times, initial.values, keyframes)
        opt_m = path_metrics(model, solution.frames.times, solution.frames.values, keyframes)
        if not args.quiet:
            print(summary_table(plain_m, opt_m, solution, weights,
                                dict(zip(objective.names, objective.weights.tolist()))))
            if reference is not None:
                from runner.mocap.contacts import worst_contact_distance

                say(f"motion capture ({_rel(reference.source)}, retargeted, {reference.count} frames): "
                    f"feet in contact stay within {1000 * worst_contact_distance(reference, model):.1f} mm "
                    "of the surface under them")
        if args.save_path is not None:  # Ctrl-C until it is written only sets stop.requested
            save_path_npz(args.save_path, solution, keyframes, reference, scene_path, weights, options,
                          {"plain": plain_m, "optimized": opt_m}, args)
            say(f"  wrote {_rel(args.save_path)}")
        if args.plot is not None:
            from runner.plots import plot_solution

            for f in plot_solution(args.plot, model, solution, keyframes, reference, objective=objective):
                say(f"  wrote {_rel(f)}")
    interrupted = solution.status is Status.INTERRUPTED or stop.requested  # also Ctrl-C while saving
    code = EXIT_INTERRUPTED if interrupted else EXIT_FAILED if failed else EXIT_OK
    if args.out is not None and not args.no_render:
        try:
            info_r = render_video(args.out, model, solution, keyframes, args)
        except KeyboardInterrupt:  # the video is written atomically: nothing half-written is left
            saved = f"; the path is saved in {_rel(args.save_path)}" if args.save_path is not None else ""
            print(f"\ndynsplines: interrupted while rendering: {_rel(args.out)} not written (an earlier file "
                  f"there is unchanged){saved}", file=sys.stderr)
            return EXIT_INTERRUPTED
        say(f"  wrote {_rel(args.out)} ({info_r.n_frames} frames, {info_r.wall_time_s:.1f} s to render)")
    return code


def _check_video_out(out, size) -> None:
    """The video's name and size are checked before the optimization (render_tracks checks again)."""
    from runner.render import VIDEO_SUFFIXES, parse_size

    if Path(out).suffix.lower() not in VIDEO_SUFFIXES:
        raise InputError(f"--out {out}: a video file must end in one of {', '.join(VIDEO_SUFFIXES)}; "
                         "use e.g. --out clip.mp4, or --no-render")
    w, h = parse_size(size)
    if w % 2 or h % 2:
        raise InputError(f"--size {w}x{h}: width and height must be even (H.264 video); e.g. --size "
                         f"{w + w % 2}x{h + h % 2}")


def _warn_penetrating_keyframes(model, keyframes, initial) -> None:
    """Keyframes are hard constraints: a contact site a keyframe puts inside a surface stays there.
    Say so before optimizing (the optimizer can only fix the in-betweens)."""
    from solver.terms.penetration import Penetration

    depth = Penetration(model, margin=0.0).depths(initial.values[initial.is_keyframe])  # (k, 4) [m]
    for k, row in enumerate(depth):
        if row.max() > 0.001:
            site = CONTACT_SITES[int(np.argmax(row))]
            print(f"dynsplines: warning: {keyframes.source}: keyframe {k} (t={keyframes.times[k]:g} s) puts "
                  f"{site} {1000 * row.max():.1f} mm inside a surface; keyframes are met exactly, so that "
                  "stays - raise the keyframe's root or bend its leg to fix it", file=sys.stderr)


def _reference(info, model):
    clip = (getattr(info, "source", None) or {}).get("clip")
    if not clip:
        return None
    path = Path(info.path).parent / clip if hasattr(info, "path") else MODELS / clip
    if not path.is_file():
        return None
    from runner.mocap.reference import load_bvh_reference

    return load_bvh_reference(path, model)


def render_video(out, model, solution, keyframes, args):
    """Side-by-side video of the plain spline and the optimized path, keyframes marked."""
    from runner.render import Track, render_tracks
    from solver.terms.penetration import Penetration

    t = sample_times(keyframes.times[0], keyframes.times[-1], 240.0)
    pen = Penetration(model, margin=0.0)
    tracks = []
    for label, fs in (("plain spline", solution.initial), ("optimized", solution.frames)):
        Y = fs.path(t)
        tracks.append(Track(label, t, Y, penetration=pen.depths(Y), sites=CONTACT_SITES))
    # keyframes with free components filled: the poses the animator set
    kq = solution.initial.values[solution.initial.is_keyframe]
    quiet = getattr(args, "quiet", False)

    tty = sys.stdout.isatty()

    def progress(i, n):
        if quiet:
            return
        if tty and (i % 10 == 0 or i == n):
            print(f"\r  rendering {i}/{n}", end="" if i < n else "\n", flush=True)
        elif not tty and (i % 50 == 0 or i == n):
            print(f"  rendering {i}/{n}", flush=True)

    return render_tracks(model, tracks, out, fps=args.fps, size=args.size, speed=args.speed,
                         keyframe_times=keyframes.times, keyframe_qpos=kq,
                         title="dynsplines: plain spline vs optimized", progress=progress)

