"""Keyframes picked from a reference motion: which frames, and which components they fix (partial)."""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import replace

import numpy as np

from runner.capture.retarget import Reference
from solver.errors import InputError
from solver.figure import Figure
from solver.keyframes import Keyframes
from solver.layout import StateLayout

#: `partial="middle"` of `keyframes_from_reference` (the command's `--partial`): the middle keyframe
#: fixes only the root and the legs.
MIDDLE_LOWER_BODY = "middle"


#: a root extreme closer than this many frames to an evenly spaced key adds no key of its own.
EXTREME_MERGE_FRAMES = 4


def keyframe_indices(reference: Reference, every: float = 0.25, extremes: bool = True) -> np.ndarray:
    """Frame indices an animator would key: evenly about every `every` seconds, first and last included,
    plus the root's highest and lowest frames (a broad jump's apex, the crouch before it).

    The clip's duration T is cut into round(T / every) equal intervals (at least one); each key is the
    frame nearest an interval end, so every gap is within a frame of T / round(T / every) (for a
    clip longer than every, between 2/3 and 4/3 of `every`). With `extremes`, the frames of the
    highest and the lowest root height (qpos z) become keys: the nearest inner key moves onto the
    extreme if it is at most every / 2 away, else the extreme is added; an extreme within
    `EXTREME_MERGE_FRAMES` frames of the first or last frame is left out (the end is its key). So the
    key count stays and the gaps stay between 1/6 and 11/6 of `every`. Evenly spaced keys
    would otherwise cut the apex of a jump off the plain spline.

    Args:
        reference: the dense motion. every: [s] spacing, > 0. extremes: also key the root's extremes.
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
    idx = np.unique(np.clip(idx, 0, reference.count - 1))
    if extremes:
        z = reference.keyed().qpos[:, 2]  # the keyed motion's root (`Reference.keyed`)
        for e in (int(np.argmax(z)), int(np.argmin(z))):
            if e in (0, reference.count - 1):
                continue
            near = int(np.argmin(np.abs(idx - e)))
            if abs(int(idx[near]) - e) < EXTREME_MERGE_FRAMES and near in (0, len(idx) - 1):
                continue  # at an end of the clip: the end is key enough
            inner = np.arange(1, len(idx) - 1)
            if len(inner):
                j = int(inner[np.argmin(np.abs(idx[inner] - e))])
                if abs(int(idx[j]) - e) * reference.frame_time <= every / 2 and e not in idx:
                    idx[j] = e  # move the nearest inner key onto the extreme
                    idx = np.unique(idx)
                    continue
            idx = np.unique(np.append(idx, e))
        idx = np.unique(idx)
    return idx


def keyframes_from_reference(
    reference: Reference,
    model,
    every: float = 0.25,
    partial: Mapping[int, Iterable[str]] | str | None = None,
    indices: np.ndarray | None = None,
) -> Keyframes:
    """Keyframes from a dense reference motion, as an animator would set them.

    Full keyframes at `indices` (default `keyframe_indices(reference, every)`), with the values of the
    capture with its resting feet planted (`Reference.keyed`, docs/mocap.md "The keyframes' feet"); the
    keyframes listed in `partial` fix only the named joints (all components of each), the rest of the
    figure is free for the optimizer.

    Args:
        reference: the dense motion (`load_bvh_reference`).
        model: the figure's or scene's MjModel (for the qpos layout).
        every: [s] keyframe spacing (about 0.2-0.3 s for a run).
        partial: None or {} (default): full keyframes only. "middle": the middle keyframe (index
            k // 2) fixes only the root and the legs (`Figure.leg_joints`; torso and arms are left
            free: the optimizer chooses the upper body, the animator pins the stride). Or a mapping
            {keyframe index: joint names it fixes}.
        indices: the frames to key (strictly increasing); default `keyframe_indices(reference, every)`.
    Returns:
        solver.Keyframes with times (k,) [s] and values/mask (k, nq); source = reference.source.
    Raises:
        InputError: bad `every`, a partial keyframe index out of range, or an unknown joint name.
    """
    layout = StateLayout.from_model(model)
    idx = keyframe_indices(reference, every) if indices is None else np.asarray(indices, int)
    k = len(idx)
    if partial is None:
        partial = {}
    if isinstance(partial, str):
        if partial != MIDDLE_LOWER_BODY:
            raise InputError(f"partial={partial!r}; give 'middle' or a mapping {{keyframe index: joint names}}")
        partial = {k // 2: Figure.from_model(model).leg_joints} if k > 2 else {}
    values = reference.keyed().qpos[idx].copy()  # the capture with its resting feet planted
    mask = np.ones_like(values, bool)
    for i, names in dict(partial).items():
        if not (isinstance(i, (int, np.integer)) and 0 <= i < k):
            raise InputError(f"partial keyframe index {i!r} is out of range; there are {k} keyframes (0..{k - 1})")
        mask[i] = False
        for name in names:
            mask[i, layout.joint(name).qpos_slice] = True
    return Keyframes(reference.times[idx], values, mask, source=reference.source)


#: `--keys` choices: evenly spaced (plus the root's extremes), or at the contact events
KEY_CHOICES = ("every", "contacts")


def given_indices(reference: Reference, frames) -> np.ndarray:
    """The frames an animator keyed (`--key-frames`), checked: (k,) strictly increasing indices into the
    reference (0 = the clip's first frame after its rest frames), k >= 2.

    Raises:
        InputError: fewer than two frames, a frame out of the clip, or frames not increasing.
    """
    idx = np.asarray(list(frames), dtype=float)
    n = reference.count
    if idx.ndim != 1 or len(idx) < 2 or not np.all(np.isfinite(idx)) or np.any(idx != np.rint(idx)):
        raise InputError(f"--key-frames {list(frames)!r}: give at least two whole frame numbers, e.g. 0,30,60")
    if idx[0] < 0 or idx[-1] > n - 1 or np.any(np.diff(idx) <= 0):
        raise InputError(f"--key-frames {','.join(f'{f:g}' for f in idx)}: the frames must increase and lie in the "
                         f"clip, 0..{n - 1} ({reference.source}: {n} frames after its rest frames)")
    return idx.astype(int)


def pick_keyframes(reference: Reference, model, contacts, keys: str = "every", every: float | None = 0.25,
                   partial: bool = False, extremes: bool = True, frames=None, frame_joints=None) -> Keyframes:
    """The keyframes of `dynsplines mocap` and `keyframes-from-bvh`.

    Args:
        reference: the retargeted clip. model: the scene's MjModel. contacts: the clip's contacts.
        keys: "every": `keyframe_indices(reference, every, extremes)`; "contacts": touch-downs,
            lift-offs, the ends and the root's extremes, then keys where the plain spline through
            them strays from the capture (`runner.capture.keyframe_selection.contact_keyframes` with a
            `CaptureError`), with `every` (or None) the largest gap [s]. Either way, then keys
            where the root or a joint turns more than 90 deg between two keys in the capture
            (`runner.capture.keyframe_selection.turn_keys`: else the plain spline joins them the short way
            round, and a full turn keyed every 0.25 s is lost).
        partial: the middle keyframe fixes only the root and the legs (`Figure.leg_joints`).
        extremes: with keys="every", also key the root's highest and lowest frames.
        frames: the frames an animator keyed (`given_indices`), or None: then `keys` and `every` are not
            used, and the keys take the clip's own values (an animator's pose is the keyframe, its feet
            are not planted: docs/mocap.md "The keyframes' feet"), plus the turn keys.
        frame_joints: with `frames`, {frame: figure joints} of the partial ones (`--key-joints`,
            runner/capture/key_joints.py); a frame that fixes no figure joint is no key.
    """
    from runner.capture.keyframe_selection import CaptureError, contact_keyframes, turn_keys
    from solver.figure import model_feet

    if frames is not None:
        reference = replace(reference, plant=None)
        idx = given_indices(reference, frames)
        joints = dict(frame_joints or {})
        idx = np.array([f for f in idx if joints.get(int(f), True)], int)  # a key of unmodelled joints only: none
        idx = np.asarray(turn_keys(idx, reference.qpos[:, StateLayout.from_model(model).quat_slots]), int)
        part = {int(np.flatnonzero(idx == f)[0]): names for f, names in joints.items() if names and f in idx}
        return keyframes_from_reference(reference, model, indices=idx,
                                        partial=part or (MIDDLE_LOWER_BODY if partial else None))
    reference = reference.keyed()  # keys are chosen on the motion they take their values from
    if keys == "contacts":
        if every is not None and not (isinstance(every, (int, float)) and math.isfinite(every) and every > 0):
            raise InputError(f"keyframe spacing every={every!r}; give a positive number of seconds, e.g. 0.25")
        error = CaptureError(model, reference.times, reference.qpos)
        idx = contact_keyframes(reference.times, contacts, reference.qpos[:, 2], model_feet(model), every=every,
                                error=error)
    elif keys == "every":
        idx = keyframe_indices(reference, 0.25 if every is None else every, extremes=extremes)
    else:
        raise InputError(f"keys={keys!r}; give one of {', '.join(KEY_CHOICES)}")
    idx = np.asarray(turn_keys(idx, reference.qpos[:, StateLayout.from_model(model).quat_slots]), int)
    return keyframes_from_reference(reference, model, indices=idx,
                                    partial=MIDDLE_LOWER_BODY if partial else None)
