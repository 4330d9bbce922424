"""Penalty continuation (`SolveOptions.limits`): after a round, stiffen the soft constraints the path
still violates by more than their bound, and have the round optimized again.

The quadratic-penalty method's schedule (Nocedal & Wright, Numerical Optimization, 2nd ed., sec. 17.1):
a quadratic penalty's violation falls about as 1/weight, so multiplying a violated term's weight by
`boost` drives it toward its bound without a constrained optimizer. A boost that did not cut the
violation below STALL_FRACTION of what it was shows the bound out of reach (the keyframes hold the path
there: 127_33 keyed every 0.33 s took four boosts and 1550 evaluations while its clearance violation
grew from 68 to 112 mm); that term is not boosted again (`PenaltyContinuation.stalled`).
"""
from __future__ import annotations

from collections.abc import Callable

from solver.metrics import sample_times

#: A boost must at least halve a violation, or the term is given up on (module docstring).
STALL_FRACTION = 0.5
#: [1/s] samples per second at which the limits are checked. Dense: a swing foot moves ~6 mm per ms, so
#: a graze of a box edge can last about a millisecond; a check at the 1000 Hz of the acceptance figures
#: would see it or not depending on phase.
LIMIT_CHECK_RATE = 4000.0


def over_limits(objective, frames, limits) -> dict[str, float]:
    """{term name: violation} of the terms whose `Term.violation` on the path (sampled at
    LIMIT_CHECK_RATE, in the term's own units, e.g. metres of penetration) exceeds their limit.

    Args:
        objective: Objective. frames: FrameSet (the path is its spline).
        limits: ((term name, tolerance >= 0), ...); names not in the objective, terms with weight 0
            and terms without a violation measure (None) are skipped.
    """
    if not limits:
        return {}
    Y = frames.path(sample_times(frames.times[0], frames.times[-1], LIMIT_CHECK_RATE))
    over = {}
    for name, tol in limits:
        if name not in objective.names:
            continue
        i = objective.names.index(name)
        v = objective.terms[i].violation(Y)
        if v is not None and v > tol and objective.weights[i] > 0:
            over[name] = float(v)
    return over


class PenaltyContinuation:
    """The continuation state of one solve: boosts made, the last boost's violations, the stalled terms.

    Args:
        limits: ((term name, tolerance), ...) (`SolveOptions.limits`).
        boost: factor (>= 1) on a violated term's weight. max_boosts: boosts in the whole solve.
        stall_fraction: a boosted term whose violation is still above this fraction of the violation
            that made the boost is not boosted again.
    Attributes:
        boosts: boosts made so far. stalled: {term: violation} of the terms given up on.
    """

    def __init__(self, limits=(), boost: float = 10.0, max_boosts: int = 4, stall_fraction: float = STALL_FRACTION):
        self.limits, self.boost, self.max_boosts, self.stall_fraction = tuple(limits), boost, max_boosts, stall_fraction
        self.boosts = 0
        self.stalled: dict[str, float] = {}
        self._last: dict[str, float] = {}  # the violations that made the last boost
        self._reported: set[str] = set()

    def after_round(self, objective, frames, progress: Callable[[str, dict], None] | None = None) -> dict[str, float]:
        """Check the limits on the round's result and boost the violated terms' weights in
        `objective.weights` (in place). Returns {term: violation} of the terms boosted (empty: none,
        the round stands). Tells progress "stalled" ({"terms": {name: violation}}, once per term) and
        "boost" ({"terms": ..., "boosts": n})."""
        over = over_limits(objective, frames, self.limits) if self.boosts < self.max_boosts else {}
        for name in [n for n in over if n in self._last and over[n] > self.stall_fraction * self._last[n]]:
            self.stalled[name] = over[name]
        fresh = set(self.stalled) - self._reported
        if fresh and progress:
            progress("stalled", {"terms": {n: self.stalled[n] for n in fresh}})
            self._reported |= fresh
        over = {n: v for n, v in over.items() if n not in self.stalled}
        self._last = over
        if not over:
            return {}
        self.boosts += 1
        for name in over:
            objective.weights[objective.names.index(name)] *= self.boost
        if progress:
            progress("boost", {"terms": over, "boosts": self.boosts})
        return over
