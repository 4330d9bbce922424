"""The frame set: keyframes (fixed) plus variable frames (free), the optimizer's variables.

Paper sec. 2, "Variable points": the spline passes through all frames; the optimizer moves the
variable frames and the components partial keyframes leave unset. Everything else is fixed, so the
hard constraints (keyframes) hold exactly at every iterate without a constrained optimizer.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.keyframes import Keyframes
from solver.spline import interpolate, interpolate_segments


@dataclass(frozen=True)
class FrameSet:
    """Frames of the spline and which of their components are free.

    Attributes:
        times: (m,) frame times [s], strictly increasing (the spline's knots).
        values: (m, nq) frame values (MuJoCo `qpos`).
        fixed: (m, nq) bool, True where a keyframe fixes the component.
        is_keyframe: (m,) bool, True for keyframes (full or partial), False for variable frames.
    """

    times: np.ndarray
    values: np.ndarray
    fixed: np.ndarray
    is_keyframe: np.ndarray

    @classmethod
    def from_keyframes(cls, keyframes: Keyframes, quat_slots: np.ndarray) -> FrameSet:
        """Frame set of the keyframes alone (the plain spline), free components filled as in
        `Keyframes.initial_values` (hemisphere-aligned quaternions)."""
        return cls(
            keyframes.times.copy(),
            keyframes.initial_values(quat_slots),
            keyframes.mask.copy(),
            np.ones(keyframes.count, bool),
        )

    @property
    def count(self) -> int:
        return len(self.times)

    @property
    def n_variable(self) -> int:
        """Number of variable frames."""
        return int((~self.is_keyframe).sum())

    @property
    def free(self) -> np.ndarray:
        """(m, nq) bool, the optimizer's variables."""
        return ~self.fixed

    @property
    def n_free(self) -> int:
        return int(self.free.sum())

    def x(self) -> np.ndarray:
        """The free components as a flat vector (row-major over frames), shape (n_free,)."""
        return self.values[self.free]

    def with_x(self, x: np.ndarray) -> FrameSet:
        """A copy with the free components replaced by x (n_free,); fixed components untouched."""
        vals = self.values.copy()
        vals[self.free] = x
        return FrameSet(self.times, vals, self.fixed, self.is_keyframe)

    def values_from_x(self, x: np.ndarray) -> np.ndarray:
        """(m, nq) frame values with free components x; the hot-path form of `with_x`."""
        vals = self.values.copy()
        vals[self.free] = x
        return vals

    def path(self, t: np.ndarray, nu: int = 0) -> np.ndarray:
        """The spline through the frames (or its nu-th derivative) at times t: (n,) -> (n, nq)."""
        return interpolate(self.times, self.values, t, nu)

    def with_midpoints(self) -> FrameSet:
        """A variable frame at the midpoint of every segment, valued on the path: `with_variable_frames`
        of the midpoints (the candidate frames subdivision scores), frame 2i the old frame i and frame
        2i+1 the new one in segment i, without the general insertion's sort and checks.

        Returns:
            FrameSet with 2m - 1 frames.
        """
        m = self.count
        mids = 0.5 * (self.times[:-1] + self.times[1:])
        times = np.empty(2 * m - 1)
        times[0::2], times[1::2] = self.times, mids
        values = np.empty((2 * m - 1,) + self.values.shape[1:])
        values[0::2] = self.values
        values[1::2] = interpolate_segments(self.times, self.values, np.array([0.5]))
        fixed = np.zeros((2 * m - 1,) + self.fixed.shape[1:], bool)
        fixed[0::2] = self.fixed
        is_key = np.zeros(2 * m - 1, bool)
        is_key[0::2] = self.is_keyframe
        return FrameSet(times, values, fixed, is_key)

    def with_variable_frames(self, times: np.ndarray) -> FrameSet:
        """Insert variable frames at `times`, valued on the current path.

        With natural end conditions the refined spline through the old path's values is the old path
        itself (docs/design.md "The spline"), so insertion leaves the path unchanged.

        Args:
            times: (r,) new frame times [s], strictly inside (times[0], times[-1]) and not on a frame.
        Returns:
            FrameSet with m + r frames.
        Raises:
            ValueError: a time is outside the path or coincides with an existing frame.
        """
        new_t = np.atleast_1d(np.asarray(times, dtype=float))
        if new_t.size == 0:
            return self
        if np.any(new_t <= self.times[0]) or np.any(new_t >= self.times[-1]):
            raise ValueError(f"variable frame times must lie inside ({self.times[0]}, {self.times[-1]})")
        all_t = np.concatenate([self.times, new_t])
        order = np.argsort(all_t, kind="stable")
        if np.any(np.diff(all_t[order]) == 0):
            raise ValueError("a variable frame time coincides with an existing frame")
        new_v = self.path(new_t)
        return FrameSet(
            all_t[order],
            np.concatenate([self.values, new_v])[order],
            np.concatenate([self.fixed, np.zeros_like(new_v, dtype=bool)])[order],
            np.concatenate([self.is_keyframe, np.zeros(len(new_t), bool)])[order],
        )
