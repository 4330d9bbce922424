"""Covariant interpolation of one orientation (paper sec. 3): keyframe quaternions in, a smooth path out.

The path is the natural cubic spline through the keyframes and variable frames in R^4 (the figure's
`FrameSet`, `Objective`, `solve`); the optimizer moves the variable frames to minimize angular
acceleration. Two objective forms:

- ``"paper"`` (eq. 9): f = lambda f1 + f2 with f1 = (1 - q.q)^2 and f2 = |q'' - q (q''.q)/(q.q)|^2 on
  the spline's own q, renormalized (eq. 7) with the paper's ratio 2:5 by the integrals on the paper's
  starting path (`RENORMALIZE_ON`). A polynomial spline cannot stay on the unit sphere (between frames
  theta apart on S^3 it dips by about theta^2/8), and shrinking q lowers this f2, so the optimum trades
  the orientation's smoothness for |q| near 1, by an amount the weights set.
- ``"normalized"`` (default, beyond the paper): f2 is the covariant acceleration of u = q/|q|, the
  orientation actually shown (MuJoCo normalizes too; `NormalizedCovariantAcceleration`), and a light
  f1 only holds the scale of q near 1. Its exact-unit limit is the natural Riemannian cubic spline on
  S^3 (Noakes, Heinzinger & Paden 1989), and the optimized path converges to it as frames are added.

docs/orient.md has the measurements behind the default (gap to the exact optimum and |q| drift of both
forms against the number of variable frames).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from solver.errors import InputError
from solver.frames import FrameSet
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.objective import Objective
from solver.paper.error_estimate import estimate_gap
from solver.paper.orient_refine import (  # noqa: F401  (measures re-exported: orient.covariant_energy, ...)
    GapToOptimum,
    covariant_energy,
    max_norm_deviation,
    unit_rows,
)
from solver.paper.solve import DEFAULT_ROUNDS as SOLVE_ROUNDS
from solver.paper.solve import Solution, SolveOptions, solve
from solver.quadrature import GAUSS_POINTS
from solver.subdivide import global_times
from solver.terms import CovariantAcceleration, NormalizedCovariantAcceleration, UnitQuaternion

FORMS = ("normalized", "paper")

#: [1] f1 weight of the normalized form, in units of the mean keyframe interval: lambda_1 = UNIT_WEIGHT /
#: mean(dt)^4 [1/s^4], so that re-timing the keyframes (all times times c) gives the same path re-timed.
#: f2 does not depend on |q| in this form, so f1 only picks the scale of the variable frames; small
#: enough not to pull the orientation (docs/orient.md, trade-off table), large enough to hold |q| near 1.
UNIT_WEIGHT = 0.1

#: [1] The paper's weights (sec. 3, figure 9): lambda_1 : lambda_2 = 2 : 5 on renormalized terms (eq. 7).
PAPER_WEIGHTS = (2.0, 5.0)

#: Uniform quadrature (`rate=` given, or `default_rate`): at least MIN_RATE points per second [Hz], and at
#: least MIN_POINTS_PER_KEY_INTERVAL points [1] in the shortest keyframe interval (so a frame inserted
#: there is determined by the integral).
MIN_RATE = 40.0
MIN_POINTS_PER_KEY_INTERVAL = 32

#: [1] Curvature the preconditioner assumes along each variable frame's radial direction, relative to the
#: tangential ones (`SolveOptions.radial_weight`), per form: the normalized form's f2 does not see the
#: scale of q, only the light f1 does (0.03-0.1 need 25-40% fewer evaluations than 1 for the same result,
#: 0.01 is worse again; docs/orient.md); the paper form's f2 falls as q shrinks, so it assumes nothing
#: (`SolveOptions`' default, 1: every direction alike).
RADIAL_WEIGHTS = {"normalized": 0.1, "paper": SolveOptions.radial_weight}

#: The path eq. 7 renormalizes on ("the initial state before any optimization has taken place"), unless
#: `orient(renormalize=...)` says otherwise: "start", the paper's starting path (sec. 3: "Initially, we
#: had one variable point between any two key frames"), with that frame at each keyframe interval's
#: midpoint and, as `orient` starts its frames, on the unit sphere. It is the same path whatever frames
#: the solve then uses, so the objective is one function of the keyframes and adding frames converges
#: to its optimum. The other reading, "keyframes" (the plain spline through the keyframes alone; the two
#: coincide if the variable frames start on that spline, as the paper's may have), divides f1 by an
#: integral 50-130x larger on the test sets: the plain spline dips by ~theta^2/8 between keyframes theta
#: apart on S^3 and f1 grows as the dip squared. With 2:5 the unit term is then so weak that |q| drifts
#: by 0.41% on the moderate set and 12-27% on large rotations ("start": 0.02% and 0.1-0.6%). The paper
#: reports |q| within 0.2% with 2:5 (figure 9); docs/orient.md has both, measured.
RENORMALIZE_ON = "start"

#: [rounds] Adaptive rounds by default, per form (fixed rounds: the paper form, or the normalized form
#: with tol=0). The paper form's unit term, renormalized on the paper's start path, is stiff (|q| within
#: 0.02-0.7% on the test sets), and a stiff unit term needs more frames for the same gap: after two
#: rounds the moderate set's gap is 8.3e-3, after three 6.3e-5 (the large sets: 1.1-3.0e-4;
#: docs/orient.md); the normalized form takes `solve`'s default.
DEFAULT_ROUNDS = {"normalized": SOLVE_ROUNDS, "paper": 3}

#: [1] Default accuracy of the normalized form, a relative gap (docs/orient.md "Accuracy on request: tol and the gap
#: estimate"): adaptive rounds until the estimated relative gap
#: (E - E*)/E* (`solver.paper.error_estimate.estimate_gap`) is at most DEFAULT_TOL / TOL_SAFETY. It replaces a
#: fixed number of rounds (DEFAULT_ROUNDS, still the paper form's default: its optimum is not E*).
DEFAULT_TOL = 1e-3

@dataclass(frozen=True)
class OrientOptions(SolveOptions):
    """SolveOptions as `orient` reads them: with refine "tol", `tol` is the estimated relative gap
    (E - E*)/E* to reach (`estimate_gap`, `solver.paper.orient_refine.GapToOptimum`): refine and re-optimize
    until it is at most tol, or the frame budget (`max_frames`, default TOL_FRAMES_PER_INTERVAL per
    keyframe interval) or the time budget (`max_time_s`) runs out. refine "rounds": a fixed number of
    adaptive `rounds` instead.
    """


LAYOUT = StateLayout.single_quaternion()


def default_options(form: str = "normalized", **changes) -> OrientOptions:
    """The solve options `orient` uses unless given others: one variable frame per keyframe interval, then
    rounds of adaptive subdivision ranked by predicted decrease (`predicted_decreases`), preconditioned
    L-BFGS, ftol_rel `solver.optimize.FTOL_REL` (`SolveOptions`' default). Normalized form: refine
    "tol", rounds until the estimated gap is at most DEFAULT_TOL (`OrientOptions.tol`), unless `rounds` is given (then refine "rounds": that many rounds)
    or the subdivision is not adaptive; paper form: refine "rounds", DEFAULT_ROUNDS rounds. A `tol` > 0
    selects refine "tol". Keyword arguments override fields (`OrientOptions`; `rounds=None` is taken
    as not given). `orient` sets `renormalize` and `radial_weight` from its own arguments (they
    belong to the objective form).

    Raises:
        InputError: unknown form; both rounds and tol given; a field `SolveOptions` rejects.
    """
    if form not in FORMS:
        raise InputError(f"unknown objective form {form!r}; choose one of: {', '.join(FORMS)}")
    if changes.get("rounds") is not None and changes.get("tol"):
        raise InputError(f"give rounds ({changes['rounds']}, fixed rounds) or tol ({changes['tol']:g}, rounds until "
                         "the estimated gap is at most tol), not both")
    base = dict(
        subdivision="adaptive", per_segment=1, per_round=0, max_frames=0,
        score="decrease", precondition=True, renormalize=False,
    )
    refine = changes.get("refine") or ("tol" if changes.get("tol") or (
        "tol" not in changes and form == "normalized" and changes.get("rounds") is None
        and changes.get("subdivision", "adaptive") == "adaptive") else "rounds")
    base.update(refine=refine, **({"tol": DEFAULT_TOL} if refine == "tol" else {"rounds": DEFAULT_ROUNDS[form]}))
    base.update({k: v for k, v in changes.items() if not (k == "rounds" and v is None)})
    return OrientOptions(**base)


@dataclass
class OrientResult:
    """An optimized orientation path and its summary numbers.

    Attributes:
        frames: optimized FrameSet, nq = 4 (w x y z); the path is the natural cubic spline through
            `frames.times`, `frames.values` (`FrameSet.path`).
        keyframe_times: (k,) [s]. keyframes: (k, 4) keyframe quaternions as interpolated: normalized and
            hemisphere-aligned (each is q or -q of the input, whichever is nearer the previous).
        form: "normalized" or "paper". weights: (lambda_1, lambda_2).
        renormalize: False, or the path eq. 7 renormalized on ("start" or "keyframes", `RENORMALIZE_ON`).
        rate: uniform quadrature points per second [1/s], or None (Gauss quadrature).
        points: Gauss-Legendre nodes per spline segment, or None (uniform quadrature).
        solution: the `Solution` of `solve` (rounds, status, objective trace).
        energy: integral |covariant acceleration of u = q/|q||^2 dt of the result [1/s^3] (Gauss-Legendre,
            8 points per spline segment), the quantity the exact optimum minimizes.
        energy_initial: the same for the plain spline through the keyframes [1/s^3] (a report on the
            input, not part of the result).
        max_norm_deviation: max over the path of |1 - |q(t)|| (exact: `orient_refine.max_norm_deviation`).
        keyframe_error: max |q(t_i) - keyframe_i| (the hard constraints; ~1e-16).
            These four are reports on the path, not needed to produce it: computed when first read
            (with a tolerance, `energy` and `max_norm_deviation` come from the last round's measures),
            so that a caller who needs only the path (the benchmark ladder, a batch of joints) does
            not pay for them (~0.4 ms of a ~2 ms call on the orientation benchmark's sets).
        wall_time_s: [s] of `solve` (optimization and subdivision; with a tolerance, all rounds and
            their error estimates).
        tol: the requested estimated gap (0: fixed rounds).
        estimated_gap: a-posteriori estimate of the relative gap (E - E*)/E* of the result
            (`solver.paper.error_estimate.estimate_gap`; normalized form only, NaN for the paper form, and
            for a tolerance run stopped before its first estimate). Without a tolerance it is
            computed when first read.
        converged_to_tol: with a tolerance, whether the estimate reached it (False: the frame or time
            budget ran out, or the solve was stopped; `solution.message` says which); None without one.
        gap_estimates: the estimate after every round (with a tolerance), last = estimated_gap.
        unit_boosts: times the unit weight was multiplied by DRIFT_BOOST to hold |q| (tolerance mode).
    """

    frames: FrameSet
    keyframe_times: np.ndarray
    keyframes: np.ndarray
    form: str
    weights: tuple
    renormalize: bool | str
    rate: float | None
    solution: Solution = field(repr=False)
    points: int | None = None
    wall_time_s: float = 0.0
    tol: float = 0.0
    converged_to_tol: bool | None = None
    gap_estimates: tuple = ()
    unit_boosts: int = 0
    _objective: Objective | None = field(default=None, repr=False)
    _measures: dict = field(default_factory=dict, repr=False)  # {"energy", "drift"} of a tolerance run

    @cached_property
    def energy(self) -> float:
        if "energy" in self._measures:
            return float(self._measures["energy"])
        return covariant_energy(self.frames.times, self.frames.values)

    @cached_property
    def max_norm_deviation(self) -> float:
        if "drift" in self._measures:
            return float(self._measures["drift"])
        return max_norm_deviation(self.frames.times, self.frames.values)

    @cached_property
    def keyframe_error(self) -> float:
        return float(np.abs(self.frames.path(self.keyframe_times) - self.keyframes).max())

    @cached_property
    def estimated_gap(self) -> float:
        if self.gap_estimates:
            return self.gap_estimates[-1]
        if self._objective is None or self.form != "normalized":
            return float("nan")
        # fixed rounds: computed when first read (three gradient evaluations, ~0.3 ms), so that runs
        # that do not ask for it (the benchmark ladder) do not pay for it
        return estimate_gap(self._objective, self.frames, self.solution.E_final)[0]

    @property
    def objective_trace(self) -> np.ndarray:
        """(N,) best objective after each evaluation, all rounds."""
        return self.solution.trace

    @cached_property
    def energy_initial(self) -> float:
        return covariant_energy(self.keyframe_times, self.keyframes)

    @property
    def n_variable(self) -> int:
        return self.frames.n_variable

    def path(self, t: np.ndarray, nu: int = 0) -> np.ndarray:
        """The spline q (or its nu-th derivative) at times t: (n,) [s] -> (n, 4)."""
        return self.frames.path(np.asarray(t, float), nu)

    def orientation(self, t: np.ndarray) -> np.ndarray:
        """The unit quaternion u = q/|q| shown at times t: (n,) [s] -> (n, 4) (w x y z)."""
        q = self.path(t)
        return q / np.linalg.norm(q, axis=1, keepdims=True)


def check_keyframes(times, quats, source: str = "keyframes") -> Keyframes:
    """Validate and normalize orientation keyframes.

    Args:
        times: (k,) keyframe times [s], strictly increasing, k >= 2.
        quats: (k, 4) quaternions (w x y z), any non-zero length (normalized here, as MuJoCo does).
        source: named in error messages (a file path).
    Returns:
        Keyframes with nq = 4, all components fixed, unit quaternions (not yet hemisphere-aligned).
    Raises:
        InputError: wrong shapes, non-finite values, times not increasing, a zero quaternion.
    """
    try:
        t = np.asarray(times, dtype=float)
        q = np.asarray(quats, dtype=float)
    except (TypeError, ValueError) as e:
        raise InputError(f"{source}: times and quaternions must be numbers ({e})") from e
    if q.ndim != 2 or q.shape[1] != 4:
        raise InputError(f"{source}: quaternions must be a list of [w, x, y, z], got shape {q.shape}")
    if t.ndim != 1 or len(t) != len(q):
        raise InputError(f"{source}: {t.size} times for {len(q)} quaternions; give one time per quaternion")
    bad = np.flatnonzero(~np.isfinite(q).all(axis=1))
    if bad.size:
        i = int(bad[0])
        raise InputError(f"{source}: quaternion {i} is {q[i].tolist()}; components must be finite numbers")
    norms = np.linalg.norm(q, axis=1)
    small = np.flatnonzero(norms < 1e-6)
    if small.size:
        i = int(small[0])
        raise InputError(f"{source}: quaternion {i} is {q[i].tolist()} (zero); give a unit quaternion "
                         "[w, x, y, z], e.g. [1, 0, 0, 0] for no rotation")
    return Keyframes(t, q / norms[:, None], np.ones(q.shape, bool), source=source)


def build_objective(keyframes: Keyframes, form: str = "normalized", weights=None, rate: float | None = None,
                    points: int | None = None):
    """The objective of `orient` for these keyframes: (Objective, weights, renormalize default).

    Args:
        keyframes: from `check_keyframes`. form: one of FORMS.
        weights: (lambda_1, lambda_2) for (unit, covariant); default: normalized
            (UNIT_WEIGHT / mean(dt)^4, 1), paper PAPER_WEIGHTS.
        rate: uniform (midpoint) quadrature at this many points per second [1/s] (the paper's rule).
        points: Gauss-Legendre quadrature with this many nodes per spline segment. Default (neither
            given): Gauss with GAUSS_POINTS; `rate="default"` gives uniform at `default_rate`.
    Raises:
        InputError: unknown form, weights not two non-negative numbers, bad rate or points, both given.
    """
    if form not in FORMS:
        raise InputError(f"unknown objective form {form!r}; choose one of: {', '.join(FORMS)}")
    t = keyframes.times
    if weights is None:
        weights = PAPER_WEIGHTS if form == "paper" else (UNIT_WEIGHT / np.mean(np.diff(t)) ** 4, 1.0)
    w = np.asarray(weights, dtype=float).reshape(-1)
    if w.shape != (2,):
        raise InputError(f"weights must be two numbers (unit, covariant), got {list(np.ravel(weights))}")
    slots = LAYOUT.quat_slots
    cov = NormalizedCovariantAcceleration(slots) if form == "normalized" else CovariantAcceleration(slots)
    if rate is not None and points is not None:
        raise InputError(f"give a uniform quadrature rate ({rate}) or Gauss points per segment ({points}), not both")
    if rate is None:
        obj = Objective([UnitQuaternion(slots), cov], w, float(t[0]), float(t[-1]), quadrature="gauss",
                        points=GAUSS_POINTS if points is None else points)
    else:
        rate = default_rate(t) if isinstance(rate, str) and rate == "default" else float(rate)
        obj = Objective([UnitQuaternion(slots), cov], w, float(t[0]), float(t[-1]), rate=rate)
    return obj, (float(w[0]), float(w[1])), form == "paper"


def default_rate(times: np.ndarray) -> float:
    """Uniform quadrature rate [1/s] (`rate="default"`): max(MIN_RATE, MIN_POINTS_PER_KEY_INTERVAL /
    shortest keyframe interval)."""
    return float(max(MIN_RATE, MIN_POINTS_PER_KEY_INTERVAL / np.min(np.diff(times))))


def orient(
    times,
    quats,
    *,
    form: str = "normalized",
    weights=None,
    renormalize: bool | str | None = None,
    radial_weight: float | None = None,
    options: SolveOptions | None = None,
    rate: float | None = None,
    points: int | None = None,
    source: str = "keyframes",
    should_stop=None,
    progress=None,
    tol: float | None = None,
) -> OrientResult:
    """Smooth orientation path through keyframe quaternions, minimizing angular acceleration (sec. 3).

    Args:
        times: (k,) keyframe times [s], strictly increasing, k >= 2.
        quats: (k, 4) keyframe quaternions (w x y z); normalized, then made hemisphere-consistent.
        form: "normalized" (default: covariant acceleration of q/|q|) or "paper" (eq. 9 on q).
        weights: (lambda_1 unit, lambda_2 covariant); default see `build_objective`.
        renormalize: divide each term by its integral on the initial path (eq. 7): False, True (on
            RENORMALIZE_ON), "start" (the paper's starting path, `paper_start`) or "keyframes" (the
            plain spline through the keyframes). Default: RENORMALIZE_ON for "paper" (its 2:5 ratio is on
            renormalized terms), False for "normalized".
        radial_weight: preconditioner curvature along the frames' radial directions
            (`SolveOptions.radial_weight`); default RADIAL_WEIGHTS[form].
        options: SolveOptions; default `default_options(form)` (adaptive subdivision). Its `renormalize`
            and `radial_weight` fields are replaced by the arguments above. With adaptive subdivision and a `max_frames`
            smaller than the starting frames (`per_segment` per interval), no starting frames are
            placed and the adaptive rounds place all of them.
        rate: uniform (midpoint) quadrature at this many points per second [1/s], the paper's rule;
            "default" for `default_rate(times)`. points: Gauss-Legendre nodes per spline segment.
            Neither given: Gauss with GAUSS_POINTS (`build_objective`).
        source: name for error messages. should_stop, progress: passed to `solve`.
        tol: refine adaptively until the estimated relative gap (E - E*)/E* is at most tol
            (`OrientOptions.tol`): > 0 sets the options' refine to "tol" with this tol, 0 to "rounds"
            (their rounds, else DEFAULT_ROUNDS[form]). Default: the options' mode (refine "tol" with
            DEFAULT_TOL in the default options of the normalized form; "rounds" in a plain SolveOptions
            or options that give `rounds`). Normalized form only: the strategy is
            `solver.paper.orient_refine.GapToOptimum`, run by `solve`'s loop. The frames start as `options`
            says (`per_segment` per interval, on the unit sphere; none with subdivision "none"); every round
            whose estimate is above tol / TOL_SAFETY adds a frame at the midpoint of the segments
            with the largest shares of it (`solver.subdivide.adaptive_times`), until the estimate
            reaches it or `max_frames` (default TOL_FRAMES_PER_INTERVAL per keyframe interval) or
            `max_time_s` runs out (`converged_to_tol` False, `solution.message` says which). A round
            that meets it with max |1 - |q|| above DRIFT_LIMIT has the unit weight stiffened
            (DRIFT_BOOST) while that lowers the drift. The estimate is `estimate_gap` plus the
            quadrature discrepancy (`solver.paper.orient_refine.quadrature_discrepancy`) and the
            optimizer's own gap (`solver.paper.error_estimate.optimization_gap`).
    Returns:
        OrientResult.
    Raises:
        InputError: bad keyframes (see `check_keyframes`), form, weights, options or tol (negative, or
            given with the paper form).
    """
    kf = check_keyframes(times, quats, source)
    obj, w, renorm_default = build_objective(kf, form, weights, rate, points)
    renorm = renorm_default if renormalize is None else renormalize
    if renorm is True:
        renorm = RENORMALIZE_ON
    if renorm not in (False, "start", "keyframes"):
        raise InputError(f"renormalize must be True, False, 'start' or 'keyframes', got {renormalize!r}")
    opts = _orient_options(kf, form, options, radial_weight)
    initial = FrameSet.from_keyframes(kf, LAYOUT.quat_slots)
    if renorm:  # eq. 7, once: the scales stay fixed through the solve (`Objective.renormalize`)
        base = initial if renorm == "keyframes" else paper_start(initial)
        obj.renormalize(base.times, base.values)
    opts = _with_tol(opts, tol, form)
    gap = GapToOptimum(opts.tol, opts) if opts.refine == "tol" else None
    sol = solve(obj, initial, opts, should_stop=should_stop, progress=progress, project=unit_rows, refinement=gap)
    return _orient_result(sol, initial, obj, form, w, renorm, gap)


def _orient_result(sol, initial: FrameSet, obj, form: str, w, renorm, gap) -> OrientResult:
    """The OrientResult of a solve: the frames, the keyframes, the objective's settings and, with a
    tolerance (`gap`), its estimates and the measures of the final frames (dropped if they are stale)."""
    tol = gap.tol if gap else 0.0
    measures = gap.measures if gap else {}
    if "frames" not in measures or not (np.array_equal(measures["frames"].times, sol.frames.times)
                                        and np.array_equal(measures["frames"].values, sol.frames.values)):
        measures = {}
    fr = sol.frames
    return OrientResult(
        frames=fr,
        keyframe_times=initial.times.copy(),
        keyframes=initial.values.copy(),
        form=form,
        weights=w,
        renormalize=renorm,
        rate=obj.rate if obj.quadrature == "uniform" else None,
        points=obj.points if obj.quadrature == "gauss" else None,
        solution=sol,
        wall_time_s=sol.wall_time_s,
        tol=tol,
        _objective=obj if gap is None else None,
        converged_to_tol=sol.converged_to_tol,
        gap_estimates=tuple(float(e) for e in sol.refinement_estimates) if gap else (),
        unit_boosts=gap.boosts if gap else 0,
        _measures=dict(measures) if measures else {},
    )


def _orient_options(kf, form: str, options: SolveOptions | None, radial_weight: float | None) -> SolveOptions:
    """`orient`'s SolveOptions: the form's defaults or the caller's, with its radial weight and the
    quaternion slots; an adaptive budget smaller than the starting frames places none of them."""
    opts = default_options(form) if options is None else options
    radial = RADIAL_WEIGHTS[form] if radial_weight is None else float(radial_weight)
    opts = replace(opts, renormalize=False, radial_weight=radial,
                   quat_slots=tuple(tuple(int(i) for i in slot) for slot in LAYOUT.quat_slots))
    if (opts.subdivision == "adaptive" and opts.max_frames
            and opts.per_segment * (kf.count - 1) > opts.max_frames):
        # `solve` does not cap the starting frames of adaptive subdivision; with a budget smaller than
        # they would be, let the Euler-Lagrange score place every frame instead
        opts = replace(opts, per_segment=0, rounds=max(opts.n_rounds, 1)) if opts.refine == "rounds" else replace(
            opts, per_segment=0)
    return opts


def _with_tol(opts: SolveOptions, tol: float | None, form: str) -> SolveOptions:
    """`opts` with `orient`'s tol argument applied: None keeps them; > 0 selects refine "tol" with it; 0
    selects refine "rounds" (the options' rounds, or DEFAULT_ROUNDS[form]).

    Raises:
        InputError: tol negative or not finite; refine "tol" with the paper form.
    """
    if tol is not None:
        tol = float(tol)
        if not (tol >= 0 and np.isfinite(tol)):
            raise InputError(f"tol must be a number >= 0, got {tol!r}")
        rounds = DEFAULT_ROUNDS[form] if opts.rounds is None else opts.rounds
        opts = (replace(opts, refine="tol", tol=tol, rounds=None) if tol > 0
                else replace(opts, refine="rounds", tol=0.0, rounds=rounds))
    if opts.refine == "tol" and form != "normalized":
        raise InputError("tol (an estimated gap to the exact-unit optimum) is for the normalized form only; "
                         "the paper form's optimum trades smoothness for unit length (use rounds)")
    return opts


def paper_start(initial: FrameSet) -> FrameSet:
    """The paper's starting path (sec. 3): the keyframes and one variable frame at the midpoint of every
    keyframe interval, on the unit sphere (`unit_rows`). eq. 7's "initial state" for `renormalize="start"`.

    Args:
        initial: the keyframes' FrameSet (`FrameSet.from_keyframes`), nq = 4.
    Returns:
        FrameSet with 2k - 1 frames.
    """
    new = global_times(initial, 1)
    fr = initial.with_variable_frames(new)
    var = ~fr.is_keyframe
    vals = fr.values.copy()
    vals[var] = unit_rows(vals[var])
    return replace(fr, values=vals)
