"""The saved path (`--save-path FILE.npz`): writing it, the versions recorded in it, and reading it back.

Fields (docs/saved-path.md): frame_times (m,) [s], frames (m, nq), frame_is_keyframe (m,),
keyframe_times (k,), keyframes (k, nq), keyframe_mask (k, nq), plain_frame_times, plain_frames,
reference_times, reference_qpos (motion capture, may be empty), scene (relative to the .npz's folder),
wall_time_s, objective_trace, status, unmet_json ({constraint or term: amount}: what the solve reports out of
reach, `Solution.unmet`), certificate_json (a list of {constraint, label, amount [SI], time, start, end [s],
pairs, unit, scale}: each limit the least violation raised, `Solution.certificate`), metrics_json, options_json, versions_json, and contacts (a structured
array: site, start, end, surface; the reference's or the keyframe file's contacts, may be empty; files
written before it have none). A path made from a BVH clip also has clip (the clip's path, relative to the
.npz's folder like the scene) and clip_text (the clip's whole text, so that `dynsplines export` writes onto
the source skeleton even when the clip has moved), path_times (r',) [s] and path_qpos (r', nq): the optimized
path at the capture's frames within the path's span (`dynsplines clean`: the cleaned clip); every path has figure (the figure MJCF the scene
includes, relative likewise; "" when the scene holds it inline).
"""
from __future__ import annotations

import json
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from runner.files import atomic_output
from runner.paths import REPO
from solver.errors import InputError


def versions() -> dict:
    """Versions of the software that made a result (recorded in the .npz), and the BLAS thread settings:
    a path is bit-identical for the same inputs, options, versions and BLAS thread count (the command
    uses one thread, see runner/environment.py; another count changes the last bits of matrix products)."""
    import os
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": sys.version.split()[0]}
    for pkg in ("dynsplines", "mujoco", "nlopt", "numpy", "scipy"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "unknown"
    out["blas_threads_env"] = {v: os.environ.get(v) for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                              "MKL_NUM_THREADS")}
    return out


#: dtype of the `contacts` field: one row per site contact
CONTACT_DTYPE = np.dtype([("site", "U16"), ("start", "f8"), ("end", "f8"), ("surface", "U64")])


def contacts_array(contacts) -> np.ndarray:
    """`solver.contacts.Contact`s as the structured `contacts` field (CONTACT_DTYPE)."""
    return np.array([(c.site, c.start, c.end, c.surface) for c in contacts or ()], dtype=CONTACT_DTYPE)


def contacts_from_array(arr) -> list:
    """The `contacts` field back as `solver.contacts.Contact`s."""
    from solver.contacts import Contact

    return [Contact(str(r["site"]), float(r["start"]), float(r["end"]), str(r["surface"])) for r in arr]


def scene_reference(scene_path, npz_path) -> str:
    """How a saved path names its scene: relative to the .npz's folder (so that a folder of outputs can be
    moved as a whole), or absolute when no relative path leads there (another drive)."""
    import os

    scene, folder = Path(scene_path).resolve(), Path(npz_path).resolve().parent
    try:
        return Path(os.path.relpath(scene, folder)).as_posix()
    except ValueError:
        return str(scene)


def scene_figure(scene_path) -> str | None:
    """The figure file a scene MJCF includes (an `<include>` of a file with `figure:foot:` annotations),
    resolved, or None when the scene holds its figure inline or cannot be read."""
    import xml.etree.ElementTree as ET

    scene = Path(scene_path)
    try:
        includes = [(scene.parent / i.get("file", "")).resolve() for i in ET.parse(scene).getroot().iter("include")]
    except (OSError, ET.ParseError):
        return None
    for inc in includes:
        try:
            texts = ET.parse(inc).getroot().iter("text")
            if any((t.get("name") or "").startswith("figure:foot:") for t in texts):
                return str(inc)
        except (OSError, ET.ParseError):
            continue
    return None


def _clip_fields(reference, npz_path) -> dict:
    """{"clip", "clip_text"} of a reference read from a BVH file (empty strings otherwise)."""
    src = Path(reference.source) if reference is not None and reference.source else None
    if src is None or src.suffix.lower() != ".bvh" or not src.is_file():
        return {"clip": np.array(""), "clip_text": np.array("")}
    capture = getattr(reference, "capture", None)  # the clip as the run read it (runner.capture.clip.Capture)
    text = capture.text if capture is not None else src.read_text(encoding="utf-8-sig")
    return {"clip": np.array(scene_reference(src, npz_path)), "clip_text": np.array(text)}


def resolve_scene(name: str, npz_path) -> Path:
    """The scene a saved path names: absolute, or relative to the .npz's folder (files written before
    that was the rule named it relative to the repository; those are found there)."""
    scene = Path(name)
    if scene.is_absolute():
        return scene
    beside = (Path(npz_path).parent / scene).resolve()
    return beside if beside.is_file() or not (REPO / scene).is_file() else REPO / scene


def _path_at_capture(frames, reference) -> dict:
    """{"path_times", "path_qpos"}: the optimized path at the capture's frames within its span (the frames'
    own values where a frame lies on a capture frame, within 1e-9 s: a cleaned clip's, `dynsplines clean`,
    exactly); {} without a capture."""
    if reference is None or not len(reference.times):
        return {}
    t = np.asarray(reference.times, float)
    t = t[(t >= frames.times[0] - 1e-9) & (t <= frames.times[-1] + 1e-9)]
    q = frames.path(np.clip(t, frames.times[0], frames.times[-1]))
    k = np.clip(np.searchsorted(frames.times, t), 0, frames.count - 1)
    near = np.where(np.abs(frames.times[k - 1] - t) < np.abs(frames.times[k] - t), k - 1, k)
    on = np.abs(frames.times[near] - t) <= 1e-9
    q[on] = frames.values[near[on]]
    return {"path_times": t, "path_qpos": q}


def save_path_npz(run, path, command: dict | None = None) -> None:
    """Write a run's optimized path (.npz) atomically (fields: the module docstring).

    Args:
        run: a `runner.run.Run` (problem, options, solution, source, metrics).
        path: the .npz file. command: the command's arguments, recorded in `options_json`.
    Raises:
        InputError: the file cannot be written (an earlier file there is unchanged).
    """
    solution, keyframes, reference = run.solution, run.problem.keyframes, run.source.reference
    opts = {"terms": run.problem.terms, "solve": asdict(run.options), "rate": run.options.rate}
    if command:
        opts["command"] = {k: (str(v) if isinstance(v, Path) else v) for k, v in command.items() if k != "func"}
    # the keyframes as the path meets them: quaternion signs as the plain spline's frames hold them
    # (a keyframe file may give q or -q, the same rotation), NaN where a partial keyframe leaves a component free
    initial = solution.initial
    met = np.where(keyframes.mask, initial.values[initial.is_keyframe], np.nan)
    fields = dict(
        frame_times=solution.frames.times,
        frames=solution.frames.values,
        frame_is_keyframe=solution.frames.is_keyframe,
        keyframe_times=keyframes.times,
        keyframes=met,
        keyframe_mask=keyframes.mask,
        plain_frame_times=initial.times,
        plain_frames=initial.values,
        reference_times=reference.times if reference is not None else np.zeros(0),
        reference_qpos=reference.qpos if reference is not None else np.zeros((0, keyframes.nq)),
        scene=np.array(scene_reference(run.source.scene_path, path)),
        wall_time_s=np.array(solution.wall_time_s),
        objective_trace=solution.trace,
        status=np.array(solution.status.value),
        unmet_json=np.array(json.dumps(dict(solution.unmet or {}), default=float)),
        certificate_json=np.array(json.dumps([asdict(r) for r in getattr(solution, "certificate", ()) or ()],
                                             default=float)),
        metrics_json=np.array(json.dumps(run.metrics, default=float)),
        options_json=np.array(json.dumps(opts, default=str)),
        versions_json=np.array(json.dumps(versions())),
        contacts=contacts_array(run.source.metric_contacts),
        figure=np.array(scene_reference(fig, path) if (fig := scene_figure(run.source.scene_path)) else ""),
        **_clip_fields(reference, path),
        **_path_at_capture(solution.frames, reference),
    )
    try:
        with atomic_output(path) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, **fields)
    except OSError as e:  # e.g. a full disk: the temporary file is gone, an earlier file is unchanged
        raise InputError(f"cannot write {path}: {e.strerror or e}; an earlier file there is unchanged; "
                         "free some space or choose another --save-path") from None


#: the fields every saved path has (`save_path_npz` writes them all)
FIELDS = ("frame_times", "frames", "frame_is_keyframe", "keyframe_times", "keyframes", "keyframe_mask",
          "plain_frame_times", "plain_frames", "reference_times", "reference_qpos", "scene", "wall_time_s",
          "objective_trace", "status", "metrics_json", "options_json", "versions_json")
#: the fields `load_saved_path` requires: the motions and the scene. The others (bookkeeping: metrics,
#: options, versions, trace, status, time) are read when present.
REQUIRED = ("frame_times", "frames", "plain_frame_times", "plain_frames", "keyframe_times", "keyframes",
            "reference_times", "reference_qpos", "scene")
#: the motions a saved path holds.
WHICH = ("optimized", "plain", "reference")


@dataclass(frozen=True)
class SavedPath:
    """A saved path read back (shapes: m frames, p plain frames, k keyframes, r reference frames).

    Attributes:
        frame_times: (m,) [s]. frames: (m, nq). plain_frame_times: (p,) [s]. plain_frames: (p, nq).
        keyframe_times: (k,) [s]. keyframes: (k, nq), NaN where a partial keyframe leaves a component free.
        reference_times: (r,) [s], r = 0 without a clip. reference_qpos: (r, nq).
        scene: the scene MJCF, resolved (a relative name is relative to the .npz's folder).
        source: the .npz file.
        arrays: every array of the file by name (also `saved["name"]`).
        metrics, options, versions: the JSON fields parsed ({} when the file lacks them).
    """

    frame_times: np.ndarray
    frames: np.ndarray
    plain_frame_times: np.ndarray
    plain_frames: np.ndarray
    keyframe_times: np.ndarray
    keyframes: np.ndarray
    reference_times: np.ndarray
    reference_qpos: np.ndarray
    scene: Path
    source: Path
    arrays: dict = field(default_factory=dict, repr=False)
    metrics: dict = field(default_factory=dict, repr=False)
    options: dict = field(default_factory=dict, repr=False)
    versions: dict = field(default_factory=dict, repr=False)

    def __getitem__(self, name: str):
        return self.arrays[name]

    @property
    def scene_path(self) -> Path:
        return self.scene

    @property
    def nq(self) -> int:
        return self.frames.shape[1]

    @property
    def has_reference(self) -> bool:
        return len(self.reference_times) >= 2

    def track(self, which: str) -> tuple[np.ndarray, np.ndarray]:
        """(times (m,) [s], frames (m, nq)) of one motion; InputError for an unknown or absent one."""
        if which not in WHICH:
            raise InputError(f"--which {which!r}: unknown motion; choose one of {', '.join(WHICH)}")
        if which == "optimized":
            return self.frame_times, self.frames
        if which == "plain":
            return self.plain_frame_times, self.plain_frames
        if not self.has_reference:
            raise InputError(f"{self.source}: --which reference, but the path has no reference motion "
                             "(it was not made from a motion-capture clip); choose --which optimized or plain")
        return self.reference_times, self.reference_qpos


def _json(arrays: dict, name: str, p: Path) -> dict:
    if name not in arrays:
        return {}
    try:
        return json.loads(str(arrays[name]))
    except ValueError as e:
        raise InputError(f"{p}: field {name!r} is not JSON ({e}); the file is damaged") from None


def load_saved_path(path) -> SavedPath:
    """Read a saved path (.npz written by `save_path_npz`, i.e. `--save-path`).

    Args:
        path: the .npz file.
    Returns:
        SavedPath.
    Raises:
        InputError: the file is missing, a folder, not an .npz (zip) archive, lacks a required field
            (named), or has a motion whose shape does not fit (named); the message names the file.
    """
    import zipfile

    p = Path(path)
    if not p.is_file():
        why = "it is a folder" if p.is_dir() else f"no such file (current folder: {Path.cwd()})"
        raise InputError(f"{p}: cannot read the saved path: {why}; give the .npz written by --save-path")
    if not zipfile.is_zipfile(p):
        raise InputError(f"{p}: not an .npz file (not a zip archive); give the .npz written by --save-path")
    try:
        with np.load(p, allow_pickle=False) as z:
            missing = [k for k in REQUIRED if k not in z.files]
            if missing:
                raise InputError(f"{p}: not a saved path: field(s) {', '.join(missing)} missing; give the .npz "
                                 "written by `dynsplines animate --save-path`")
            arrays = {k: np.array(z[k]) for k in z.files}
    except InputError:
        raise
    except Exception as e:  # zipfile / pickle / format errors of a user file
        raise InputError(f"{p}: not a readable .npz file ({type(e).__name__}: {e}); give the .npz written by "
                         "--save-path") from None
    scene = resolve_scene(str(arrays["scene"]), p)
    try:
        f = {k: np.asarray(arrays[k], float) for k in REQUIRED if k != "scene"}
    except (TypeError, ValueError) as e:
        raise InputError(f"{p}: a motion field is not numeric ({e}); the file is damaged") from None
    nq = f["frames"].shape[1] if f["frames"].ndim == 2 else -1
    for times, values, least in (("frame_times", "frames", 2), ("plain_frame_times", "plain_frames", 2),
                                 ("keyframe_times", "keyframes", 2), ("reference_times", "reference_qpos", 0)):
        v, t = f[values], f[times]
        if v.ndim != 2 or v.shape[1] != nq or len(v) < least:
            raise InputError(f"{p}: field {values!r} has shape {v.shape}; expected (m >= {least}, {nq}); "
                             "the file is damaged")
        if t.shape != (len(v),):
            raise InputError(f"{p}: field {times!r} has shape {t.shape}; expected ({len(v)},) like {values!r}; "
                             "the file is damaged")
    return SavedPath(**f, scene=scene, source=p, arrays=arrays, metrics=_json(arrays, "metrics_json", p),
                     options=_json(arrays, "options_json", p), versions=_json(arrays, "versions_json", p))
