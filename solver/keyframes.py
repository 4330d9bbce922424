"""Keyframes: the animator's hard constraints, full or partial.

A keyframe fixes the state at a time; a *partial keyframe* fixes only some components (paper sec. 2),
the others are free and chosen by the optimizer. Keyframes are met exactly at every iterate.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from solver.errors import InputError
from solver.quaternion import align_hemispheres


@dataclass(frozen=True)
class Keyframes:
    """Keyframes of a state vector (MuJoCo `qpos`) at fixed times.

    Attributes:
        times: (k,) keyframe times [s], strictly increasing, finite, k >= 2.
        values: (k, nq) state at each keyframe; components not fixed by the mask may be NaN.
        mask: (k, nq) bool, True where the keyframe fixes that component. A full keyframe is all True.
        source: where they came from (a file path), used in error messages.

    Raises:
        InputError: on shape mismatch, non-finite or non-increasing times, fewer than two keyframes,
            non-finite fixed values, or a keyframe that fixes nothing.
    """

    times: np.ndarray
    values: np.ndarray
    mask: np.ndarray
    source: str = field(default="keyframes", compare=False)

    def __post_init__(self):
        times = np.asarray(self.times, dtype=float)
        values = np.asarray(self.values, dtype=float)
        mask = np.asarray(self.mask, dtype=bool)
        src = self.source
        if times.ndim != 1:
            raise InputError(f"{src}: keyframe times must be a 1-D list, got shape {times.shape}")
        if len(times) < 2:
            raise InputError(f"{src}: need at least two keyframes to interpolate, got {len(times)}")
        if values.ndim != 2 or values.shape[0] != len(times):
            raise InputError(
                f"{src}: keyframe values must have shape (k={len(times)}, nq), got {values.shape}"
            )
        if mask.shape != values.shape:
            raise InputError(f"{src}: keyframe mask shape {mask.shape} != values shape {values.shape}")
        bad = np.flatnonzero(~np.isfinite(times))
        if bad.size:
            i = int(bad[0])
            raise InputError(f"{src}: keyframe {i} has time {float(times[i])}; times must be finite numbers")
        if times[0] < 0:
            raise InputError(f"{src}: keyframe 0 has negative time {times[0]} s; times start at 0 or later")
        steps = np.diff(times)
        bad = np.flatnonzero(steps <= 0)
        if bad.size:
            i = int(bad[0])
            what = "duplicates" if steps[i] == 0 else "comes before"
            raise InputError(
                f"{src}: keyframe {i + 1} (t={times[i + 1]} s) {what} keyframe {i} (t={times[i]} s); "
                "keyframe times must be strictly increasing"
            )
        empty = np.flatnonzero(~mask.any(axis=1))
        if empty.size:
            i = int(empty[0])
            raise InputError(
                f"{src}: keyframe {i} (t={times[i]} s) fixes no component; a partial keyframe must fix at "
                "least one joint (or delete the keyframe)"
            )
        nonfinite = mask & ~np.isfinite(values)
        if nonfinite.any():
            i, c = (int(a) for a in np.argwhere(nonfinite)[0])
            raise InputError(
                f"{src}: keyframe {i} (t={times[i]} s) component {c} is {float(values[i, c])}; "
                "fixed values must be finite numbers"
            )
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", np.where(mask, values, np.nan))
        object.__setattr__(self, "mask", mask)

    @property
    def count(self) -> int:
        return len(self.times)

    @property
    def nq(self) -> int:
        return self.values.shape[1]

    @property
    def is_partial(self) -> np.ndarray:
        """(k,) bool, True for partial keyframes."""
        return ~self.mask.all(axis=1)

    def initial_values(self, quat_slots: np.ndarray) -> np.ndarray:
        """Keyframe values ready to interpolate: quaternions hemisphere-aligned, free components filled.

        1. Each quaternion slot that is fully fixed at consecutive keyframes is flipped to q or -q,
           whichever is nearer the previous fixed one (docs/design.md).
        2. A component a partial keyframe leaves free gets the value of the natural cubic spline through
           the keyframes that do fix it (linear with two, constant with one): the starting guess the
           optimizer moves.

        Args:
            quat_slots: (s, 4) qpos indices of the quaternions.
        Returns:
            (k, nq) finite values; fixed components equal `values` up to the sign of whole quaternions.
        Raises:
            InputError: a fixed quaternion is zero or near zero (|q| < 1e-6); a slot outside 0..nq-1.
        """
        vals = self.values.copy()
        slots = np.asarray(quat_slots, dtype=int).reshape(-1, 4)
        if slots.size and (slots.min() < 0 or slots.max() >= self.nq):
            raise InputError(f"{self.source}: quaternion slots {slots.tolist()} do not fit keyframes of nq={self.nq}; "
                             "pass the layout of the model the keyframes are for (layout.quat_slots)")
        for slot in slots:
            full = self.mask[:, slot].all(axis=1)
            norms = np.linalg.norm(vals[full][:, slot], axis=1)
            if np.any(norms < 1e-6):
                i = int(np.flatnonzero(full)[np.argmin(norms)])
                raise InputError(
                    f"{self.source}: keyframe {i} (t={self.times[i]} s) has a zero quaternion at qpos "
                    f"{slot.tolist()}: {vals[i, slot].tolist()}; give a unit quaternion (w x y z), "
                    "e.g. [1, 0, 0, 0] for no rotation"
                )
            rows = np.flatnonzero(full)
            vals[np.ix_(rows, slot)] = align_hemispheres(vals[np.ix_(rows, slot)])
        for c in range(self.nq):
            have = self.mask[:, c]
            if have.all():
                continue
            t, y = self.times[have], vals[have, c]
            if len(t) == 0:
                fill = np.zeros(self.count)
            elif len(t) == 1:
                fill = np.full(self.count, y[0])
            else:
                from scipy.interpolate import make_interp_spline  # partial keyframes only: most runs never pay it

                k = 3 if len(t) >= 4 else 1
                bc = "natural" if k == 3 else None
                fill = make_interp_spline(t, y, k=k, bc_type=bc)(self.times)
            vals[~have, c] = fill[~have]
        # a quaternion that is zero after filling (no keyframe fixes its free components, and the fixed
        # ones are zero, e.g. [0, null, 0, 0]) gets 1 in its first free component: a unit quaternion
        # that still meets the keyframe (a fully fixed zero quaternion was rejected above)
        for slot in slots:
            for i in np.flatnonzero(np.linalg.norm(vals[:, slot], axis=1) < 1e-6):
                free = slot[~self.mask[i, slot]]
                vals[i, free] = 0.0
                vals[i, free[0]] = 1.0
        return vals
