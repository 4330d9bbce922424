"""From a motion-capture clip to the same clip cleaned: `process_clean`, the work of `dynsplines clean`.

The clip is the motion to keep: it is read and retargeted as `mocap` reads it (the figure, the scene
fitted to where its feet rest, the contacts and flights found on it: `runner.pipeline`), and the path is
the capture plus the least displacement that meets the constraints (`solver.displacement`), pinned to
the capture at the `--pin` times (and with `--pin-ends` at the clip's first and last frame). No keyframes are picked and
no in-betweens replace the performance: where nothing must change, the capture comes back exactly.

Outputs, in renders/<clip stem>/ (`--out-dir`), beside `mocap`'s: `<stem>.clean.npz` (the saved path: the
cleaned clip at the capture's frames, `path_times`/`path_qpos`, beside the capture, `reference_qpos`),
`<stem>.clean.bvh` (on the source skeleton: `runner.capture.source_export`), `<stem>.clean.glb`, `<stem>.clean.metrics.json`
and, unless `--no-render`, `<stem>.clean.mp4` (capture | cleaned).
"""
from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from runner.capture.figure_choice import SUBJECT
from runner.capture.reference_motion import ROOT_SCALE_LEGS
from runner.capture.scene import AUTO
from runner.paths import display_path
from runner.show_options import ShowOptions
from solver.errors import InputError
from solver.least_change import LeastChangeOptions

__all__ = ["CleanOptions", "process_clean"]


@dataclass(frozen=True)
class CleanOptions(ShowOptions):
    """What `process_clean` does with a clip (the options of `dynsplines clean`): the video and console
    options of `ShowOptions` (render: the video capture | cleaned; fps, size, speed, camera, quiet, summary,
    command: recorded in the saved path) and these.

    Attributes:
        pins: [s] times where the cleaned clip is the capture (each on the nearest capture frame). pin_ends:
            the first and last frame too (else they move with the clean: a contact that runs into them
            can be fixed there). feet: "planted" (a foot in contact slides no more than the pins force) or
            "captured" (no more than the capture: only penetration, float and flight cleaned;
            `solver.displacement.FEET`). scene, figure, mass, root_scale, skeleton_map: as `runner.pipeline.ClipKeys`.
        solve: LeastChangeOptions (None: the defaults). contacts: a contacts file (or a keyframe file with
            contacts) whose schedule replaces contact detection (`runner.capture.contacts_file`); None: detect.
    """

    pins: tuple = ()
    pin_ends: bool = False
    feet: str = "planted"
    scene: str | os.PathLike = AUTO
    figure: str | os.PathLike = SUBJECT
    mass: float | None = None
    root_scale: float | str = ROOT_SCALE_LEGS
    skeleton_map: str | os.PathLike | None = None
    solve: LeastChangeOptions | None = None
    contacts: str | os.PathLike | None = None


def clean_paths(clip: Path, out_dir: Path, o: CleanOptions) -> dict:
    """The output files of a clean ({name: path}), each folder checked for writing before any work."""
    from runner.files import check_writable_dir

    stem = clip.stem
    paths = {"save_path": out_dir / f"{stem}.clean.npz", "bvh": out_dir / f"{stem}.clean.bvh",
             "glb": out_dir / f"{stem}.clean.glb",
             "metrics": out_dir / f"{stem}.clean.metrics.json", "scene": out_dir / f"{stem}.scene.xml",
             "contacts": out_dir / f"{stem}.contacts.json"}
    if o.render:
        from runner.render.side_by_side import check_video_out

        paths["video"] = out_dir / f"{stem}.clean.mp4"
        check_video_out(paths["video"], o.size)
    check_writable_dir(paths["save_path"], "--out-dir")
    return paths


def _capture(clip: Path, o: CleanOptions, scene_out: Path, say):
    """The clip retargeted (figure, fitted scene) with its contacts and flights, as `mocap` reads it."""
    from runner.capture.clip import read_capture
    from runner.capture.scene import clip_scene
    from runner.pipeline import ClipKeys, _skeleton_map, clip_figure_scene
    from solver.model import check_scene

    k = ClipKeys(scene=o.scene, figure=o.figure, mass=o.mass, root_scale=o.root_scale, skeleton_map=o.skeleton_map)
    capture = read_capture(clip)  # once: the figure and the scene take it, the reference carries it
    figure, scene = clip_figure_scene(capture, k, scene_out)
    cs = clip_scene(capture, scene, figure, scene_out, k.root_scale, _skeleton_map(k))
    ref, model = cs.reference, cs.model
    check_scene(model, cs.scene_path)
    contacts, flights = _contacts(o, model, ref)
    say(f"dynsplines clean: {clip} -> {ref.count} frames at {1 / ref.frame_time:.4g} Hz ({ref.duration:.2f} s), "
        f"{len(contacts)} contacts{f' from {display_path(o.contacts)}' if o.contacts else ''}, {len(flights)} flights; "
        f"scene {'fitted: ' if cs.fitted is not None else ''}{display_path(cs.scene_path)}")
    for note in cs.warnings:
        say(f"  warning: {note}")
    return cs, contacts, flights


def _contacts(o: CleanOptions, model, ref) -> tuple[tuple, tuple]:
    """The clip's contacts (each on the surface under it, unless the file names one) and flights: detected
    (`reference_contacts`, the capture's own flights), or read from `o.contacts` (its flights, else the capture's)."""
    from runner.capture.contact_detection import reference_contacts
    from runner.capture.contacts_file import read_contacts_file
    from runner.capture.scene import name_surfaces
    from solver.problem import capture_airborne

    flights = tuple(capture_airborne(model, ref.times, ref.qpos))
    if o.contacts:
        found, flights = read_contacts_file(o.contacts, model, ref.duration, flights)
    else:
        found = reference_contacts(model, ref.qpos, ref.frame_time)
    named = name_surfaces(model, ref, found)
    return tuple(c if c.surface else n for c, n in zip(found, named, strict=True)), tuple(flights)


def process_clean(clip, out_dir=None, options: CleanOptions | None = None, say=print) -> dict:
    """Clean a BVH clip (module docstring).

    Args:
        clip: the .bvh file. out_dir: the output folder [renders/<clip stem>/], created if missing.
        options: CleanOptions [defaults]. say: where result lines go.
    Returns:
        {"clip", "status", "exit" ("ok" | "failed" | "interrupted"), "frames", "fps", "pins" ([s]),
        "displacement_frames", "split_intervals" (capture frame intervals in more than one quadrature panel,
        `solver.displacement.frame_panels`), "solve_time_s", "cpu_time_s" (the whole command's process time), "solve_cpu_s"
        (the clean's own process time: building and solving the displacement from the retargeted capture and
        its contacts, what the IK peer's CPU time is compared with), "clean"
        (`runner.clean_metrics.clean_figures`), "certificate", "keyframes_on_source" (the pins on the
        written BVH, read back, and the free ends' change apart: `_on_source`), "outputs"}.
    Raises:
        InputError: a missing or malformed clip, another skeleton, an unwritable output, a pin outside the clip,
            a contacts file (`CleanOptions.contacts`) that is missing, malformed or not of this clip's figure and scene.
    """
    from runner.capture.contacts_file import write_contacts_file
    from runner.pipeline import default_out_dir

    cpu0 = time.process_time()
    o = options or CleanOptions()
    clip = Path(clip)
    if not clip.is_file():
        raise InputError(f"{clip}: no such BVH clip (current folder: {Path.cwd()}); give the path of a .bvh file")
    out_dir = Path(out_dir) if out_dir is not None else default_out_dir(clip)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = clean_paths(clip, out_dir, o)
    cs, contacts, flights = _capture(clip, o, paths["scene"], say)
    write_contacts_file(paths["contacts"], contacts, flights, clip)  # the schedule to edit and give back (--contacts)
    say(f"  wrote {display_path(paths['contacts'])} (the contacts: edit them and clean again with --contacts)")
    run, disp, sol, solve_cpu = _solve(cs, contacts, flights, o, clip, say)
    return _outputs(run, disp, sol, cs, o, paths, clip, (cpu0, solve_cpu), say)


def _solve(cs, contacts, flights, o: CleanOptions, clip: Path, say):
    """Build and solve the displacement: (the Run of the cleaned clip (plain: the capture) with its metrics, the
    Displacement, its Solution, [s] the process time of building and solving it)."""
    from runner.progress import Progress, StopRequest
    from runner.run import Run, Source, run_metrics
    from solver.displacement import CUBIC_ERROR, build_displacement, clean_solution, solve_displacement
    from solver.keyframes import Keyframes
    from solver.optimize import Status
    from solver.problem import ProblemSpec, build_problem

    ref, model = cs.reference, cs.model
    options = o.solve or LeastChangeOptions()
    cpu0 = time.process_time()  # the method's, as the IK peer's clock starts after `import mink` (0.3 s of loading)
    disp = build_displacement(model, ref.times, ref.qpos, pins=o.pins, pin_ends=o.pin_ends, contacts=contacts, flights=flights,
                              feet=o.feet)
    if disp.panels.max() > 1:
        say(f"  {int((disp.panels > 1).sum())} of the capture's {len(disp.panels)} frame intervals split into up to "
            f"{int(disp.panels.max())} quadrature panels: its feet move so far from one frame to the next (a low frame "
            f"rate, or poses estimated from video) that a cubic between two points misses them by more than "
            f"{CUBIC_ERROR * 1e3:.2g} mm (docs/mocap.md \"Cleaning a clip\")")
    with StopRequest(o.quiet) as stop:
        progress = Progress(o.quiet)
        sol = solve_displacement(disp, options, should_stop=stop, progress=progress)
        progress.done()
    out = clean_solution(disp, sol)
    solve_cpu = time.process_time() - cpu0  # the clean itself: from the retargeted capture and its contacts
    # the problem's keyframes: the pins and the clip's ends (the cleaned clip's values: the capture's at a pin)
    at = out.frames.is_keyframe
    keys = Keyframes(out.frames.times[at], out.frames.values[at], np.ones((int(at.sum()), model.nq), bool), str(clip))
    problem = build_problem(model, ProblemSpec(keys, contacts, False, (ref.times, ref.qpos), flights))
    source = Source(Path(cs.scene_path), ref, contacts, label=str(clip))
    interrupted = sol.status is Status.INTERRUPTED or stop.requested
    why = "interrupted (Ctrl-C), best path so far kept" if stop.requested else sol.message
    say(f"  stopped: {why}; {sol.n_evals} evaluations, {sol.frames.count} displacement frames, {sol.wall_time_s:.2f} s")
    metrics = run_metrics(problem, out, source)
    for name, fs in (("plain", out.initial), ("optimized", out.frames)):  # a clean's keyframes are its pins alone
        metrics[name]["keyframe_error"] = _pin_error(fs, disp)
    return Run(problem, options, out, source, metrics, interrupted), disp, sol, solve_cpu


def _pin_error(frames, disp) -> float:
    """The keyframe error of `frames` at the pins, where the cleaned clip is the capture (`solver.metrics.pose_error`);
    0 without a pin (the clip's ends are keyframes of the problem, but unpinned they fix nothing)."""
    from solver.metrics import pose_error

    pins = disp.pins
    return pose_error(frames, disp.times[pins], disp.qpos[pins], np.ones(disp.qpos[pins].shape, bool), disp.lc.layout.quat_slots)


def _on_source(paths: dict, say) -> dict | None:
    """Write the cleaned clip onto the source skeleton (`runner.capture.source_export.export_on_source`) and
    say how far the file, read back, is from the source at the pins (there the source's own pose within
    `runner.capture.source_check.ON_SOURCE`) and, apart, at the clip's free ends (the clean's change there).
    Returns the pins' figures ("max_mm", "joint", "time_s", "keys_moved", "keys") and "ends_max_mm" at the
    free ends, or None without a checked frame."""
    from runner.capture.source_export import export_on_source

    res = export_on_source(paths["save_path"], paths["bvh"], required=True)
    say(f"  wrote {res.describe()}")
    for note in res.notes:
        say(f"  {note}")
    check = res.check
    if check is None or not len(check.times):
        return None
    for what, figures in check.lines():
        say(f"  {what} read back from {display_path(paths['bvh'])}: {figures}")
    out, pins = {}, check.held()
    if len(pins.times):
        k, j = pins.worst()
        out |= {"max_mm": round(pins.max_mm(), 3), "joint": pins.joints[j], "time_s": round(float(pins.times[k]), 4),
                "keys_moved": int(pins.moved.sum()), "keys": len(pins.times)}
    ends = check.ends()
    if ends is not None and len(ends.times):
        out["ends_max_mm"] = round(ends.max_mm(), 3)
    return out


def _import_clamp(ref) -> str:
    """The change line's clause for the capture's knees or elbows the import straightened before the clean (its
    "capture" is the retargeted clip, `Reference.clamped`), "" where it straightened none: that correction is
    not in the deviation, but the file on the source skeleton carries it."""
    worst = max(((float(a.max()), j) for j, a in (ref.clamped or {}).items() if len(a) and a.max() > 0), default=None)
    if worst is None:
        return ""
    return (f"; before it, the import straightened knees or elbows the capture bends backwards, {worst[1]} by up to "
            f"{worst[0]:.1f} deg, which the file on the source skeleton carries too (docs/mocap.md \"Back onto the "
            "source skeleton\")")


def _outputs(run, disp, sol, cs, o: CleanOptions, paths: dict, clip: Path, cpu: tuple, say) -> dict:
    """The summary, the saved path, the BVH on the source skeleton (checked at the pins), the metrics, the
    video; the result dict of `process_clean`. cpu: ([s] the command's process time at its start, [s] the
    clean's own, `_solve`)."""
    from runner.capture.gaps import clip_gaps
    from runner.clean_metrics import clean_figures
    from runner.render.side_by_side import VideoOptions
    from runner.run import Outputs, _filtered_capture, render_with_progress, report, write_metrics_json, write_results
    from solver.layout import StateLayout

    ref, model = cs.reference, cs.model
    fig = clean_figures(model, run.solution.frames.values, ref.qpos, 1.0 / ref.frame_time,
                        _filtered_capture(ref, StateLayout.from_model(model)))
    if o.summary:
        say(report(run).replace("plain spline", "capture"))
    say(f"  change from the capture: deviation mean {fig['deviation_mean_cm']:.2f} cm, max {fig['deviation_max_cm']:.2f} cm; "
        f"joint angles mean {fig['angle_mean_deg']:.2f} deg, max {fig['angle_max_deg']:.1f} deg; "
        f"peak acceleration of the change: pelvis {fig['change_pelvis_m_s2']:.2f} m/s^2 (capture at 6 Hz "
        f"{fig['capture_pelvis_m_s2']:.2f}), joints {fig['change_joint_rad_s2']:.1f} rad/s^2 at {fig['change_joint']} "
        f"(capture at 6 Hz {fig['capture_joint_rad_s2']:.1f}){_import_clamp(ref)}")
    video = VideoOptions(fps=o.fps, size=o.size, speed=o.speed, camera=o.camera, quiet=o.quiet,
                         panels=("reference", "optimized"))  # capture | cleaned
    pins = [float(t) for t in disp.times[disp.pins]]
    outputs = Outputs(save_path=paths["save_path"], video=None, video_options=video, summary=False, quiet=o.quiet,
                      command={"command": o.command, "mode": "clean", "pins": pins})
    write_results(run, outputs, say)
    on_source = _on_source(paths, say)
    from runner.export import export_saved_path

    say(f"  wrote {export_saved_path(paths['save_path'], paths['glb'], option='--out-dir').describe()}")
    solve_cpu, cpu = cpu[1], time.process_time() - cpu[0]
    result = {"clip": str(clip), "status": "interrupted" if run.interrupted else run.solution.status.value,
              "exit": "interrupted" if run.interrupted else "failed" if run.failed else "ok",
              "frames": ref.count, "fps": 1.0 / ref.frame_time, "pins": pins,
              "displacement_frames": sol.frames.count, "split_intervals": int((disp.panels > 1).sum()),
              "solve_time_s": sol.wall_time_s, "cpu_time_s": cpu,
              "solve_cpu_s": solve_cpu,
              "clean": fig, "certificate": [r.__dict__ for r in sol.certificate],
              "reference_gaps": [str(g) for g in clip_gaps(ref)],
              "keyframes_on_source": on_source, "outputs": {k: str(v) for k, v in paths.items()}}
    write_metrics_json(run, paths["metrics"], extra={k: v for k, v in result.items() if k not in ("status", "exit")})
    say(f"  wrote {display_path(paths['metrics'])}")
    if "video" in paths and not run.interrupted:
        try:
            info = render_with_progress(paths["video"], run, video, quiet=o.quiet)
            say(f"  wrote {display_path(paths['video'])} ({info.summary()})")
        except KeyboardInterrupt:
            print(f"\ndynsplines: interrupted while rendering: {display_path(paths['video'])} not written",
                  file=sys.stderr)
            result["exit"] = "interrupted"
    say(f"  cpu time {cpu:.1f} s (before the video)")
    return result
