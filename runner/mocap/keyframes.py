"""Keyframes picked from a reference motion: which frames, and which components they fix (partial)."""
from __future__ import annotations

import math
from typing import Iterable, Mapping

import numpy as np

from runner.mocap.retarget import Reference
from solver.errors import InputError
from solver.keyframes import Keyframes
from solver.layout import StateLayout


#: joints a default partial keyframe fixes: the root and the legs; torso and arms are left free
#: (the optimizer chooses the upper body, the animator pins the stride).
LOWER_BODY_JOINTS: tuple[str, ...] = ("root", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle")


#: default `partial` argument of `keyframes_from_reference`: the middle keyframe fixes only the root and
#: the legs.
MIDDLE_LOWER_BODY = "middle"


def keyframe_indices(reference: Reference, every: float = 0.25) -> np.ndarray:
    """Frame indices an animator would key: evenly about every `every` seconds, first and last included.

    The clip's duration T is cut into round(T / every) equal intervals (at least one); each key is the
    frame nearest an interval end, so every gap is within a frame of T / round(T / every) (for a
    clip longer than every, between 2/3 and 4/3 of `every`).

    Args:
        reference: the dense motion. every: [s] spacing, > 0.
    Returns:
        (k,) strictly increasing frame indices, k >= 2, first 0, last n - 1.
    Raises:
        InputError: `every` is not a positive number, or the clip is shorter than two frames.
    """
    if isinstance(every, bool) or not (isinstance(every, (int, float)) and math.isfinite(every) and every > 0):
        raise InputError(f"keyframe spacing every={every!r}; give a positive number of seconds, e.g. 0.25")
    if reference.count < 2:
        raise InputError(f"{reference.source}: the clip has {reference.count} frame(s); need at least 2")
    T = reference.duration
    intervals = max(1, int(round(T / every)))
    idx = np.rint(np.linspace(0.0, T, intervals + 1) / reference.frame_time).astype(int)
    return np.unique(np.clip(idx, 0, reference.count - 1))


def keyframes_from_reference(
    reference: Reference,
    model,
    every: float = 0.25,
    partial: Mapping[int, Iterable[str]] | str = MIDDLE_LOWER_BODY,
) -> Keyframes:
    """Keyframes from a dense reference motion, as an animator would set them.

    Full keyframes at `keyframe_indices(reference, every)`; the keyframes listed in `partial` fix only
    the named joints (all components of each), the rest of the figure is free for the optimizer.

    Args:
        reference: the dense motion (`load_bvh_reference`).
        model: the figure's or scene's MjModel (for the qpos layout).
        every: [s] keyframe spacing (about 0.2-0.3 s for a run).
        partial: "middle" (default): the middle keyframe (index k // 2) fixes only `LOWER_BODY_JOINTS`
            (root and legs; torso and arms free). Or a mapping {keyframe index: joint names it fixes};
            {} for full keyframes only.
    Returns:
        solver.Keyframes with times (k,) [s] and values/mask (k, nq); source = reference.source.
    Raises:
        InputError: bad `every`, a partial keyframe index out of range, or an unknown joint name.
    """
    layout = StateLayout.from_model(model)
    idx = keyframe_indices(reference, every)
    k = len(idx)
    if isinstance(partial, str):
        if partial != MIDDLE_LOWER_BODY:
            raise InputError(f"partial={partial!r}; give 'middle' or a mapping {{keyframe index: joint names}}")
        partial = {k // 2: LOWER_BODY_JOINTS} if k > 2 else {}
    values = reference.qpos[idx].copy()
    mask = np.ones_like(values, bool)
    for i, names in dict(partial).items():
        if not (isinstance(i, (int, np.integer)) and 0 <= i < k):
            raise InputError(f"partial keyframe index {i!r} is out of range; there are {k} keyframes (0..{k - 1})")
        mask[i] = False
        for name in names:
            mask[i, layout.joint(name).qpos_slice] = True
    return Keyframes(reference.times[idx], values, mask, source=reference.source)
