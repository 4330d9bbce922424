"""Penalty continuation (`SolveOptions.limits`): after a round, stiffen the soft constraints the path
still violates by more than their bound, and have the round optimized again.

The quadratic-penalty method's schedule (Nocedal & Wright, Numerical Optimization, 2nd ed., sec. 17.1):
a quadratic penalty's violation falls about as 1/weight, so multiplying a violated term's weight by
`boost` drives it toward its bound without a constrained optimizer. A boost that did not cut the
violation below STALL_FRACTION of what it was shows the bound out of reach (the keyframes hold the path
there: 127_33 keyed every 0.33 s took four boosts and 1550 evaluations while its clearance violation
grew from 68 to 112 mm); that term is not boosted again (`PenaltyContinuation.stalled`).

A boost whose every boosted term stalled bought nothing it was made for, and it is not free: the x10
weight moves every joint that reaches the constrained sites (on the tuning clip 16_23 keyed every 0.25 s,
a planted boost that took the violation from 29 to 26 mm moved both hips 4 degrees and the root 3 cm,
raising the joint-angle error against the capture from 4.5 to 5.8 degrees, the plain spline's 5.2, and
bent a knee 4 degrees backward, which took two more boosts). Such a boost is undone
(`PenaltyContinuation.after_round`, `undo_stalled`): the path, weights and round result from before it are restored, and the
solve goes on from there with the stalled terms given up on (docs/corpus.md "Near the plain spline").

A boost stiffens only the parts of a term its violation measures (`boost_terms`). The contact terms leave
out of their violation the contacts the keyframes contradict (`solver.schedule_conflicts`): no weight
reaches a bound there. Multiplying the whole term's weight pulled ten times harder on those as well, and
the optimizer bent the legs between the keyframes to bring the excused sites down (a knee turned
backward under a heel the keyframes hold up; tests/solver/test_continuation_excused.py). A term with
such parts gives, with `for_boost(factor)`, the term to use under the boosted weight, which keeps their
effective weight (docs/contacts.md "The contact terms").
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


def boost_terms(objective, names, factor: float) -> None:
    """Multiply the weights of the terms `names` in `objective.weights` by `factor` (in place); a term with
    parts its `violation` leaves out (a `for_boost(factor)` method, e.g. `Planted`: contacts the keyframes
    contradict) is replaced in a new `objective.terms` list by the term `for_boost` gives, which keeps
    those parts' effective weight (module docstring). The old list and its terms are not changed."""
    terms = list(objective.terms)
    for name in names:
        i = objective.names.index(name)
        objective.weights[i] *= factor
        hook = getattr(terms[i], "for_boost", None)
        if hook is not None:
            terms[i] = hook(factor)
    objective.terms = terms


class PenaltyContinuation:
    """The continuation state of one solve: boosts made, the last boost's violations, the stalled terms.

    Args:
        limits: ((term name, tolerance), ...) (`SolveOptions.limits`).
        boost: factor (>= 1) on a violated term's weight. max_boosts: boosts in the whole solve.
        stall_fraction: a boosted term whose violation is still above this fraction of the violation
            that made the boost is not boosted again.
        undo_stalled: undo a boost whose every boosted term stalled (module docstring).
    Attributes:
        boosts: boosts made so far (undone ones included). stalled: {term: violation} of the terms
        given up on. undone: boosts undone. restored: after `after_round`, (frames, round result) to
        go on from when it undid a boost, else None.
    """

    def __init__(self, limits=(), boost: float = 10.0, max_boosts: int = 4, stall_fraction: float = STALL_FRACTION,
                 undo_stalled: bool = True):
        self.limits, self.boost, self.max_boosts, self.stall_fraction = tuple(limits), boost, max_boosts, stall_fraction
        self.undo_stalled = bool(undo_stalled)
        self.boosts = 0
        self.undone = 0
        self.stalled: dict[str, float] = {}
        self.restored = None
        self._last: dict[str, float] = {}  # the violations that made the last boost
        self._before = None  # (frames, weights, round result) from before the last boost
        self._reported: set[str] = set()

    def after_round(self, objective, frames, progress: Callable[[str, dict], None] | None = None,
                    result=None) -> dict[str, float]:
        """Check the limits on the round's result and boost the violated terms' weights in
        `objective.weights` (in place). Returns {term: violation} of the terms boosted (empty: none,
        the round stands).

        A last boost whose every boosted term stalled is undone first (with `undo_stalled`; module
        docstring): the weights from before it are restored in `objective.weights`, `restored` is set
        to (frames, result) of the round before it - the caller goes on from those - and the limits are
        checked again there. Otherwise `restored` is None.

        Args:
            objective: the solve's working Objective. frames: the round's FrameSet.
            progress: told "stalled" ({"terms": {name: violation}}, once per term), "undo" ({"terms":
                the stalled violations, "boosts": boosts undone so far}) and "boost" ({"terms": ...,
                "boosts": n}).
            result: the round's OptimizeResult, kept with `frames` and the weights for an undo.
        """
        self.restored = None
        checked = self.boosts < self.max_boosts or bool(self._last)
        over = over_limits(objective, frames, self.limits) if checked else {}
        for name in [n for n in over if n in self._last and over[n] > self.stall_fraction * self._last[n]]:
            self.stalled[name] = over[name]
        fresh = set(self.stalled) - self._reported
        if fresh and progress:
            progress("stalled", {"terms": {n: self.stalled[n] for n in fresh}})
            self._reported |= fresh
        if self.undo_stalled and self._before is not None and self._last and all(n in self.stalled for n in self._last):
            frames, weights, result, objective.terms = self._before
            objective.weights[:] = weights
            self.restored, self._before, self.undone = (frames, result), None, self.undone + 1
            if progress:
                progress("undo", {"terms": {n: self.stalled[n] for n in self._last}, "boosts": self.undone})
            over = over_limits(objective, frames, self.limits)
        if self.boosts >= self.max_boosts:
            over = {}
        over = {n: v for n, v in over.items() if n not in self.stalled}
        self._last = over
        if not over:
            return {}
        self.boosts += 1
        self._before = (frames, objective.weights.copy(), result, objective.terms)
        boost_terms(objective, over, self.boost)
        if progress:
            progress("boost", {"terms": over, "boosts": self.boosts})
        return over
