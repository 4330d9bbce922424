"""The refinement strategies of `solve`'s loop (solver/refinement.py), each alone on a hand-built
objective, and the loop's use of a strategy and a back end given to `solve` (Round.kind)."""
import numpy as np
import pytest

from solver.errors import InputError
from solver.frames import FrameSet
from solver.objective import Objective
from solver.optimize import OptimizeResult, Status
from solver.paper.refinement import (
    STOP,
    TOL_FRAMES_PER_INTERVAL,
    FixedRounds,
    NoRefinement,
    Refinement,
    Step,
    ToTolerance,
    refinement_estimate,
)
from solver.paper.solve import DEFAULT_ROUNDS, SolveOptions, solve
from solver.terms.base import Term, TermEval


class TrackSine(Term):
    """f = (Y_0 - sin(3 t))^2: the spline through few frames cannot follow the sine, so inserting a frame
    lowers E (predicted decreases > 0 in every segment)."""

    name, needs = "sine", (0,)

    def evaluate(self, t, Y, Y1, Y2, grad=True):
        r = Y[:, 0] - np.sin(3 * t)
        dY = np.zeros_like(Y)
        dY[:, 0] = 2 * r
        return TermEval(r**2, dY=dY if grad else None)


def sine_problem(keys=3):
    """Keyframes on the sine at 0..2 s (nq = 1) and the objective."""
    times = np.linspace(0.0, 2.0, keys)
    values = np.sin(3 * times)[:, None]
    fs = FrameSet(times, values, np.ones((keys, 1), bool), np.ones(keys, bool))
    return fs, Objective([TrackSine()], [1.0], 0.0, 2.0, rate=200.0)


def result_at(obj, frames):
    """An OptimizeResult standing for a round that ended at `frames` (fun = E there)."""
    E = obj.evaluate(frames.times, frames.values, grad=False).E
    return OptimizeResult(frames.x(), E, Status.CONVERGED, "converged", 1, 1, np.array([E]), 0.0, "fake")


def test_no_refinement_stops_after_one_round():
    fs, obj = sine_problem()
    strategy = NoRefinement()
    assert strategy.first_frames(obj, fs) is fs
    assert strategy.after_round(obj, fs, result_at(obj, fs), 0, None) is STOP
    assert strategy.converged is None and strategy.estimates == []


def test_fixed_rounds_refines_rounds_times_within_its_budget():
    fs, obj = sine_problem()
    strategy, events = FixedRounds(2, per_round=1), []
    frames = fs
    for i in range(2):
        step = strategy.after_round(obj, frames, result_at(obj, frames), i, lambda e, info: events.append((e, info)))
        assert step.action == "refine" and step.times.size == 1  # per_round frames
        assert step.scores.shape == (frames.count - 1,)
        # the new frame is in the segment with the largest predicted decrease
        seg = int(np.argmax(step.scores))
        assert frames.times[seg] < step.times[0] < frames.times[seg + 1]
        frames = frames.with_variable_frames(step.times)
    assert strategy.after_round(obj, frames, result_at(obj, frames), 2, None) is STOP  # rounds done
    assert [e for e, _ in events] == ["estimate", "estimate"] and len(strategy.estimates) == 2
    # the estimate is the sum of the predicted decreases over E
    est, D = refinement_estimate(obj, fs)
    assert strategy.estimates[0] == pytest.approx(est, rel=1e-12) and est > 0 and D.shape == (2,)


def test_fixed_rounds_stop_when_max_frames_is_used_up():
    fs, obj = sine_problem()
    full = fs.with_variable_frames(np.array([0.5]))
    assert FixedRounds(5, max_frames=1).after_round(obj, full, result_at(obj, full), 0, None) is STOP


def test_fixed_rounds_by_gradient_score_compute_no_estimate():
    fs, obj = sine_problem()
    strategy = FixedRounds(1, score="gradient")
    step = strategy.after_round(obj, fs, result_at(obj, fs), 0, None)
    assert step.action == "refine" and strategy.estimates == []


def test_to_tolerance_accepts_rejects_and_runs_out_of_frames():
    fs, obj = sine_problem()
    est, _ = refinement_estimate(obj, fs)
    loose = ToTolerance(2 * est)
    assert loose.first_frames(obj, fs) is fs and loose.max_frames == TOL_FRAMES_PER_INTERVAL * 2
    step = loose.after_round(obj, fs, result_at(obj, fs), 0, None)
    assert step.action == "stop" and loose.converged is True and "<= tol" in step.message
    assert loose.final_estimate == pytest.approx(est, rel=1e-12)
    tight = ToTolerance(est / 100, max_frames=5)
    tight.first_frames(obj, fs)
    step = tight.after_round(obj, fs, result_at(obj, fs), 0, None)
    assert step.action == "refine" and tight.converged is False and step.times.size == 2  # one per segment
    full = fs.with_variable_frames(np.array([0.1, 0.4, 0.7, 1.3, 1.6]))
    step = tight.after_round(obj, full, result_at(obj, full), 1, None)
    assert step.action == "stop" and "frame budget of 5 variable frames reached" in step.message
    assert tight.final_message(Status.MAX_TIME, "time limit of 1 s reached").endswith(f"(tol {est / 100:g})")


class PolishOnce(Refinement):
    """A strategy that has the same frames optimized once more at a stricter ftol_rel, then stops."""

    def __init__(self):
        super().__init__()
        self.ftols, self.polished = [], False

    def round_options(self, options):
        from dataclasses import replace

        opts = replace(options, ftol_rel=1e-3 if not self.polished else 1e-12)
        self.ftols.append(opts.ftol_rel)
        return opts

    def after_round(self, objective, frames, result, index, progress):
        if self.polished:
            return Step("stop", message="done polishing")
        self.polished = True
        return Step("polish")


def test_solve_runs_a_given_strategy_and_backend_and_names_the_round_kinds():
    fs, obj = sine_problem()
    fs = fs.with_variable_frames(np.array([0.3, 1.2]))
    calls = []

    def backend(objective, frames, options, remaining, should_stop, progress, evals_before):
        calls.append((options.ftol_rel, frames.count, evals_before))
        return result_at(objective, frames)  # does not move the frames

    strategy, events = PolishOnce(), []
    sol = solve(obj, fs, SolveOptions(subdivision="none", renormalize=False), refinement=strategy,
                backend=backend, progress=lambda e, i: events.append((e, i)))
    assert calls == [(1e-3, 5, 0), (1e-12, 5, 1)]  # the strategy's options reached the back end
    assert [r.kind for r in sol.rounds] == ["start", "polish"]
    assert [i["kind"] for e, i in events if e == "round"] == ["start", "polish"]
    assert sol.message == "done polishing (2 rounds: 1 start, 1 polish)"
    assert sol.round_counts == {"start": 1, "polish": 1} and sol.n_evals == 2


def test_solve_default_strategy_follows_the_options():
    fs, obj = sine_problem()
    sol = solve(obj, fs, SolveOptions(subdivision="adaptive", refine="rounds", rounds=1, renormalize=False))
    assert [r.kind for r in sol.rounds] == ["start", "refine"] and sol.converged_to_tol is None
    sol = solve(obj, fs, SolveOptions(subdivision="adaptive", refine="tol", tol=1e9, renormalize=False))
    assert [r.kind for r in sol.rounds] == ["start"] and sol.converged_to_tol is True


def test_the_refinement_mode_is_a_choice():
    assert SolveOptions().refine == "rounds" and SolveOptions().n_rounds == DEFAULT_ROUNDS
    assert SolveOptions(rounds=5).n_rounds == 5 and SolveOptions(refine="tol", tol=1e-3).tol == 1e-3
    with pytest.raises(InputError, match="refine='tol' needs a tolerance tol > 0, got tol=0"):
        SolveOptions(refine="tol")
    with pytest.raises(InputError, match="tol=0.001 is the parameter of refine='tol'.*would be ignored"):
        SolveOptions(tol=1e-3)
    with pytest.raises(InputError, match="rounds=3 is the parameter of refine='rounds'"):
        SolveOptions(refine="tol", tol=1e-3, rounds=3)
    with pytest.raises(InputError, match="unknown refine 'fixed'; choose one of: rounds, tol"):
        SolveOptions(refine="fixed")
    with pytest.raises(InputError, match="rounds must be a whole number >= 0"):
        SolveOptions(rounds=-1)
