"""Gaps in a capture: frames where the file gives a joint no number, filled from the frames around them.

A BVH exporter writes "nan" where it has no value: an optical system's joint whose markers were all lost
for a few frames, or a converter whose Euler decomposition failed (mdm2bvh's SMPL output has "nan" in one
spine joint's angles at 17 of its 120 frames). Such a frame is a gap in that joint's track, as in any
capture's marker trajectories, and is filled as capture software's linear gap fill fills a short one (Motive's
"Linear" interpolation; Vicon Nexus's spline fill is its smooth variant): from the joint's last frame before
the gap and its first frame after it. `fill_gaps` takes the rotation along the slerp between the two
orientations (constant angular velocity between them, the shortest way round: Shoemake, "Animating rotation
with quaternion curves", SIGGRAPH 1985; scipy's `Slerp`, as the glitch repair) and a translation along the straight line; a gap at the clip's start
or end holds the nearest frame with a number. `runner.capture.glitches` then judges the filled frames like
any other. The summary names every gap filled (`gaps_line`) and the metrics report lists them
(`reference_gaps`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from runner.capture.glitches import slerp
from solver.errors import InputError

__all__ = ["Gap", "fill_gaps", "gaps_line", "clip_gaps"]


@dataclass(frozen=True)
class Gap:
    """One run of consecutive frames in which the file gives a joint no number.

    Attributes:
        joint: the joint's name in the file.
        first, last: the first and last frame of the run (1-based, counted as the file's frame lines are,
            the rest frames included).
        frame_time: [s] time between frames.
    """

    joint: str
    first: int
    last: int
    frame_time: float

    @property
    def frames(self) -> int:
        return self.last - self.first + 1

    @property
    def span(self) -> str:
        """"frame 14" or "frames 57-59", and the gap's duration."""
        which = f"frame {self.first}" if self.first == self.last else f"frames {self.first}-{self.last}"
        return f"{which} ({self.frames * self.frame_time:.3f} s)"

    def __str__(self) -> str:
        return f"{self.joint} {self.span}"


def _runs(bad: np.ndarray) -> list[tuple[int, int]]:
    """[(a, b)] the 0-based first and last index of each run of True in the (n,) boolean array `bad`."""
    edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1))


def _fill_track(quat: np.ndarray, pos: np.ndarray, bad: np.ndarray) -> None:
    """Fill, in place, the frames `bad` (n,) of one joint's (n, 4) rotations and (n, 3) translations from the
    frames on either side (module docstring); at least one frame is not bad."""
    n = len(bad)
    for a, b in _runs(bad):
        before, after = a - 1, b + 1
        if before < 0 or after >= n:  # at an end: hold the nearest frame with a number
            held = after if before < 0 else before
            quat[a:b + 1], pos[a:b + 1] = quat[held], pos[held]
            continue
        u = (np.arange(a, b + 1) - before) / float(after - before)
        quat[a:b + 1] = slerp(quat[before], quat[after], u)
        pos[a:b + 1] = np.outer(1.0 - u, pos[before]) + np.outer(u, pos[after])


def fill_gaps(quat: np.ndarray, pos: np.ndarray, names, frame_time: float,
              src: str) -> tuple[np.ndarray, np.ndarray, tuple[Gap, ...]]:
    """Fill the frames where a joint has a value that is not a number (module docstring).

    Args:
        quat: (n, J, 4) local rotations (w x y z; NaN where the file has no number for the joint's angles).
        pos: (n, J, 3) local translations (NaN where the file has no number for the joint's position channels).
        names: the J joint names. frame_time: [s]. src: the file, for the error.
    Returns:
        (quat, pos, gaps): filled copies, and one `Gap` per run of frames filled, in joint order.
    Raises:
        InputError: a joint has no number in any frame (nothing to fill its track from).
    """
    quat, pos, gaps = np.array(quat, float), np.array(pos, float), []
    bad = ~(np.isfinite(quat).all(axis=2) & np.isfinite(pos).all(axis=2))  # (n, J)
    for j in np.flatnonzero(bad.any(axis=0)):
        if bad[:, j].all():
            raise InputError(f"{src}: joint {names[j]} has no number in any frame (every value 'nan'); export the "
                             "clip again, or remove the joint from the HIERARCHY and its channels from the frames")
        _fill_track(quat[:, j], pos[:, j], bad[:, j])
        gaps += [Gap(names[j], int(a) + 1, int(b) + 1, frame_time) for a, b in _runs(bad[:, j])]
    return quat, pos, tuple(gaps)


def gaps_line(gaps) -> str | None:
    """The printed line of what `fill_gaps` filled, per joint: frames in all, runs and the longest; None
    when nothing was."""
    if not gaps:
        return None
    parts = []
    for joint in dict.fromkeys(g.joint for g in gaps):
        mine = [g for g in gaps if g.joint == joint]
        longest = max(mine, key=lambda g: g.frames).span
        parts.append(str(mine[0]) if len(mine) == 1 else
                     f"{joint} {sum(g.frames for g in mine)} frames in {len(mine)} gaps, the longest {longest}")
    return ("gaps filled (frames where the file gives a joint no number, 'nan': each the slerp between the joint's "
            "frames around it; docs/mocap.md \"Gaps\"): " + "; ".join(parts))


def clip_gaps(reference) -> tuple[Gap, ...]:
    """The gaps filled in the clip a `runner.capture.retarget.Reference` was read from (none for a motion not
    read from a clip)."""
    capture = getattr(reference, "capture", None)
    return () if capture is None else capture.clip.gaps
