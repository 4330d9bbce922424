"""Keyframes an animator would set on a reference motion: the contact poses and the extremes.

Where a feet-driven motion is keyed by hand, the keys sit at touch-downs and lift-offs (the contact
and passing poses of a walk or run cycle) and at the body's highest and lowest points in between
(a jump's apex, the compression after a landing). `contact_keyframes` picks those frames from the
contacts and the root height; evenly spaced keys (`every`) only fill gaps longer than `every`.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from solver.contacts import Contact, touchdowns_liftoffs
from solver.errors import InputError

#: contact events closer than this many frames merge into one key (at their mean frame).
MERGE_FRAMES = 4


def _merge(idx: list[int], gap: int, fixed: set[int]) -> list[int]:
    """Merge sorted indices closer than `gap` into clusters; a cluster keeps its fixed member if any,
    else its rounded mean."""
    out: list[list[int]] = []
    for i in sorted(set(idx)):
        if out and i - out[-1][-1] < gap:
            out[-1].append(i)
        else:
            out.append([i])
    keys = []
    for c in out:
        f = [i for i in c if i in fixed]
        keys.append(f[0] if f else int(round(np.mean(c))))
    return keys


def contact_keyframes(times: np.ndarray, contacts: Sequence[Contact], root_z: np.ndarray,
                      every: float | None = None, merge_frames: int = MERGE_FRAMES) -> np.ndarray:
    """Frame indices of keyframes at the contact events and the root's extremes.

    1. Touch-downs and lift-offs of the feet (`touchdowns_liftoffs`, heel and toe of a foot merged),
       each at the frame nearest its time; events closer than `merge_frames` frames merge into one
       key at their mean frame (e.g. one foot lands as the other leaves).
    2. The first and last frames.
    3. Between consecutive keys of 1-2, the frames of the highest and the lowest root_z, unless
       they fall within `merge_frames` of a key already there (then the interval has no extreme
       of its own: the root rises or falls monotonically).
    4. With `every` [s]: while two consecutive keys are more than `every` apart, the gap is split
       evenly with the fewest keys that make every gap at most `every`.

    Args:
        times: (n,) frame times [s], increasing. contacts: site contacts (times in [s]).
        root_z: (n,) root height [m]. every: optional maximum spacing [s], > 0.
        merge_frames: events closer than this many frames merge (>= 1).
    Returns:
        (k,) strictly increasing int indices, first 0 and last n - 1 (k = 1 when n = 1).
    Raises:
        InputError: shapes disagree, or `every` is not positive.
    """
    times = np.asarray(times, float)
    root_z = np.asarray(root_z, float)
    n = len(times)
    if n == 0 or root_z.shape != (n,):
        raise InputError(f"times (n,) and root_z (n,) must match and be non-empty; got {times.shape}, {root_z.shape}")
    if every is not None and not (every > 0):
        raise InputError(f"every must be a positive number of seconds or None; got {every!r}")
    td, lo = touchdowns_liftoffs(contacts)
    events = [int(np.argmin(np.abs(times - t))) for t, _ in td + lo]
    keys = _merge(events + [0, n - 1], merge_frames, {0, n - 1})
    extremes = []
    for a, b in zip(keys[:-1], keys[1:]):
        if b - a < 2:
            continue
        seg = root_z[a:b + 1]
        for i in (a + int(np.argmax(seg)), a + int(np.argmin(seg))):
            if i - a >= merge_frames and b - i >= merge_frames:
                extremes.append(i)
    keys = sorted(set(keys) | set(extremes))
    if every is not None:
        filled = [keys[0]]
        for a, b in zip(keys[:-1], keys[1:]):
            m = int(np.ceil((times[b] - times[a]) / every - 1e-9))
            for j in range(1, m):
                filled.append(int(np.argmin(np.abs(times - (times[a] + j * (times[b] - times[a]) / m)))))
            filled.append(b)
        keys = sorted(set(filled))
    return np.array(keys, dtype=int)
