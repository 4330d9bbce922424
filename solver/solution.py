"""What `solve` returns: the rounds it ran (`Round`, with why each ran) and the `Solution`."""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from solver.frames import FrameSet
from solver.objective import Objective
from solver.optimize import OptimizeResult, Status
from solver.subdivide import refinement_estimate

#: `Round.kind` values: why a round ran.
ROUND_KINDS = ("start", "refine", "boost", "polish", "certify")


@dataclass(frozen=True)
class Round:
    """One optimization round: the frames it started with and the optimizer's result (read-only).

    Attributes:
        n_frames, n_variable: frames the round optimized, and how many of them are variable frames.
        result: the optimizer's OptimizeResult.
        scores: (n_frames_before - 1,) the subdivision scores (`SolveOptions.score`; the least change:
            the predicted decreases, `Solution.segment_decreases`) that chose this round's new frames,
            on the previous round's segments; None for the first round, a boost and a polish.
        times: (n_frames,) the frame times this round optimized [s].
        kind: why the round ran (`ROUND_KINDS`): "start" (the first), "refine" (frames were added),
            "boost" (the same frames under a weight the strategy raised: the orientation's unit term,
            `solver.paper.orient_refine.GapToOptimum`) "polish" (the same frames at a stricter stopping test) or "certify" (the least
            change's first subproblem on the path of the least violation, `solver.feasibility`).
    """

    n_frames: int
    n_variable: int
    result: OptimizeResult
    scores: np.ndarray | None = None
    times: np.ndarray | None = None
    kind: str = "start"


@dataclass(frozen=True)
class Solution:
    """The result of `solve` and of the least change (read-only: a frozen dataclass whose arrays are not
    writeable).

    Attributes:
        frames: optimized FrameSet (the path is the natural cubic spline through it), (m, nq) values.
        initial: the plain spline's FrameSet (a read-only copy of `solve`'s `initial`).
        rounds: (Round, ...) per-round results.
        status: Status of the last round (INTERRUPTED etc. end the solve early).
        message: why it ended.
        E_initial, E_final: objective on the plain spline and on the result, both under the
            renormalization scales (the least change: Phi, the measure of change).
        integrals_initial, integrals_final: {term: integral of f_j dt} on each (unweighted).
        scales: {term: renormalization divisor} (eq. 7; 1 without renormalization).
        trace: (N,) best objective after each evaluation, all rounds concatenated.
        wall_time_s: [s], optimization and subdivision (excludes building the terms).
        n_evals: objective evaluations in all rounds.
        weights: {term: lambda_j} of the objective (`solve`); {} for the least change.
        objective: the working copy of the objective the last round optimized (final weights and
            scales, terms prepared on the result): for scores or evaluations on the result under the
            objective that produced it. `solve` never changes the caller's Objective.
        refinement_estimates: the refinement strategy's estimate after each round that computed one:
            with adaptive subdivision `refinement_estimate` (refine "rounds" with score "decrease":
            every round but the last; refine "tol": every round); `solver.paper.orient_refine.GapToOptimum`:
            the estimated gap.
        converged_to_tol: with a tolerance, whether the solve ended because the estimate reached it (the
            least change: with every constraint met; not after a budget or a stop request); None without one.
        final_estimate: the last estimate of a strategy with a tolerance, NaN otherwise.
        estimate_kind: what `final_estimate` is: "refinement" (the decrease of Phi more frames predict over
            Phi), "progress" (on a `LeastChange.grid`, where no frame can be added: the decrease of Phi over
            the last subproblem, over Phi), "reference" (0: the reference motion met every constraint and is
            returned unchanged, `solver.least_change`) or "search" (NaN: a grid's solve ended on the least
            violation's path, which met every constraint as posed).
        unmet: {constraint: amount [SI]} of the constraints the least change could not meet: the largest
            raise of each (`solver.feasibility`); {} for `solve`.
        certificate: the least change's `solver.feasibility.Raise`s: per constraint and column, the least
            violation no path through the keyframes beats [SI], where and over which span; () for `solve`.
        relaxations: the least change's `solver.foot_bounds.Relaxation`s: where the keyframes decide a
            constraint (which, site or joint, keyframe, span [s], amount [SI]); () for `solve`.
        segment_decreases: the least change's refinement checks, in order: ((frame times (m,) [s],
            (m - 1,) the decrease of Phi a midpoint frame predicts in each segment: the Euler-Lagrange
            residual of the augmented integrand, `solver.least_change_refine`), ...); () for `solve`.
        finer: the certificate checked at a finer spacing (`solver.animate.solve_problem`): (rate [1/s] of the
            finer solve, kept: True when its path is the one returned (it raised no limit more and one less
            or by less), the other solve's Raises: the coarser's when kept, else the finer's); () when nothing was
            raised or the check did not run.
        multipliers: the least change's multiplier estimates at its end, ((constraint name, (p,) lambda >= 0
            per pair, per unit of c/tol), ...) in the problem's order (Nocedal & Wright, sec. 17.3); () for
            `solve`.
    """

    frames: FrameSet
    initial: FrameSet
    rounds: tuple[Round, ...]
    status: Status
    message: str
    E_initial: float
    E_final: float
    integrals_initial: dict
    integrals_final: dict
    scales: dict
    trace: np.ndarray
    wall_time_s: float
    n_evals: int = field(default=0)
    weights: dict = field(default_factory=dict)
    objective: Objective | None = field(default=None, repr=False, compare=False)
    refinement_estimates: tuple = ()
    converged_to_tol: bool | None = None
    final_estimate: float = float("nan")
    estimate_kind: str = "refinement"
    unmet: dict = field(default_factory=dict)
    relaxations: tuple = ()
    segment_decreases: tuple = ()
    certificate: tuple = ()
    finer: tuple = ()
    multipliers: tuple = ()

    @cached_property
    def refinement_estimate(self) -> float:
        """`refinement_estimate` of the result (relative to E_final): the last round's with a
        tolerance, else computed when first read (three gradient evaluations with a frame in every
        segment); NaN without the objective."""
        if np.isfinite(self.final_estimate):
            return self.final_estimate
        if self.objective is None:
            return float("nan")
        return refinement_estimate(self.objective, self.frames, self.E_final)[0]

    @property
    def round_counts(self) -> dict[str, int]:
        """{kind: number of rounds} over `ROUND_KINDS` (`Round.kind`), kinds that did not occur left out."""
        kinds = [r.kind for r in self.rounds]
        return {k: kinds.count(k) for k in ROUND_KINDS if k in kinds}

    @property
    def round_summary(self) -> str:
        """The rounds in words, e.g. "3 rounds: 1 start, 1 refine, 1 polish" (refinement rounds add frames;
        boost and polish rounds optimize the same frames again)."""
        return round_summary(self.rounds)


def round_summary(rounds) -> str:
    """The rounds in words: "n rounds: a start, b refine, c boost, d polish" (the kinds that occurred, in
    ROUND_KINDS order). rounds: a sequence of `Round`."""
    kinds = [r.kind for r in rounds]
    parts = [f"{kinds.count(k)} {k}" for k in ROUND_KINDS if k in kinds]
    return f"{len(kinds)} round{'s' if len(kinds) != 1 else ''}: " + ", ".join(parts)
