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

A pair the method cannot meet on any frame set (it stalls, and refining the frames no longer cuts the
infeasibility by 10 %) is reported, with
where and by how much, and the lowest priority in the conflict gives (`_relax_unmet`): its broken pairs'
limits are raised to what the path reaches, and its met pairs that hold a broken pair of a higher
priority back give what that pair needs (`_bind_freed`), so the rest of the problem is solved as posed
(`Solution.unmet`, in the constraint's SI unit). The multipliers and the penalty go back
to their values before the stall: on an infeasible problem the first-order estimates of every
constraint in the conflict grow without bound, and carried past the relaxation they would push the path
away from the point the raised limits were read at (safeguarded multipliers, Birgin & Martinez 2014,
sec. 4.1 and ch. 5: bounded estimates keep the method convergent to a least-infeasible point).
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from solver.change import MeasureOfChange
from solver.constraint_set import figure_constraints
from solver.constraints.forces import figure_forces
from solver.contact_schedule import ContactSchedule
from solver.errors import InputError
from solver.figure import Figure
from solver.frames import FrameSet
from solver.inverse_dynamics import InverseDynamics
from solver.kinematic_tree import SiteKinematics
from solver.kinematics import TangentMap
from solver.lagrangian import GAMMA, AugmentedLagrangian, Preconditioner, initial_penalty, solve_subproblem
from solver.layout import StateLayout
from solver.least_change_refine import doerfler_times, predicted_decreases
from solver.manifold import FrameVariables
from solver.optimize import Status
from solver.peak_bounds import peak_bounds
from solver.quadrature import check_points, quadrature_times
from solver.reference import ReferenceMotion
from solver.solution import Round, Solution
from solver.spline_basis import SplineBasis
from solver.subdivide import knot_hint_times

__all__ = ["LeastChange", "LeastChangeOptions", "build_least_change", "solve_least_change"]

#: [m/s^2] gravity's acceleration (standard gravity, CGPM 1901): D0 = m g^2 T makes D dimensionless
STANDARD_GRAVITY = 9.80665
#: a subproblem whose penalty grew stalls when it cut the infeasibility V by under 10 %; two in a row
#: on one frame set send it to refinement, and two more report the pairs as unmet once a refinement no
#: longer cut V by 10 % (and a relaxation after which V did not fall by 10 % by the next passes the next
#: to a higher priority)
STALL_RATIO = 0.9


@dataclass(frozen=True)
class LeastChangeOptions:
    """How the least-change problem is solved (read-only).

    Attributes:
        tol: refinement stops when the decrease of Phi it still predicts is at most tol times Phi's
            nonnegative part (`AugmentedLagrangian.shift`) and every constraint is met (dimensionless;
            1 %: the paper's fig. 5 "good enough" test as a fraction).
        min_gap: [s] no two frames closer: 1/48 s, half a frame of 24 fps film; a cubic spline through
            frames closer than that kinks between them (its second derivative grows like 1/h^2).
        max_subproblems: subproblems in all (each an L-BFGS run), a guard against a method that cycles:
            100, above the most a converging solve was measured to need (24 on the corpus: 83_02 keyed at
            its contacts; 81: a Bandai-Namco walk backwards keyed every 0.2 s, its acceleration limits raised
            one stall at a time, each relaxation and refinement level costing a few).
        per_level: subproblems on one frame set before refining it anyway (the multipliers converge
            linearly; refining is cheaper than more updates on too few frames).
        ftol_rel: each subproblem's relative tolerance on Phi (nlopt's ftol_rel): 1e-3, a subproblem
            need not be solved tightly while its multipliers are still estimates (inexact subproblems,
            Birgin & Martinez 2014, sec. 4.1); a tighter 1e-6 with a cap of 200 evaluations was slower
            and met fewer bounds on the corpus.
        max_evals: evaluations of the whole solve, subproblems and refinement estimates (0: no limit): when
            they are spent the solve ends with the path so far (status MAX_EVALS), as with `max_time_s`.
        max_time_s: [s] stop after this much time in all, keeping the path so far (0: no limit).
        rate: [1/s] quadrature points per second: 200, at least four points in the shortest segment
            (min_gap) for the integrals; penetration holds between them too (its deepest point over each
            interval, `solver.constraints.penetration`).
    """

    tol: float = 1e-2
    min_gap: float = 1.0 / 48.0
    max_subproblems: int = 100
    per_level: int = 8
    ftol_rel: float = 1e-3
    max_evals: int = 0
    max_time_s: float = 0.0
    rate: float = 200.0

    def __post_init__(self):
        if not (isinstance(self.rate, (int, float)) and np.isfinite(self.rate) and self.rate > 0):
            raise InputError(f"LeastChangeOptions.rate must be > 0 points per second, got {self.rate!r}")
        for name in ("tol", "min_gap", "ftol_rel", "max_time_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
                raise InputError(f"LeastChangeOptions.{name} must be a number >= 0, got {v!r}")
        for name in ("max_subproblems", "per_level", "max_evals"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or v < 0:
                raise InputError(f"LeastChangeOptions.{name} must be an integer >= 0, got {v!r}")


@dataclass
class LeastChange:
    """One built least-change problem (`build_least_change`).

    Attributes:
        model: mujoco.MjModel. layout: its StateLayout. figure: its Figure. plain: FrameSet of the plain
        spline through the keyframes (the reference motion). al: the AugmentedLagrangian (D, the
        constraints, multipliers, penalty). relaxations: the `solver.constraint_set.Relaxation`s the
        keyframes force. knots: (r,) [s] times where a contact starts or ends (frames go there first).
    """

    model: object = field(repr=False)
    layout: StateLayout = field(repr=False)
    figure: Figure = field(repr=False)
    plain: FrameSet = field(repr=False)
    al: AugmentedLagrangian = field(repr=False)
    relaxations: tuple = ()
    knots: np.ndarray = field(default_factory=lambda: np.zeros(0))


def build_least_change(model, keyframes, *, contacts=(), flights=None, capture=None, rate: float = LeastChangeOptions.rate,
                       forces: bool = False, peaks=None) -> LeastChange:
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
    Returns:
        LeastChange.
    Raises:
        InputError: fewer than two keyframes.
    """
    if keyframes.count < 2:
        raise InputError(f"{keyframes.source}: a path needs at least two keyframes, got {keyframes.count}")
    layout = StateLayout.from_model(model)
    figure = Figure.from_model(model)
    tmap = TangentMap.from_layout(layout)
    plain = FrameSet.from_keyframes(keyframes, layout.quat_slots)
    t0, t1 = float(plain.times[0]), float(plain.times[-1])
    check_points(t0, t1, rate)
    t, h = quadrature_times(t0, t1, rate)
    reference = ReferenceMotion.from_frames(model, plain, t, np.full(len(t), h))
    if forces or capture is not None:  # the force bounds, or the effort bound of a capture's keyframes
        engine = InverseDynamics(model, figure.contact_sites)
    else:
        engine = SiteKinematics(model, figure.contact_sites) if figure.contact_sites else None
    schedule = ContactSchedule.of(contacts or (), figure.contact_sites)
    flights = tuple(schedule.flights()) if flights is None else tuple(flights)
    constraints, relaxations = figure_constraints(model, figure, reference, plain, tuple(schedule), flights,
                                                  engine, capture=capture)
    if forces:
        if capture is None:
            peak = None
        else:
            peak = (peaks if peaks is not None else peak_bounds(model, plain, capture)).ground_force_bw
        constraints += figure_forces(model, t, flights, peak)
    # the pose part's frequency: the keyframes' own Nyquist frequency (a change slower than the keyframe
    # spacing is priced by its pose, a faster one by its acceleration)
    omega = np.pi / float(np.mean(np.diff(keyframes.times)))
    change = MeasureOfChange(reference, tmap, omega=omega, joints=layout.articulated_dofs)
    d0 = float(np.sum(model.body_mass)) * STANDARD_GRAVITY ** 2 * (t1 - t0)
    al = AugmentedLagrangian(change, constraints, tmap, engine, d0)
    knots = np.array([x for c in schedule for x in (c.start, c.end)], float)
    return LeastChange(model, layout, figure, plain, al, tuple(relaxations), knots)


def _start_frames(lc: LeastChange, min_gap: float) -> FrameSet:
    """The plain spline's frames with variable frames at the contacts' ends and in every segment."""
    frames = lc.plain.with_variable_frames(knot_hint_times(lc.plain, lc.knots, min_gap))
    mids = 0.5 * (frames.times[:-1] + frames.times[1:])
    return _with_frames(frames, mids[np.diff(frames.times) >= 2 * min_gap], lc.layout.quat_slots)


def _start(lc: LeastChange, min_gap: float) -> tuple[FrameSet, SplineBasis]:
    """The starting frames (`_start_frames`) and their SplineBasis; sets the starting penalty rho_0 on
    `lc.al` (`solver.lagrangian.initial_penalty`)."""
    al = lc.al
    frames = _start_frames(lc, min_gap)
    basis = SplineBasis(frames.times, al.t)
    var = FrameVariables(frames, lc.layout.quat_slots)
    al.rho = initial_penalty(al, basis, var, Preconditioner(var, basis, al.change, al.tmap, al.d0))
    return frames, basis


def _with_frames(frames: FrameSet, times: np.ndarray, quat_slots: np.ndarray) -> FrameSet:
    """`frames.with_variable_frames(times)` with every free quaternion made unit: a frame inserted on the
    path takes its chord's shorter quaternion (norm cos(theta/2) between two frames theta apart), and the
    variables move a quaternion on its own sphere (`solver.manifold`), so it would keep that norm."""
    return _unit_quaternions(frames.with_variable_frames(times), quat_slots)


def _unit_quaternions(frames: FrameSet, quat_slots: np.ndarray) -> FrameSet:
    """`frames` with every free quaternion (quat_slots (s, 4)) divided by its norm."""
    values = frames.values.copy()
    for slot in quat_slots:
        free = ~frames.fixed[:, slot].any(axis=1)
        q = values[np.ix_(free, slot)]
        values[np.ix_(free, slot)] = q / np.linalg.norm(q, axis=1, keepdims=True)
    return FrameSet(frames.times, values, frames.fixed, frames.is_keyframe)


class Freed(NamedTuple):
    """Pairs `_relax_unmet` freed for one subproblem (`_bind_freed`): pairs ((constraint index, (p,) mask,
    limit before), ...), targets ((constraint index, (p,) mask), ...) the broken pairs of higher priority
    they held back. Empty: nothing freed."""

    pairs: tuple = ()
    targets: tuple = ()


def _unfree(al: AugmentedLagrangian, freed: Freed) -> None:
    """Put the freed pairs' limits back."""
    for j, _, old in freed.pairs:
        al.constraints[j].limit = old


def _relax_unmet(al: AugmentedLagrangian, basis, frames: FrameSet, scaled: list, before: tuple,
                 above: int | None = None) -> tuple[dict, int | None, Freed]:
    """Let the lowest `Constraint.priority` in the conflict give (module docstring): its broken pairs are
    raised to what the path reaches, and its pairs that hold a broken pair of a higher priority back (met,
    but beyond their limit with their multipliers grown since `before`) are freed for one subproblem
    (their limit +inf, `_bind_freed` then raises it by what the higher ones need).

    The conflict's levels are those broken and, below the highest broken, those holding; `level` is the
    lowest above `above` (the loop passes the priority it let give at the last stall when V has not
    fallen since: letting it give again would not end the conflict; 83_02 at its contacts raised its
    acceleration bounds at 14 stalls in a row while its slide stayed 3.9 tolerances over), else the
    lowest. So the unit-norm bound of the spline's representation gives first, then the bounds set by the
    reference motion (no jolts, effort), the contact schedule's wishes (planted, slide, clearance) next,
    and the limits of the body, the scene and physics (a foot in the floor, a knee bent backwards) last: a
    lexicographic order, as in prioritized inverse kinematics (Kanoun, Lamiraux & Wieber, "Kinematic
    control of redundant manipulators: generalizing the task-priority framework to inequality tasks",
    IEEE T-RO 27, 2011). A met pair counts as well as a broken one: 74_05 keyed every 0.33 s held its
    slide (met) by turning a knee 3.8 degrees off its hinge (broken), and raising the hinge, the broken
    one, put the body's limit below the schedule's wish.

    Args: al: its multipliers after the stall. scaled: (p,) c/tol per constraint on `frames`. before:
        (multipliers, rho) after the last subproblem that still cut V; they go back to these, a raised
        or freed pair's multiplier to 0.
    Returns: ({constraint: largest amount raised [SI]}, the priority let give (None: nothing broken),
        the `Freed` pairs for `_bind_freed`).
    """
    state = al.state(basis, frames.values)
    bad = [ch > 1.0 for ch in scaled]
    hold = [(ch > 0.0) & (ch <= 1.0) & (lam > lam0) for ch, lam, lam0 in zip(scaled, al.lam, before[0])]
    al.lam, al.rho, al.V = [lam.copy() for lam in before[0]], before[1], np.inf
    top = max((c.priority for c, b in zip(al.constraints, bad) if b.any()), default=None)
    levels = [c.priority for c, b, h in zip(al.constraints, bad, hold) if b.any() or (h.any() and top is not None and c.priority < top)]
    level = min((p for p in levels if above is None or p > above), default=min(levels, default=None))
    above_it = [(j, b) for j, (c, b) in enumerate(zip(al.constraints, bad)) if b.any() and c.priority > level]
    unmet, freed = {}, []
    for j, c in enumerate(al.constraints):
        b, h = bad[j], hold[j] if above_it else np.zeros_like(bad[j])
        if c.priority != level or not (b.any() or h.any()):
            continue
        c.limit = c.limit.copy()
        if b.any():
            v = c.values(state)
            unmet[c.name] = max(unmet.get(c.name, 0.0), float(v[b].max()))
            c.limit[b] += v[b]
        if h.any():
            freed.append((j, h, c.limit.copy()))
            c.limit[h] = np.inf
        al.lam[j] = np.where(b | h, 0.0, al.lam[j])
    return unmet, level, Freed(tuple(freed), tuple(above_it)) if freed else Freed()


def _bind_freed(al: AugmentedLagrangian, basis, stalled: FrameSet, solved: FrameSet, freed: Freed,
                quat_slots) -> tuple[FrameSet, dict, int]:
    """Give the freed pairs (`_relax_unmet`) what the broken pairs above them need, no more: along the
    segment from the stalled path to the one solved without them (frame values blended, free quaternions
    made unit), the first path on which those pairs are met (bisection, until the freed pairs' values
    at its ends differ by under their tolerance) becomes the path, and each freed limit the larger of
    its own and what that path reaches. If the solved path does not meet them either, the freed limits go
    back and the solved path stays: the conflict was elsewhere. Returns (frames, {constraint: largest
    amount raised [SI]}, the paths evaluated)."""
    if not freed.pairs:
        return solved, {}, 0
    _unfree(al, freed)
    targets, limits, evaluated = freed.targets, [(al.constraints[j], h, old) for j, h, old in freed.pairs], []

    def at(alpha: float) -> tuple[FrameSet, float, np.ndarray]:
        """The blended path, the worst broken pair's c/tol on it, the freed pairs' c/tol on it."""
        evaluated.append(alpha)
        frames = _unit_quaternions(replace(stalled, values=(1.0 - alpha) * stalled.values + alpha * solved.values),
                                   quat_slots)
        state = al.state(basis, frames.values)
        worst = max(float((al.constraints[j].values(state) / al.constraints[j].tolerance)[b].max()) for j, b in targets)
        return frames, worst, np.concatenate([(c.values(state) / c.tolerance)[h] for c, h, _ in limits])

    (u0, lo), (u1, hi) = (0.0, at(0.0)), (1.0, at(1.0))  # the blend's ends: stalled, solved
    if hi[1] > 1.0:
        return solved, {}, len(evaluated)
    for _ in range(np.finfo(float).nmant):  # until the freed values are read to within their tolerance
        if np.abs(hi[2] - lo[2]).max() <= 1.0:
            break
        mid = 0.5 * (u0 + u1)
        point = at(mid)
        (u0, lo), (u1, hi) = ((u0, lo), (mid, point)) if point[1] <= 1.0 else ((mid, point), (u1, hi))
    frames, state, unmet = hi[0], al.state(basis, hi[0].values), {}
    for c, h, old in limits:
        rise = np.where(h, np.maximum(c.values(state), 0.0), 0.0)
        c.limit = old + rise
        if rise.max() > 0.0:
            unmet[c.name] = max(unmet.get(c.name, 0.0), float(rise.max()))
    return frames, unmet, len(evaluated)


def _merge(unmet: dict, raised: dict) -> None:
    """Add `raised` ({constraint: amount [SI]}) to `unmet`, keeping each constraint's largest amount."""
    for name, amount in raised.items():
        unmet[name] = max(unmet.get(name, 0.0), amount)


def solve_least_change(lc: LeastChange, options: LeastChangeOptions | None = None, *,
                       should_stop: Callable[[], bool] | None = None,
                       progress: Callable[[str, dict], None] | None = None) -> Solution:
    """Solve a built problem by the method of multipliers with adaptive variable frames (module docstring).

    Args:
        lc: from `build_least_change` (its multipliers change). options: LeastChangeOptions.
        should_stop: polled during each subproblem; True ends the solve with the path so far.
        progress: progress(event, info): "round" (a subproblem starts: round, frames, variable), "eval"
            (evals, E = Phi), "constraints" (it ended: round, worst, value as `_worst`, rho: the next
            penalty), "estimate" (round, estimate: the predicted decrease over Phi, tol).
    Returns:
        Solution: frames, initial (the plain spline's), one Round per subproblem, status, E = D/D0 before
        (0) and after, `integrals_*` each constraint's largest c/tol, `unmet` {constraint: amount [SI]}.
    """
    o = options or LeastChangeOptions()
    al, quat, start = lc.al, lc.layout.quat_slots, time.perf_counter()
    frames, basis = _start(lc, o.min_gap)
    rounds, trace, unmet, estimate, decreases, scores = [], [], {}, float("nan"), [], None
    evals, level_its, stall, refined_at, kind, last = 0, 0, 0, None, "start", None
    before, freed, stalled = al.estimates(), Freed(), None  # the multipliers and penalty before a stall
    status, message = Status.CONVERGED, "every constraint met and refinement predicts under tol"
    for k in range(o.max_subproblems):
        left, spent = _budget(o, start, evals)
        if spent:
            _unfree(al, freed)  # the solve ends before a freed pair is bound: its limit goes back
            status, message = spent, _stop_message(spent, "", o)
            break
        if progress:
            progress("round", {"round": k, "frames": frames.count, "variable": frames.n_variable})
        cb = None if progress is None else (lambda n, best, e0=evals: progress("eval", {"evals": e0 + n, "E": best}))
        r = solve_subproblem(al, frames, quat, ftol_rel=o.ftol_rel, basis=basis,
                             max_evals=o.max_evals - evals if o.max_evals else 0,
                             max_time_s=max(left, 0.0), should_stop=should_stop, callback=cb)
        frames, bound, n = _bind_freed(al, basis, stalled, r.frames, freed, quat)
        evals, freed = evals + r.result.n_evals + n, Freed()
        _merge(unmet, bound)
        rounds.append(Round(frames.count, frames.n_variable, r.result, scores, frames.times.copy(), kind))
        trace.append(np.asarray(r.result.trace))
        if r.result.status in (Status.INTERRUPTED, Status.MAX_TIME, Status.NONFINITE, Status.MAX_EVALS):
            status, message = r.result.status, _stop_message(r.result.status, r.result.message, o)
            break
        scaled, V_prev, rho_prev = al.scaled_values(basis, frames.values), al.V, al.rho
        V = al.update(scaled)
        worst = _worst(al, scaled)
        if progress:
            progress("constraints", {"round": k, **worst, "rho": al.rho})
        met = worst["value"] <= 1.0 and V <= 1.0
        stall = stall + 1 if (STALL_RATIO * V_prev < V and al.rho > rho_prev) else 0
        before = al.estimates() if STALL_RATIO * V_prev >= V else before
        level_its, kind, scores = level_its + 1, "boost", None
        if _out_of_reach(stall, refined_at, V):  # raise one priority's limits (_relax_unmet)
            above = last[0] if last and STALL_RATIO * last[1] < V else None
            raised, level, freed = _relax_unmet(al, basis, frames, scaled, before, above)
            stalled, stall, refined_at, last = frames, 0, None, (level, V)
            _merge(unmet, raised)
            continue
        if not (met or stall >= 2 or level_its >= o.per_level):
            continue
        refined_at = V if stall >= 2 else refined_at  # a stall refines while refining still cuts V
        new, estimate, dec = _refinement(al, frames, quat, o, k, progress)
        decreases.append((frames.times.copy(), dec))
        evals += 3
        if met and estimate <= o.tol:
            message = (f"refinement estimate {estimate:.3g} <= tol {o.tol:g}, every constraint met"
                       + (" within reach" if unmet else ""))
            break
        if new.size == 0:
            if met or stall >= 2:
                message = "no segment predicts a decrease" if met else "constraints left unmet"
                break
            continue
        frames, scores = _with_frames(frames, new, quat), dec
        basis = SplineBasis(frames.times, al.t)
        al.rho /= GAMMA if stall >= 2 else 1.0  # a stalled penalty starts the finer frames one step softer
        stall, level_its, kind = 0, 0, "refine"
    else:
        status, message = Status.MAX_EVALS, f"{o.max_subproblems} subproblems without converging"
    return _solution(lc, frames, basis, rounds, trace, status, message, evals, unmet, time.perf_counter() - start,
                     estimate, o.tol, tuple(decreases))


def _budget(o: LeastChangeOptions, start: float, evals: int) -> tuple[float, Status | None]:
    """([s] the time left of `o.max_time_s` (0: no limit), the status that ends the solve before its next
    subproblem: MAX_TIME or MAX_EVALS when that budget is spent, else None)."""
    left = o.max_time_s - (time.perf_counter() - start) if o.max_time_s else 0.0
    if o.max_time_s and left <= 0:
        return left, Status.MAX_TIME
    return left, Status.MAX_EVALS if o.max_evals and evals >= o.max_evals else None


def _out_of_reach(stall: int, refined_at: float | None, V: float) -> bool:
    """Whether the broken pairs are out of reach: the solve stalled twice in a row (`stall`) on frames
    refined at a stall since the last relaxation, and that refinement did not cut the infeasibility V by
    10 % (`refined_at`: V at the stall that sent it to refinement, None if none did; STALL_RATIO). While
    refining still helps, frames where the pairs are broken may be all the path lacks (docs/solvers.md)."""
    return stall >= 2 and refined_at is not None and STALL_RATIO * refined_at < V


def _worst(al: AugmentedLagrangian, scaled: list) -> dict:
    """{"worst": the name of the constraint furthest over its tolerance ("" without one), "value": its
    largest c/tol (met at <= 1)}."""
    value, name = max(((float(s.max()), c.name) for c, s in zip(al.constraints, scaled) if s.size), default=(0.0, ""))
    return {"worst": name, "value": value}


def _stop_message(status: Status, message: str, o: LeastChangeOptions) -> str:
    """Why a solve ended on `status`: the whole solve's budget for MAX_TIME and MAX_EVALS (a subproblem
    reports only its own share), else the subproblem's `message`."""
    if status is Status.MAX_TIME:
        return f"time limit of {o.max_time_s:g} s reached"
    if status is Status.MAX_EVALS:
        return f"evaluation budget of {o.max_evals} spent"
    return message


def _refinement(al, frames, quat, o: LeastChangeOptions, k: int, progress) -> tuple[np.ndarray, float, np.ndarray]:
    """(times of new variable frames, the predicted decrease of Phi over Phi + shift, (m - 1,) each segment's
    predicted decrease) on `frames`."""
    dec, phi = predicted_decreases(al, frames, quat, o.min_gap)
    estimate = float(dec.sum() / max(phi + al.shift(), 1e-300))  # Phi itself can be <= 0 (PHR)
    if progress:
        progress("estimate", {"round": k, "estimate": estimate, "tol": o.tol})
    return doerfler_times(dec, frames), estimate, dec


def _solution(lc, frames, basis, rounds, trace, status, message, evals, unmet, seconds, estimate, tol,
              decreases=()) -> Solution:
    """The Solution of a solve (`solve_least_change`'s Returns)."""
    al = lc.al
    plain_basis = SplineBasis(lc.plain.times, al.t)
    _, _, D = al.evaluate(basis, frames.values, grad=False)

    def worst(b, P):
        return {c.name: float(s.max()) if s.size else 0.0 for c, s in zip(al.constraints, al.scaled_values(b, P))}

    if unmet:  # the limits were raised to what the path reaches
        message += "; out of reach (limit raised by [SI]): " + ", ".join(f"{k} {v:.3g}" for k, v in unmet.items())
    return Solution(frames, lc.plain, tuple(rounds), status, message, 0.0, D / al.d0,
                    worst(plain_basis, lc.plain.values), worst(basis, frames.values), {},
                    np.concatenate(trace) if trace else np.zeros(0), seconds, evals, unmet=dict(unmet),
                    converged_to_tol=bool(status is Status.CONVERGED and np.isfinite(estimate) and estimate <= tol
                                          and not unmet),
                    final_estimate=estimate, relaxations=tuple(lc.relaxations), segment_decreases=decreases)
