"""Tracking glitches of a capture: a joint that turns, between two frames, faster than any human joint turns.

Optical capture loses or swaps markers for a few frames, and the solved skeleton then flips a joint by
tens of degrees and back within one frame: on CMU 74_05 (a kick) the right ankle turns 66, 82, 96, 128
and 176 degrees between consecutive 1/120 s frames at 1.32-1.46 s, 8,000-21,000 deg/s. Keyframes taken
there (the keys `turn_keys` adds to follow a joint's turns) put the flip into every path through them:
the plain spline's ankle reached 42,000 rad/s^2, the capture's own, filtered at 6 Hz, 2,200.

`repair_glitches` bounds the turn rate by the fastest joint rotation measured in human movement, the
shoulder's internal rotation in baseball pitching, whose peak is about 7,000 deg/s (`OMEGA_MAX`; Fleisig,
Andrews, Dillman & Escamilla, "Kinetics of baseball pitching with implications about injury mechanisms",
Am. J. Sports Med. 23(2), 1995): per orientation (the root's and every ball joint's), walking the frames
with the last frame kept, g, a frame i is kept when its orientation is within OMEGA_MAX (i - g) dt of
frame g's; the frames between two kept frames that are not are a glitch, replaced by the slerp between
the two. A glitch that does not come back is kept once the allowance, growing with i - g, covers the new
orientation (a 176 degree turn after 3 frames at 120 Hz), so a real fast turn loses at most that little;
frames after the last kept one at the end of the clip hold its orientation.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.layout import StateLayout
from solver.quaternion import normalize

__all__ = ["OMEGA_MAX", "Glitch", "repair_glitches", "glitches_line", "slerp"]

#: [rad/s] the fastest rotation of a human joint measured: baseball pitching's shoulder internal rotation,
#: about 7,000 deg/s at its peak (Fleisig et al. 1995, module docstring)
OMEGA_MAX = float(np.radians(7000.0))


@dataclass(frozen=True)
class Glitch:
    """One repaired glitch.

    Attributes:
        joint: the joint's name (the root's orientation: the free joint's name).
        start, end: [s] the first and last frame replaced (from the clip's first frame after its rest frames).
        turn_deg: [deg] the largest turn from the last kept frame among the replaced frames.
    """

    joint: str
    start: float
    end: float
    turn_deg: float

    def __str__(self) -> str:
        return f"{self.joint} {self.start:.3f}-{self.end:.3f} s ({self.turn_deg:.0f} deg off)"


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    """[rad] the rotation angle between unit quaternions a and b (q and -q alike)."""
    return 2.0 * float(np.arccos(min(1.0, abs(float(a @ b)))))


def slerp(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(k, 4) unit quaternions (w x y z) from a (u = 0) to b (u = 1) at (k,) u, the short way round
    (`scipy.spatial.transform.Slerp`), in a's hemisphere."""
    from scipy.spatial.transform import Rotation, Slerp

    q = Slerp([0.0, 1.0], Rotation.from_quat(np.stack([a, b])[:, [1, 2, 3, 0]]))(u).as_quat()[:, [3, 0, 1, 2]]
    return q * np.where(q @ a < 0, -1.0, 1.0)[:, None]


def _repair_one(q: np.ndarray, step: float) -> tuple[np.ndarray, list[tuple[int, int, float]]]:
    """(n, 4) unit quaternions with glitches replaced (module docstring), and [(first, last, turn [rad])]
    of the replaced runs; `step` [rad] is the turn allowed per frame."""
    q = q.copy()
    runs, g, worst = [], 0, 0.0
    for i in range(1, len(q)):
        turn = _angle(q[g], q[i])
        if turn > step * (i - g):
            worst = max(worst, turn)
            continue
        if i - g > 1:
            q[g + 1:i] = slerp(q[g], q[i], (np.arange(g + 1, i) - g) / (i - g))
            runs.append((g + 1, i - 1, worst))
        g, worst = i, 0.0
    if g < len(q) - 1:  # the clip ends in a glitch: hold the last kept orientation
        q[g + 1:] = q[g]
        runs.append((g + 1, len(q) - 1, worst))
    return q, runs


def repair_glitches(qpos: np.ndarray, layout: StateLayout, frame_time: float) -> tuple[np.ndarray, tuple[Glitch, ...]]:
    """Replace the frames where an orientation turns faster than `OMEGA_MAX` (module docstring).

    Args:
        qpos: (n, nq) motion (quaternions w x y z, any norm). layout: its `StateLayout`. frame_time: [s].
    Returns:
        (qpos (n, nq) with unit quaternions and the glitches replaced, the glitches repaired).
    """
    out = np.array(qpos, float)
    names = {tuple(j.quat_index): j.name for j in layout.joints if j.quat_index is not None}
    found = []
    for slot in layout.quat_slots:
        q, runs = _repair_one(normalize(out[:, slot]), OMEGA_MAX * frame_time)
        out[:, slot] = q
        found += [Glitch(names[tuple(slot)], a * frame_time, b * frame_time, float(np.degrees(t))) for a, b, t in runs]
    return out, tuple(found)


def glitches_line(glitches) -> str | None:
    """The printed line of what `repair_glitches` replaced, or None when nothing was."""
    if not glitches:
        return None
    return (f"tracking glitches repaired (a joint turning faster than {np.degrees(OMEGA_MAX):.0f} deg/s, the fastest "
            "human joint; docs/mocap.md \"Tracking glitches\"): " + "; ".join(str(g) for g in glitches))
