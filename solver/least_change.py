"""The least change that meets the constraints (docs/design.md): build the problem and solve it.

    minimize D(P)   over the free frame values P   subject to   c_p(P) <= 0 for every pair p

D is the mass-weighted change of the path's accelerations from the reference motion's
(`solver.change`), the constraints are each a function with its unit and tolerance
(`solver.constraint_set`), and the method of multipliers (`solver.lagrangian`) turns the problem into a
sequence of unconstrained subproblems whose variables are the free values of the frames: the keyframes
are not variables, so every iterate meets them exactly and is a path (paper sec. 2). Between
subproblems the multipliers and the penalty are updated; when a subproblem on the current frames is
done (the constraints met, or no longer improving), variable frames are added where the Euler-Lagrange
residual of the augmented integrand predicts the largest decrease (`solver.least_change_refine`, paper
sec. 4.2 and fig. 5), never closer than `min_gap` to another frame.

Where a frame set's subproblems are spent (`per_level`) with a constraint still broken, the method of multipliers alone
cannot tell a problem it has not yet solved from one no path can solve, so the least violation is sought
(`solver.feasibility`): the constraints' violation is minimized over the same paths, every constraint at once and, where
that leaves a pair broken, level by level in the order in which limits give (`Constraint.priority`), with frames added
where pairs stay broken. A limit rises only by what that solve shows no path through the keyframes beats
(`Solution.certificate`, in the constraint's SI unit); the solve goes on from the path it found, which meets every
certified limit (a raised pair's multiplier from 0, the rest as it was). It also starts from the capture, a keyed
path's (`solver.feasibility.capture_start`) and a clean's d = 0, as a stalled path can be anywhere (docs/design.md). A
path the solve ends on beyond a limit (a budget spent) gives way to the best one that met them all; on a grid (a clean's
one frame set) with nothing raised, so does one above their least D.
A clean (a grid; not with `newton`) searches first, from d = 0, before any subproblem, and a search that raises
nothing ends the solve; one that raises something is undone and its path kept as the second start of the search after
the rounds (a least violation from one start is a local one), whose certificate replaces the first's only where no
column of it is worse by more than a tolerance (`solver.least_change_end.kept_certificate`). The search's descent of
the violation runs in D's preconditioned variables, where D is about |z|^2, from z = 0: L-BFGS's every step is a
combination of the broken pairs' gradients there, so the path it stops on, the first that meets every pair, is of the
form d = H^-1 A^T lam, the least-D path's form for linearized constraints (Landweber's iteration from 0 converges to the
least-norm solution: Engl, Hanke & Neubauer, "Regularization of Inverse Problems", 1996, sec. 6.1). On the 13 shipped
cleans whose search raises nothing it took half the evaluations of the multipliers' rounds then the search, its D lower
on 8 and higher on 5 (by 11-28 %, docs/solvers.md).
Off a grid, the refinement judges such a search's path as it judges a round's (the solve ends there when it predicts
under tol), not another round first: those rounds ended above the search's D on 7 of the 9 shipped clips keyed every
0.25 s whose search raised nothing (by 3-45 %; at it on one, 5 % below it with 9 more frames on one). A reference motion
(the plain spline; a clean's capture) that meets every constraint within its tolerance is the answer as it is: D >= 0 is
0 there (the multipliers would move it to the limits).
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from solver.change import MeasureOfChange
from solver.constraint_set import figure_constraints, flight_edge_frames
from solver.constraints.forces import figure_forces
from solver.contact_schedule import ContactSchedule
from solver.errors import InputError
from solver.feasibility import Certificate, capture_start, least_violation, on_points, with_frames
from solver.figure import Figure
from solver.frames import FrameSet
from solver.gauss_newton import cached_preconditioner
from solver.grid_preconditioner import grid_maps
from solver.inverse_dynamics import InverseDynamics
from solver.kinematic_tree import SiteKinematics
from solver.kinematics import TangentMap
from solver.lagrangian import AugmentedLagrangian, frame_maps, initial_penalty, solve_subproblem
from solver.layout import StateLayout
from solver.least_change_end import (
    as_posed,
    better_path,
    budget_left,
    grid_done,
    kept_certificate,
    kept_path,
    stop_message,
    worst_pair,
)
from solver.least_change_refine import refinement
from solver.manifold import FrameVariables
from solver.optimize import Status
from solver.peak_bounds import peak_bounds
from solver.quadrature import check_points, quadrature_points
from solver.reference import ReferenceMotion
from solver.solution import Round, Solution
from solver.spline_basis import SplineBasis
from solver.subdivide import knot_hint_times

_MET_AS_IS = "the reference motion meets every constraint within its tolerance: it is the least change (D = 0)"
__all__ = ["LeastChange", "LeastChangeOptions", "build_least_change", "least_violation_of", "solve_least_change"]

#: [m/s^2] gravity's acceleration (standard gravity, CGPM 1901): D0 = m g^2 T makes D dimensionless
STANDARD_GRAVITY = 9.80665
#: [pairs] L-BFGS correction pairs on a `LeastChange.grid` (n ~ 1e4-1e5 variables): the standard limited memory (Nocedal
#: & Wright, sec. 7.2: "3 to 20"; L-BFGS-B's default); nlopt's, sized by n, costs an evaluation an iteration
GRID_PAIRS = 10


@dataclass(frozen=True)
class LeastChangeOptions:
    """How the least-change problem is solved (read-only).

    Attributes:
        tol: refinement stops when the decrease of Phi it still predicts is at most tol times Phi's nonnegative part
            (`AugmentedLagrangian.shift`) and every constraint is met (dimensionless; 1 %: the paper's fig. 5 "good
            enough" test as a fraction); until then a frame goes to each segment over its share by length. On a `LeastChange.grid`, where no
            frame can be added, the solve ends when every constraint is met and a subproblem lowered Phi by
            at most tol of that part (`subproblem_progress`).
        min_gap: [s] no two frames the refinement adds closer: 1/48 s, half a frame of 24 fps film; a cubic
            spline through frames closer than that kinks between them (its second derivative grows like
            1/h^2). The least violation (`solver.feasibility`) splits a segment holding a broken pair down to two
            quadrature intervals (2 / rate); `solver.animate.solve_problem` checks a raised limit at twice the rate.
        max_subproblems: subproblems in all (each an L-BFGS run), a guard against a method that cycles:
            100, above the most a converging solve was measured to need (24 on the corpus, 83_02 at contacts).
        per_level: subproblems on one frame set before refining it anyway (the multipliers converge
            linearly; refining is cheaper than more updates on too few frames).
        ftol_rel: each subproblem's relative tolerance on Phi (nlopt's ftol_rel): 1e-3, a subproblem
            need not be solved tightly while its multipliers are still estimates (inexact subproblems,
            Birgin & Martinez 2014, sec. 4.1); a tighter 1e-6 with a cap of 200 evaluations was slower
            and met fewer bounds on the corpus.
        round_evals: [evaluations] the most a subproblem spends before the multipliers are updated (0: no limit): 100 at
            200 points/s, what fits a round in 5 s per 10 s of clip (30-50 ms an evaluation per 10 s of clip), fewer
            at denser points; inexact subproblems (Birgin & Martinez 2014, sec. 4.1; docs/solvers.md). Not on a
            `LeastChange.grid`, whose solve ends on a whole subproblem's progress (`grid_done`).
        max_evals: evaluations of the whole solve, subproblems and refinement estimates (0: no limit): when
            they are spent the solve ends with the path so far (status MAX_EVALS), as with `max_time_s`.
        max_time_s: [s] stop after this much time in all, keeping the path so far (0: no limit).
        rate: [1/s] quadrature points per second: 200, at least four points in the shortest segment
            (min_gap) for the integrals; penetration holds between them too (its deepest point over each
            interval, `solver.constraints.penetration`).
        newton: on a `LeastChange.grid` (a clean), the rounds before any search, preconditioned by the Gauss-Newton
            Hessian of all of Phi until the least violation is sought (`solver.gauss_newton`; False: the search
            first, D's preconditioner alone; docs/solvers.md).
    """

    tol: float = 1e-2
    min_gap: float = 1.0 / 48.0
    max_subproblems: int = 100
    per_level: int = 8
    ftol_rel: float = 1e-3
    round_evals: int = 100
    max_evals: int = 0
    max_time_s: float = 0.0
    rate: float = 200.0
    newton: bool = False

    def __post_init__(self):
        if not (isinstance(self.rate, (int, float)) and np.isfinite(self.rate) and self.rate > 0):
            raise InputError(f"LeastChangeOptions.rate must be > 0 points per second, got {self.rate!r}")
        for name in ("tol", "min_gap", "ftol_rel", "max_time_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
                raise InputError(f"LeastChangeOptions.{name} must be a number >= 0, got {v!r}")
        for name in ("max_subproblems", "per_level", "round_evals", "max_evals"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or v < 0:
                raise InputError(f"LeastChangeOptions.{name} must be an integer >= 0, got {v!r}")


@dataclass(frozen=True)
class LeastChange:
    """One built least-change problem (`build_least_change`), read-only: a solve works on its own copy of
    `al` (`AugmentedLagrangian.posed`), so the same problem solved twice gives the same Solution.

    Attributes:
        model: mujoco.MjModel. layout: its StateLayout. figure: its Figure. plain: FrameSet of the plain
        spline through the keyframes (the reference motion). al: the AugmentedLagrangian (D, the
        constraints, multipliers, penalty). relaxations: the `solver.foot_bounds.Relaxation`s the
        keyframes force. knots: (r,) [s] times where a contact starts or ends (frames go there first).
        capture: None, or (times (n,) [s], qpos (n, nq)) the capture the keyframes came from (the least
        violation's second start, `solver.feasibility.capture_start`; a clean's is `plain` itself, d = 0).
        grid: (g,) [s] quadrature points that are every one a variable frame from the start, the finest
        path of a fixed spacing (None: frames start at the contacts' ends and in every segment and are
        added where the refinement says). A clean's is the capture's frames (`solver.displacement`): neither the
        refinement nor the least violation adds a frame off it (the cleaned clip is written at those frames).
    """

    model: object = field(repr=False)
    layout: StateLayout = field(repr=False)
    figure: Figure = field(repr=False)
    plain: FrameSet = field(repr=False)
    al: AugmentedLagrangian = field(repr=False)
    relaxations: tuple = ()
    knots: np.ndarray = field(default_factory=lambda: np.zeros(0))
    capture: tuple | None = field(default=None, repr=False)
    grid: np.ndarray | None = None


def build_least_change(model, keyframes, *, contacts=(), flights=None, capture=None, rate: float = LeastChangeOptions.rate,
                       forces: bool = False, peaks=None, bounds=()) -> LeastChange:
    """Build the problem: the plain spline as the reference motion, D, the figure's constraints.

    Args:
        model: mujoco.MjModel of the scene with the figure. keyframes: Keyframes (k, nq) at times (k,) [s].
        contacts: the contact schedule (`Contact`s). flights: ((start, end), ...) [s] where every site
            is clear; None: the schedule's gaps. capture: None or (times (n,) [s], qpos (n, nq)), the
            motion capture the keyframes came from (its filtered peaks bound the accelerations).
        rate: quadrature points per second [1/s]. forces: add the force bounds
            (`solver.constraints.forces`: ballistic flights, the friction cone, with a capture the peak
            ground force), computed by the inverse dynamics. peaks: with `forces`, the problem's
            `solver.peak_bounds.PeakBounds` when already made (`Problem.force_bounds`); None: made here.
        bounds: constraints of the caller's own (`ProblemSpec.bounds`): callables make(t) -> Constraint,
            t (n,) the quadrature times [s].
    Returns:
        LeastChange.
    Raises:
        InputError: fewer than two keyframes; a bound that is not a Constraint or whose rows or limit do
            not fit the quadrature points.
    """
    if keyframes.count < 2:
        raise InputError(f"{keyframes.source}: a path needs at least two keyframes, got {keyframes.count}")
    layout = StateLayout.from_model(model)
    figure = Figure.from_model(model)
    tmap = TangentMap.from_layout(layout)
    plain = FrameSet.from_keyframes(keyframes, layout.quat_slots)
    t0, t1 = float(plain.times[0]), float(plain.times[-1])
    check_points(t0, t1, rate)
    schedule = ContactSchedule.of(contacts or (), figure.contact_sites)
    flights = tuple(schedule.flights()) if flights is None else tuple(flights)
    edges = () if capture is None else flight_edge_frames(flights, capture[0], plain.times)
    t, w = quadrature_points(t0, t1, rate, np.concatenate([plain.times, edges]))  # keyframes: no jolt unseen
    reference = ReferenceMotion.from_frames(model, plain, t, w)
    if forces or capture is not None:  # the force bounds, or the effort bound of a capture's keyframes
        engine = InverseDynamics(model, figure.contact_sites)
    else:
        engine = SiteKinematics(model, figure.contact_sites) if figure.contact_sites else None
    constraints, relaxations = figure_constraints(model, figure, reference, plain, tuple(schedule), flights,
                                                  engine, capture=capture, track=True)
    if forces:  # with a capture, its peak ground force bounds the path's
        peak = None if capture is None else (peaks if peaks is not None else peak_bounds(model, plain, capture)).ground_force_bw
        constraints += figure_forces(model, t, flights, peak)
    constraints += [_own_bound(make, t) for make in bounds]
    # the pose part's frequency: the keyframes' own Nyquist frequency (a change slower than the keyframe
    # spacing is priced by its pose, a faster one by its acceleration)
    omega = np.pi / float(np.mean(np.diff(keyframes.times)))
    change = MeasureOfChange(reference, tmap, omega=omega, joints=layout.articulated_dofs)
    d0 = float(np.sum(model.body_mass)) * STANDARD_GRAVITY ** 2 * (t1 - t0)
    al = AugmentedLagrangian(change, constraints, tmap, engine, d0)
    knots = np.array([x for c in schedule for x in (c.start, c.end)], float)
    return LeastChange(model, layout, figure, plain, al, tuple(relaxations), knots, capture)


def _own_bound(make, t: np.ndarray):
    """A caller's constraint, `make(t)`, checked: a `Constraint` whose pairs are quadrature points of t."""
    from solver.constraints.base import Constraint

    c = make(t)
    if not isinstance(c, Constraint):
        raise InputError(f"a bound of ProblemSpec.bounds made {type(c).__name__}, not a solver.Constraint; "
                         "make(t) must return a Constraint (docs/design.md 'A constraint of your own')")
    rows = np.asarray(c.rows)
    if rows.size and (rows.min() < 0 or rows.max() >= len(t) or np.shape(c.limit) != rows.shape):
        raise InputError(f"bound {c.name!r}: rows must index the {len(t)} quadrature points and limit have one "
                         f"value per row, got rows {rows.min()}..{rows.max()} and limit of shape {np.shape(c.limit)}")
    return c


def _start_frames(lc: LeastChange, min_gap: float) -> FrameSet:
    """The plain spline's frames with variable frames at the contacts' ends and in every segment; on a
    `grid`, at every time of it (the finest path it allows: a clean's displacement at every capture frame)."""
    if lc.grid is not None:
        return with_frames(lc.plain, on_points(lc.grid, lc.grid, lc.plain), lc.layout.quat_slots)
    frames = lc.plain.with_variable_frames(on_points(knot_hint_times(lc.plain, lc.knots, min_gap), lc.al.t, lc.plain))
    mids = 0.5 * (frames.times[:-1] + frames.times[1:])
    return with_frames(frames, on_points(mids[np.diff(frames.times) >= 2 * min_gap], lc.al.t, frames), lc.layout.quat_slots)


def _start(lc: LeastChange, min_gap: float, frames: FrameSet | None = None) -> tuple[FrameSet, tuple]:
    """The starting frames (`frames`, or `_start_frames`) and their maps (`_grid`); sets the
    starting penalty rho_0 on `lc.al` (`solver.lagrangian.initial_penalty`)."""
    al = lc.al
    frames = _start_frames(lc, min_gap) if frames is None else frames
    basis, pre = _grid(lc)[0](al, frames, lc.layout.quat_slots)
    al.rho = initial_penalty(al, basis, FrameVariables(frames, lc.layout.quat_slots), pre)
    return frames, (basis, pre)


def solve_least_change(lc: LeastChange, options: LeastChangeOptions | None = None, *,
                       should_stop: Callable[[], bool] | None = None,
                       progress: Callable[[str, dict], None] | None = None, from_frames: FrameSet | None = None) -> Solution:
    """Solve a built problem by the method of multipliers with adaptive variable frames, and the least
    violation where a frame set's subproblems end with a constraint broken (module docstring).

    Args:
        lc: from `build_least_change`, not modified (the solve raises limits and moves multipliers on its own
            copy). options: LeastChangeOptions (on a `LeastChange.grid`, `tol` bounds the last subproblem's progress).
        should_stop: polled during each subproblem; True ends the solve with the path so far.
        progress: progress(event, info): "round" (a subproblem starts: round, frames, variable), "eval"
            (evals, E: the best Phi so far), "constraints" (it ended: round, worst, value as `worst_pair`, rho:
            the next penalty), "certify" (the least violation was sought: round, frames, raised {constraint:
            amount [SI]}, evals: the solve's so far, spent: the search's), "estimate" (round, estimate: the predicted decrease over Phi, tol).
        from_frames: the frames to start from (a path through `lc`'s keyframes, e.g. another rate's solution); None:
            the plain spline's with variable frames at the contacts' ends and in every segment.
    Returns:
        Solution: frames, initial (the plain spline's), one Round per subproblem, status (CONVERGED only
        when no limit was raised; INFEASIBLE when the certificate raised one and the rest converged), E =
        D/D0 before (0) and after, `integrals_*` each constraint's largest c/tol, `unmet` {constraint:
        amount [SI]} and `certificate` (`solver.feasibility.Raise`s).
    """
    o = options or LeastChangeOptions()
    lc = replace(lc, al=lc.al.posed())  # the solve's own multipliers and limits
    al, start = lc.al, time.perf_counter()
    frames, (basis, pre) = _start(lc, o.min_gap, from_frames)
    if from_frames is None and worst_pair(al, al.scaled_values(basis, frames.values))["value"] <= 1.0:  # met at D = 0, D's least
        return replace(_solution(lc, frames, basis, [], [], Status.CONVERGED, _MET_AS_IS, 0, (),
                                 time.perf_counter() - start, 0.0, o.tol), estimate_kind="reference")
    return _iterate(lc, o, frames, (basis, pre), start, should_stop, progress)


def _iterate(lc: LeastChange, o: LeastChangeOptions, frames: FrameSet, maps: tuple, start: float, should_stop,
             progress) -> Solution:
    """The subproblems, the search and the refinement of `solve_least_change` from its starting `frames` and
    their (SplineBasis, Preconditioner) `maps`, `start` [s, perf_counter] the solve's."""
    al, quat, (basis, pre) = lc.al, lc.layout.quat_slots, maps
    o = o if lc.grid is None else replace(o, round_evals=0)  # a grid's solve ends on a whole subproblem's progress
    raises, limits = [], [c.limit.copy() for c in al.constraints]  # the limits as posed
    rounds, estimate, decreases, scores, on_search = [], float("nan"), [], None, False
    evals, level_its, kind, certified, best, grid = 0, 0, "start", False, (np.inf, frames), {}  # best: (D, frames) met
    status, message = Status.CONVERGED, "every constraint met and refinement predicts under tol"
    first, met, prior = lc.grid is not None and not o.newton, False, None  # a clean searches first (module docstring)
    for k in range(o.max_subproblems):
        if k or not first:
            newton = o.newton and lc.grid is not None and not certified  # D's preconditioner after a search
            maps = (basis, (newton and cached_preconditioner(grid, basis, al, frames, quat)) or pre)
            r, spent = _subproblem(al, frames, maps, quat, o, (start, evals), should_stop, progress, k, _grid(lc)[1])
            if spent:
                status, message = spent, stop_message(spent, "", o)
                break
            frames, evals = r.frames, evals + r.result.n_evals
            rounds.append(Round(frames.count, frames.n_variable, r.result, scores, frames.times.copy(), kind))
            if r.result.status in (Status.INTERRUPTED, Status.MAX_TIME, Status.NONFINITE, Status.MAX_EVALS):
                status, message = r.result.status, stop_message(r.result.status, r.result.message, o)
                break
            shift, (worst, met) = al.shift(), _multipliers(al, frames, basis, progress, k)  # shift: under the old multipliers
            best = better_path(al, best, frames, basis) if worst["value"] <= 1.0 else best
            level_its, kind, scores = level_its + 1, "boost", None
            if not (met or level_its >= o.per_level):
                continue
            if not met and certified:  # spent again after the search: its path, or a better one, is the answer
                message = "subproblems spent with a pair broken after the least violation was found"
                break
        if not met:  # spent with a pair broken (or a clean's start): the search, once (its path meets every limit)
            cert = _certify(lc, frames, o, start, evals, should_stop, progress, k - (not rounds),
                            prior[0].frames if rounds and prior else None)
            evals = evals + cert.n_evals
            if cert.status is not Status.CONVERGED:
                status, message = cert.status, stop_message(cert.status, "while seeking the least violation", o)
                break
            if cert.raises and not rounds:  # one start's least violation is no proof: the rounds, then both starts
                prior = (cert, [c.limit.copy() for c in al.constraints])
                as_posed(al, limits)
                continue
            cert = kept_certificate(al, cert, prior, limits, progress)
            raises, certified = raises + list(cert.raises), True
            best, frames = better_path(al, best, cert.frames), cert.frames  # a path that meets every certified limit
            (basis, pre), level_its, kind = _grid(lc)[0](al, frames, quat), 0, "certify"
            if cert.raises:
                continue
            if lc.grid is not None:  # met as posed: on a grid the continuation raised D (module docstring)
                message, on_search = f"every constraint met on the grid's {frames.count} frames by the least violation", True
                break
            met = True  # met as posed: the refinement judges the search's path as it judges a round's (module docstring)
        if lc.grid is not None:  # a frame at every time of the grid already: done when a subproblem no longer moves
            estimate, message = grid_done(r.result, shift, frames.count, o, level_its, message)
            if estimate <= o.tol or level_its >= o.per_level:
                break
            continue
        new, estimate, dec = refinement(al, frames, quat, o.min_gap, o.tol)
        if progress:
            progress("estimate", {"round": k, "estimate": estimate, "tol": o.tol})
        decreases.append((frames.times.copy(), dec))
        evals += 3
        if met and (estimate <= o.tol or new.size == 0):
            message = (f"every constraint met; refinement estimate {estimate:.3g} <= tol {o.tol:g}" if estimate <= o.tol
                       else "every constraint met; no segment over its share can take another frame")
            break
        if new.size:
            frames, scores = with_frames(frames, new, quat), dec
            basis, pre = frame_maps(al, frames, lc.layout.quat_slots)
            level_its, kind = 0, "refine"
    else:
        status, message = Status.MAX_EVALS, f"{o.max_subproblems} subproblems without converging"
    frames, basis, message, raises = kept_path(al, frames, basis, best, message, raises, limits, lc.grid is not None)
    status = Status.INFEASIBLE if status is Status.CONVERGED and raises else status
    return _solution(lc, frames, basis, rounds, [np.asarray(r.result.trace) for r in rounds], status, message, evals,
                     tuple(raises), time.perf_counter() - start, estimate, o.tol, tuple(decreases), on_search)


def _multipliers(al: AugmentedLagrangian, frames: FrameSet, basis, progress, k: int) -> tuple[dict, bool]:
    """The multiplier update at the end of subproblem k (`AugmentedLagrangian.update`), reported ("constraints");
    returns (the worst pair as `worst_pair`, met: every pair within its tolerance and the infeasibility V <= 1)."""
    scaled = al.scaled_values(basis, frames.values)
    V = al.update(scaled)
    worst = worst_pair(al, scaled)
    if progress:
        progress("constraints", {"round": k, **worst, "rho": al.rho})
    return worst, worst["value"] <= 1.0 and V <= 1.0


def _subproblem(al, frames: FrameSet, maps: tuple, quat, o: LeastChangeOptions, spent_so_far: tuple, should_stop,
                progress, k: int, pairs: int | None = None):
    """Subproblem k on `frames` with their (SplineBasis, Preconditioner) `maps`, at most `round_evals` evaluations within the
    solve's budget (`spent_so_far`: its start [s, perf_counter] and evaluations), L-BFGS keeping `pairs` (None: by size):
    (its SubproblemResult, CONVERGED where its own cap ended it, None), or (None, MAX_TIME or MAX_EVALS: the budget spent)."""
    start, evals = spent_so_far
    left, spent = budget_left(o, start, evals)
    if spent:
        return None, spent
    if progress:
        progress("round", {"round": k, "frames": frames.count, "variable": frames.n_variable})
    cb = None if progress is None else (lambda n, phi: progress("eval", {"evals": evals + n, "E": phi}))
    solve_left = o.max_evals - evals if o.max_evals else 0
    # round_evals at the default rate's points per second: denser points (the finer check's 400) cost more an evaluation
    cap = max(1, int(o.round_evals * min(1.0, LeastChangeOptions.rate * al.T / len(al.t)))) if o.round_evals else 0
    own = bool(cap) and not 0 < solve_left <= cap  # the round's own cap, not the solve's budget
    r = solve_subproblem(al, frames, quat, ftol_rel=o.ftol_rel, basis=maps[0], pre=maps[1], max_evals=cap if own else solve_left,
                         max_time_s=max(left, 0.0), should_stop=should_stop, callback=cb, pairs=pairs)
    if own and r.result.status is Status.MAX_EVALS:  # an inexact subproblem: the multipliers are updated next
        r = replace(r, result=replace(r.result, status=Status.CONVERGED, message=f"the round's {cap} evaluations spent (round_evals)"))
    return r, None


def _certify(lc: LeastChange, frames: FrameSet, o: LeastChangeOptions, start: float, evals: int, should_stop,
             progress, k: int, second: FrameSet | None = None):
    """`solver.feasibility.least_violation` from `frames` within what is left of the solve's budget; reports
    it ("search" after round k, -1 before any, its "eval"s, "certify") and sets the multipliers of the pairs it
    raised to 0. Returns the Certificate. second: the second start (None: the capture's, `capture_start`, or
    for a clean's first search, whose `frames` are the capture, none)."""
    left = o.max_time_s - (time.perf_counter() - start) if o.max_time_s else 0.0
    before = [c.limit.copy() for c in lc.al.constraints]
    # the search splits segments down to two quadrature intervals, the shortest whose (linear) acceleration two
    # points fix, so the bounds hold between them; min_gap is the refinement's, not a limit of the search's paths
    gap, quat = (np.inf if lc.grid is not None else 2.0 / o.rate), lc.layout.quat_slots  # a grid's paths: no split
    # the second start (module docstring): a clean's capture itself, d = 0; a keyed path's capture, or none
    if second is None and k >= 0:
        second = lc.plain if lc.grid is not None else (
            None if lc.capture is None else capture_start(lc.plain, lc.capture, lc.al.t, gap, quat))
    if progress:  # the search's evaluations as they happen ("search", then "eval" with F), its outcome after
        progress("search", {"round": k, "frames": frames.count})
    cert = least_violation(lc.al, frames, quat, min_gap=gap, ftol_rel=o.ftol_rel, per_level=o.per_level, second=second,
                           maps=_grid(lc)[0], pairs=_grid(lc)[1], max_evals=max(o.max_evals - evals, 1) if o.max_evals else 0,
                           max_time_s=max(left, 1e-9) if o.max_time_s else 0.0, should_stop=should_stop,
                           callback=progress and (lambda n, F: progress("eval", {"evals": evals + n, "F": F})))
    if progress:
        progress("certify", {"round": k, "frames": cert.frames.count, "raised": cert.unmet,
                             "evals": evals + cert.n_evals, "spent": cert.n_evals})
    al = lc.al  # a raised pair's multiplier estimated its old limit's pull: it starts again from 0
    al.lam = [np.where(c.limit != old, 0.0, lam) for c, lam, old in zip(al.constraints, al.lam, before)]
    al.V = np.inf if cert.raises else al.V
    return cert


def least_violation_of(lc: LeastChange, frames: FrameSet, options: LeastChangeOptions, *, should_stop=None, progress=None):
    """The least violation of `lc` as posed, searched from `frames` as a solve searches it after a stall (`_certify`:
    both starts, segments down to two quadrature intervals), on its own copy: `solver.animate`'s check of a certificate
    at a finer spacing. Returns the `solver.feasibility.Certificate`."""
    return _certify(replace(lc, al=lc.al.posed()), frames, options, time.perf_counter(), 0, should_stop, progress, 0)


def _grid(lc: LeastChange) -> tuple:
    """(`lc`'s frame sets' maps, its subproblems' L-BFGS pairs): `grid_maps` and GRID_PAIRS on a grid, else `frame_maps` and None."""
    return (frame_maps, None) if lc.grid is None else (grid_maps, GRID_PAIRS)


def _solution(lc, frames, basis, rounds, trace, status, message, evals, raises, seconds, estimate, tol,
              decreases=(), on_search: bool = False) -> Solution:
    """The Solution of a solve (`solve_least_change`'s Returns); `on_search`: a grid's solve ended on the least
    violation's path (estimate_kind "search", no estimate: met as posed, it is converged)."""
    al = lc.al
    plain_basis = SplineBasis(lc.plain.times, al.t)
    _, _, D = al.evaluate(basis, frames.values, grad=False)

    def worst(b, P):
        return {c.name: float(s.max()) if s.size else 0.0 for c, s in zip(al.constraints, al.scaled_values(b, P))}

    unmet = Certificate(raises).unmet
    if unmet:  # the limits were raised to the least violation
        message += "; out of reach (limit raised by [SI]): " + ", ".join(f"{k} {v:.3g}" for k, v in unmet.items())
    return Solution(frames, lc.plain, tuple(rounds), status, message, 0.0, D / al.d0,
                    worst(plain_basis, lc.plain.values), worst(basis, frames.values), {},
                    np.concatenate(trace) if trace else np.zeros(0), seconds, evals, unmet=dict(unmet),
                    converged_to_tol=bool(status is Status.CONVERGED and (on_search or np.isfinite(estimate) and estimate <= tol)
                                          and not unmet),
                    final_estimate=estimate, estimate_kind=_estimate_kind(lc, on_search),
                    relaxations=tuple(lc.relaxations), segment_decreases=decreases,
                    certificate=raises, multipliers=tuple((c.name, lam.copy()) for c, lam in zip(al.constraints, al.lam)))


def _estimate_kind(lc: LeastChange, on_search: bool) -> str:
    """What a solve's final estimate is (`Solution.estimate_kind`): "search" where a grid's solve ended on the least
    violation's path, else "refinement" off a grid and "progress" on one."""
    return "search" if on_search else ("refinement" if lc.grid is None else "progress")
