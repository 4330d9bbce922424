"""The saved path (`--save-path FILE.npz`): writing it, the versions recorded in it, and reading it back.

Fields (README "The saved path"): frame_times (m,) [s], frames (m, nq), frame_is_keyframe (m,),
keyframe_times (k,), keyframes (k, nq), keyframe_mask (k, nq), plain_frame_times, plain_frames,
reference_times, reference_qpos (motion capture, may be empty), scene (repository-relative path),
wall_time_s, objective_trace, status, metrics_json, options_json, versions_json, and contacts (a structured
array: site, start, end, surface; the reference's or the keyframe file's contacts, may be empty; files
written before it have none).
"""
from __future__ import annotations

import json
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from runner.files import atomic_output
from runner.paths import REPO, repo_relative
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


def save_path_npz(path, solution, keyframes, reference, scene_path, weights, options, metrics, args=None,
                  contacts=None):
    """Write the optimized path (.npz) atomically. Fields: README "The saved path"; `contacts`:
    `solver.contacts.Contact`s (or None: an empty field)."""
    scene_rel = repo_relative(scene_path)
    opts = {"weights": weights, "solve": asdict(options)}
    if args is not None:
        opts["command"] = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()
                           if k not in ("func",)}
    fields = dict(
        frame_times=solution.frames.times,
        frames=solution.frames.values,
        frame_is_keyframe=solution.frames.is_keyframe,
        keyframe_times=keyframes.times,
        keyframes=keyframes.values,
        keyframe_mask=keyframes.mask,
        plain_frame_times=solution.initial.times,
        plain_frames=solution.initial.values,
        reference_times=reference.times if reference is not None else np.zeros(0),
        reference_qpos=reference.qpos if reference is not None else np.zeros((0, keyframes.nq)),
        scene=np.array(scene_rel),
        wall_time_s=np.array(solution.wall_time_s),
        objective_trace=solution.trace,
        status=np.array(solution.status.value),
        metrics_json=np.array(json.dumps(metrics, default=float)),
        options_json=np.array(json.dumps(opts, default=str)),
        versions_json=np.array(json.dumps(versions())),
        contacts=contacts_array(contacts),
    )
    try:
        with atomic_output(path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **fields)
    except OSError as e:  # e.g. a full disk: the temporary file is gone, an earlier file is unchanged
        raise InputError(f"cannot write {path}: {e.strerror or e}; an earlier file there is unchanged; "
                         "free some space or choose another --save-path") from None


#: the fields every saved path has (`save_path_npz` writes them, `load_saved_path` checks them)
FIELDS = ("frame_times", "frames", "frame_is_keyframe", "keyframe_times", "keyframes", "keyframe_mask",
          "plain_frame_times", "plain_frames", "reference_times", "reference_qpos", "scene", "wall_time_s",
          "objective_trace", "status", "metrics_json", "options_json", "versions_json")


@dataclass(frozen=True)
class SavedPath:
    """A saved path read back: the arrays of the .npz (see the module docstring), the JSON fields parsed,
    and `scene_path`, the scene resolved against the repository (a relative `scene` is repository-relative)."""

    arrays: dict
    metrics: dict
    options: dict
    versions: dict
    scene_path: Path

    def __getitem__(self, name: str):
        return self.arrays[name]


def load_saved_path(path) -> SavedPath:
    """Read a path written by `save_path_npz` (`--save-path`).

    Args:
        path: the .npz file.
    Returns:
        SavedPath.
    Raises:
        InputError: the file is missing or not a NumPy archive, or lacks a field (named).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"saved path {path} does not exist; write one with --save-path")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError) as e:
        raise InputError(f"{path}: not a saved path (.npz): {e}") from None
    missing = [f for f in FIELDS if f not in arrays]
    if missing:
        raise InputError(f"{path}: not a dynsplines saved path, missing field(s) {', '.join(missing)}")
    scene = Path(str(arrays["scene"]))
    return SavedPath(arrays=arrays, metrics=json.loads(str(arrays["metrics_json"])),
                     options=json.loads(str(arrays["options_json"])),
                     versions=json.loads(str(arrays["versions_json"])),
                     scene_path=scene if scene.is_absolute() else REPO / scene)
