"""Keyframes an animator would set on a reference motion: the contact poses and the extremes.

Where a feet-driven motion is keyed by hand, the keys sit at touch-downs and lift-offs (the contact
and passing poses of a walk or run cycle) and at the body's highest and lowest points in between
(a jump's apex, the compression after a landing). `contact_keyframes` picks those frames from the
contacts and the root height, then keys where the plain spline through them strays from the capture
(`CaptureError`, `add_keys_to_tolerance`); evenly spaced keys (`every`) only fill gaps longer than `every`.
Whatever keys are chosen, `turn_keys` then adds keys where the root or a joint turns far between two keys
in the capture, so that the plain spline cannot join them the short way round.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from solver.contacts import Contact, figure_sites, touchdowns_liftoffs
from solver.errors import InputError
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.spline import interpolate

#: contact events closer than this many frames merge into one key (at their mean frame).
MERGE_FRAMES = 4
#: [deg] mean joint-angle error of the plain spline at a frame that `CaptureError` counts as 1, and
#: [cm] the same for the mean contact-site error. Chosen on the tuning clips (127_33, 16_23, 35_17):
#: below the mean errors of the plain spline keyed every 0.25 s there (5.2-9.1 deg, 6.4-12.3 cm), so
#: no frame of the contact keying's plain spline is further from the capture than the evenly keyed
#: one's average frame. There they add 2, 5 and 0 keys to the events and extremes (16, 17, 16 keys);
#: 4 deg / 2 cm and 6 deg / 4 cm give the same keys on 127_33 and 35_17 and 23 and 20 on 16_23.
KEY_JOINT_DEG = 5.0
KEY_SITE_CM = 3.0
#: [s] an added key is at least this far from the keys beside it (`add_keys_to_tolerance`): keys
#: closer than a tenth of a second would key the capture's jitter rather than its poses.
KEY_MIN_GAP = 0.1
#: [deg] the farthest the capture may take the root or any joint from its pose at a key before the next
#: key (rotation angle, `turn_keys`). The plain spline joins two keyed orientations the short way round
#: (hemisphere-aligned quaternions): it cannot tell a turn by A from one by A - 360 deg, so a capture
#: that turns 188 deg between keys is joined by a -172 deg turn. Rotations within 90 deg of one
#: orientation form a convex ball of SO(3) (geodesic balls of radius under 90 deg are convex), so the
#: spline's short way between two keys in it stays in it, as does the capture's path: they are the same
#: way round, with 90 deg to spare before the ambiguity at 180 deg; keys added later keep that.
KEY_TURN_DEG = 90.0


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
                      feet: Mapping[str, Sequence[str]], every: float | None = None, merge_frames: int = MERGE_FRAMES,
                      error: Callable[[Sequence[int]], np.ndarray] | None = None,
                      min_gap: float = KEY_MIN_GAP) -> np.ndarray:
    """Frame indices of keyframes at the contact events and the root's extremes.

    1. Touch-downs and lift-offs of the feet (`touchdowns_liftoffs`, heel and toe of a foot merged),
       each at the frame nearest its time; events closer than `merge_frames` frames merge into one
       key at their mean frame (e.g. one foot lands as the other leaves).
    2. The first and last frames.
    3. Between consecutive keys of 1-2, the frames of the highest and the lowest root_z, unless
       they fall within `merge_frames` of a key already there (then the interval has no extreme
       of its own: the root rises or falls monotonically).
    4. With `error` (a `CaptureError`): the frame where the plain spline through the keys strays
       furthest from the capture becomes a key, while that error is above 1 there
       (`add_keys_to_tolerance`; added keys at least `min_gap` from the others). The events and
       extremes alone leave long stretches unkeyed where nothing starts or ends (a 0.7 s step onto a
       ledge, the crouch after a landing); the plain spline cuts across them and the optimizer, with
       one free frame per interval, strays further still.
    5. With `every` [s]: while two consecutive keys are more than `every` apart, the gap is split
       evenly with the fewest keys that make every gap at most `every`.

    Args:
        times: (n,) frame times [s], increasing. contacts: site contacts (times in [s]).
        root_z: (n,) root height [m]. feet: {foot: its sites}, the figure's (`Figure.feet`).
        every: optional maximum spacing [s], > 0.
        merge_frames: events closer than this many frames merge (>= 1).
        error: None, or callable(keys) -> (n,) per-frame error of the plain spline through `keys`,
            1 = at tolerance (`CaptureError`). min_gap: [s] the least spacing of a key added for it.
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
    td, lo = touchdowns_liftoffs(contacts, feet)
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
    if error is not None:
        keys = add_keys_to_tolerance(keys, error, times, min_gap)
    if every is not None:
        filled = [keys[0]]
        for a, b in zip(keys[:-1], keys[1:]):
            m = int(np.ceil((times[b] - times[a]) / every - 1e-9))
            for j in range(1, m):
                filled.append(int(np.argmin(np.abs(times - (times[a] + j * (times[b] - times[a]) / m)))))
            filled.append(b)
        keys = sorted(set(filled))
    return np.array(keys, dtype=int)


class CaptureError:
    """Per-frame distance of the plain spline through a set of keys from the capture it keys.

    The plain spline is the natural cubic spline through the capture's poses at the keys, quaternions
    hemisphere-aligned (`Keyframes.initial_values`), i.e. the path `dynsplines` starts from. At each frame
    the error is the larger of two ratios: the mean over the ball and free joints of the angle between
    the spline's and the capture's joint quaternion, over `joint_deg`, and the mean over the contact
    sites of the distance between the spline's and the capture's site, over `site_cm`: the per-frame
    forms of the corpus' joint-angle and contact-site error (`runner.motion_metrics`, docs/corpus.md).

    Args:
        model: the scene's MjModel (the figure's qpos layout and contact sites).
        times: (n,) frame times [s], increasing. qpos: (n, nq) the capture's poses.
        joint_deg: [deg] > 0, the mean joint-angle error counted as 1. site_cm: [cm] > 0, the mean
            contact-site error counted as 1.
        sites: the contact sites (default the model's figure's, `solver.contacts.figure_sites`).
    Raises:
        InputError: shapes disagree, a tolerance is not positive, a site is missing.
    """

    def __init__(self, model, times, qpos, joint_deg: float = KEY_JOINT_DEG, site_cm: float = KEY_SITE_CM,
                 sites=None):
        from solver.kinematic_tree import SiteKinematics

        self.times = np.asarray(times, float)
        self.qpos = np.asarray(qpos, float)
        if self.qpos.shape != (len(self.times), model.nq):
            raise InputError(f"qpos has shape {self.qpos.shape}; give one pose per frame time, "
                             f"({len(self.times)}, nq={model.nq})")
        for name, v in (("joint_deg", joint_deg), ("site_cm", site_cm)):
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise InputError(f"{name}={v!r}; give a positive tolerance")
        self.joint_deg, self.site_cm = float(joint_deg), float(site_cm)
        layout = StateLayout.from_model(model)
        self.quat_slots = layout.quat_slots
        self.engine = SiteKinematics(model, figure_sites(model, sites))
        self.ref_sites = self.engine.positions(self.qpos)
        self.ref_quats = _unit(self.qpos[:, self.quat_slots])

    def plain(self, keys: Sequence[int]) -> np.ndarray:
        """(n, nq) the plain spline through the capture's poses at `keys` (frame indices), at every frame."""
        idx = np.asarray(keys, int)
        kf = Keyframes(self.times[idx], self.qpos[idx], np.ones((len(idx), self.qpos.shape[1]), bool))
        return interpolate(self.times[idx], kf.initial_values(self.quat_slots), self.times)

    def __call__(self, keys: Sequence[int]) -> np.ndarray:
        """(n,) the error at every frame of the plain spline through `keys` (1 = at a tolerance)."""
        Y = self.plain(keys)
        dot = np.abs(np.einsum("nsk,nsk->ns", _unit(Y[:, self.quat_slots]), self.ref_quats))
        joint = np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0))).mean(axis=1)
        site = 100.0 * np.linalg.norm(self.engine.positions(Y) - self.ref_sites, axis=-1).mean(axis=1)
        return np.maximum(joint / self.joint_deg, site / self.site_cm)


def _unit(q: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) scaled to unit length."""
    return q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-12)


def add_keys_to_tolerance(keys: Sequence[int], error, times: np.ndarray, min_gap: float = KEY_MIN_GAP,
                          max_keys: int | None = None) -> list[int]:
    """Keys added where the plain spline strays furthest from the capture, until it is within tolerance.

    Greedy curve simplification in reverse (the key-posture extraction of Lim and Thalmann, "Key-posture
    extraction out of human motion data by curve simplification", EMBS 2001, with the animator's
    keys as the start): the frame of largest `error` becomes a key, as long as it is at least `min_gap`
    from the keys around it, and the error is measured again, until no frame that could become a key
    has error above 1 (or `max_keys` is reached).

    Args:
        keys: sorted frame indices, the first and last frames among them.
        error: callable(keys) -> (n,) per-frame error, 1 = at tolerance (a `CaptureError`).
        times: (n,) frame times [s]. min_gap: [s] >= 0, the least spacing of an added key from the
            others. max_keys: at most this many keys in all (None: no cap).
    Returns:
        sorted frame indices, a superset of `keys`.
    """
    keys = sorted({int(k) for k in keys})
    times = np.asarray(times, float)
    while max_keys is None or len(keys) < max_keys:
        e = np.array(error(keys), float)
        k = np.asarray(keys)
        right = np.searchsorted(k, np.arange(len(times)))  # index of the first key at or after each frame
        right = np.clip(right, 1, len(k) - 1)
        ok = (times - times[k[right - 1]] >= min_gap - 1e-9) & (times[k[right]] - times >= min_gap - 1e-9)
        ok[k] = False
        e = np.where(ok, e, -np.inf)
        i = int(np.argmax(e))
        if not e[i] > 1.0:
            break
        keys = sorted(keys + [i])
    return keys


def _angles(q: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """[deg] rotation angle between unit quaternions q (..., s, 4) and ref (s, 4), per joint, either sign."""
    dot = np.abs(np.einsum("...sk,sk->...s", q, ref))
    return np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))


def turn_keys(keys: Sequence[int], quats: np.ndarray, limit_deg: float = KEY_TURN_DEG) -> list[int]:
    """Keys added until, between any two consecutive keys, the capture keeps the root and every joint
    within `limit_deg` of its orientation at the first of them (`KEY_TURN_DEG` says why).

    An interval [a, b] whose frames stray further is split where the joint that strays furthest has
    done half of its turning (its frame-to-frame rotation angles summed from a: the middle of a turn,
    the far point of a turn out and back), and each half is checked again. A full turn keyed every
    0.25 s (360 deg in 0.5 s, up to 245 deg between keys) gets a key halfway through each interval
    that turns more than 90 deg. An interval of two adjacent frames is never split (the capture itself
    turns that far in one frame).

    Args:
        keys: sorted frame indices, the first and last frames among them.
        quats: (n, s, 4) the capture's orientations per frame: the root's and each ball joint's unit
            quaternion (w x y z, either sign), e.g. qpos[:, layout.quat_slots].
        limit_deg: [deg] in (0, 180).
    Returns:
        sorted frame indices, a superset of `keys`.
    Raises:
        InputError: quats is not (n, s, 4), a key is outside 0..n-1, or limit_deg is out of range.
    """
    q = np.asarray(quats, float)
    if q.ndim != 3 or q.shape[-1] != 4:
        raise InputError(f"quats must have shape (n, s, 4); got {q.shape}")
    if not (isinstance(limit_deg, (int, float)) and 0.0 < limit_deg < 180.0):
        raise InputError(f"limit_deg={limit_deg!r}; give an angle in degrees between 0 and 180, e.g. {KEY_TURN_DEG}")
    q = _unit(q)
    out = sorted({int(k) for k in keys})
    if out and (out[0] < 0 or out[-1] >= len(q)):
        raise InputError(f"keys {out[0]}..{out[-1]} fall outside the {len(q)} frames of quats")
    todo = list(zip(out[:-1], out[1:]))
    while todo:
        a, b = todo.pop()
        if b - a < 2:
            continue
        from_a = _angles(q[a:b + 1], q[a])  # (b - a + 1, s)
        if from_a.max() <= limit_deg:
            continue
        joint = int(np.argmax(from_a.max(axis=0)))
        dot = np.abs(np.einsum("nk,nk->n", q[a + 1:b + 1, joint], q[a:b, joint]))
        step = np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))  # (b - a,) its rotation frame to frame
        arc = np.concatenate([[0.0], np.cumsum(step)])  # (b - a + 1,) turning done from a
        c = a + 1 + int(np.argmin(np.abs(arc[1:-1] - arc[-1] / 2)))
        out.append(c)
        todo += [(a, c), (c, b)]
    return sorted(out)
