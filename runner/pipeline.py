"""From a motion-capture clip to a video, a saved path and a metrics report: `process_clip`, the work of
`dynsplines mocap` (the command module is argument glue) and of a batch of clips.

Steps (docs/architecture.md; the contact steps: docs/contacts.md):

0. The clip read once (`runner.capture.clip.read_capture`): every step below takes that `Capture`, and the
   reference carries it to the summary and the way back (which reads back only the file it writes).
1. Figure and scene: the figure (`--figure`: by default the subject's own, made from the clip's
   HIERARCHY and written next to the outputs as `<stem>.figure.xml`, runner/capture/figure_choice.py);
   the given scene MJCF (with the chosen figure included), or (`"auto"`) a floor and boxes fitted to
   where the clip's feet rest, written next to the outputs as `<stem>.scene.xml`
   (`runner.capture.scene.clip_scene`); the clip's skeleton recognised (runner/capture/skeleton.py, or named
   by `--skeleton-map FILE`) and the clip retargeted onto the figure (`load_bvh_reference`: a leading rest
   frame dropped, channel orders and frame time read from the file; on the subject's figure without
   loss, docs/mocap.md).
2. Contacts of the reference (`runner.capture.contact_detection.reference_contacts`, surfaces named).
3. Keyframes (`runner.capture.capture_keys.pick_keyframes`): evenly spaced plus the root's extremes, or at
   the contact events; written as `<stem>.keyframes.json` with the contacts (a user can edit it and
   rerun `dynsplines animate` on it), and read back, so the solve is the one `animate` would do.
4. Solve (solver.paper.solve), acceptance figures of the plain spline and the optimized path
   (`solver.metrics.path_metrics`), and the motion metrics of both and of the reference, at the
   reference's frames (`runner.motion_metrics`).
5. Outputs: the saved path (.npz, with `metrics_json` and `contacts`), the metrics (.json), plots, video.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from runner.capture.capture_keys import pick_keyframes
from runner.capture.clip import Capture, as_capture
from runner.capture.contact_detection import reference_contacts
from runner.capture.figure_choice import SUBJECT, choose_figure, is_default, scene_with_figure
from runner.capture.gaps import clip_gaps
from runner.capture.key_joints import frame_joints
from runner.capture.reference_motion import ROOT_SCALE_LEGS
from runner.capture.scene import AUTO, FLOOR, clip_scene, name_surfaces, read_boxes
from runner.paths import display_path
from runner.show_options import ShowOptions
from solver.errors import InputError
from solver.figure import FIGURE_FILE
from solver.keyframe_file import read_keyframes, write_keyframes
from solver.layout import StateLayout
from solver.least_change import LeastChangeOptions
from solver.model import check_scene

#: the figure every scene includes
FIGURE = FIGURE_FILE  # the shipped figure (solver.figure)


@dataclass(frozen=True)
class ClipOptions(ShowOptions):
    """What `process_clip` does with a clip (the options of `dynsplines mocap`): the video and console
    options of `ShowOptions` (render, fps, size, speed, camera, quiet, summary; command: recorded in the
    keyframe file's "source") and these.

    Attributes:
        keys: "every" (evenly spaced plus the root's extremes) or "contacts" (contact events).
        every: [s] key spacing (default 0.25 with "every"; with "contacts" the largest gap, None = none).
        partial: the middle keyframe fixes only the root and the legs.
        scene: "auto" (fitted) or an MJCF file. figure: "subject" (the subject's own figure, made from the
            clip), "default" (the shipped figure) or a figure MJCF. mass: [kg] the subject's body mass
            (None: from the stature; "subject" only).
        forces: also the force bounds (`--terms all`, `solver.ProblemSpec.forces`).
        solve: LeastChangeOptions (None: the defaults).
        out, save_path, metrics, plot: output paths (None: the defaults under the output folder:
            <stem>.mp4, <stem>.npz, <stem>.metrics.json; no plots).
        panels: the video's panels, left to right (`runner.render.side_by_side.VideoOptions`).
        exports: the optimized path also written as these .bvh / .glb files.
        root_scale: the scale of the captured root path (`load_bvh_reference`): "legs" (the figure's
            leg length over the subject's) or a number (1: as captured); the value used is recorded in
            the keyframe file's "source".
        skeleton_map: a skeleton map file naming the joints of roles the recogniser cannot find
            (`--skeleton-map`; runner/capture/skeleton_map.py), or None.
        key_frames: the clip's frames an animator keyed (`--key-frames`; 0 = the first after its rest
            frames): the keyframes, instead of `keys` and `every` (`pick_keyframes`); None: picked.
        key_joints: a file naming the clip's joints keyed at the partial key frames (`--key-joints`), or None.
        boxes: with scene "floor", boxes in the clip's coordinates (`--boxes FILE.json`), or None.
    """

    keys: str = "every"
    every: float | None = None
    partial: bool = False
    scene: str | os.PathLike = AUTO
    figure: str | os.PathLike = SUBJECT
    mass: float | None = None
    forces: bool = False
    solve: LeastChangeOptions | None = None
    out: Path | None = None
    save_path: Path | None = None
    metrics: Path | None = None
    plot: Path | None = None
    exports: tuple = ()
    panels: tuple = ("plain", "optimized")
    root_scale: float | str = ROOT_SCALE_LEGS
    skeleton_map: str | os.PathLike | None = None
    key_frames: tuple[int, ...] | None = None
    key_joints: str | os.PathLike | None = None
    boxes: str | os.PathLike | None = None


def default_out_dir(clip) -> Path:
    """renders/<clip stem>/, in the current folder."""
    return Path("renders") / Path(clip).stem


@dataclass(frozen=True)
class ClipKeys:
    """How a clip becomes a keyframe file (`write_clip_keyframes`): `dynsplines mocap`, `batch` and
    `keyframes-from-bvh` alike.

    Attributes:
        scene: "auto" (a floor and boxes fitted to where the clip's feet rest, written to `scene_out`)
            or a scene MJCF. figure: "subject", "default" or a figure MJCF (`choose_figure`; a subject
            figure is written to `figure_out`). mass: [kg] the subject's body mass (None: from the stature).
            root_scale: "legs" or a number (`load_bvh_reference`).
        keys: "every" or "contacts". every: [s] key spacing (None: 0.25 with "every", no limit with
            "contacts"). partial: the middle keyframe fixes only the root and the legs.
        extremes: with "every", also key the root's highest and lowest frames.
        command: the command line recorded in the file's "source".
        skeleton_map: a skeleton map file (`--skeleton-map`), or None; the skeleton as read is recorded
            in the file's "source" "skeleton" (so `animate` reads the clip again with it).
        key_frames: the frames an animator keyed (`pick_keyframes` `frames`), or None: picked.
        key_joints: a file naming the joints keyed at the partial ones (runner/capture/key_joints.py), or None.
        boxes: with scene "floor", a file of boxes in the clip's coordinates (`read_boxes`), or None.
    """

    scene: str | os.PathLike = AUTO
    figure: str | os.PathLike = SUBJECT
    mass: float | None = None
    root_scale: float | str = ROOT_SCALE_LEGS
    keys: str = "every"
    every: float | None = None
    partial: bool = False
    extremes: bool = True
    command: str = ""
    skeleton_map: str | os.PathLike | None = None
    key_frames: tuple[int, ...] | None = None
    key_joints: str | os.PathLike | None = None
    boxes: str | os.PathLike | None = None


#: the stages of `write_clip_keyframes`, for a progress bar
CLIP_STAGES = ("retargeting (and fitting the scene)", "contacts", "keyframes", "writing")


def figure_path_for(scene_out: Path) -> Path:
    """Where the subject's figure is written: beside the scene, `<stem>.figure.xml` for `<stem>.scene.xml`."""
    name = scene_out.name
    return scene_out.with_name(f"{name[:-len('.scene.xml')] if name.endswith('.scene.xml') else scene_out.stem}.figure.xml")


def clip_figure_scene(clip: Path | Capture, k: ClipKeys, scene_out: Path):
    """The figure file of the clip (the run's `Capture`, or its file; `choose_figure`, a subject figure
    written beside `scene_out`), and the scene
    to retarget onto: "auto", or the given scene with that figure (`scene_with_figure`, written to
    `scene_out` when the figure differs from the scene's own; with the default figure, the given scene
    as it is)."""
    scene = k.scene
    if str(scene) not in (AUTO, FLOOR) and not is_default(k.figure):
        from solver.model import load_model

        check_scene(load_model(scene), scene)  # the user's scene first: a floor, the figure (file and fix named)
    figure = choose_figure(k.figure, clip, figure_path_for(scene_out), k.mass, _skeleton_map(k))
    if str(scene) not in (AUTO, FLOOR) and not is_default(k.figure):
        scene = scene_with_figure(scene, figure, scene_out)
    return figure, scene


def _skeleton_map(k: ClipKeys):
    """The `SkeletonMap` of `k.skeleton_map` (read and checked), or None."""
    if k.skeleton_map is None:
        return None
    from runner.capture.skeleton_map import read_skeleton_map

    return read_skeleton_map(k.skeleton_map)


def write_clip_keyframes(clip: Path | Capture, out: Path, k: ClipKeys, scene_out: Path, progress=None):
    """A clip's (read once here, `read_capture`, unless given as the run's `Capture`: every step takes that
    value, and the reference carries it) figure and scene (given or fitted), its retargeted reference, its contacts and keyframes
    picked from it (`pick_keyframes`), written as the keyframe file `out` (with the contacts and the
    capture's flights, `solver.problem.capture_airborne`, the figure
    as "model" and a "source" naming the clip relative to the file, the command and the root scale).
    `progress(i, stage)` is called as each of CLIP_STAGES finishes (None: silent).

    Returns:
        (clip_scene result, contacts, the keyframes written).
    Raises:
        InputError: a missing or malformed clip, another skeleton, a scene without the figure or a floor,
            an unwritable file.
    """
    def done(i):
        if progress is not None:
            progress(i + 1, CLIP_STAGES[i])

    capture = as_capture(clip)
    figure, scene = clip_figure_scene(capture, k, scene_out)
    smap = _skeleton_map(k)
    boxes = read_boxes(k.boxes) if k.boxes is not None else ()
    cs = clip_scene(capture, scene, figure, scene_out, k.root_scale, smap, root_height=k.key_frames is None, boxes=boxes)
    ref, model = cs.reference, cs.model
    check_scene(model, cs.scene_path)  # a floor, the free root, the contact sites (names the file and the fix)
    done(0)
    contacts = name_surfaces(model, ref, reference_contacts(model, ref.qpos, ref.frame_time))
    done(1)
    every = k.every if (k.every is not None or k.keys == "contacts") else 0.25
    keyframes = pick_keyframes(ref, model, contacts, keys=k.keys, every=every, partial=k.partial, extremes=k.extremes,
                               frames=k.key_frames, frame_joints=frame_joints(capture, ref, model, k.key_frames, k.key_joints))
    done(2)
    source = {"clip": Path(os.path.relpath(Path(capture.source).resolve(), Path(out).parent.resolve())).as_posix(),
              "command": k.command, "hand_edits": "none", "root_scale": round(ref.root_scale, 6)}
    if ref.skeleton is not None:  # read again by `animate` as read here
        source["skeleton"] = json.loads(ref.skeleton.skeleton_map().text())
    from solver.problem import capture_airborne

    write_keyframes(out, keyframes, StateLayout.from_model(model), model=figure, scene=cs.scene_path,
                    source=source, contacts=contacts, flights=capture_airborne(model, ref.times, ref.qpos))
    done(3)
    return cs, contacts, keyframes


def clip_keyframes(clip: Path, out_dir: Path, o: ClipOptions, paths: dict, say=print):
    """Steps 1-3 of `process_clip`: `write_clip_keyframes` to paths["keyframes"] (the fitted scene to
    paths["scene"] with --scene auto), read back as `dynsplines animate FILE` reads it.

    Returns:
        (clip_scene result, reference, model, keyframes, keyframe-file info with the contacts).
    Raises:
        InputError: as `process_clip`.
    """
    k = ClipKeys(scene=o.scene, figure=o.figure, mass=o.mass, root_scale=o.root_scale, keys=o.keys, every=o.every,
                 partial=o.partial, command=o.command, skeleton_map=o.skeleton_map, key_frames=o.key_frames,
                 key_joints=o.key_joints, boxes=o.boxes)
    from runner.progress import Steps

    with Steps(f"keyframes from {clip.name}", len(CLIP_STAGES), o.quiet, unit=" stages") as bar:
        cs, contacts, _ = write_clip_keyframes(clip, paths["keyframes"], k,
                                               paths.get("scene", out_dir / f"{clip.stem}.scene.xml"),
                                               progress=lambda i, stage: bar.update(i, note=stage))
    ref, model = cs.reference, cs.model
    say(f"dynsplines mocap: {clip} -> {ref.count} frames at {1 / ref.frame_time:.4g} Hz ({ref.duration:.2f} s), "
        f"{len(contacts)} contacts; scene {'fitted: ' if cs.fitted is not None else ''}{display_path(cs.scene_path)}")
    if cs.fitted is not None:
        say(f"  fitted capture {cs.capture_floor.describe_floor()}; levelled: the scene's floor is z = 0")
        for i, (c, h) in enumerate(cs.fitted.boxes):
            say(f"  fitted box{i}: top {100 * (c[2] + h[2]):.1f} cm, x {100 * (c[0] - h[0]):.1f} .. "
                f"{100 * (c[0] + h[0]):.1f} cm, y {100 * (c[1] - h[1]):.1f} .. {100 * (c[1] + h[1]):.1f} cm; "
                f"floor {100 * cs.fitted.floor_z:.1f} cm")
    for note in cs.warnings:
        say(f"  warning: {note}")
    keyframes, info = read_keyframes(paths["keyframes"], model)
    say(f"  wrote {display_path(paths['keyframes'])}: {keyframes.count} keyframes ({int(keyframes.is_partial.sum())} partial) "
        f"at {', '.join(f'{t:.3f}' for t in keyframes.times)} s")
    return cs, ref, model, keyframes, info


def clip_problem(clip: Path, out_dir: Path, o: ClipOptions, paths: dict, say=print):
    """Steps 1-3 of `process_clip` and the problem they make: `clip_keyframes`, then the problem with the
    clip's contacts and capture (`solver.build_problem`), as `dynsplines animate` would make it from the keyframe file
    written here. What `mocap`, `batch` and `bench contacts` solve for a clip.

    Returns:
        (problem, source, clip_scene result).
    Raises:
        InputError: as `process_clip`.
    """
    from runner.run import Source
    from solver.problem import ProblemSpec, build_problem

    cs, ref, model, keyframes, info = clip_keyframes(clip, out_dir, o, paths, say)
    contacts = tuple(info.contacts or ())
    problem = build_problem(model, ProblemSpec(keyframes, contacts, o.forces, (ref.times, ref.qpos), info.flights))
    return problem, Source(Path(cs.scene_path), ref, contacts, label=str(clip)), cs


def clip_paths(clip: Path, out_dir: Path, o: ClipOptions) -> dict:
    """The output files of a clip ({name: path}): keyframes, save_path, metrics, video (with render),
    scene (with --scene auto); each folder checked for writing before any work."""
    from runner.files import check_writable_dir

    stem = clip.stem
    paths = {
        "keyframes": out_dir / f"{stem}.keyframes.json",
        "save_path": Path(o.save_path) if o.save_path is not None else out_dir / f"{stem}.npz",
        "metrics": Path(o.metrics) if o.metrics is not None else out_dir / f"{stem}.metrics.json",
    }
    if o.render:
        paths["video"] = Path(o.out) if o.out is not None else out_dir / f"{stem}.mp4"
    for key, option in (("save_path", "--save-path"), ("metrics", "--metrics"), ("video", "--out")):
        if key in paths:
            check_writable_dir(paths[key], option)
    if o.render:
        from runner.render.side_by_side import check_video_out

        check_video_out(paths["video"], o.size)
    if o.plot is not None:
        check_writable_dir(Path(o.plot) / "plot.png", "--plot")
    if o.exports:
        from runner.run import check_exports

        check_exports(o.exports)
    if str(o.scene) in (AUTO, FLOOR) or not is_default(o.figure):
        paths["scene"] = out_dir / f"{stem}.scene.xml"
    if str(o.figure) == SUBJECT:
        paths["figure"] = out_dir / f"{stem}.figure.xml"
    return paths


def process_clip(clip, out_dir=None, options: ClipOptions | None = None, say=print) -> dict:
    """Turn a BVH clip into keyframes, an optimized path and its metrics (module docstring).

    Args:
        clip: the .bvh file (CMU skeleton family: any subject's bone lengths, any channel order and
            frame rate). out_dir: the output folder [renders/<clip stem>/ in the current folder],
            created if missing.
        options: ClipOptions [defaults]. say: where result lines go (print; a no-op in a batch's workers).
            Progress bars follow `options.quiet`.
    Returns:
        {"clip", "status" (solver Status value, or "interrupted"), "exit" ("ok" | "failed" |
        "interrupted"), "frames" (reference frames), "fps", "keyframes" (count), "partial", "contacts"
        (count), "reference_contact_distance_mm" and "reference_feet_disagreement_mm" (the retargeted clip's
        resting feet from the surfaces and the capture's own disagreement, `runner.capture.root_height.feet_line`;
        None off the subject's figure), "reference_footplant_mm" (`FootPlant.largest_mm`: the most each foot
        and the root were lowered to put resting feet on their surfaces), "reference_glitches" (the tracking glitches
        repaired, `runner.capture.glitches.Glitch`), "reference_gaps" (the frames filled where the file had no number,
        `runner.capture.gaps.Gap`), "keyframes_on_source" (`keyframes_on_source_report`; None off the
        subject's figure), "variable_frames", "wall_time_s" (whole pipeline), "solve_time_s", "keyframe_conflicts" (keyframes
        where the keyframes decide a constraint, `Solution.relaxations`), "relaxed" ({constraint: count} of
        those relaxations), "stalled" ({constraint: amount [SI]}
        the keyframes leave out of reach, `Solution.unmet`), "certificate" (a dict per limit raised:
        `solver.feasibility.Raise`'s fields), "certificate_finer" (`_finer`: the certificate checked at a finer
        spacing, or None), "unmet_at_end" ({constraint: worst value over
        its tolerance} of those still beyond it when the solve ended, `Solution.integrals_final`),
        "plain_constraints" ({constraint: worst value over its tolerance} on the plain spline,
        `Solution.integrals_initial`), "metrics"
        ({"plain", "optimized": path_metrics; "motion": {"plain", "optimized": motion_metrics}}),
        "scene_fitted" (the capture floor's floor_z and floor_slope, capture_frame (w x y z tx ty tz: the
        transform to the levelled frame), boxes in that frame as centre/half lists, or None), "outputs"
        ({name: path})}.
    Raises:
        InputError: a missing or malformed clip, another skeleton (the missing joints named), an
            unwritable output, a bad option.
    """
    from runner.render.side_by_side import VideoOptions
    from runner.run import Outputs, execute, write_metrics_json

    t_start = time.perf_counter()
    o = options or ClipOptions()
    clip = Path(clip)
    if not clip.is_file():
        raise InputError(f"{clip}: no such BVH clip (current folder: {Path.cwd()}); give the path of a .bvh file")
    out_dir = Path(out_dir) if out_dir is not None else default_out_dir(clip)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = clip_paths(clip, out_dir, o)
    problem, source, cs = clip_problem(clip, out_dir, o, paths, say)
    options_ = o.solve or LeastChangeOptions()
    video = VideoOptions(fps=o.fps, size=o.size, speed=o.speed, panels=o.panels, camera=o.camera, quiet=o.quiet)
    outputs = Outputs(save_path=paths["save_path"], exports=tuple(o.exports), plot_dir=o.plot, video=paths.get("video"),
                      video_options=video, summary=o.summary, quiet=o.quiet, command={"command": o.command})
    run = execute(problem, options_, source, outputs, say)
    on_source = keyframes_on_source_report(paths["save_path"], cs, problem.keyframes, say)
    ref = source.reference
    status = "interrupted" if run.interrupted else run.solution.status.value
    result = {
        "clip": str(clip), "status": status,
        "exit": "interrupted" if run.interrupted else "failed" if run.failed else "ok",
        "frames": ref.count, "fps": 1.0 / ref.frame_time, "keyframes": problem.keyframes.count,
        "partial": int(problem.keyframes.is_partial.sum()), "contacts": len(problem.contacts),
        **_solve_fields(run.solution),
        "max_penetration_mm": run.metrics["optimized"]["max_penetration_mm"],
        "keyframe_error": run.metrics["optimized"].get("keyframe_error"),
        **_reference_fields(ref, problem.model),
        "stance_agreement": _agreement(problem, ref),
        "keyframes_on_source": on_source,
        "metrics": run.metrics, "scene_fitted": _scene_fitted(cs), "outputs": {k: str(v) for k, v in paths.items()},
    }
    if o.plot is not None:
        result["outputs"]["plot"] = str(o.plot)
    extra = {k: v for k, v in result.items() if k not in ("metrics", "status", "exit", "keyframes", "partial", "contacts")}
    write_metrics_json(run, paths["metrics"], extra=extra)
    say(f"  wrote {display_path(paths['metrics'])}")
    result["wall_time_s"] = time.perf_counter() - t_start
    say(f"  wall time {result['wall_time_s']:.1f} s")
    return result


def _reference_fields(ref, model) -> dict:
    """The metrics report's figures of the retargeted capture `ref` itself (`process_clip`'s "reference_*")."""
    from runner.capture.root_height import feet_disagreement, worst_contact_distance

    apart = feet_disagreement(ref, model)  # [m], None off the subject's figure
    return {"reference_contact_distance_mm": 1000.0 * worst_contact_distance(ref, model),
            "reference_feet_disagreement_mm": None if apart is None else 1000.0 * apart,
            "reference_footplant_mm": ref.plant.largest_mm() if ref.plant is not None else None,
            "reference_glitches": [str(g) for g in ref.glitches],
            "reference_gaps": [str(g) for g in clip_gaps(ref)]}


def _scene_fitted(cs) -> dict | None:
    """The metrics report's "scene_fitted" of a clip's scene (`process_clip`), None when not fitted."""
    return None if cs.fitted is None else {
        "floor_z": cs.capture_floor.floor_z, "floor_slope": list(cs.capture_floor.floor_slope),
        "capture_frame": [*cs.frame.quat.tolist(), *cs.frame.shift.tolist()],
        "boxes": [{"center": c.tolist(), "half": h.tolist()} for c, h in cs.fitted.boxes], "notes": list(cs.warnings)}


def keyframes_on_source_report(npz: Path, cs, keyframes, say=print) -> dict | None:
    """The saved path written onto the source skeleton (as `dynsplines export --to FILE.bvh` writes it, into a
    temporary file) and read back: how far its joints are from the clip's own at the keyframes
    (`runner.capture.source_check.keys_on_source`), said in one line that names, at the key moved most,
    the corrections responsible (the knee and elbow hyperextension clamp, the footplant, the repair of
    tracking glitches, a partial key; the root-height correction and the levelling are taken off by the
    export). Only on the subject's own figure (another figure's bones are not the source's), with a
    saved path.

    Returns:
        {"max_mm", "joint", "time_s", "keys_moved" (keys with a joint beyond `ON_SOURCE`), "keys",
        "clamped_deg" ({knee or elbow: [deg] hyperextension removed at that key}), "planted_mm" ({foot or
        "root": [mm] the footplant lowered it at that key, `FootPlant.moved_at`}), "unexplained_s" (the times [s] of
        keys moved where the import changed nothing: the way back off there, [] when it is exact)}, all read
        from the written file; or None.
    """
    import tempfile

    from runner.capture.source_check import ON_SOURCE, corrections_at, corrections_text
    from runner.capture.source_export import export_on_source

    ref = cs.reference
    if not ref.captured_root or ref.skeleton is None or not Path(npz).is_file():
        return None
    with tempfile.TemporaryDirectory(prefix="dynsplines-way-back-") as tmp:
        res = export_on_source(npz, Path(tmp) / "way_back.bvh",
                               clip=ref.capture.clip if ref.capture is not None else None)  # the run's parse
    check = None if res is None else res.check
    if check is None or not len(check.times):
        return None
    k, j = check.worst()
    t = float(check.times[k])
    clamped, planted, glitched, partial = corrections_at(ref, keyframes, t)
    unexplained = [round(float(s), 4) for s, moved in zip(check.times, check.moved)
                   if moved and not any(corrections_at(ref, keyframes, float(s)))]
    out = {"max_mm": round(check.max_mm(), 3), "joint": check.joints[j], "time_s": round(t, 4),
           "keys_moved": int(check.moved.sum()), "keys": len(check.times), "clamped_deg": clamped,
           "planted_mm": planted, "unexplained_s": unexplained}
    line = f"  keyframes on the source skeleton (export --to FILE.bvh, read back): {check.summary()}"
    if check.moved.any():
        why = corrections_text(clamped, planted, glitched, partial)
        line += (f" ({why}; beyond {1000 * ON_SOURCE:g} mm the import's clean-up - the knee and elbow hyperextension "
                 "clamp, the footplant, the repair of tracking glitches - moved the capture: docs/mocap.md \"Back onto "
                 "the source skeleton\")")
    if unexplained:
        line += (f"; {len(unexplained)} key(s) moved where the import changed nothing, at "
                 f"{', '.join(f'{s:.2f}' for s in unexplained)} s: the way back is off there")
    say(line)
    for note in res.notes:
        say(f"  {note}")
    return out


def _agreement(problem, ref) -> dict:
    """The contact schedule's recall and precision of the capture's stance frames (runner/capture/stance.py)."""
    from runner.capture.stance import schedule_agreement

    a = schedule_agreement(problem.model, ref.qpos, ref.frame_time, problem.contacts)
    return {"recall": a.recall, "precision": a.precision, "stance_frames": a.stance_frames,
            "schedule_frames": a.schedule_frames}


def _solve_fields(solution) -> dict:
    """The solve's fields of `process_clip`'s result: its frames, time, relaxations, the constraints out of
    reach or unmet at the end, and each constraint's worst value over its tolerance on the plain spline."""
    return {"variable_frames": solution.frames.n_variable, "solve_time_s": solution.wall_time_s,
            "keyframe_conflicts": len(solution.relaxations), "relaxed": _relaxed(solution),
            "stalled": dict(solution.unmet or {}),
            "certificate": [asdict(r) for r in getattr(solution, "certificate", ()) or ()],
            "certificate_finer": _finer(solution),
            "unmet_at_end": {k: v for k, v in solution.integrals_final.items() if v > 1.0},
            "plain_constraints": dict(solution.integrals_initial)}


def _finer(solution) -> dict | None:
    """`Solution.finer` as JSON: {"rate" [1/s], "kept" (the finer solve's path returned), "other" (the other
    solve's raises, `solver.feasibility.Raise`'s fields)}, or None when the certificate was not checked."""
    finer = getattr(solution, "finer", ()) or ()
    if not finer:
        return None
    rate, kept, other = finer
    return {"rate": float(rate), "kept": bool(kept), "other": [asdict(r) for r in other]}


def _relaxed(solution) -> dict:
    """{constraint name: how many relaxations the keyframes forced on it} (`Solution.relaxations`)."""
    out: dict = {}
    for r in getattr(solution, "relaxations", ()) or ():
        out[r.constraint] = out.get(r.constraint, 0) + 1
    return out
