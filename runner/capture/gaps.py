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

A frame can also be corrupt as a whole: a decoder's garbage (ShaderMotion's decoded test.bvh puts the root
1,460 m away in 5 of its first 7 frames, every joint's angles with it). `corrupt_frames` finds a frame whose root
is farther from the median of the frames within `HALF_WINDOW` than a human body moves in that time
(`ROOT_SPEED_MAX`): Hampel's outlier identifier (Pearson, "Outliers in process modeling and identification",
IEEE Trans. Control Syst. Technol. 10(1), 2002) with a physical threshold instead of a statistical one. The
true root is within `ROOT_SPEED_MAX` h of its place at every frame of a window of half-width h, so the
component-wise median of the window is within sqrt(3) times that (a corner of the cube), as long as fewer
than half of the window's frames are corrupt; no real motion is ever taken for corrupt. Such a frame is a
gap of every joint, filled as above, and named as one (`Gap.joint` `EVERY_JOINT`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import median_filter

from runner.capture.glitches import slerp
from solver.errors import InputError

__all__ = ["EVERY_JOINT", "Gap", "HALF_WINDOW", "ROOT_SPEED_MAX", "clip_gaps", "corrupt_frames", "fill_gaps", "gaps_line",
           "rest_size"]

#: [body sizes per second] the fastest a human body's root moves: 12.4 m/s, a sprinter's peak speed (Bolt in
#: the 2009 Berlin 100 m; Graubner & Nixdorf, New Studies in Athletics 26(1/2), 2011), over a 1.75 m body,
#: rounded up (the body's size is the skeleton's, `rest_size`, so the bound needs no unit)
ROOT_SPEED_MAX = 7.5
#: [s] the half-width of the window whose median a frame's root is compared with: a run of corrupt frames up
#: to this long is found; two frames of 30 fps capture fit many times
HALF_WINDOW = 0.25
#: the `Gap.joint` of a corrupt frame, filled for every joint
EVERY_JOINT = "every joint"


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


def rest_size(places: np.ndarray, end_sites: dict) -> float:
    """[file units] the skeleton's size: the largest extent, along the file's axes, of its joints and End Sites in
    the rest pose (a standing body's height, a T-pose's arm span at most about as much).

    Args: places (J, 3) the joints' rest places (`runner.capture.bvh.rest_places`), end_sites {joint: (3,) OFFSET}."""
    points = np.vstack([places] + [places[j] + np.asarray(e, float) for j, e in end_sites.items()])
    return float((points.max(axis=0) - points.min(axis=0)).max())


def corrupt_frames(root: np.ndarray, size: float, frame_time: float) -> np.ndarray:
    """(n,) bool: the frames whose (n, 3) `root` position [file units] is farther from the component-wise median
    of the frames within `HALF_WINDOW` than sqrt(3) `ROOT_SPEED_MAX` `size` `HALF_WINDOW` (module docstring).
    A NaN position (a gap of the root's, `fill_gaps`) is not corrupt, and stands in the median as the clip's."""
    k = max(1, int(round(HALF_WINDOW / frame_time)))
    finite = np.isfinite(root).all(axis=1)
    if not finite.any():
        return np.zeros(len(root), bool)
    filled = np.where(finite[:, None], root, np.nanmedian(root[finite], axis=0))
    median = median_filter(filled, size=(2 * k + 1, 1), mode="mirror")  # an end: the frames after it, once
    reach = np.sqrt(3.0) * ROOT_SPEED_MAX * size * k * frame_time
    return finite & (np.linalg.norm(filled - median, axis=1) > reach)


def fill_gaps(quat: np.ndarray, pos: np.ndarray, names, frame_time: float, src: str,
              corrupt: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, tuple[Gap, ...]]:
    """Fill the frames where a joint has a value that is not a number, and the corrupt frames (module docstring).

    Args:
        quat: (n, J, 4) local rotations (w x y z; NaN where the file has no number for the joint's angles).
        pos: (n, J, 3) local translations (NaN where the file has no number for the joint's position channels).
        names: the J joint names. frame_time: [s]. src: the file, for the error.
        corrupt: (n,) bool, frames to fill for every joint (`corrupt_frames`), or None.
    Returns:
        (quat, pos, gaps): filled copies, and one `Gap` per run of frames filled: the corrupt frames' first
        (joint `EVERY_JOINT`), then each joint's own, in joint order.
    Raises:
        InputError: a joint has no number in any frame (nothing to fill its track from), or every frame is corrupt.
    """
    quat, pos = np.array(quat, float), np.array(pos, float)
    nan = ~(np.isfinite(quat).all(axis=2) & np.isfinite(pos).all(axis=2))  # (n, J)
    whole = np.zeros(len(quat), bool) if corrupt is None else np.asarray(corrupt, bool) & ~nan.all(axis=1)
    if whole.all():
        raise InputError(f"{src}: every frame's root is farther from its neighbours' than a body moves; check the "
                         "position channels of the ROOT")
    gaps = [Gap(EVERY_JOINT, int(a) + 1, int(b) + 1, frame_time) for a, b in _runs(whole)]
    for j in np.flatnonzero((nan | whole[:, None]).any(axis=0)):
        if nan[:, j].all():
            raise InputError(f"{src}: joint {names[j]} has no number in any frame (every value 'nan'); export the "
                             "clip again, or remove the joint from the HIERARCHY and its channels from the frames")
        _fill_track(quat[:, j], pos[:, j], nan[:, j] | whole)
        gaps += [Gap(names[j], int(a) + 1, int(b) + 1, frame_time) for a, b in _runs(nan[:, j] & ~whole)]
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
    return ("gaps filled (frames where the file gives a joint no number, 'nan', or whose root is farther from the frames "
            "around it than a body moves: each the slerp between the joint's frames around it; docs/mocap.md "
            "\"Gaps\"): " + "; ".join(parts))


def clip_gaps(reference) -> tuple[Gap, ...]:
    """The gaps filled in the clip a `runner.capture.retarget.Reference` was read from (none for a motion not
    read from a clip)."""
    capture = getattr(reference, "capture", None)
    return () if capture is None else capture.clip.gaps
