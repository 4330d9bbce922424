"""Sample a saved path (.npz from `--save-path`) at a frame rate: the motion an exporter writes.

A saved path holds three motions of the figure (README "Files"):

* ``optimized``: the natural cubic spline through ``frame_times``/``frames`` (keyframes + variable frames);
* ``plain``: the natural cubic spline through ``plain_frame_times``/``plain_frames`` (the keyframes alone);
* ``reference``: the retargeted motion capture ``reference_times``/``reference_qpos`` (if any), also read
  as the natural cubic spline through its frames, so at the clip's own rate the samples are its frames.

Samples are MuJoCo ``qpos`` rows with every quaternion normalized (the orientation MuJoCo shows:
``mj_kinematics`` normalizes too) and hemisphere-aligned over time.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from solver.errors import InputError
from solver.quaternion import align_hemispheres, normalize
from solver.spline import interpolate

__all__ = ["WHICH", "DEFAULT_FPS", "SavedPath", "Motion", "load_saved_path", "default_fps", "sample_motion",
           "sample_times_at"]

#: the motions a saved path holds.
WHICH = ("optimized", "plain", "reference")
#: [Hz] sampling rate when the path has no reference clip.
DEFAULT_FPS = 30.0

_REQUIRED = ("frame_times", "frames", "plain_frame_times", "plain_frames", "keyframe_times", "keyframes",
             "reference_times", "reference_qpos", "scene")


@dataclass(frozen=True)
class SavedPath:
    """The fields of a saved path this package uses (shapes: m frames, k keyframes, r reference frames).

    Attributes:
        frame_times: (m,) [s]. frames: (m, nq). plain_frame_times: (p,) [s]. plain_frames: (p, nq).
        keyframe_times: (k,) [s]. keyframes: (k, nq), NaN where a partial keyframe leaves a component free.
        reference_times: (r,) [s], r = 0 without a clip. reference_qpos: (r, nq).
        scene: the scene MJCF, resolved (relative names are relative to the repository root).
        source: the .npz file.
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


@dataclass(frozen=True)
class Motion:
    """A sampled motion. times: (n,) [s], spaced 1/fps from the first frame. qpos: (n, nq)."""

    name: str
    times: np.ndarray
    qpos: np.ndarray
    fps: float


def load_saved_path(path: str | Path) -> SavedPath:
    """Read a saved path (.npz written by `--save-path`).

    Raises:
        InputError: the file is missing, not an .npz, or lacks a field (the message names the file).
    """
    from runner.paths import REPO

    p = Path(path)
    if not p.is_file():
        why = "it is a folder" if p.is_dir() else f"no such file (current folder: {Path.cwd()})"
        raise InputError(f"{p}: cannot read the saved path: {why}; give the .npz written by --save-path")
    import zipfile

    if not zipfile.is_zipfile(p):
        raise InputError(f"{p}: not an .npz file (not a zip archive); give the .npz written by --save-path")
    try:
        with np.load(p, allow_pickle=False) as z:
            missing = [k for k in _REQUIRED if k not in z.files]
            if missing:
                raise InputError(f"{p}: not a saved path: field(s) {', '.join(missing)} missing; give the .npz "
                                 "written by `dynsplines animate --save-path`")
            f = {k: np.array(z[k]) for k in _REQUIRED}
    except InputError:
        raise
    except Exception as e:  # zipfile / pickle / format errors of a user file
        raise InputError(f"{p}: not a readable .npz file ({type(e).__name__}: {e}); give the .npz written by "
                         "--save-path") from None
    scene = Path(str(f.pop("scene")))
    if not scene.is_absolute():
        scene = REPO / scene
    nq = f["frames"].shape[1] if f["frames"].ndim == 2 else -1
    for k in ("frames", "plain_frames"):
        if f[k].ndim != 2 or f[k].shape[1] != nq or len(f[k]) < 2:
            raise InputError(f"{p}: field {k!r} has shape {f[k].shape}; expected (m >= 2, nq); the file is damaged")
    return SavedPath(**{k: np.asarray(v, float) for k, v in f.items()}, scene=scene, source=p)


def default_fps(saved: SavedPath) -> float:
    """[Hz] the reference clip's frame rate if the path has one, else `DEFAULT_FPS`."""
    if saved.has_reference:
        return float(1.0 / np.median(np.diff(saved.reference_times)))
    return DEFAULT_FPS


def sample_times_at(t0: float, t1: float, fps: float) -> np.ndarray:
    """(n,) times t0 + i/fps [s] for i = 0, 1, ... while <= t1; a sample within 1/1000 of a frame
    past t1 is kept and clamped to t1 (saved times are rounded, e.g. 1.699993 for the clip's 1.6999932)."""
    if not (fps > 0 and math.isfinite(fps)):
        raise InputError(f"--fps {fps}: must be a positive number of frames per second, e.g. --fps 30")
    n = int(math.floor((t1 - t0) * fps + 1e-3)) + 1
    return np.minimum(t0 + np.arange(n) / fps, t1)


def sample_motion(saved: SavedPath, which: str, fps: float, quat_slots: np.ndarray) -> Motion:
    """Sample one motion of a saved path at `fps`.

    Args:
        saved: the saved path. which: one of `WHICH`. fps: [Hz] samples per second.
        quat_slots: (s, 4) qpos indices of every quaternion (`StateLayout.quat_slots`).
    Returns:
        Motion with times t0 + i/fps over the motion's span and qpos (n, nq), quaternions unit and
        hemisphere-aligned over time.
    Raises:
        InputError: unknown `which`, no reference, bad fps.
    """
    times, frames = saved.track(which)
    t = sample_times_at(float(times[0]), float(times[-1]), fps)
    qpos = np.array(interpolate(times, frames, t), float)
    for idx in np.asarray(quat_slots, int):
        qpos[:, idx] = align_hemispheres(normalize(qpos[:, idx]))
    return Motion(which, t, qpos, float(fps))
