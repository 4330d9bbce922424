"""Sample a saved path (`runner.saved_path.load_saved_path`) at a frame rate: the motion an exporter writes.

A saved path holds three motions of the figure (docs/saved-path.md):

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

import numpy as np

from runner.saved_path import WHICH, SavedPath
from solver.errors import InputError
from solver.quaternion import align_hemispheres, normalize
from solver.spline import interpolate

__all__ = ["WHICH", "DEFAULT_FPS", "Motion", "default_fps", "sample_motion", "sample_times_at"]

#: [Hz] sampling rate when the path has no reference clip.
DEFAULT_FPS = 30.0


@dataclass(frozen=True)
class Motion:
    """A sampled motion. times: (n,) [s], spaced 1/fps from the first frame. qpos: (n, nq)."""

    name: str
    times: np.ndarray
    qpos: np.ndarray
    fps: float


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
