"""Refinement strategies of `solve`'s outer loop (paper fig. 5: optimize -> subdivide -> optimize ...).

After each round, `solve` asks its strategy what next: stop, add
frames (`Step.times`) and optimize again, or optimize the same frames again (a "polish" at a stricter
stopping test, or a "boost" after the strategy changed the objective's weights). The strategies:

- `NoRefinement`: one round (subdivision "none" or "global": the frames are placed before it).
- `FixedRounds`: `rounds` rounds of adaptive subdivision (`SolveOptions.refine = "rounds"`).
- `ToTolerance`: adaptive subdivision until the decrease of E refinement still predicts, relative to
  E (`refinement_estimate`), is at most tol (`SolveOptions.refine = "tol"`).
- `solver.paper.orient_refine.GapToOptimum`: the orientation's estimated gap to the exact optimum.

A strategy is made fresh for each solve and keeps its own state (`estimates`, `converged`).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from solver.frames import FrameSet
from solver.optimize import OptimizeResult, Status
from solver.subdivide import adaptive_times, refinement_estimate, weak_form_scores

#: [frames] With a tolerance (`ToTolerance`, the orientation's `GapToOptimum`) and no `max_frames`: the frame budget,
#: per keyframe interval, a guard against a tolerance the frames cannot reach. 40 frames cut an interval into
#: pieces 1/41 as long (docs/orient.md, "The loop").
TOL_FRAMES_PER_INTERVAL = 40
#: `Step.action` values: what the loop does after a round.
ACTIONS = ("stop", "refine", "polish", "boost")


@dataclass(frozen=True)
class Step:
    """What the loop does after a round (`Refinement.after_round`).

    Attributes:
        action: "stop"; "refine" (add the frames at `times`, (r,) [s], then optimize); "polish" (the same
            frames again, options from `Refinement.round_options`); "boost" (the same frames again after
            the strategy raised weights).
        scores: with "refine", (m-1,) the scores that chose `times` on the round's segments (`Round.scores`).
        message: the solve's message if it stops here; None keeps the round's.
    """

    action: str
    times: np.ndarray | None = None
    scores: np.ndarray | None = None
    message: str | None = None


STOP = Step("stop")


class Refinement:
    """Base strategy: one round, no estimate. Subclasses override the hooks they need.

    Attributes:
        estimates: the estimate after each round that computed one (`Solution.refinement_estimates`).
        converged: whether a tolerance was reached; None for a strategy without one.
        final_estimate: the estimate the last round computed where the strategy checks a tolerance, NaN
            otherwise (`Solution.refinement_estimate` then computes one when read).
    """

    converged: bool | None = None

    def __init__(self):
        self.estimates: list[float] = []
        self.final_estimate = float("nan")

    def first_frames(self, objective, frames: FrameSet) -> FrameSet:
        """Frames to add before the first round (after the subdivision's starting frames). Default: none."""
        return frames

    def round_options(self, options):
        """The SolveOptions the back end gets for the next round. Default: `options`."""
        return options

    def after_round(self, objective, frames: FrameSet, result: OptimizeResult, index: int,
                    progress: Callable[[str, dict], None] | None) -> Step:
        """The round `index` ended with `result` (`frames` hold its x; `objective` prepared on them).
        Returns the Step. May raise NonFiniteError (the loop ends with status NONFINITE)."""
        return STOP

    def final_message(self, status: Status, message: str) -> str:
        """The solve's message once the loop has ended with `status`. Default: `message`."""
        return message


class NoRefinement(Refinement):
    """One round on the starting frames (subdivision "none", or "global" with its frames placed)."""


def _budget(frames: FrameSet, per_round: int, max_frames: int) -> int:
    """Frames the next adaptive round may add: per_round (0: one per segment), capped by max_frames."""
    budget = per_round or (frames.count - 1)
    if max_frames:
        budget = min(budget, max_frames - frames.n_variable)
    return budget


class FixedRounds(Refinement):
    """`rounds` adaptive rounds after the first, each adding at most `per_round` frames (0: one per
    segment; `max_frames` in total) where `score` ranks the segments highest ("decrease":
    `predicted_decreases`, whose sum also gives the refinement estimate of every round but the last;
    "gradient": `weak_form_scores`)."""

    def __init__(self, rounds: int, per_round: int = 0, max_frames: int = 0, score: str = "decrease"):
        super().__init__()
        self.rounds, self.per_round, self.max_frames, self.score = rounds, per_round, max_frames, score
        self._done = 0

    def after_round(self, objective, frames, result, index, progress):
        self._done += 1
        if self._done > self.rounds:
            return STOP
        budget = _budget(frames, self.per_round, self.max_frames)
        if budget <= 0:
            return STOP
        if self.score == "decrease":
            est, scores = refinement_estimate(objective, frames, result.fun)
            self.estimates.append(est)
            if progress:
                progress("estimate", {"round": index, "estimate": est, "tol": 0.0})
        else:
            scores = weak_form_scores(objective, frames)
        new = adaptive_times(scores, frames, budget)
        return Step("refine", new, scores) if new.size else STOP


class ToTolerance(Refinement):
    """Adaptive rounds until `refinement_estimate` <= tol, or the frame budget (`max_frames`; 0:
    TOL_FRAMES_PER_INTERVAL per keyframe interval) runs out, or no segment can be refined. New frames
    as `FixedRounds` places them."""

    converged = False
    #: what the estimate is, in the solve's messages
    what = "refinement estimate"

    def __init__(self, tol: float, per_round: int = 0, max_frames: int = 0, score: str = "decrease"):
        super().__init__()
        self.tol, self.per_round, self.max_frames, self.score = tol, per_round, max_frames, score
        self.accept_at, self.bound = tol, f"tol {tol:g}"  # where a round is accepted, and how the message says it

    def first_frames(self, objective, frames):
        if not self.max_frames:
            self.max_frames = TOL_FRAMES_PER_INTERVAL * (int(frames.is_keyframe.sum()) - 1)
        return frames

    def estimate(self, objective, frames: FrameSet, result: OptimizeResult) -> tuple[float, np.ndarray]:
        """(estimate, (m-1,) per-segment decreases that rank the segments) of the round's path:
        `refinement_estimate`. A subclass may estimate another error the same way."""
        return refinement_estimate(objective, frames, result.fun)

    def after_round(self, objective, frames, result, index, progress):
        est, D = self.estimate(objective, frames, result)
        self.estimates.append(est)
        self.final_estimate = est
        if progress:
            progress("estimate", {"round": index, "estimate": est, "tol": self.tol})
        if est <= self.accept_at:
            self.converged = True
            return Step("stop", message=f"{self.what} {est:.2g} <= {self.bound}")
        budget = _budget(frames, self.per_round, self.max_frames)
        if budget <= 0:
            return Step("stop", message=f"frame budget of {self.max_frames} variable frames reached at "
                                        f"{self.what} {est:.2g} (tol {self.tol:g})")
        scores = D if self.score == "decrease" else weak_form_scores(objective, frames)
        new = adaptive_times(scores, frames, budget)
        if new.size == 0:
            return Step("stop", message=f"no segment to refine at {self.what} {est:.2g} (tol {self.tol:g})")
        return Step("refine", new, scores)

    def final_message(self, status, message):
        if status is Status.MAX_TIME and self.estimates:
            return f"{message} at {self.what} {self.estimates[-1]:.2g} (tol {self.tol:g})"
        return message
