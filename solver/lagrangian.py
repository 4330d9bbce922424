"""The method of multipliers: the least change that meets the constraints, by unconstrained subproblems.

    minimize D(P) / D0   subject to   c_p(P) <= 0  (every pair p of every constraint, `solver.constraints`)

is solved as a sequence of unconstrained problems in the free frame values P (the keyframes are not
variables, so every iterate meets them: the paper's central point), the Powell-Hestenes-Rockafellar
augmented Lagrangian (Nocedal & Wright, Numerical Optimization, 2nd ed., sec. 17.4; Birgin & Martinez,
Practical Augmented Lagrangian Methods for Constrained Optimization, SIAM 2014, Algorithm 4.1):

    Phi(P) = D(P)/D0 + (rho/2) sum_j sum_p (w_p/T) [ max(0, lam_p/rho + c_p/tol_j)^2 - (lam_p/rho)^2 ]

with each constraint scaled by its tolerance tol_j (so c/tol is dimensionless and 1 means "at the
tolerance"), w_p the quadrature weight of the pair's point over the path's length T (a constraint is an
integral over time, so the penalty does not grow with the quadrature rate), and D0 = m g^2 T (the
whole body's mass, gravity's acceleration, the path's length: D in units of a change of the body's
acceleration by g sustained over the path). After each subproblem, lam_p <- max(0, lam_p + rho c_p/tol_j)
(the first-order multiplier update), and rho grows by GAMMA when the infeasibility-complementarity
measure V = max_p |min(-c_p/tol_j, lam_p/rho)| did not fall below TAU of its last value (Birgin &
Martinez's rule, their defaults gamma = 10, tau = 0.5).

A subproblem is L-BFGS (nlopt) in preconditioned variables: z with x = x0 + R^-1 z, R^T R the
Gauss-Newton Hessian of D/D0 alone with the time-averaged mass matrix and pose diagonal in place of
M(t) and P(t) (`Preconditioner`: the spline's Gram matrices of second derivatives and of values times
those, inverted exactly), which removes the spline's ill-conditioning (its curvature grows like 1/h^3 in
the frame spacing h).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg

from solver.frames import FrameSet
from solver.manifold import FrameVariables
from solver.optimize import OptimizeResult, Status, minimize
from solver.path_state import PathState
from solver.spline_basis import SplineBasis

__all__ = ["AugmentedLagrangian", "Preconditioner", "frame_maps"]

#: [1] Birgin & Martinez (2014), Algorithm 4.1, their values: rho grows by GAMMA when the infeasibility V did
#: not fall below TAU of its last value
GAMMA = 10.0
TAU = 0.5


class AugmentedLagrangian:
    """Phi, its gradient and the multipliers of one problem (module docstring).

    Args:
        change: `solver.change.MeasureOfChange`. constraints: the `Constraint`s. tmap: TangentMap.
        engine: the site engine (None without site constraints). gravity_scale: D0 [kg m^2/s^3].
        rho: the starting penalty parameter (dimensionless).
        elastic: None (the objective is D/D0), or `Constraint`s whose violation is the objective in place
            of D/D0, the elastic problem of `solver.feasibility` (its least value over the paths is how far
            those constraints cannot be met while `constraints` hold): F = (1/2) sum_j sum_p (w_p/T)
            max(0, c_p/tol_j - aim)^2, or with `elastic_sum` F = sum_j sum_p (w_p/T) huber(max(0, c_p/tol_j -
            aim)), huber quadratic up to the tolerance's edge (c/tol = 1) and linear beyond. `change` still
            gives the preconditioner.
        base: None (the path is the spline through the frames), or (Y0, Y1_0, Y2_0), each (n, nq) at the
            quadrature points: a fixed motion the spline is added to (the path is base + spline, its
            derivatives the base's plus the spline's), the captured clip of a motion displacement
            (`solver.displacement`). dPath/dP is the spline's either way.
        aim: with `elastic`, the value of c/tol from which a pair counts in F (dimensionless, <= 1: a pair
            is met at c/tol <= 1; < 1 with `elastic_sum`). elastic_sum: F the sum of the violations, not of
            their squares.
    Raises:
        ValueError: elastic_sum with aim >= 1 (the sum's quadratic part spans aim..1).
    """

    def __init__(self, change, constraints, tmap, engine, d0: float, rho: float = 1.0, elastic=None, base=None,
                 aim: float = 1.0, elastic_sum: bool = False):
        if elastic_sum and not aim < 1.0:
            raise ValueError(f"aim={aim!r}: the sum of the violations counts a pair from c/tol = aim < 1")
        self.elastic_sum = bool(elastic_sum)
        self.change, self.constraints, self.tmap, self.engine = change, list(constraints), tmap, engine
        self.base = None if base is None else tuple(np.asarray(b, float) for b in base)
        self.elastic = None if elastic is None else list(elastic)
        self.aim = float(aim)
        ref = change.ref
        self.t, self.T = ref.t, ref.duration
        self.d0 = float(d0)
        self.w = [c.pair_weights(ref.weights) / self.T for c in self.constraints]
        self.w_elastic = [c.pair_weights(ref.weights) / self.T for c in self.elastic or ()]
        self.lam = [np.zeros(c.size) for c in self.constraints]
        self.rho = float(rho)
        self.V = np.inf
        #: with `elastic`: the largest c/tol of the last evaluation, held and elastic pairs (<= 1: all met)
        self.worst = np.inf


    def posed(self) -> AugmentedLagrangian:
        """A copy for one solve, as the problem was posed: the same D, engine, base and elastic objective;
        each constraint a shallow copy holding its own `limit` (a solve raises limits on its copy,
        `solver.feasibility`), the multipliers 0 and rho 1. Returns AugmentedLagrangian."""
        import copy

        def own(c):
            c = copy.copy(c)
            c.limit = np.array(c.limit, float)
            return c

        return AugmentedLagrangian(self.change, [own(c) for c in self.constraints], self.tmap, self.engine, self.d0,
                                   elastic=self.elastic, base=self.base, aim=self.aim, elastic_sum=self.elastic_sum)

    def state(self, basis, P: np.ndarray) -> PathState:
        """The PathState of frame values P (m, nq) through `basis` (a `SplineBasis` at the points), plus
        the base motion where there is one."""
        Y, Y1, Y2 = basis.evaluate(P, (0, 1, 2))
        if self.base is not None:
            Y, Y1, Y2 = Y + self.base[0], Y1 + self.base[1], Y2 + self.base[2]
        return PathState(self.t, Y, Y1, Y2, self.tmap, self.engine)

    def evaluate(self, basis, P: np.ndarray, grad: bool = True):
        """(Phi, dPhi/dP (m, nq) or None, D [kg m^2/s^3]; with `elastic`, D is 0 and Phi's first part F)."""
        st = self.state(basis, P)
        if self.elastic is None:
            D = self.change.evaluate(st, grad)
            if grad:
                for a in ("gY", "gY1", "gY2"):
                    setattr(st, a, getattr(st, a) / self.d0)
                st.g_acc = None if st.g_acc is None else st.g_acc / self.d0
            phi = D / self.d0
        else:
            D, phi = 0.0, self._elastic(st, grad)
        rho = self.rho
        for c, w, lam in zip(self.constraints, self.w, self.lam):
            ch = c.values(st) / c.tolerance
            if self.elastic is not None and ch.size:
                self.worst = max(self.worst, float(ch.max()))
            s = np.maximum(0.0, lam + rho * ch)
            phi += float(w @ (s * s - lam * lam)) / (2.0 * rho)
            if grad and s.any():
                c.pull(st, w * s / c.tolerance)
        if not grad:
            return phi, None, D
        dY, dY1, dY2 = st.pullback()
        return phi, basis.pullback(dY, dY1, dY2), D

    def _elastic(self, st, grad: bool) -> float:
        """F over the elastic constraints, v_p = max(0, c_p/tol - aim): (1/2) sum (w_p/T) v_p^2, or with
        `elastic_sum` sum (w_p/T) huber_d(v_p), d = 1 - aim (`solver.feasibility`: huber_d(v) = v^2 / (2 d) up
        to the tolerance's edge, v - d/2 beyond); with `grad` its gradient is added to the state's adjoints.
        Sets `worst`, the largest c/tol of the evaluation (elastic and held constraints; <= 1: every pair met
        within its tolerance)."""
        F, self.worst, d = 0.0, 0.0, 1.0 - self.aim
        for c, w in zip(self.elastic, self.w_elastic):
            ch = c.values(st) / c.tolerance
            self.worst = max(self.worst, float(ch.max(initial=0.0)))
            v = np.maximum(0.0, ch - self.aim)
            if self.elastic_sum:
                F += float(w @ np.where(v <= d, 0.5 * v * v / d, v - 0.5 * d))
                slope = np.minimum(v / d, 1.0)
            else:
                F += 0.5 * float(w @ (v * v))
                slope = v
            if grad and v.any():
                c.pull(st, w * slope / c.tolerance)
        return F

    def shift(self) -> float:
        """sum_j sum_p (w_p/T) lam_p^2 / (2 rho): the part of Phi no path changes, with the sign that makes
        Phi + shift = D/D0 + (1/(2 rho)) sum w max(0, lam + rho c/tol)^2 >= 0 (PHR's Phi itself can be
        negative where multipliers stand on met constraints)."""
        return sum(float(w @ (lam * lam)) for w, lam in zip(self.w, self.lam)) / (2.0 * self.rho)

    def scaled_values(self, basis, P: np.ndarray) -> list[np.ndarray]:
        """c_p / tol_j at every pair of every constraint, on the path of P."""
        st = self.state(basis, P)
        return [c.values(st) / c.tolerance for c in self.constraints]

    def estimates(self) -> tuple[list[np.ndarray], float]:
        """(a copy of the multipliers, rho): what `solver.least_change` goes back to after a stall."""
        return [lam.copy() for lam in self.lam], self.rho

    def update(self, scaled: list[np.ndarray]) -> float:
        """The multiplier and penalty updates after a subproblem (module docstring); returns V."""
        V = 0.0
        for j, ch in enumerate(scaled):
            if ch.size:
                V = max(V, float(np.abs(np.minimum(-ch, self.lam[j] / self.rho)).max()))
            self.lam[j] = np.maximum(0.0, self.lam[j] + self.rho * ch)
        if V > TAU * self.V:
            self.rho *= GAMMA
        self.V = V
        return V


class Preconditioner:
    """x = x0 + R^-1 z with R^T R the Gauss-Newton Hessian of D/D0 (module docstring).

    The Hessian of the acceleration part is sum_i w_i (W2[i] (x) I)^T M_i (W2[i] (x) I) over the
    quadrature points; with the time-averaged mass matrix Mbar in place of M_i it is the Kronecker
    product K2 (x) Mbar, K2 = W2^T diag(w) W2, and the pose part's is K0 (x) Pbar, K0 = omega^4 W^T diag(w)
    W and Pbar the time-averaged diagonal of the pose part, over the frames where the degrees of freedom
    are free. The sum of the two is diagonalized by the Kronecker product of the generalized
    eigenvectors of the pairs (K2, K0) and (Mbar, Pbar) (V^T K0 V = I, V^T K2 V = diag(lambda); U^T Pbar U =
    I, U^T Mbar U = diag(sigma)): H = (V (x) U)^-T diag(lambda_f sigma_k + 1) (V (x) U)^-1, so
    R^-1 = (V (x) U) diag(lambda_f sigma_k + 1)^(-1/2) (Van Loan, "The ubiquitous Kronecker product",
    J. Comput. Appl. Math. 123, 2000, on sums of Kronecker products). Degrees of freedom free at
    the same frames (all of them in a variable frame) share a block; a partial keyframe's free
    components form blocks of their own.

    Args:
        variables: FrameVariables. basis: the frame set's `SplineBasis` at the quadrature points.
        change: MeasureOfChange (weights, mbar, pbar, omega). tmap: TangentMap. d0: D0.
    """

    def __init__(self, variables: FrameVariables, basis, change, tmap, d0: float):
        K2, K0 = _frame_grams(basis, change, d0)
        self.size = variables.size  # z has as many components as x
        frames, dofs = _variable_dofs(variables, tmap)
        by_dof = {}
        for d in np.unique(dofs):
            at = np.flatnonzero(dofs == d)
            at = at[np.argsort(frames[at], kind="stable")]
            by_dof.setdefault(frames[at].tobytes(), []).append((d, at))
        self.groups = []  # (index (f, k) into x, V (f, f), U (k, k), diag(lambda sigma + 1)^(-1/2) (f, k))
        for key, members in by_dof.items():
            F = np.frombuffer(key, dtype=frames.dtype)
            D = np.array([d for d, _ in members])
            index = np.stack([at for _, at in members], axis=1)  # (f, k)
            lam, V = _pair_basis(K2[np.ix_(F, F)], K0[np.ix_(F, F)])
            sig, U = _pair_basis(change.mbar[np.ix_(D, D)], change.pbar[np.ix_(D, D)])
            self.groups.append((index, V, U, 1.0 / np.sqrt(np.outer(lam, sig) + 1.0)))

    def apply(self, z: np.ndarray) -> np.ndarray:
        """R^-1 z."""
        out = np.empty_like(z)
        for index, V, U, S in self.groups:
            out[index] = V @ (z[index] * S) @ U.T
        return out

    def apply_transpose(self, g: np.ndarray) -> np.ndarray:
        """R^-T g (a gradient in x as one in z)."""
        out = np.empty_like(g)
        for index, V, U, S in self.groups:
            out[index] = (V.T @ g[index] @ U) * S
        return out


def frame_maps(al: AugmentedLagrangian, frames: FrameSet, quat_slots) -> tuple:
    """(SplineBasis, Preconditioner) of a frame set at `al`'s points: what every subproblem on it shares. The
    preconditioner depends on which values of the frames are free and on the measure of change, not on the
    values, and building it is O(m^3) in the m frames (a clean's m is every capture frame).

    Args:
        al: AugmentedLagrangian (its points, measure of change, D0). frames: FrameSet (m, nq).
        quat_slots: (s, 4) the layout's quaternion slots.
    """
    basis = SplineBasis(frames.times, al.t)
    return basis, Preconditioner(FrameVariables(frames, quat_slots), basis, al.change, al.tmap, al.d0)


def _frame_grams(basis, change, d0: float) -> tuple[np.ndarray, np.ndarray]:
    """(K2, K0), each (m, m) over the frames: D/D0's Gauss-Newton Hessian is K2 (x) Mbar + K0 (x) Pbar
    (`Preconditioner`), K2 = (2/D0) W2^T diag(w) W2 and K0 = (2/D0) omega^4 W^T diag(w) W."""
    w = change.ref.weights
    return basis.gram(2, w) * (2.0 / d0), change.omega ** 4 * basis.gram(0, w) * (2.0 / d0)


def _pair_basis(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lambda (n,), V (n, n)) with V^T B V = I and V^T A V = diag(lambda), lambda >= 0: the generalized
    eigenvectors of A v = lambda B v (A symmetric positive semidefinite, B positive definite up to a
    relative ridge of 1e-12, as a spline through two frames has no curvature; LAPACK's sygvd)."""
    B = B.copy()
    B.flat[:: len(B) + 1] += 1e-12 * np.trace(B) / len(B) + 1e-300
    lam, V = scipy.linalg.eigh(A, B)
    return np.maximum(lam, 0.0), V


def initial_penalty(al: AugmentedLagrangian, basis, variables: FrameVariables, pre: Preconditioner) -> float:
    """rho_0 = |g|^2 / |A g|^2: A the Jacobian of the broken constraints (c/tol, each pair weighted by
    sqrt(w_p/T)) in the preconditioned variables, where D/D0's Hessian is about the identity, and
    g = A^T r the gradient of the violations' half square |r|^2 / 2 there: the penalty's Gauss-Newton
    curvature along the direction that most reduces the violation (a Rayleigh quotient of A^T A; Golub &
    Van Loan, Matrix Computations, sec. 8.2) is then the objective's, so the first subproblem's step
    along it weighs both alike. A g by central differences of the constraint values, A^T r by the
    constraints' own reverse pass.

    Returns:
        rho_0 > 0 (1 where no constraint is broken).
    """
    P0 = variables.values(np.zeros(variables.size))
    scaled = al.scaled_values(basis, P0)
    if not any((ch > 0).any() for ch in scaled):
        return 1.0
    sq = [np.sqrt(w) * (ch > 0) for w, ch in zip(al.w, scaled)]
    st = al.state(basis, P0)
    for c, q, ch in zip(al.constraints, sq, scaled):
        if q.any():
            c.pull(st, q * q * np.maximum(ch, 0.0) / c.tolerance)
    g = pre.apply_transpose(variables.pullback(np.zeros(variables.size), basis.pullback(*st.pullback())))
    gg = float(g @ g)
    if gg == 0:
        return 1.0
    step = pre.apply(g)
    eps = _probe_length(step)
    hi = al.scaled_values(basis, variables.values(eps * step))
    lo = al.scaled_values(basis, variables.values(-eps * step))
    Ag2 = sum(float(((q * (a - b)) ** 2).sum()) for q, a, b in zip(sq, hi, lo)) / (2 * eps) ** 2
    return gg / Ag2 if Ag2 > 0 else 1.0


def _probe_length(dx: np.ndarray) -> float:
    """The multiple h of a direction dx (in x) whose largest component moves 1e-6 [m or rad]: a finite
    difference's step, 1e-6 of a body's scale (truncation error ~1e-6 relative, round-off ~1e-10)."""
    return 1e-6 / max(1e-300, float(np.abs(dx).max()))


def _variable_dofs(variables: FrameVariables, tmap) -> tuple[np.ndarray, np.ndarray]:
    """(frame (n,), dof (n,)) of each variable: its frame and the qvel component it moves."""
    lin = variables.linear_mask()
    fr, comp = np.nonzero(lin)
    dof = np.empty(len(comp), int)
    qv = {int(q): int(v) for q, v in zip(tmap.lin_q, tmap.lin_v)}
    for qq, vv in zip(tmap.quat_q, tmap.quat_v):
        for q in qq:
            qv.setdefault(int(q), int(vv[0]))
    for i, c in enumerate(comp):
        dof[i] = qv[int(c)]
    rows, slots = variables.quaternion_frames()
    qfr = np.repeat(rows, 3)
    qdof = tmap.quat_v[slots].ravel()
    return np.r_[fr, qfr].astype(int), np.r_[dof, qdof].astype(int)


@dataclass
class SubproblemResult:
    """One subproblem's outcome: the frames, the optimizer's result and the time it took."""

    frames: FrameSet
    result: OptimizeResult
    seconds: float
    D: float = 0.0
    extra: dict = field(default_factory=dict)


def solve_subproblem(al: AugmentedLagrangian, frames: FrameSet, quat_slots, *, ftol_rel: float,
                     max_evals: int = 0, max_time_s: float = 0.0, should_stop=None, callback=None,
                     basis=None, pre=None, pairs: int | None = None) -> SubproblemResult:
    """Minimize Phi over the free values of `frames` (L-BFGS in the preconditioned variables).

    Args:
        al: AugmentedLagrangian (multipliers and rho as they are). frames: FrameSet to start from.
        quat_slots: (s, 4) the layout's quaternion slots. ftol_rel: the relative decrease that ends the run,
            of Phi + `AugmentedLagrangian.shift` (>= 0; PHR's Phi itself can be 0 or negative). max_evals,
            max_time_s, should_stop, callback: as `solver.optimize.minimize` (the callback is given Phi).
            basis: the frames' SplineBasis.
        pre: the frames' Preconditioner, or None (built here). It depends on which values of the frames
            are free and on `al.change`, not on the values: one serves every subproblem on a frame set. Or
            any object with its `size`, `apply` and `apply_transpose` (`solver.gauss_newton`).
        pairs: L-BFGS correction pairs (`solver.optimize.minimize`; None: nlopt's default by size).
    Returns:
        SubproblemResult (frames at the best iterate).
    """
    t0 = time.perf_counter()
    var = FrameVariables(frames, quat_slots)
    pre = pre if pre is not None else Preconditioner(var, basis, al.change, al.tmap, al.d0)

    start = {}  # Phi and its gradient at z = 0, where first_step_scale and L-BFGS both begin
    evals = [0]

    def preconditioned(z, need_grad):
        if need_grad and start and not z.any():
            return start["at"]
        evals[0] += 1
        x = pre.apply(z)
        phi, G, _ = al.evaluate(basis, var.values(x), need_grad)
        out = phi, (pre.apply_transpose(var.pullback(x, G)) if need_grad else None)
        if need_grad and not z.any():
            start["at"] = out
        return out

    # the scale's probe counts against the budget; with two evaluations or fewer left it would spend it
    c = first_step_scale(preconditioned, pre, pre.size, up=al.elastic is not None) if max_evals == 0 or max_evals > 2 else 1.0
    probe = evals[0] - bool(start)  # evaluations beyond the one at z = 0 that L-BFGS reuses

    shift = al.shift()  # ftol_rel is relative to Phi + shift >= 0, not to PHR's Phi (0 in the elastic problem: lam = 0)

    def fun(z, need_grad):
        phi, g = preconditioned(c * z, need_grad)
        return phi + shift, (None if g is None else c * g)

    res = minimize(fun, np.zeros(pre.size), algorithm="lbfgs", ftol_rel=ftol_rel, max_evals=max_evals and max_evals - probe,
                   max_time_s=max_time_s, should_stop=should_stop, callback=callback and (lambda n, f: callback(n, f - shift)),
                   pairs=pairs)
    res = replace(res, n_evals=evals[0], fun=res.fun - shift, trace=np.asarray(res.trace) - shift)  # evals: with first_step_scale's
    out = var.frame_set(pre.apply(c * res.x))
    return SubproblemResult(out, res, time.perf_counter() - t0)


def first_step_scale(fun, pre: Preconditioner, n: int, up: bool = False) -> float:
    """The scale c <= 1 of the subproblem's variables z = c z' that makes L-BFGS's first step the right
    length: gamma = s^T y / y^T y, the inverse curvature along the steepest-descent direction from one
    gradient difference (y) over a short step (s), the scaling of the initial inverse Hessian H0 = gamma I
    (Nocedal & Wright, Numerical Optimization, 2nd ed., eq. 7.20) taken before the first step rather than
    after it; c = sqrt(gamma) where gamma < 1, else 1 (with `up`, sqrt(gamma) either way: the elastic
    problem's curvature is its constraints' alone, which D's preconditioner does not make about 1).

    The preconditioner makes D/D0's Hessian about the identity, so without a broken constraint gamma is
    about 1 and nothing changes. A large penalty adds curvature rho |grad c|^2 along the directions that
    move a broken constraint (measured: 3e7 on a walk once rho reached 3e2); nlopt's L-BFGS (Luksan) then
    tries a first step of the gradient's length, 10^4 times too long, and its line search gives up after ten
    reductions with a generic failure, the path unchanged, while the method of multipliers raises rho on.

    Args:
        fun: fun(z, need_grad) -> (Phi, dPhi/dz) in the preconditioned variables. pre: the Preconditioner
            (the step's length in x). n: the number of variables.
    Returns:
        c in (0, 1], or > 0 with `up` (1 when the gradient vanishes or the curvature is not positive).
    """
    if n == 0:
        return 1.0
    _, g0 = fun(np.zeros(n), True)
    gn = float(np.linalg.norm(g0))
    if gn == 0 or not np.isfinite(gn):
        return 1.0
    d = -g0 / gn
    h = _probe_length(pre.apply(d))
    _, g1 = fun(h * d, True)
    y = g1 - g0
    yy, sy = float(y @ y), float(h * (d @ y))
    gamma = sy / yy if yy > 0 and sy > 0 else 1.0
    return float(np.sqrt(gamma)) if gamma < 1.0 or up else 1.0


__all__ += ["SubproblemResult", "solve_subproblem", "Status"]
