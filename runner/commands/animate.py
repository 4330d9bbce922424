"""`dynsplines animate KEYFRAMES --scene SCENE` and its showcase shortcut `dynsplines run-and-step`.

Reads keyframes, optimizes the in-betweens (solver.solve), prints progress and a summary of what the
optimization bought (plain spline vs optimized), saves the path (.npz) and renders a side-by-side video.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from runner.animate_options import add_options, solve_options
from runner.console import Progress, StopRequest, summary_table
from runner.exit_codes import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from runner.files import check_writable_dir
from runner.paths import RENDERS, display_path as _rel
from runner.problem_file import RUN_AND_STEP_KEYFRAMES, find_reference, load_problem
from runner.saved_path import save_path_npz
from solver.errors import InputError
from solver.frames import FrameSet
from solver.layout import CONTACT_SITES
from solver.metrics import path_metrics, sample_times
from solver.optimize import Status
from solver.problem import figure_objective, parse_terms
from solver.solve import solve


# ----------------------------------------------------------------------------------------- arguments
def register(sub) -> None:
    """Add `animate` and `run-and-step` to the `dynsplines` parser."""
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


# -------------------------------------------------------------------------------------------- run


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
    contacts = tuple(getattr(info, "contacts", ()) or ())
    file_terms = dict(getattr(info, "terms", None) or {})
    weights_in = dict(args.weight)
    if args.terms is None and file_terms:
        try:
            parse_terms(",".join(file_terms), file_terms, contacts)
        except InputError as e:
            raise InputError(f"{args.keyframes}: field 'terms': {e}; fix the file, or choose with --terms") from None
        weights = parse_terms(",".join(file_terms), {**file_terms, **weights_in}, contacts)
    else:
        weights = parse_terms(args.terms, weights_in, contacts)
    objective = figure_objective(model, weights, keyframes.times[0], keyframes.times[-1], rate=args.rate,
                                 contacts=contacts)
    options = solve_options(args, weights)
    initial = FrameSet.from_keyframes(keyframes, layout.quat_slots)
    _warn_penetrating_keyframes(model, keyframes, initial)
    _warn_contact_conflicts(objective, keyframes, initial)
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

        reference = find_reference(info, model)
        plain_m = path_metrics(model, initial.times, initial.values, keyframes)
        opt_m = path_metrics(model, solution.frames.times, solution.frames.values, keyframes)
        if not args.quiet:
            rows = contact_summary_rows(model, solution, reference, contacts, objective)
            print(summary_table(plain_m, opt_m, solution, weights,
                                dict(zip(objective.names, objective.weights.tolist())), contact_rows=rows))
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
            info_r = render_video(args.out, model, solution, keyframes, args, contacts)
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


def _warn_contact_conflicts(objective, keyframes, initial) -> None:
    """Keyframes that contradict the contact schedule (a site the schedule plants held up, a swing
    site held on the ground): keyframes are met exactly, so the contact terms cannot fix those."""
    from solver.problem import keyframe_conflicts

    for name, k, site, dist in keyframe_conflicts(objective, keyframes.times, initial.values[initial.is_keyframe]):
        if name == "planted":
            what = f"holds {site} {1000 * dist:+.1f} mm from where the contact schedule plants it"
        else:
            what = f"holds {site} {1000 * dist:.1f} mm inside the clearance band where the schedule swings it"
        print(f"dynsplines: warning: {keyframes.source}: keyframe {k} (t={keyframes.times[k]:g} s) {what}; "
              "keyframes are met exactly, so that stays (not held to the bound) - edit the keyframe or the "
              "contact's times", file=sys.stderr)


def contact_summary_rows(model, solution, reference, contacts, objective) -> list:
    """Summary rows for the feet (issue 11): float, skate, skating ratio and flight time of both paths
    against the motion-capture reference (`motion_metrics` at the clip's rate, the capture's own figure
    in the label; contacts: the schedule, else `reference_contacts` of the clip), and the friction-cone
    residual when the cone term is on."""
    rows = []
    if reference is not None:
        from solver.contacts import reference_contacts
        from solver.motion_metrics import motion_metrics

        # the capture's contacts: the file's schedule, else detected on the clip
        contacts = contacts or tuple(reference_contacts(model, reference.qpos, reference.frame_time))

        t0, t1 = solution.initial.times[0], solution.initial.times[-1]
        on = (reference.times >= t0 - 1e-9) & (reference.times <= t1 + 1e-9)
        t, ref_q = reference.times[on], reference.qpos[on]
        fps = 1.0 / reference.frame_time
        got = [motion_metrics(model, fs.path(t), fps, ref_q, contacts) for fs in (solution.initial, solution.frames)]
        capture = got[0]["reference"]
        for label, key, scale, fmt in (
            ("float in contact [mm]", "float_contact_mm", 1.0, "{:.2f}"),
            ("skate in contact [mm/frame]", "skate_contact_mm", 1.0, "{:.2f}"),
            ("skate, PhysDiff [mm/frame]", "skate_mm", 1.0, "{:.2f}"),
            ("skating ratio (contacts)", "skating_ratio_contacts", 1.0, "{:.3f}"),
            ("flight time [s]", "flight_time_s", 1.0, "{:.3f}"),
        ):
            rows.append((f"{label} (capture {fmt.format(scale * capture[key])})",
                         scale * got[0]["path"][key], scale * got[1]["path"][key], fmt))
    if "cone" in objective.names:
        from solver.metrics import sample_times
        from solver.terms.contact_wrench import cone_metrics

        term = objective.terms[objective.names.index("cone")]
        t = sample_times(solution.initial.times[0], solution.initial.times[-1], 400.0)
        cm = [cone_metrics(term, t, fs.path(t), fs.path(t, 1), fs.path(t, 2))
              for fs in (solution.initial, solution.frames)]
        rows.append(("RMS friction-cone residual [N]", cm[0]["cone_rms"], cm[1]["cone_rms"], "{:.1f}"))
        rows.append(("peak friction-cone residual [N]", cm[0]["cone_peak"], cm[1]["cone_peak"], "{:.1f}"))
    return rows


def render_video(out, model, solution, keyframes, args, contacts=()):
    """Side-by-side video of the plain spline and the optimized path, keyframes marked, planted sites
    of the contact schedule dotted green."""
    from runner.render import Track, render_tracks
    from solver.terms.penetration import Penetration

    t = sample_times(keyframes.times[0], keyframes.times[-1], 240.0)
    pen = Penetration(model, margin=0.0)
    tracks = []
    planted = None
    if contacts:
        from solver.contacts import contact_mask

        planted = contact_mask(contacts, CONTACT_SITES, t)
    for label, fs in (("plain spline", solution.initial), ("optimized", solution.frames)):
        Y = fs.path(t)
        tracks.append(Track(label, t, Y, penetration=pen.depths(Y), sites=CONTACT_SITES, planted=planted))
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
