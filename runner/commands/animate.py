"""`dynsplines animate KEYFRAMES --scene SCENE` and its showcase shortcut `dynsplines run-and-step`.

Reads keyframes, optimizes the in-betweens (solver.solve), prints progress and a summary of what the
optimization bought (plain spline vs optimized), saves the path (.npz) and renders a side-by-side video.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from runner.animate_options import add_options, solve_options
from runner.console import Progress, StopRequest, motion_metrics_table, summary_table
from runner.exit_codes import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from runner.files import check_writable_dir
from runner.paths import RENDERS
from runner.paths import display_path as _rel
from runner.pipeline import render_with_progress
from runner.problem_file import RUN_AND_STEP_KEYFRAMES, find_reference, load_problem
from runner.render.side_by_side import VideoOptions
from runner.render.side_by_side import check_video_out as _check_video_out
from runner.saved_path import save_path_npz
from solver.errors import InputError
from solver.layout import CONTACT_SITES
from solver.metrics import path_metrics
from solver.optimize import Status
from solver.problem import figure_problem, parse_terms
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


def default_video(keyframes) -> Path:
    """renders/<name>.mp4 for keyframe file <name>.keyframes.json (or <name>.json)."""
    name = Path(keyframes).name
    for suffix in (".json", ".keyframes"):
        name = name.removesuffix(suffix)
    return RENDERS / f"{name or 'animation'}.mp4"


def run_animate(args) -> int:
    """Run `animate` / `run-and-step`. Returns the exit code."""
    if args.out is None and not args.no_render:
        args.out = default_video(args.keyframes)
    for out, option in ((args.out, "--out"), (args.save_path, "--save-path")):
        if out is not None:
            check_writable_dir(out, option)
    if args.out is not None and not args.no_render:
        _check_video_out(args.out, args.size)  # before the optimization, not after it
    if args.plot is not None:
        check_writable_dir(Path(args.plot) / "plot.png", "--plot")
    _check_exports(args.export)
    keyframes, info, model, layout, scene_path = load_problem(args.keyframes, args.scene)
    reference = find_reference(info, model, quiet=args.quiet)
    if "reference" in getattr(args, "panels", ()) and args.out is not None and not args.no_render \
            and reference is None:
        raise InputError(f"--panels reference: {args.keyframes} names no motion-capture clip that is there "
                         "(its \"source\": {\"clip\": ...}, relative to the file); drop the reference panel")
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
    objective, initial, conflicts = figure_problem(model, weights, keyframes, rate=args.rate, contacts=contacts)
    options = solve_options(args, weights)
    _warn_penetrating_keyframes(model, keyframes, initial)
    _warn_contact_conflicts(conflicts, keyframes)
    say = print  # results; --quiet silences progress only
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

        plain_m = path_metrics(model, initial.times, initial.values, keyframes)
        opt_m = path_metrics(model, solution.frames.times, solution.frames.values, keyframes)
        metrics = {"plain": plain_m, "optimized": opt_m}
        if reference is not None:
            from runner.pipeline import reference_motion_metrics
            from solver.contacts import reference_contacts

            if not contacts:
                contacts = tuple(reference_contacts(model, reference.qpos, reference.frame_time))
            metrics["motion"] = reference_motion_metrics(model, layout, solution, reference, contacts)
        if not args.no_summary:
            rows = contact_summary_rows(metrics.get("motion"), solution.objective, solution)
            print(summary_table(plain_m, opt_m, solution, weights, dict(solution.weights), contact_rows=rows))
            if reference is not None:
                print(motion_metrics_table(metrics["motion"]["plain"], metrics["motion"]["optimized"]))
        if reference is not None:
            from runner.mocap.contacts import worst_contact_distance

            say(f"motion capture ({_rel(reference.source)}, retargeted, {reference.count} frames): "
                f"feet in contact stay within {1000 * worst_contact_distance(reference, model):.1f} mm "
                "of the surface under them")
        if args.save_path is not None:  # Ctrl-C until it is written only sets stop.requested
            save_path_npz(args.save_path, solution, keyframes, reference, scene_path, weights, options,
                          metrics, args, contacts=contacts)
            say(f"  wrote {_rel(args.save_path)}")
        if args.export:
            for res in export_results(args, solution, keyframes, reference, scene_path, weights, options,
                                      metrics):
                say(f"  wrote {res.describe()}")
        if args.plot is not None:
            from runner.plots import plot_solution

            for f in plot_solution(args.plot, model, solution, keyframes, reference, objective=solution.objective,
                                   contacts=contacts):
                say(f"  wrote {_rel(f)}")
    interrupted = solution.status is Status.INTERRUPTED or stop.requested  # also Ctrl-C while saving
    code = EXIT_INTERRUPTED if interrupted else EXIT_FAILED if failed else EXIT_OK
    if args.out is not None and not args.no_render:
        try:
            info_r = render_with_progress(args.out, model, solution, keyframes, VideoOptions.from_args(args),
                                          reference, contacts)
        except KeyboardInterrupt:  # the video is written atomically: nothing half-written is left
            saved = f"; the path is saved in {_rel(args.save_path)}" if args.save_path is not None else ""
            print(f"\ndynsplines: interrupted while rendering: {_rel(args.out)} not written (an earlier file "
                  f"there is unchanged){saved}", file=sys.stderr)
            return EXIT_INTERRUPTED
        say(f"  wrote {_rel(args.out)} ({info_r.n_frames} frames, {info_r.wall_time_s:.1f} s to render)")
    else:
        say("  no video (--no-render)")
    return code


def _check_exports(exports) -> None:
    """--export names are checked before the optimization: a known extension, a writable folder, no repeats."""
    from runner.export import check_output_name

    for out in exports:
        check_output_name(out, "--export")
        check_writable_dir(out, "--export")
    seen = [Path(out).resolve() for out in exports]
    dup = next((out for i, out in enumerate(exports) if seen[i] in seen[:i]), None)
    if dup is not None:
        raise InputError(f"--export {dup}: given twice; name each file once")


def export_results(args, solution, keyframes, reference, scene_path, weights, options, metrics):
    """Write every `--export FILE` (the optimized path) from the saved path: `--save-path` if given (already
    written), else a temporary one. Returns the ExportResults. Raises InputError naming the failed file."""
    import tempfile

    from runner.console import Steps
    from runner.export import export_saved_path

    results = []
    with tempfile.TemporaryDirectory(prefix="dynsplines-export-") as tmp, \
            Steps("exporting", len(args.export), args.quiet, unit=" files") as bar:
        npz = args.save_path
        if npz is None:
            npz = Path(tmp) / "path.npz"
            save_path_npz(npz, solution, keyframes, reference, scene_path, weights, options, metrics, args)
        for out in args.export:
            try:
                results.append(export_saved_path(npz, out, "optimized", None, option="--export"))
                bar.update(len(results), note=Path(out).name)
            except InputError as e:
                kept = f"; the path is saved in {_rel(args.save_path)}" if args.save_path is not None else ""
                raise InputError(f"--export {out}: not written: {e}{kept}") from None
    return results


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


def _warn_contact_conflicts(conflicts, keyframes) -> None:
    """Keyframes that contradict the contact schedule (`keyframe_conflicts`: a site the schedule plants
    held up, a swing site held on the ground): keyframes are met exactly, so the contact terms cannot
    fix those."""
    for name, k, site, dist in conflicts:
        if name == "planted":
            what = f"holds {site} {1000 * dist:+.1f} mm from where the contact schedule plants it"
        elif name == "sliding":
            what = (f"and an earlier keyframe in the same contact hold {site} {1000 * dist:.1f} mm apart along "
                    "the ground (it must slide)")
        else:
            what = f"holds {site} {1000 * dist:.1f} mm inside the clearance band where the schedule swings it"
        print(f"dynsplines: warning: {keyframes.source}: keyframe {k} (t={keyframes.times[k]:g} s) {what}; "
              "keyframes are met exactly, so that stays (not held to the bound) - edit the keyframe or the "
              "contact's times", file=sys.stderr)


def contact_summary_rows(motion, objective, solution) -> list:
    """Summary rows for the feet (issue 11): float, skate, skating ratio, flight time and flight-phase
    error (`solver.motion_metrics.flight_mismatch`, extra + missed) of both paths against the
    motion-capture reference (`motion`: metrics["motion"], the `motion_metrics` of both paths
    at the clip's rate; the capture's own figure in the label), and the friction-cone residual when the
    cone term is on."""
    rows = []
    if motion is not None:
        capture = motion["plain"]["reference"]
        for label, key, fmt in (
            ("float in contact [mm]", "float_contact_mm", "{:.2f}"),
            ("skate in contact [mm/frame]", "skate_contact_mm", "{:.2f}"),
            ("skate, PhysDiff [mm/frame]", "skate_mm", "{:.2f}"),
            ("skating ratio (contacts)", "skating_ratio_contacts", "{:.3f}"),
            ("flight time [s]", "flight_time_s", "{:.3f}"),
        ):
            rows.append((f"{label} (capture {fmt.format(capture[key])})", motion["plain"]["path"][key],
                         motion["optimized"]["path"][key], fmt))
        # flight-phase error: frames in flight in one and not the other (flight times can cancel)
        rows.append(("flight phase error vs capture [s]",
                     *(motion[p]["error"]["flight_extra_s"] + motion[p]["error"]["flight_missed_s"]
                       for p in ("plain", "optimized")), "{:.3f}"))
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
