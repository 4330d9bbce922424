"""A figure problem from files: the keyframe file, its scene (or --scene) and the motion-capture clip it
was made from (the reference shown in the summary and the saved path). `file_problem` is what
`dynsplines animate`, `run-and-step` and the benchmarks of a keyframe file solve."""
from __future__ import annotations

import sys
from pathlib import Path

from runner.capture.reference_motion import IMPORT_STAGES, load_bvh_reference
from runner.paths import MODELS
from solver.errors import InputError
from solver.keyframe_file import read_document, read_keyframes
from solver.layout import StateLayout
from solver.model import check_scene, load_model
from solver.problem import forces_of

RUN_AND_STEP_KEYFRAMES = MODELS / "run_and_step.keyframes.json"


def load_problem(keyframes_path: Path, scene: Path | None):
    """(keyframes, info, model, layout, scene_path) for a keyframe file and an optional scene override.

    Raises:
        InputError: an unreadable or malformed keyframe file, no scene, a scene MuJoCo cannot load, or a
            scene without the figure (no free joint or no contact sites) or without a floor
            (`solver.model.check_scene`); the message names the file.
    """
    keyframes_path = Path(keyframes_path)
    head = _peek_scene(keyframes_path)  # also reports a missing, unreadable or malformed file
    scene_path = Path(scene) if scene is not None else head
    if scene_path is None:
        raise InputError(f"{keyframes_path}: no 'scene' in the file; give one with --scene SCENE.xml")
    if scene is None and not scene_path.exists():  # a file copied without its scene
        raw = read_document(keyframes_path)["scene"]
        raise InputError(f"{keyframes_path}: field 'scene' {raw!r} is read relative to the keyframe file's folder "
                         f"({keyframes_path.resolve().parent}), where there is no {raw}; copy the scene (and the "
                         "figure it includes) there, correct the path in the file, or give --scene SCENE.xml")
    model = load_model(scene_path)
    check_scene(model, scene_path)
    layout = StateLayout.from_model(model)
    keyframes, info = read_keyframes(keyframes_path, model)
    return keyframes, info, model, layout, scene_path


def _peek_scene(path: Path) -> Path | None:
    data = read_document(path)  # InputError naming the file for anything unreadable
    scene = data.get("scene") if isinstance(data, dict) else None
    if isinstance(scene, str) and "\x00" in scene:
        raise InputError(f"{path}: field 'scene' is {scene!r}; give a path relative to the keyframe file")
    return (path.parent / scene).resolve() if isinstance(scene, str) and scene else None


def find_reference(info, model, quiet=False):
    """The motion-capture reference of a keyframe file (its "source" "clip", relative to the file), or None
    when the file names no clip or the clip is not there. Progress of the import unless `quiet`. The root
    path is scaled as the file's keyframes were made: its "source" "root_scale", or 1 (as captured) for a
    file that records none (made before the scaling, like the shipped run_and_step.keyframes.json), and
    the clip's skeleton read as the file records it ("skeleton": roles, unit, up axis); a file that records
    none was made with the CMU skeleton's rest pose as the figure's (`runner.capture.body_frames.
    rest_pose_frames`) and is read so."""
    source = getattr(info, "source", None) or {}
    clip = source.get("clip")
    if not clip:
        return None
    path = Path(info.path).parent / clip if hasattr(info, "path") else MODELS / clip
    if not path.is_file():  # a file copied without its clip: said, since the capture's bounds go with it
        where = f"{info.path}: " if hasattr(info, "path") else ""
        print(f"dynsplines: warning: {where}source.clip {clip!r} is read relative to the keyframe file, and {path.resolve()} "
              "is not there: solved without the capture (no comparison with it, no no-jolt or effort bounds from "
              "it); copy the clip there or correct source.clip", file=sys.stderr)
        return None
    import json

    from runner.capture.skeleton_map import parse_skeleton_map
    from runner.progress import Steps

    recorded = source.get("skeleton")
    smap = parse_skeleton_map(json.dumps(recorded), f"{info.path}: source.skeleton") if recorded else None
    with Steps(f"importing {path.name}", len(IMPORT_STAGES), quiet, unit=" stages") as bar:
        return load_bvh_reference(path, model, progress=lambda i, stage: bar.update(i, note=stage),
                                  root_scale=source.get("root_scale", 1.0), skeleton_map=smap, rest_pose=not recorded)


def file_forces(keyframes_path, info, terms: str | None) -> bool:
    """Whether the force bounds are on for a keyframe file: `--terms` when given, else the file's
    "terms" ("default" or "all"), else not.

    Raises:
        InputError: a bad --terms; a bad "terms" field names the file and the field.
    """
    if terms is not None:
        return forces_of(terms, "--terms")
    in_file = getattr(info, "terms", None) or None
    return forces_of(in_file, f"{keyframes_path}: field 'terms'")


def file_problem(keyframes_path, scene=None, terms: str | None = None, quiet: bool = True):
    """The figure problem of a keyframe file, as `dynsplines animate` solves it.

    Args:
        keyframes_path: the keyframe file. scene: a scene MJCF overriding the file's "scene".
        terms: `--terms` (`file_forces`). quiet: no progress while the reference clip is imported.
    Returns:
        (problem, source): a `solver.Problem` with the file's contacts, and a `runner.run.Source` (scene
        path, reference or None, the contacts the metrics use: the file's, else those detected on the
        reference).
    Raises:
        InputError: as `load_problem`, `file_forces` and `solver.build_problem`.
    """
    from runner.run import Source
    from solver.problem import ProblemSpec, build_problem

    keyframes, info, model, _, scene_path = load_problem(keyframes_path, scene)
    contacts = tuple(getattr(info, "contacts", ()) or ())
    forces = file_forces(keyframes_path, info, terms)
    reference = find_reference(info, model, quiet=quiet)
    capture = None if reference is None else (reference.times, reference.qpos)  # the no-jolt and force bounds
    problem = build_problem(model, ProblemSpec(keyframes, contacts, forces, capture, getattr(info, "flights", None)))
    metric_contacts = contacts
    if reference is not None and not contacts:
        from runner.capture.contact_detection import reference_contacts

        metric_contacts = tuple(reference_contacts(model, reference.qpos, reference.frame_time))
    return problem, Source(Path(scene_path), reference, metric_contacts, label=str(keyframes_path))
