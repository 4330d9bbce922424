"""From a motion-capture clip to a video, a saved path and a metrics report: `process_clip`, the work of
`dynsplines mocap` (the command module is argument glue) and of a batch of clips.

Steps (docs/contacts.md "Where runner/mocap should call these"):

1. Scene: the given MJCF, or (`"auto"`) a floor and boxes fitted to where the clip's feet rest, written
   next to the outputs as `<stem>.scene.xml` (`runner.mocap.scene.clip_scene`); the clip retargeted
   onto it (`load_bvh_reference`: the synthetic first frame dropped, channel orders and frame time read
   from the file, the figure keeping its bone lengths).
2. Contacts of the reference (`solver.contacts.reference_contacts`, surfaces named).
3. Keyframes (`runner.mocap.keyframes.pick_keyframes`): evenly spaced plus the root's extremes, or at
   the contact events; written as `<stem>.keyframes.json` with the contacts (a user can edit it and
   rerun `dynsplines animate` on it), and read back, so the solve is the one `animate` would do.
4. Solve (solver.solve), acceptance figures of the plain spline and the optimized path
   (`solver.metrics.path_metrics`), and the motion metrics of both and of the reference, at the
   reference's frames (`solver.motion_metrics`).
5. Outputs: the saved path (.npz, with `metrics_json` and `contacts`), the metrics (.json), plots, video.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from runner.console import Progress, StopRequest, motion_metrics_table, summary_table
from runner.files import atomic_output, check_writable_dir
from runner.mocap.keyframes import pick_keyframes
from runner.mocap.reference import ROOT_SCALE_LEGS
from runner.mocap.scene import AUTO, clip_scene, name_surfaces
from runner.paths import RENDERS
from runner.saved_path import save_path_npz
from solver.animate import DEFAULT_RATE, default_options
from solver.contacts import reference_contacts
from solver.errors import InputError
from solver.figure import FIGURE_FILE
from solver.frames import FrameSet
from solver.keyframe_file import read_keyframes, write_keyframes
from solver.layout import StateLayout
from solver.metrics import path_metrics
from solver.motion_metrics import motion_metrics
from solver.optimize import Status
from solver.problem import default_limits, figure_problem, parse_terms
from solver.solve import SolveOptions, solve

#: the figure every scene includes
FIGURE = FIGURE_FILE  # the shipped figure (solver.figure)


@dataclass
class ClipOptions:
    """What `process_clip` does with a clip (the options of `dynsplines mocap`).

    Attributes:
        keys: "every" (evenly spaced plus the root's extremes) or "contacts" (contact events).
        every: [s] key spacing (default 0.25 with "every"; with "contacts" the largest gap, None = none).
        partial: the middle keyframe fixes only the root and the legs.
        scene: "auto" (fitted) or an MJCF file. figure: the figure's MJCF.
        terms: the objective terms as for `solver.problem.parse_terms` (None: the default terms, which
            add the contact terms when the clip has contacts). weights: {term: weight} overrides.
            solve: SolveOptions (None: default_options); its `limits` follow the terms chosen for the
            clip (`default_limits`), which are known only once its contacts are.
        rate: quadrature points per second.
        out, save_path, metrics, plot: output paths (None: the defaults under the output folder:
            <stem>.mp4, <stem>.npz, <stem>.metrics.json; no plots). render: write the video.
        fps, size, speed: video settings. quiet: no progress output. command: the command line, recorded
            in the keyframe file's "source".
        root_scale: the scale of the captured root path (`load_bvh_reference`): "legs" (the figure's
            leg length over the subject's) or a number (1: as captured); the value used is recorded in
            the keyframe file's "source".
    """

    keys: str = "every"
    every: float | None = None
    partial: bool = False
    scene: str | os.PathLike = AUTO
    figure: str | os.PathLike = FIGURE
    terms: str | None = None
    weights: dict = field(default_factory=dict)
    solve: SolveOptions | None = None
    rate: float = DEFAULT_RATE
    out: Path | None = None
    save_path: Path | None = None
    metrics: Path | None = None
    plot: Path | None = None
    render: bool = True
    fps: float = 30.0
    size: tuple[int, int] = (960, 540)
    speed: float = 0.5
    quiet: bool = False
    command: str = ""
    extra: dict = field(default_factory=dict)
    root_scale: float | str = ROOT_SCALE_LEGS


def default_out_dir(clip) -> Path:
    """renders/<clip stem>/"""
    return RENDERS / Path(clip).stem


def _sample(frames: FrameSet, times: np.ndarray, layout: StateLayout) -> np.ndarray:
    """The path at `times`, unit quaternions (what MuJoCo's kinematics use)."""
    Y = frames.path(np.clip(times, frames.times[0], frames.times[-1]))
    for slot in layout.quat_slots:
        Y[:, slot] /= np.linalg.norm(Y[:, slot], axis=1, keepdims=True)
    return Y


def reference_motion_metrics(model, layout: StateLayout, solution, reference, contacts) -> dict:
    """`motion_metrics` of the plain spline and the optimized path against the reference clip, over the
    reference's frames within the keyframes' time span (contact times shifted with them).

    Returns:
        {"plain": ..., "optimized": ...}, each a `solver.motion_metrics.motion_metrics` dict.
    """
    from solver.contacts import Contact

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
    return {label: motion_metrics(model, _sample(fs, times, layout), fps, qpos, shifted)
            for label, fs in (("plain", solution.initial), ("optimized", solution.frames))}


def clip_keyframes(clip: Path, out_dir: Path, o: ClipOptions, paths: dict, say=print):
    """Steps 1-3 of `process_clip`: the clip's scene (given or fitted), its retargeted reference, its
    contacts, and keyframes picked from it, written to paths["keyframes"] (and the fitted scene to
    paths["scene"] with --scene auto) and read back as `dynsplines animate FILE` reads them.

    Returns:
        (clip_scene result, reference, model, keyframes, keyframe-file info with the contacts).
    Raises:
        InputError: as `process_clip`.
    """
    # 1-2: scene, reference, contacts
    cs = clip_scene(clip, o.scene, o.figure, paths.get("scene", out_dir / f"{clip.stem}.scene.xml"), o.root_scale)
    ref, model = cs.reference, cs.model
    contacts = name_surfaces(model, ref, reference_contacts(model, ref.qpos, ref.frame_time))
    say(f"dynsplines mocap: {clip} -> {ref.count} frames at {1 / ref.frame_time:.4g} Hz ({ref.duration:.2f} s), "
        f"{len(contacts)} contacts; scene {'fitted: ' if cs.fitted is not None else ''}{cs.scene_path}")
    if cs.fitted is not None:
        for i, (c, h) in enumerate(cs.fitted.boxes):
            say(f"  fitted box{i}: top {100 * (c[2] + h[2]):.1f} cm, x {100 * (c[0] - h[0]):.1f} .. "
                f"{100 * (c[0] + h[0]):.1f} cm, y {100 * (c[1] - h[1]):.1f} .. {100 * (c[1] + h[1]):.1f} cm; "
                f"floor {100 * cs.fitted.floor_z:.1f} cm")

    # 3: keyframes, written and read back (what `dynsplines animate FILE` reads)
    layout = StateLayout.from_model(model)
    every = o.every if (o.every is not None or o.keys == "contacts") else 0.25
    kf0 = pick_keyframes(ref, model, contacts, keys=o.keys, every=every, partial=o.partial)
    source = {"clip": Path(os.path.relpath(clip.resolve(), out_dir.resolve())).as_posix(),
              "command": o.command, "hand_edits": "none", "root_scale": round(ref.root_scale, 6)}
    write_keyframes(paths["keyframes"], kf0, layout, model=o.figure, scene=cs.scene_path, source=source,
                    contacts=contacts)
    keyframes, info = read_keyframes(paths["keyframes"], layout)
    say(f"  wrote {paths['keyframes']}: {keyframes.count} keyframes ({int(keyframes.is_partial.sum())} partial) "
        f"at {', '.join(f'{t:.3f}' for t in keyframes.times)} s")
    return cs, ref, model, keyframes, info


def process_clip(clip, out_dir=None, options: ClipOptions | None = None, say=print) -> dict:
    """Turn a BVH clip into keyframes, an optimized path and its metrics (module docstring).

    Args:
        clip: the .bvh file (CMU skeleton family: any subject's bone lengths, any channel order and
            frame rate). out_dir: the output folder [renders/<clip stem>/], created if missing.
        options: ClipOptions [defaults]. say: where progress lines go (print; a no-op for quiet).
    Returns:
        {"clip", "status" (solver Status value, or "interrupted"), "exit" ("ok" | "failed" |
        "interrupted"), "frames" (reference frames), "fps", "keyframes" (count), "partial", "contacts"
        (count), "variable_frames", "wall_time_s" (whole pipeline), "solve_time_s", "metrics"
        ({"plain", "optimized": path_metrics; "motion": {"plain", "optimized": motion_metrics}}),
        "scene_fitted" (floor_z, boxes as centre/half lists, or None), "outputs" ({name: path}),
        "summary" and "table" (the printed tables)}.
    Raises:
        InputError: a missing or malformed clip, another skeleton (the missing joints named), an
            unwritable output, a bad option.
    """
    t_start = time.perf_counter()
    o = options or ClipOptions()
    clip = Path(clip)
    if not clip.is_file():
        raise InputError(f"{clip}: no such BVH clip (current folder: {Path.cwd()}); give the path of a .bvh file")
    stem = clip.stem
    out_dir = Path(out_dir) if out_dir is not None else default_out_dir(clip)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {
        "keyframes": out_dir / f"{stem}.keyframes.json",
        "save_path": Path(o.save_path) if o.save_path is not None else out_dir / f"{stem}.npz",
        "metrics": Path(o.metrics) if o.metrics is not None else out_dir / f"{stem}.metrics.json",
    }
    if o.render:
        paths["video"] = Path(o.out) if o.out is not None else out_dir / f"{stem}.mp4"
    for key in ("save_path", "metrics", "video"):
        if key in paths:
            check_writable_dir(paths[key], {"save_path": "--save-path", "metrics": "--metrics",
                                            "video": "--out"}[key])
    if o.render:
        from runner.render.side_by_side import check_video_out

        check_video_out(paths["video"], o.size)
    if str(o.scene) == AUTO:
        paths["scene"] = out_dir / f"{stem}.scene.xml"

    cs, ref, model, keyframes, info = clip_keyframes(clip, out_dir, o, paths, say)
    layout = StateLayout.from_model(model)

    # 4: solve and metrics
    weights = parse_terms(o.terms, dict(o.weights or {}), info.contacts)
    options = replace(o.solve or default_options(weights), limits=default_limits(weights))
    objective, initial, conflicts = figure_problem(model, weights, keyframes, rate=o.rate, contacts=info.contacts)
    if conflicts:  # the clip's own keyframes against its own contacts: a heel "in contact" 3 cm up
        say(f"  {len(conflicts)} keyframe(s) hold a site off the contact schedule (met exactly; those contacts "
            "and swings are not held to the bounds)")
    progress = Progress(o.quiet)
    with StopRequest(o.quiet) as stop:
        solution = solve(objective, initial, options, should_stop=stop, progress=progress)
        progress.done()
    interrupted = solution.status is Status.INTERRUPTED or stop.requested
    failed = solution.status in (Status.NONFINITE, Status.FAILED)
    say(f"  stopped: {'interrupted (Ctrl-C), best path so far kept' if stop.requested else solution.message}; "
        f"{solution.n_evals} evaluations, {solution.wall_time_s:.2f} s")
    plain_m = path_metrics(model, initial.times, initial.values, keyframes)
    opt_m = path_metrics(model, solution.frames.times, solution.frames.values, keyframes)
    fps = 1.0 / ref.frame_time
    motion = reference_motion_metrics(model, layout, solution, ref, info.contacts)
    summary = summary_table(plain_m, opt_m, solution, weights, dict(solution.weights))
    table = motion_metrics_table(motion["plain"], motion["optimized"])
    from runner.mocap.contacts import worst_contact_distance

    contact_mm = 1000.0 * worst_contact_distance(ref, model)
    say(summary)
    say(table)
    say(f"motion capture ({clip.name}, retargeted, {ref.count} frames): feet in contact stay within "
        f"{contact_mm:.1f} mm of the surface under them")

    # 5: outputs
    metrics = {"plain": plain_m, "optimized": opt_m, "motion": motion}
    save_path_npz(paths["save_path"], solution, keyframes, ref, cs.scene_path, weights, options, metrics,
                  contacts=info.contacts)
    say(f"  wrote {paths['save_path']}")
    fitted = None if cs.fitted is None else {
        "floor_z": cs.fitted.floor_z,
        "boxes": [{"center": c.tolist(), "half": h.tolist()} for c, h in cs.fitted.boxes]}
    result = {
        "clip": str(clip), "status": "interrupted" if interrupted else solution.status.value,
        "exit": "interrupted" if interrupted else "failed" if failed else "ok",
        "frames": ref.count, "fps": fps, "keyframes": keyframes.count,
        "partial": int(keyframes.is_partial.sum()), "contacts": len(info.contacts),
        "variable_frames": solution.frames.n_variable, "solve_time_s": solution.wall_time_s,
        "max_penetration_mm": opt_m["max_penetration_mm"], "keyframe_error": opt_m.get("keyframe_error"),
        "reference_contact_distance_mm": contact_mm,
        "metrics": metrics, "scene_fitted": fitted, "outputs": {k: str(v) for k, v in paths.items()},
    }
    report = {k: v for k, v in result.items() if k != "metrics"} | {"metrics": metrics}
    with atomic_output(paths["metrics"], suffix=".json") as tmp:
        Path(tmp).write_text(json.dumps(report, indent=1, default=float) + "\n")
    say(f"  wrote {paths['metrics']}")
    if o.plot is not None:
        from runner.plots import plot_solution

        for f in plot_solution(o.plot, model, solution, keyframes, ref, objective=solution.objective,
                               contacts=info.contacts):
            say(f"  wrote {f}")
        result["outputs"]["plot"] = str(o.plot)
    if o.render and not interrupted:
        from types import SimpleNamespace

        args = SimpleNamespace(fps=o.fps, size=o.size, speed=o.speed, quiet=o.quiet)
        r = render_with_progress(paths["video"], model, solution, keyframes, args, ref, info.contacts)
        say(f"  wrote {paths['video']} ({r.n_frames} frames, {r.wall_time_s:.1f} s to render)")
    result["wall_time_s"] = time.perf_counter() - t_start
    result["summary"], result["table"] = summary, table
    say(f"  wall time {result['wall_time_s']:.1f} s")
    return result


def render_with_progress(out, model, solution, keyframes, args, reference=None, contacts=()):
    """The side-by-side video (`runner.render.side_by_side.render_video`) with a progress bar over its
    frames (`runner.console.Steps`; silent with `args.quiet`). Returns the render's info."""
    from runner.console import Steps
    from runner.paths import display_path
    from runner.render import frame_times
    from runner.render.side_by_side import render_video

    n = len(frame_times(float(keyframes.times[0]), float(keyframes.times[-1]), args.fps, args.speed))
    with Steps(f"rendering {display_path(out)}", n, getattr(args, "quiet", False), unit=" frames") as bar:
        return render_video(out, model, solution, keyframes, args, reference, contacts,
                            progress=lambda i, _n: bar.update(i))
