"""One run of a figure problem, the one place where a problem becomes a solution, metrics and outputs.

Every command that optimizes keyframes (`animate`, `run-and-step`, `mocap`, `batch`) calls `execute`:

1. solve the `solver.Problem` (progress bars, Ctrl-C keeps the best path so far);
2. the metrics of the plain spline and the optimized path (`solver.metrics.path_metrics`) and, with a
   motion-capture reference, the motion metrics of both against it (`runner.motion_metrics`);
3. the summary tables, then the outputs the user asked for: the saved path (.npz), exports (.bvh,
   .glb), plots, the metrics report (.json) and the side-by-side video.

The commands are argument glue: they make the problem (`runner.problem_file`, `runner.pipeline`) and an
`Outputs` value and hand both here; benchmarks build their problems with the same functions.
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from runner.console import FEET_ROWS, motion_metrics_table, summary_table
from runner.exit_codes import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from runner.files import atomic_output
from runner.paths import display_path
from runner.progress import Progress, StopRequest
from runner.render.side_by_side import VideoOptions
from runner.saved_path import save_path_npz
from solver.animate import solve_problem
from solver.errors import InputError
from solver.layout import StateLayout
from solver.least_change import LeastChangeOptions
from solver.metrics import path_metrics
from solver.optimize import Status
from solver.problem import Problem
from solver.solution import Solution


@dataclass(frozen=True)
class Source:
    """Where a problem came from, for the metrics and the outputs.

    Attributes:
        scene_path: the scene MJCF the model was loaded from.
        reference: the motion-capture reference (`runner.capture.reference_motion.Reference`: times (r,) [s],
            qpos (r, nq)) the keyframes were made from, or None.
        metric_contacts: the contacts the motion metrics judge feet by: the problem's schedule, or,
            for a keyframe file without one, the contacts detected on the reference.
        label: what the run is called in messages (the keyframe file or the clip).
    """

    scene_path: Path
    reference: object | None = None
    metric_contacts: tuple = ()
    label: str = ""


@dataclass(frozen=True)
class Outputs:
    """What a run writes (None or empty: not written); paths as the user gave them.

    Attributes:
        save_path: the saved path (.npz). exports: the optimized path as .bvh / .glb files.
        plot_dir: folder for the plots (PNG). metrics_json: the metrics report (.json).
        video: the side-by-side video (.mp4); `video_options` its settings.
        summary: print the summary tables. quiet: no progress bars (results are still printed).
        command: the command's arguments, recorded in the saved path.
    """

    save_path: Path | None = None
    exports: tuple = ()
    plot_dir: Path | None = None
    metrics_json: Path | None = None
    video: Path | None = None
    video_options: VideoOptions = field(default_factory=VideoOptions)
    summary: bool = True
    quiet: bool = False
    command: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Run:
    """A solved problem with its metrics (read-only).

    Attributes:
        problem: the Problem solved. options: the LeastChangeOptions used. solution: the Solution.
        source: where the problem came from (`Source`).
        metrics: {"plain", "optimized": `path_metrics` dicts; "motion" with a reference:
            {"plain", "optimized": `motion_metrics` dicts}}.
        interrupted: Ctrl-C (or a stop request) ended the solve or came while writing.
    """

    problem: Problem
    options: LeastChangeOptions
    solution: Solution
    source: Source
    metrics: dict
    interrupted: bool = False

    @property
    def failed(self) -> bool:
        """The optimizer failed (the best path before that is kept)."""
        return self.solution.status in (Status.NONFINITE, Status.FAILED)

    @property
    def exit_code(self) -> int:
        """The command's exit code (runner/exit_codes.py)."""
        return EXIT_INTERRUPTED if self.interrupted else EXIT_FAILED if self.failed else EXIT_OK

    @property
    def keyframes(self):
        return self.problem.keyframes

    @property
    def model(self):
        return self.problem.model


def run_metrics(problem: Problem, solution: Solution, source: Source) -> dict:
    """The metrics of a run: `path_metrics` of the plain spline and the optimized path (1000 Hz), and with
    a reference the motion metrics of both against it (`reference_motion_metrics`)."""
    model, keyframes = problem.model, problem.keyframes
    metrics = {name: path_metrics(model, fs.times, fs.values, keyframes)
               for name, fs in (("plain", solution.initial), ("optimized", solution.frames))}
    if source.reference is not None:
        metrics["motion"] = reference_motion_metrics(model, solution, source.reference, source.metric_contacts)
    if problem.force_bounds is not None:  # the force bounds (solver.peak_bounds)
        metrics["force_bounds"] = problem.force_bounds.as_dict()
    return metrics


def _sample(frames, times: np.ndarray, layout: StateLayout) -> np.ndarray:
    """The path at `times`, unit quaternions (what MuJoCo's kinematics use)."""
    Y = frames.path(np.clip(times, frames.times[0], frames.times[-1]))
    for slot in layout.quat_slots:
        Y[:, slot] /= np.linalg.norm(Y[:, slot], axis=1, keepdims=True)
    return Y


def reference_motion_metrics(model, solution, reference, contacts) -> dict:
    """`motion_metrics` of the plain spline and the optimized path against the reference clip, over the
    reference's frames within the keyframes' time span (contact times shifted with them), and what the
    keyframes alone force on any path (`runner.motion_metrics.forced_skate_mm`, over the full keyframes).

    Returns:
        {"plain": ..., "optimized": ...}, each a `runner.motion_metrics.motion_metrics` dict (the reference's
        jolt figures of the capture filtered over the whole clip, `_filtered_capture`), and
        "keyframes": {"forced_skate_contact_mm": lower bound of skate_contact_mm [mm/frame]}.
    Raises:
        InputError: fewer than 4 reference frames in the keyframes' span.
    """
    from runner.capture.stance import capture_stance
    from runner.motion_metrics import forced_skate_mm, motion_metrics
    from solver.contacts import Contact

    layout = StateLayout.from_model(model)
    t0, t1 = solution.initial.times[0], solution.initial.times[-1]
    tol = 2e-6  # keyframe times in a file are rounded to 1e-6 s: the end frames still count
    keep = (reference.times >= t0 - tol) & (reference.times <= t1 + tol)
    times, qpos = reference.times[keep], reference.qpos[keep]
    if len(times) < 4:
        raise InputError(f"the keyframes span {t0:g}..{t1:g} s, which holds {len(times)} frames of the reference "
                         f"{reference.source}; motion metrics need at least 4")
    shift = float(times[0])
    shifted = [Contact(c.site, c.start - shift, c.end - shift, c.surface) for c in contacts
               if c.end >= shift and c.start <= times[-1]]
    fps = 1.0 / reference.frame_time
    # the capture's own stance (runner/capture/stance.py), over the whole clip so its hysteresis starts there
    stance = capture_stance(model, reference.qpos, reference.frame_time)[keep]
    smooth = _filtered_capture(reference, layout)[keep]  # the capture's jolt figures (runner.jolts)
    out = {label: motion_metrics(model, _sample(fs, times, layout), fps, qpos, shifted, stance=stance,
                                 capture_filtered=smooth)
           for label, fs in (("plain", solution.initial), ("optimized", solution.frames))}
    keys = solution.initial
    full = keys.is_keyframe & keys.fixed.all(axis=1)
    out["keyframes"] = {"forced_skate_contact_mm": forced_skate_mm(model, keys.times[full] - shift, keys.values[full],
                                                                   fps, shifted, len(times))}
    return out


def _filtered_capture(reference, layout: StateLayout) -> np.ndarray:
    """The reference's qpos low-pass filtered over the whole clip (`runner.jolts.filter_capture`, 6 Hz, Winter),
    so the filter's ends lie outside the keyframes' span where the clip extends beyond it; a clip too short
    to filter (under `solver.peak_bounds.MIN_FRAMES`) is returned as it is."""
    from runner.jolts import filter_capture

    try:
        return filter_capture(reference.times, reference.qpos, layout)
    except InputError:
        return np.array(reference.qpos, float)


def solve_run(problem: Problem, options: LeastChangeOptions, source: Source, *, quiet: bool = False, stop=None) -> Run:
    """Solve `problem` with a progress bar (silent with `quiet`) and compute the run's metrics.

    Args:
        problem: from `solver.build_problem`. options: LeastChangeOptions. source: `Source`.
        stop: a `runner.progress.StopRequest` (Ctrl-C) polled by the optimizer, or None.
    Returns:
        Run.
    """
    progress = Progress(quiet)
    solution = solve_problem(problem, options, should_stop=stop, progress=progress)
    progress.done()
    interrupted = solution.status is Status.INTERRUPTED or bool(stop is not None and stop.requested)
    return Run(problem, options, solution, source, run_metrics(problem, solution, source), interrupted)


def execute(problem: Problem, options: LeastChangeOptions, source: Source, outputs: Outputs, say=print) -> Run:
    """The whole run: solve, metrics, summary and every output of `outputs` (module docstring).

    Args:
        problem, options, source: what to solve (`solve_run`). outputs: `Outputs`.
        say: where result lines go (print; batches pass a no-op). Progress bars follow `outputs.quiet`.
    Returns:
        Run (`Run.exit_code` is the command's exit code; a video interrupted by Ctrl-C makes it 130).
    Raises:
        InputError: an output that cannot be written (named; the outputs before it are written).
    """
    with StopRequest(outputs.quiet) as stop:
        run = solve_run(problem, options, source, quiet=outputs.quiet, stop=stop)
        why = "interrupted (Ctrl-C), best path so far kept" if stop.requested else run.solution.message
        say(f"  stopped: {why}; {run.solution.n_evals} evaluations, {run.solution.wall_time_s:.2f} s")
        if run.failed:
            print(f"dynsplines: warning: the optimization failed ({run.solution.message}); the best path before "
                  "that (it meets every keyframe) is reported and written", file=sys.stderr)
        if outputs.summary:
            say(report(run))
        write_results(run, outputs, say)  # Ctrl-C until they are written only sets stop.requested
    if stop.requested and not run.interrupted:
        run = _replace(run, interrupted=True)
    if outputs.video is not None:  # after a first Ctrl-C too: the video of the best path so far
        try:
            info = render_with_progress(outputs.video, run, outputs.video_options, quiet=outputs.quiet)
        except KeyboardInterrupt:  # the video is written atomically: nothing half-written is left
            saved = f"; the path is saved in {display_path(outputs.save_path)}" if outputs.save_path else ""
            print(f"\ndynsplines: interrupted while rendering: {display_path(outputs.video)} not written (an "
                  f"earlier file there is unchanged){saved}", file=sys.stderr)
            return _replace(run, interrupted=True)
        say(f"  wrote {display_path(outputs.video)} ({info.summary()})")
    elif outputs.video is None:
        say("  no video (--no-render)")
    return run


def _replace(run: Run, **changes) -> Run:
    from dataclasses import replace

    return replace(run, **changes)


def report(run: Run) -> str:
    """The summary of a run: the verdict and what the optimization bought (plain spline vs optimized,
    `summary_table`), the motion metrics against the capture, and how close the capture's own feet are to
    the scene."""
    motion = run.metrics.get("motion")
    rows = contact_summary_rows(motion)
    lines = [summary_table(run.metrics["plain"], run.metrics["optimized"], run.solution, contact_rows=rows,
                           force_bounds=run.problem.force_bounds, motion=motion, tol=run.options.tol)]
    ref = run.source.reference
    if ref is not None:
        from runner.capture.gaps import clip_gaps, gaps_line
        from runner.capture.glitches import glitches_line
        from runner.capture.root_height import feet_line

        lines.append(motion_metrics_table(motion["plain"], motion["optimized"], shown=[k for _, k, _ in FEET_ROWS]))
        forced = motion.get("keyframes", {}).get("forced_skate_contact_mm")
        if forced is not None and f"{forced:.2f}" != "0.00":  # keys that hold the feet still force no skate
            lines.append(f"skate in contact that the keyframes force on any path through them: {forced:.2f} mm/frame "
                         "(a lower bound: the distance between a site's keyed positions inside each contact)")
        worst = [motion["plain"]["path"], motion["optimized"]["path"], motion["plain"]["reference"]]
        lines.append("beyond range of motion (AAOS 1965, docs/anatomy.md), worst: " + "; ".join(
            f"{who} {w['rom_excess_motion'] or 'none'}" for who, w in zip(("plain", "optimized", "capture"), worst)))
        lines.append(f"motion capture ({display_path(ref.source)}, retargeted, {ref.count} frames): "
                     + feet_line(ref, run.model))
        if (glitch := glitches_line(ref.glitches)) is not None:
            lines.append(glitch)
        if (gap := gaps_line(clip_gaps(ref))) is not None:
            lines.append(gap)
    return "\n".join(lines)


def write_results(run: Run, outputs: Outputs, say=print) -> None:
    """The files of a run other than the video, in order: saved path, exports, metrics report, plots.
    Each is written atomically and announced with `say("  wrote PATH")`."""
    if outputs.save_path is not None:
        save_path_npz(run, outputs.save_path, command=outputs.command)
        say(f"  wrote {display_path(outputs.save_path)}")
    if outputs.exports:
        for res in export_results(run, outputs):
            say(f"  wrote {res.describe()}")
    if outputs.metrics_json is not None:
        write_metrics_json(run, outputs.metrics_json)
        say(f"  wrote {display_path(outputs.metrics_json)}")
    if outputs.plot_dir is not None:
        from runner.plots import plot_solution

        for f in plot_solution(outputs.plot_dir, run.model, run.solution, run.keyframes, run.source.reference,
                               objective=run.solution.objective, contacts=run.source.metric_contacts):
            say(f"  wrote {display_path(f)}")


def check_exports(exports) -> None:
    """--export names are checked before the optimization: a known extension, a writable folder, no repeats.

    Raises:
        InputError: naming the option and the file."""
    from runner.export import check_output_name
    from runner.files import check_writable_dir

    for out in exports:
        check_output_name(out, "--export")
        check_writable_dir(out, "--export")
    seen = [Path(out).resolve() for out in exports]
    dup = next((out for i, out in enumerate(exports) if seen[i] in seen[:i]), None)
    if dup is not None:
        raise InputError(f"--export {dup}: given twice; name each file once")


def export_results(run: Run, outputs: Outputs) -> list:
    """Write every export (the optimized path) from the saved path: `outputs.save_path` if given (already
    written), else a temporary one. Returns the ExportResults. Raises InputError naming the failed file."""
    import tempfile

    from runner.export import export_saved_path
    from runner.progress import Steps

    results = []
    with tempfile.TemporaryDirectory(prefix="dynsplines-export-") as tmp, \
            Steps("exporting", len(outputs.exports), outputs.quiet, unit=" files") as bar:
        npz = outputs.save_path
        if npz is None:
            npz = Path(tmp) / "path.npz"
            save_path_npz(run, npz, command=outputs.command)
        for out in outputs.exports:
            try:
                results.append(export_saved_path(npz, out, "optimized", None, option="--export"))
                bar.update(len(results), note=Path(out).name)
            except InputError as e:
                kept = f"; the path is saved in {display_path(outputs.save_path)}" if outputs.save_path else ""
                raise InputError(f"--export {out}: not written: {e}{kept}") from None
    return results


def write_metrics_json(run: Run, path: Path, extra: dict | None = None) -> None:
    """The metrics report (.json, atomically): the run's metrics, its status, its solve's time, evaluations and
    longest round ("longest_round_s" [s], one subproblem or round of `Solution.rounds`; the least violation's search
    is not a round) and `extra` fields."""
    report_ = {"status": "interrupted" if run.interrupted else run.solution.status.value,
               "exit": "interrupted" if run.interrupted else "failed" if run.failed else "ok",
               "keyframes": run.keyframes.count, "partial": int(run.keyframes.is_partial.sum()),
               "contacts": len(run.problem.contacts), "variable_frames": run.solution.frames.n_variable,
               "solve_time_s": run.solution.wall_time_s, "n_evals": run.solution.n_evals,
               "longest_round_s": max((r.result.wall_time_s for r in run.solution.rounds), default=0.0),
               "terms": run.problem.terms, **(extra or {}), "metrics": run.metrics}
    with atomic_output(path, suffix=".json") as tmp:
        Path(tmp).write_text(json.dumps(report_, indent=1, default=float) + "\n")


def render_with_progress(out, run: Run, video: VideoOptions, quiet: bool = False):
    """The side-by-side video of a run (`runner.render.side_by_side.render_video`) with a progress bar over
    its frames (`runner.progress.Steps`; silent with `quiet`). Returns the render's info."""
    from runner.progress import Steps
    from runner.render import frame_times
    from runner.render.side_by_side import render_video

    kf = run.keyframes
    n = len(frame_times(float(kf.times[0]), float(kf.times[-1]), video.fps, video.speed))
    with Steps(f"rendering {display_path(out)}", n, quiet, unit=" frames") as bar:
        return render_video(out, run.model, run.solution, kf, video, run.source.reference,
                            run.source.metric_contacts, progress=lambda i, _n: bar.update(i))


#: the anatomy rows of the summary (`anatomy_summary_rows`): (label, `anatomy_figures` key, format)
ANATOMY_ROWS = (("knee rotation off the hinge [deg]", "off_hinge_knee_deg", "{:.1f}"),
                ("elbow rotation off the hinge [deg]", "off_hinge_elbow_deg", "{:.1f}"),
                ("beyond range of motion [deg]", "rom_excess_deg", "{:.1f}"))


def anatomy_summary_rows(motion) -> list:
    """Summary rows for the anatomical limits (`runner.motion_metrics.anatomy_figures`, docs/anatomy.md):
    the largest knee and elbow rotation off the hinge and the largest angle beyond the published range of
    motion, plain spline and optimized at the capture's frames, the capture's own in the label.

    Returns:
        [(label, plain value, optimized value, format, mark), ...] (`runner.verdict.motion_mark`, against
        the capture's figure too).
    """
    from runner.verdict import motion_mark

    capture = motion["plain"]["reference"]
    rows = []
    for label, key, fmt in ANATOMY_ROWS:
        if key not in capture:  # metrics written without the anatomy figures
            continue
        a, b = motion["plain"]["path"][key], motion["optimized"]["path"][key]
        rows.append((f"{label} (capture {fmt.format(capture[key])})", a, b, fmt, motion_mark(key, a, b, 0.0, capture[key])))
    return rows


def contact_summary_rows(motion) -> list:
    """Summary rows for the feet: float, skate, skating ratio, flight time and flight-phase error
    (`runner.motion_metrics.flight_mismatch`, extra + missed) of both paths against the motion-capture
    reference (`motion`: metrics["motion"], the `motion_metrics` of both paths at the clip's rate; the
    capture's own figure in the label), then the anatomy rows (`anatomy_summary_rows`); each marked where
    the optimized path is worse than the plain spline or moved toward the capture (`runner.verdict.motion_mark`).

    Returns:
        [(label, plain value, optimized value, format, mark), ...].
    """
    from runner.verdict import motion_mark

    rows = []
    if motion is not None:
        capture = motion["plain"]["reference"]
        frame_s = 1.0 / float(motion["plain"]["fps"])
        for label, key, fmt in FEET_ROWS:
            if key in capture:
                a, b = motion["plain"]["path"][key], motion["optimized"]["path"][key]
                rows.append((f"{label} (capture {fmt.format(capture[key])})", a, b, fmt,
                             motion_mark(key, a, b, frame_s, capture[key])))
        # flight-phase error: frames in flight in one and not the other (flight times can cancel)
        a, b = (motion[p]["error"]["flight_extra_s"] + motion[p]["error"]["flight_missed_s"] for p in ("plain", "optimized"))
        rows.append(("flight phase error vs capture [s]", a, b, "{:.3f}", motion_mark("flight_phase_error_s", a, b, frame_s)))
        rows += anatomy_summary_rows(motion)
    return rows
