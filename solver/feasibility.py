"""The least violation: how far no path through the keyframes can meet each constraint, shown by a solve.

Before the least change is solved (`solver.least_change`), the constraints' violation itself is
minimized over the same paths (the frames' free values, the keyframes fixed), the elastic problem of
SQP methods (Gill, Murray & Saunders, "SNOPT: an SQP algorithm for large-scale constrained
optimization", SIAM Review 47, 2005, sec. 1.3: when no feasible point is found, the sum of the
violations is minimized instead):

    feasible?             F_S(P) = (1/2) sum_{j in S} sum_p (w_p/T) max(0, c_p/tol_j - aim)^2,  aim = 1 - ftol_rel
    what must give?       F_S(P) = sum_{j in S} sum_p (w_p/T) huber(max(0, c_p/tol_j - 1/2)),
                          huber(v) = v^2 for v <= 1/2,  v - 1/4 beyond   (Huber, Ann. Math. Statist. 35, 1964)

A pair is met at c_p/tol_j <= 1. Whether every pair can be met (step 1 below) is asked of the squares,
which are 0 exactly where every pair is within its aim, ftol_rel of a tolerance inside the edge (so that
a descent that approaches the edge from outside and stops once an iteration gains less than ftol_rel
stops inside it), and smooth, which L-BFGS reaches fastest. Which pairs must give, and by how much (step
2), is asked of the sum of the violations beyond the tolerances' edges (SNOPT's l1 elastic objective),
smoothed over each tolerance's outer half (counted from its middle, `RAISED_AT`, where a raised pair is
held). A sum raises only the pairs that must give; the squares spread a violation: their gradient grows
with it, so their minimum buys a little off a large violation with small ones wherever a pair can take
some, and another spacing of frames, landing elsewhere on that spread, beats the small raises (keyed
every 0.25 s, the unseen bvh_test1's right shoulder, 74.7 rad/s^2 beyond its no-jolt peak, and its
effort, 4.96 N m, beside the right elbow's 3.08e3 rad/s^2; at 1/96 s the shoulder was not raised). Under
the sum, a pair traded against one that gives at a higher price stops where its slope equals the price
ratio, inside its tolerance's outer half: it is not raised. (The sum asked whether every pair can be met
was slower and less sure of it on the shipped keyed corpus: 20 % more evaluations, and two pairs that meet
every constraint, 74_05 and 75_03 every 0.25 s, certified limits again.)
Either way a pair the least change met counts for nothing, so a solve's relative progress, on which
L-BFGS stops (`ftol_rel`), is the broken pairs' alone. (Counted from c_p = 0, where the least change aims,
the met pairs made most of F: on 83_02's clean the first solve stopped after 4 evaluations, F down 0.15 %,
and the search certified 3.4 mm of slide; counted from the edge, the same solve met every pair in 563.)

1. **Every constraint at once** (S = all): an L-BFGS solve from the given path, stopped as soon as
   every pair is within its tolerance and started again from its end while a run gains more than
   ftol_rel of F (`_elastic_solve`), with a variable frame added to every segment that holds a broken
   pair while the segment can take one (`min_gap`: the least change passes two quadrature intervals, the
   shortest segment whose acceleration, linear in time, two of its points fix; a finer spacing needs a finer
   quadrature: `solver.animate.solve_problem` checks a certificate at twice the rate), and solved again. Where this meets every pair the
   problem is feasible: nothing is raised.
2. **Else level by level** (`Constraint.priority`: the limits of the body and the scene first, then the
   bounds on what the reference motion's body does, the contact schedule's wishes, and the unit-norm
   bound of the spline's representation last): the level's violation F_S is minimized while every pair of
   the levels above holds the limit certified for it (a quadratic penalty raised until they do,
   `_elastic_solve`), with the same refinement. What is left is the least violation: each pair still
   beyond its tolerance has its limit raised by its value there less half its tolerance, and the next level
   holds it: the path that reaches the least violation then holds the pair in the middle of its tolerance.
   The least change aims every pair at its limit and accepts it within its tolerance; a pair at its least
   violation cannot reach the limit, so it needs slack inside the tolerance (raised to just below the edge,
   the least change stalled there) and no more than half of one outside it (raised by the whole value, it
   could end a whole tolerance beyond the least violation). This is the
   lexicographic order of prioritized inverse kinematics (Kanoun, Lamiraux & Wieber, "Kinematic control
   of redundant manipulators: generalizing the task-priority framework to inequality tasks", IEEE T-RO 27,
   2011): a lower level never costs a higher one anything.

F is not convex in the frames, so a search reaches a least violation of its start's basin. When the
keyframes came from a capture, the capture is a second start (`capture_start`: a path through the
keyframes at the search's finest spacing): both are searched, every constraint at once and level by
level (each level from the paths that meet the limits certified above it), and the lower F is certified.

The path reached meets every certified limit, so the least change that follows is feasible and starts
on a feasible path. The certificate (`Certificate.raises`) says per constraint and column (a site, a
joint) by how much [SI], where and over which span the limit was raised.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from solver.frames import FrameSet
from solver.lagrangian import GAMMA, AugmentedLagrangian, frame_maps, solve_subproblem
from solver.optimize import Status
from solver.spline_basis import SplineBasis

#: [1] where the search's path holds a raised pair, in tolerances beyond its new limit: the middle of its tolerance,
#: room either way for the least change that follows (it aims at the limit and accepts within the tolerance)
RAISED_AT = 0.5

__all__ = ["Certificate", "Raise", "beyond", "capture_start", "least_violation", "on_points", "still_raised", "with_frames"]




@dataclass(frozen=True)
class Raise:
    """The pairs of one constraint at one column whose limit the least violation raised (read-only).

    Attributes:
        constraint: the constraint's name. label: its column (a contact site, a joint, "" for one column).
        amount: [SI] the largest raise, the least violation reached at `time` [s].
        start, end: [s] the first and last quadrature point raised. pairs: how many pairs were raised.
        unit, scale: the unit shown to users and SI per shown unit (1e-3 for mm).
    """

    constraint: str
    label: str
    amount: float
    time: float
    start: float
    end: float
    pairs: int
    unit: str = ""
    scale: float = 1.0

    def describe(self) -> str:
        """e.g. "penetration at rtoe 4.2 mm at 1.350 s (1.32-1.38 s)"."""
        where = f" at {self.label}" if self.label else ""
        return (f"{self.constraint}{where} {self.amount / self.scale:.3g} {self.unit} at {self.time:.3f} s"
                f" ({self.start:.3g}-{self.end:.3g} s)").replace("  ", " ")


@dataclass(frozen=True)
class Certificate:
    """The outcome of `least_violation` (read-only).

    Attributes:
        raises: (Raise, ...) per constraint and column raised; () when the problem is feasible.
        frames: the path that reaches the least violation (it meets every certified limit).
        n_evals: evaluations spent. status: CONVERGED, or the budget or stop request that ended it early.
        start: which start `frames` descends from (0: the given frames, 1: the second, `least_violation`).
    """

    raises: tuple = ()
    frames: FrameSet | None = field(default=None, repr=False)
    n_evals: int = 0
    status: Status = Status.CONVERGED
    start: int = 0

    @property
    def unmet(self) -> dict:
        """{constraint: the largest raise [SI]} ({} when nothing was raised)."""
        out: dict = {}
        for r in self.raises:
            out[r.constraint] = max(out.get(r.constraint, 0.0), r.amount)
        return out


def on_points(times: np.ndarray, points: np.ndarray, frames: FrameSet) -> np.ndarray:
    """New variable-frame times moved each to the nearest quadrature point, those falling on a frame dropped.

    The acceleration of a cubic spline is linear in time on each segment, so its extremes are at the
    frames: a frame on a quadrature point is where the bounds on acceleration (no jolts) see the path's
    hardest acceleration, not a point up to half an interval from it.

    Args:
        times: (r,) [s] times for new frames. points: (n,) [s] the quadrature points, increasing.
        frames: FrameSet (m, nq) the frames so far.
    Returns:
        (r',) [s] sorted distinct quadrature points, none a frame's time.
    """
    times = np.asarray(times, float)
    if times.size == 0:
        return times
    i = np.clip(np.searchsorted(points, times), 1, len(points) - 1)
    snapped = np.unique(np.where(times - points[i - 1] <= points[i] - times, points[i - 1], points[i]))
    # [s] a point within round-off of a frame is that frame (times are sums of the same float steps)
    return snapped[np.min(np.abs(snapped[:, None] - frames.times[None]), axis=1) > 1e-12]


def with_frames(frames: FrameSet, times: np.ndarray, quat_slots: np.ndarray) -> FrameSet:
    """`frames.with_variable_frames(times)` with every free quaternion made unit: a frame inserted on the
    path takes its chord's shorter quaternion (norm cos(theta/2) between two frames theta apart), and the
    variables move a quaternion on its own sphere (`solver.manifold`), so it would keep that norm."""
    frames = frames.with_variable_frames(times)
    values = frames.values.copy()
    for slot in quat_slots:
        free = ~frames.fixed[:, slot].any(axis=1)
        q = values[np.ix_(free, slot)]
        values[np.ix_(free, slot)] = q / np.linalg.norm(q, axis=1, keepdims=True)
    return FrameSet(frames.times, values, frames.fixed, frames.is_keyframe)


class _Budget:
    """The evaluations and time left of a solve, and its stop request."""

    def __init__(self, max_evals: int, max_time_s: float, should_stop, callback=None):
        self.max_evals, self.max_time_s, self.should_stop, self.callback = max_evals, max_time_s, should_stop, callback
        self.start, self.evals, self.status = time.perf_counter(), 0, Status.CONVERGED

    def spent(self) -> bool:
        """Whether the solve's budget is spent (`status` says which)."""
        if self.max_time_s and time.perf_counter() - self.start >= self.max_time_s:
            self.status = Status.MAX_TIME
        elif self.max_evals and self.evals >= self.max_evals:
            self.status = Status.MAX_EVALS
        return self.status is not Status.CONVERGED

    def kwargs(self, done) -> dict:
        """`solve_subproblem`'s budget arguments; `done()` True (every pair met) also ends it. The solve's
        `callback(n, F)` gets the search's evaluations so far (n) and each evaluation's F."""
        left = self.max_time_s - (time.perf_counter() - self.start) if self.max_time_s else 0.0
        user = self.should_stop or (lambda: False)
        spent, report = self.evals, self.callback
        return {"max_evals": max(self.max_evals - self.evals, 1) if self.max_evals else 0,
                "max_time_s": max(left, 0.0), "should_stop": lambda: done() or user(),
                "callback": report and (lambda n, F: report(spent + n, F))}


def _scaled(constraints, state) -> list[np.ndarray]:
    return [c.values(state) / c.tolerance for c in constraints]


def _broken_times(al: AugmentedLagrangian, constraints, state) -> np.ndarray:
    """(r,) [s] the quadrature times of the pairs of `constraints` beyond their tolerance."""
    rows = [c.rows[c.values(state) / c.tolerance > 1.0] for c in constraints]
    rows = np.concatenate(rows) if rows else np.zeros(0, int)
    return al.t[np.unique(rows)]


def _split_times(frames: FrameSet, at: np.ndarray, min_gap: float) -> np.ndarray:
    """The midpoints of the segments of `frames` that hold a time of `at` and are at least 2 min_gap long."""
    if at.size == 0:
        return np.zeros(0)
    seg = np.unique(np.clip(np.searchsorted(frames.times, at, side="right") - 1, 0, frames.count - 2))
    seg = seg[np.diff(frames.times)[seg] >= 2.0 * min_gap]
    return 0.5 * (frames.times[seg] + frames.times[seg + 1])


def _elastic_solve(al: AugmentedLagrangian, objective: list, held: list, frames: FrameSet, quat_slots,
                   budget: _Budget, min_gap: float, ftol_rel: float, per_level: int, pairs: int | None,
                   level: bool = True, maps=frame_maps) -> FrameSet:
    """Minimize F over `objective` while `held` meet their limits (module docstring; `level`: F the sum of
    the violations, else the squares of step 1), adding a variable frame to every segment holding a broken
    pair of `objective` while one fits; returns the path with the least F among those on which `held` are
    met (the start is one; a path refined after it, which moves between its old frames, only where it still
    meets them).

    The held pairs are priced by the quadratic penalty (rho/2) sum (w_p/T) max(0, c_p/tol)^2,
    starting at rho = 1 (a held pair's violation costs what an objective pair's does) and raised by GAMMA
    until a solve from the start (which meets them) ends with them met: the penalty method's continuation
    (Nocedal & Wright, sec. 17.1), each solve from the feasible start so that none wanders into a basin
    where the held pairs cannot be met again. A solve that meets the held pairs and lowers F by more than
    ftol_rel is started again from where it ended, with a fresh L-BFGS memory (a restart: Nocedal & Wright,
    sec. 7.2), until one gains no more than that or `per_level` solves are spent: an L-BFGS run stops when
    one of its iterations gains less than ftol_rel, which a badly scaled stretch of the descent does long
    before F is stationary, and a limit is raised only where a fresh descent no longer helps."""
    eal = AugmentedLagrangian(al.change, held, al.tmap, al.engine, al.d0, elastic=objective, base=al.base,
                              **_measure(level, ftol_rel))
    basis, pre = maps(al, frames, quat_slots)
    best, best_F = frames, eal.evaluate(basis, frames.values, grad=False)[0]
    witness = frames  # the last path found on which `held` are met: the start, then each better one

    def held_met_on(fr, b) -> bool:
        return all(float(s.max(initial=0.0)) <= 1.0 for s in eal.scaled_values(b, fr.values))

    def answer() -> FrameSet:  # a refined path moves between its old frames: it may break a held pair
        return best if best is witness or held_met_on(best, basis) else witness

    while True:
        eal.rho, eal.lam = 1.0, [np.zeros(c.size) for c in held]
        for _ in range(per_level):
            if best_F == 0.0 or budget.spent():
                return answer()
            r = solve_subproblem(eal, best, quat_slots, ftol_rel=ftol_rel, basis=basis, pre=pre, pairs=pairs,
                                 **budget.kwargs(lambda: eal.worst <= 1.0))
            budget.evals += r.result.n_evals
            if r.result.status is Status.INTERRUPTED and budget.should_stop is not None and budget.should_stop():
                budget.status = Status.INTERRUPTED
            F = eal.evaluate(basis, r.frames.values, grad=False)[0]
            every_met = eal.worst <= 1.0  # set by the evaluation: the objective's pairs and the held ones
            held_met = held_met_on(r.frames, basis)
            gained = held_met and (1.0 - ftol_rel) * best_F > F
            if held_met and best_F > F:
                best, best_F, witness = r.frames, F, r.frames
            if budget.spent() or every_met or (held_met and not gained):
                break
            if not held_met:  # else a restart at the same penalty
                eal.rho *= GAMMA
        if budget.spent():
            return answer()
        new = on_points(_split_times(best, _broken_times(al, objective, eal.state(basis, best.values)), min_gap),
                        al.t, best)
        if new.size == 0:
            return answer()
        best = with_frames(best, new, quat_slots)
        basis, pre = maps(al, best, quat_slots)
        best_F = eal.evaluate(basis, best.values, grad=False)[0]


def beyond(al: AugmentedLagrangian, constraints, frames: FrameSet, limits=None) -> list[Raise]:
    """The pairs of `constraints` beyond their tolerance on the path of `frames`, per constraint and column.

    Args:
        al: the AugmentedLagrangian (its quadrature points and engine). constraints: the `Constraint`s.
        frames: FrameSet (m, nq). limits: per constraint (p,) [SI] limits to measure against (None: their
            own `limit`).
    Returns:
        [Raise, ...]: the largest amount c = measure - limit [SI] of each column beyond its tolerance, where.
    """
    state = al.state(SplineBasis(frames.times, al.t), frames.values)
    out = []
    for j, c in enumerate(constraints):
        m, lim = c.measure(state), np.broadcast_to(c.limit if limits is None else limits[j], (c.size,))
        v = m - lim
        bad = v / c.tolerance > 1.0
        labels = np.asarray(c.labels, object) if len(c.labels) == c.size else np.full(c.size, "", object)
        for label in dict.fromkeys(labels[bad]):
            at = bad & (labels == label)
            i = np.flatnonzero(at)[np.argmax(v[at])]
            t = al.t[c.rows[at]]
            amount = float(c.excess(m, lim, np.array([i]))[0])  # [SI] the quantity's own excess
            out.append(Raise(c.name, str(label), amount, float(al.t[c.rows[i]]), float(t.min()), float(t.max()),
                             int(at.sum()), c.column_unit(str(label)), c.scale))
    return out


def still_raised(certified: list, final: list) -> list:
    """The certified `Raise`s whose column (constraint, label) the final path is beyond as posed (`final`,
    `beyond`), each at the smaller of the two amounts: the certificate's least
    violation, or less where the path needs less; a column the path meets as posed is not raised."""
    out = {(r.constraint, r.label): r for r in final}
    return [r if r.amount <= out[(r.constraint, r.label)].amount else out[(r.constraint, r.label)]
            for r in certified if (r.constraint, r.label) in out]


def _raise(al: AugmentedLagrangian, constraints, frames: FrameSet) -> list[Raise]:
    """Raise the limit of every pair of `constraints` beyond its tolerance on `frames` by its value there (the
    least violation reached) less `RAISED_AT` of its tolerance, so that the path reaching the least violation holds the
    pair in the middle of its raised tolerance (module docstring), and describe what was raised (`beyond`:
    each amount the least violation from the limit as posed)."""
    out = beyond(al, constraints, frames)
    state = al.state(SplineBasis(frames.times, al.t), frames.values)
    for c in constraints:
        v = c.values(state)
        tol = np.broadcast_to(c.tolerance, v.shape)
        c.limit = c.limit + np.where(v / tol > 1.0, v - RAISED_AT * tol, 0.0)
    return out


def capture_start(plain: FrameSet, capture, points: np.ndarray, gap: float, quat_slots) -> FrameSet:
    """The capture the keyframes came from as a path through them: a second start for `least_violation`.

    The keyframes were taken from the capture, so it passes through (or within its own sampling of) every
    one: with variable frames on the quadrature points, `gap` apart as the search's finest spacing, valued
    on the capture (linear between its samples, each quaternion made unit and put on the plain spline's
    hemisphere), the keyframes fixed as they are, it is a path of the search's space whose violation is
    about the capture's own, reached by no descent from the least change's path.

    Args:
        plain: FrameSet (k, nq) of the keyframes. capture: (times (n,) [s], qpos (n, nq)), increasing times.
        points: (p,) [s] the quadrature points, increasing. gap: [s] the least spacing of two frames.
        quat_slots: (s, 4) the layout's quaternion slots.
    Returns:
        FrameSet (k + r, nq): the keyframes and r variable frames.
    """
    keys, new = plain.times, []
    last = keys[0]
    for t in points:
        i = int(np.searchsorted(keys, t, side="right"))
        last = max(last, keys[i - 1])
        # [s] round-off: the points are sums of the same float step, so a spacing of exactly gap may read 1 ulp under
        if i < len(keys) and t - last >= gap - 1e-12 and keys[i] - t >= gap - 1e-12:
            new.append(t)
            last = t
    frames = plain.with_variable_frames(np.array(new))
    times, qpos = (np.asarray(a, float) for a in capture)
    sampled = np.stack([np.interp(frames.times, times, q) for q in qpos.T], axis=1)
    for slot in quat_slots:  # unit, on the side of the plain spline's quaternion at the same time
        q = sampled[:, slot] / np.linalg.norm(sampled[:, slot], axis=1, keepdims=True)
        sampled[:, slot] = q * np.where(np.sum(q * frames.values[:, slot], axis=1) < 0, -1.0, 1.0)[:, None]
    values = frames.values.copy()
    values[frames.free] = sampled[frames.free]
    return FrameSet(frames.times, values, frames.fixed, frames.is_keyframe)


def _meets(al: AugmentedLagrangian, constraints, frames: FrameSet) -> bool:
    """Whether every pair of `constraints` is within its tolerance on the path of `frames`."""
    state = al.state(SplineBasis(frames.times, al.t), frames.values)
    return all(float(s.max(initial=0.0)) <= 1.0 for s in _scaled(constraints, state))


def _measure(level: bool, ftol_rel: float) -> dict:
    """The elastic measure's arguments (`AugmentedLagrangian`'s aim, elastic_sum): a level's, the sum of the
    violations from the middle of the tolerance; step 1's, their squares from ftol_rel inside its edge."""
    return dict(aim=RAISED_AT, elastic_sum=True) if level else dict(aim=1.0 - ftol_rel, elastic_sum=False)


def _violation(al: AugmentedLagrangian, constraints, frames: FrameSet) -> float:
    """A level's F over `constraints` (module docstring) on the path of `frames`."""
    eal = AugmentedLagrangian(al.change, [], al.tmap, al.engine, al.d0, elastic=constraints, base=al.base,
                              **_measure(True, 0.0))
    return eal.evaluate(SplineBasis(frames.times, al.t), frames.values, grad=False)[0]


def least_violation(al: AugmentedLagrangian, frames: FrameSet, quat_slots, *, min_gap: float, ftol_rel: float,
                    per_level: int, second: FrameSet | None = None, max_evals: int = 0, max_time_s: float = 0.0,
                    should_stop=None, pairs: int | None = None, callback=None, maps=frame_maps) -> Certificate:
    """The least violation of the constraints over the paths through the keyframes (module docstring).

    Args:
        al: the least change's AugmentedLagrangian (its constraints; the limits of those that cannot be
            met are raised in place, `Constraint.limit`). frames: the start FrameSet (m, nq).
        quat_slots: (s, 4) the layout's quaternion slots. min_gap: [s] no two frames closer.
        ftol_rel: each L-BFGS solve's relative tolerance. per_level: the most L-BFGS solves (restarts and
            penalty raises, `_elastic_solve`) per level and frame set. second: None, or a second start FrameSet (m', nq)
            through the same keyframes (`capture_start`): each level is searched from both paths that meet
            the limits certified so far, and the lower F is certified. max_evals, max_time_s, should_stop:
            the solve's budget (0: none; spent, the Certificate's status says so). pairs: L-BFGS correction
            pairs of each solve (None: by size, `solver.optimize.lbfgs_storage`). callback: None, or
            f(n, F) after each evaluation: the search's evaluations so far and that evaluation's F (progress).
        maps: maps(al, frames, quat_slots) -> (SplineBasis, preconditioner) of each frame set searched
            (`solver.lagrangian.frame_maps`; a grid's: `solver.grid_preconditioner.grid_maps`).
    Returns:
        Certificate: what was raised, the path that reaches it, the evaluations spent.
    """
    budget = _Budget(max_evals, max_time_s, should_stop, callback)
    cons = list(al.constraints)
    kw = dict(budget=budget, min_gap=min_gap, ftol_rel=ftol_rel, per_level=per_level, pairs=pairs, maps=maps)
    paths = [(0, _elastic_solve(al, cons, [], frames, quat_slots, level=False, **kw))]
    if second is not None and not _meets(al, cons, paths[0][1]):  # the second start only where the first falls short
        paths.append((1, _elastic_solve(al, cons, [], second, quat_slots, level=False, **kw)))
    met = [(i, p) for i, p in paths if _meets(al, cons, p)]
    if budget.status is not Status.CONVERGED or met:
        i, p = (met or paths)[0]
        return Certificate((), p, budget.evals, budget.status, i)
    raises: list[Raise] = []
    for level in sorted({c.priority for c in cons}, reverse=True):
        objective = [c for c in cons if c.priority == level]
        held = [c for c in cons if c.priority > level]
        kept = [(i, p) for i, p in paths if _meets(al, held, p)]
        if not kept:  # none meets what is certified (round-off at a held pair's edge): the last certified path stands
            break
        paths = [(i, _elastic_solve(al, objective, held, p, quat_slots, **kw)) for i, p in kept]
        if budget.status is not Status.CONVERGED:
            break
        # the lower F is certified; the other path goes on while it meets what that certifies
        paths.sort(key=lambda ip: _violation(al, objective, ip[1]))
        raises += _raise(al, objective, paths[0][1])
    return Certificate(tuple(raises), paths[0][1], budget.evals, budget.status, paths[0][0])
