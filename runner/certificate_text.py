"""The summary's lines on the limits a solve raised: the certificate of the least violation (`Solution.certificate`)
and its check at a finer spacing (`Solution.finer`), under the console's table (`runner.console`)."""
from __future__ import annotations

import numpy as np

from solver.animate import FINER
from solver.optimize import Status

__all__ = ["CERTIFIED_SHOWN", "certificate_lines"]

#: raised limits shown one per line under the table (the rest counted): the summary stays short
CERTIFIED_SHOWN = 6


def certificate_lines(solution) -> list[str]:
    """The summary's lines on the limits the least violation raised (`Solution.certificate`): per
    constraint and column, the amount no path through the keyframes beats, where, and the keyframes
    around it; [] when nothing was raised."""
    raises = sorted(getattr(solution, "certificate", ()) or (), key=lambda r: -r.amount / max(r.scale, 1e-300))
    finer = getattr(solution, "finer", ()) or ()
    unproved = bool(finer) and getattr(solution, "status", None) not in (None, Status.INFEASIBLE, Status.CONVERGED)
    if not raises:  # nothing raised, or a finer spacing met what the solve's own had raised
        return _finer_lines(finer, unproved)
    keys = np.asarray(solution.frames.times)[np.asarray(solution.frames.is_keyframe, bool)]
    out = ["limits raised, not proved out of reach (the check at a finer spacing, below, raised less):" if unproved else
           "out of reach (certified: the least violation no path through the keyframes beats; the limit raised by it):"]
    for r in raises[:CERTIFIED_SHOWN]:
        i = int(np.clip(np.searchsorted(keys, r.time, side="right") - 1, 0, len(keys) - 1))
        near = int(np.argmin(np.abs(keys - r.time)))
        if abs(keys[near] - r.time) <= 1e-3:  # [s] within a millisecond of a keyframe: at it (points are 5 ms apart)
            where = f", at keyframe {near}"
        else:  # a clean's keyframes are its pins and the clip's ends: between the ends says nothing
            where = f", between keyframes {i} and {min(i + 1, len(keys) - 1)}" if len(keys) > 2 else ""
        out.append(f"  {r.describe()}{where}")
    if len(raises) > CERTIFIED_SHOWN:
        out.append(f"  and {len(raises) - CERTIFIED_SHOWN} more (the saved path's certificate_json)")
    return out + _finer_lines(finer, unproved)


def _finer_lines(finer: tuple, unproved: bool = False) -> list[str]:
    """The line on the certificate's check at a finer spacing (`Solution.finer`); [] when it did not run.
    `unproved`: the check's search raised less, and the budget ended before the least change at its rate."""
    if not finer:
        return []
    rate, kept, other = finer
    said = "; ".join(r.describe() for r in other[:CERTIFIED_SHOWN]) or "nothing"
    if unproved:
        return [f"checked at a finer spacing: at {rate:g} points/s the search raised less ({said}), but the budget "
                "ended before the least change at that rate: the path is the coarser solve's, its raised limits "
                "not proved out of reach (a larger --max-time or --max-evals)"]
    if kept:  # the finer solve's path is the one returned
        return [f"checked at a finer spacing: the path is the solve's at {rate:g} points/s, which raised less than "
                f"the solve at {rate / FINER:g} ({said})"]
    return [f"checked at a finer spacing: at {rate:g} points/s the search raised no less ({said}); the certificate stands"]
