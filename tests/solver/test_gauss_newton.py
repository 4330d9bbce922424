"""The Levenberg-Marquardt back end (`solver.gauss_newton`) and its banded normal equations
(`solver.least_squares`): J^T J and J^T rho against central finite differences of the weighted
residuals, the damped step against a dense reference solve, and whole solves against nlopt's."""
from dataclasses import replace

import mujoco
import numpy as np
import pytest
from toy_problem import SCHEDULE, moved, toy_keyframes

import solver
from solver.errors import InputError
from solver.frames import FrameSet
from solver.gauss_newton import has_residuals, levenberg_marquardt
from solver.least_squares import LocalSpline, normal_equations, term_residuals
from solver.optimize import Status
from solver.problem import make_problem
from solver.solve import SolveOptions, solve

from conftest import TOY_SCENE


@pytest.fixture(scope="module")
def toy():
    """The toy figure with four keyframes low over the floor (tests/toy_problem.py), the third partial (its
    root height free)."""
    model = mujoco.MjModel.from_xml_string(TOY_SCENE)
    return model, solver.StateLayout.from_model(model), toy_keyframes(model, turn_last=True, partial=True)


def _rho(objective, frames):
    """All weighted residuals rho (E = |rho|^2) as one vector, from the terms' residual forms."""
    basis = objective.basis(frames.times)
    Y, Y1, Y2 = basis.evaluate(frames.values, objective.needs)
    q = np.full(len(basis.t), objective.h) if basis.weights is None else basis.weights
    return np.concatenate([(res.r * np.sqrt(c * q)[:, None]).ravel()
                           for _, c, res in term_residuals(objective, basis, Y, Y1, Y2)])


def _fd_jacobian(objective, frames, directions, h=1e-6):
    """d rho / d s along each column of `directions` (n_free, k) of the free components, central
    differences."""
    x = frames.x()
    cols = [(_rho(objective, frames.with_x(x + h * d)) - _rho(objective, frames.with_x(x - h * d))) / (2 * h)
            for d in directions.T]
    return np.stack(cols, axis=1)


def _dense(ab):
    n = ab.shape[1]
    A = np.zeros((n, n))
    for d in range(len(ab)):
        i = np.arange(d, n)
        A[i, i - d] = ab[d, : n - d]
        A[i - d, i] = ab[d, : n - d]
    return A


@pytest.mark.slow
def test_normal_equations_match_finite_differences_with_every_residual_term(toy):
    model, _, kf = toy
    problem = make_problem(model, kf, "all", contacts=SCHEDULE, rate=40.0)
    assert set(problem.terms) >= {"penetration", "unit", "bending", "smooth", "torque", "root", "planted",
                                  "clearance", "cone"}
    objective, frames = moved(problem)
    assert has_residuals(objective)
    local = LocalSpline(frames, objective.basis(frames.times).t)
    ne = normal_equations(objective, frames, local)
    rho = _rho(objective, frames)
    assert pytest.approx(objective.evaluate(frames.times, frames.values, grad=False).E, rel=1e-10) == ne.E
    assert pytest.approx(rho @ rho, rel=1e-10) == ne.E
    J = _fd_jacobian(objective, frames, local.E.toarray())  # d rho / d xi (x = x0 + E xi)
    H = _dense(ne.ab)
    scale = np.abs(J.T @ J).max()
    np.testing.assert_allclose(H, J.T @ J, atol=1e-5 * scale)
    np.testing.assert_allclose(ne.g, J.T @ rho, atol=1e-5 * np.abs(J.T @ rho).max())
    # the objective's own gradient (dE/dx, its chain rule through the spline) agrees: dE/dxi = E^T dE/dx
    gx = objective.evaluate(frames.times, frames.values, grad=True).grad[frames.free]
    np.testing.assert_allclose(local.E.T @ gx, 2 * ne.g, atol=1e-8 * np.abs(gx).max())


def test_local_coefficients_reproduce_the_spline_and_keep_the_keyframes(toy):
    model, _, kf = toy
    problem = make_problem(model, kf, "unit,smooth", rate=40.0)
    frames = problem.initial.with_midpoints()
    basis = problem.objective.basis(frames.times)
    local = LocalSpline(frames, basis.t)
    rng = np.random.default_rng(0)
    xi = rng.normal(size=local.n_free)
    moved = frames.with_x(frames.x() + local.E @ xi)
    # the keyframes' fixed components are untouched, the partial keyframe's free one moved
    np.testing.assert_array_equal(moved.values[frames.fixed], frames.values[frames.fixed])
    assert moved.values[4, 2] != frames.values[4, 2]
    # the B-spline values of c = Z xi are the natural spline's change through the moved frames
    dY = basis.evaluate(moved.values - frames.values, (0, 1, 2))
    dc = (local.Z @ xi).reshape(local.m + 2, local.nq)[local.seg[:, None] + np.arange(4)]
    for k in range(3):
        got = np.einsum("na,naq->nq", local.vals[k], dc)
        np.testing.assert_allclose(got, dY[k], atol=1e-9 * np.abs(dY[k]).max())
    # Z is local: a free coefficient moves only the coefficients of the frames beside it (here, keyframes
    # and variable frames alternating: at most 2 on either side), not the whole spline as a frame value does
    Z = local.Z.tocsc()
    for j in range(local.n_free):
        u = Z.indices[Z.indptr[j]:Z.indptr[j + 1]] // local.nq
        assert u.max() - u.min() <= 4
    assert np.count_nonzero(np.abs(basis.W) > 1e-12) > 0.9 * basis.W.size


def test_damped_step_is_the_dense_least_squares_step(toy):
    model, _, kf = toy
    problem = make_problem(model, kf, "penetration,unit,bending,smooth,planted,clearance", contacts=SCHEDULE,
                           rate=40.0)
    objective, frames = moved(problem, seed=5)
    local = LocalSpline(frames, objective.basis(frames.times).t)
    ne = normal_equations(objective, frames, local)
    rho = _rho(objective, frames)
    # in the frame values themselves: the Gauss-Newton step is invariant to the change of variables
    Jx = _fd_jacobian(objective, frames, np.eye(frames.n_free))
    dx_ref = np.linalg.lstsq(Jx, -rho, rcond=None)[0]
    dx = local.E @ ne.solve(0.0)
    np.testing.assert_allclose(dx, dx_ref, atol=1e-5 * np.abs(dx_ref).max())
    # damped: (J^T J + mu diag(J^T J)) h = -J^T rho, dense
    H = _dense(ne.ab)
    h_ref = np.linalg.solve(H + 0.1 * np.diag(np.diag(H)), -ne.g)
    np.testing.assert_allclose(ne.solve(0.1), h_ref, rtol=1e-8, atol=1e-12 * np.abs(h_ref).max())
    assert ne.model_decrease(h_ref) == pytest.approx(rho @ rho - np.sum((rho + Jx @ (local.E @ h_ref)) ** 2),
                                                     rel=1e-5)


@pytest.fixture(scope="module")
def contact_problem(toy):
    model, _, kf = toy
    return make_problem(model, kf, None, contacts=SCHEDULE, rate=40.0)


@pytest.mark.slow
def test_lm_solve_reaches_nlopts_objective(contact_problem):
    # the toy's feet are deep in the floor: hinge residuals (penetration, clearance) switch on and off
    # along every long step, which costs a Gauss-Newton model its accuracy (docs/solvers.md "Choosing
    # the default"): many short steps, but to within 0.5 % of L-BFGS's E
    options = replace(solver.default_options(dict(contact_problem.weights)), limits=())
    lbfgs = solve(contact_problem.objective, contact_problem.initial, options)
    lm = solve(contact_problem.objective, contact_problem.initial, replace(options, backend="lm"))
    assert lm.status is Status.CONVERGED and lbfgs.status is Status.CONVERGED
    assert all(r.result.algorithm == "lm" for r in lm.rounds)
    assert lm.E_final <= lbfgs.E_final * (1 + 5e-3)
    np.testing.assert_array_equal(lm.frames.values[lm.frames.fixed], lm.initial.values[lm.initial.fixed])


def test_lm_keeps_the_best_iterate_and_honours_budgets_and_stop_requests(contact_problem):
    objective, frames = moved(contact_problem, seed=1)
    E0 = objective.evaluate(frames.times, frames.values, grad=False).E
    seen = []
    r = levenberg_marquardt(objective, frames, max_evals=4, callback=lambda n, E: seen.append((n, E)))
    assert r.status is Status.MAX_EVALS and r.n_evals == 4 and [n for n, _ in seen] == [1, 2, 3, 4]
    assert r.fun == pytest.approx(objective.evaluate(frames.times, frames.values_from_x(r.x), grad=False).E)
    # the trace's last entry may come from the residual sum at the same point (the Jacobian's pass): equal
    # to the objective's value up to round-off
    assert r.fun <= E0 and np.all(np.diff(r.trace) <= 0) and r.trace[-1] == pytest.approx(r.fun, rel=1e-12)
    calls = []
    r = levenberg_marquardt(objective, frames, should_stop=lambda: calls.append(1) or len(calls) > 2)
    assert r.status is Status.INTERRUPTED and r.fun <= E0
    empty = FrameSet(frames.times, frames.values, np.ones_like(frames.fixed), frames.is_keyframe)
    assert levenberg_marquardt(objective, empty).status is Status.NOTHING_TO_DO


def test_an_objective_without_residuals_falls_back_to_nlopt(contact_problem, monkeypatch):
    from solver.terms.base import Term
    from solver.terms.covariant import CovariantAcceleration

    monkeypatch.setattr(CovariantAcceleration, "residual", Term.residual)
    assert not has_residuals(contact_problem.objective)
    options = replace(solver.default_options(dict(contact_problem.weights)), limits=(), backend="lm",
                      refine="rounds", rounds=0, tol=0.0)
    sol = solve(contact_problem.objective, contact_problem.initial, options)
    assert sol.rounds[0].result.algorithm == "lbfgs"


def test_backend_option_is_checked():
    with pytest.raises(InputError, match="unknown backend 'gn'; choose one of: nlopt, lm"):
        SolveOptions(backend="gn")


def test_a_term_zero_up_to_rounding_on_the_plain_spline_keeps_scale_1():
    from solver.objective import RENORMALIZE_FLOOR, Objective
    from solver.terms.base import Term, TermEval

    class Constant(Term):
        def __init__(self, name, value):
            self.name, self.value = name, value

        def evaluate(self, t, Y, Y1, Y2, grad=True):
            return TermEval(np.full(len(t), self.value), dY=np.zeros_like(Y))

    # integrals over 1 s: 1e-31 (rounding: a penetration of 1e-16 m squared) and 1e-6 (a real one)
    obj = Objective([Constant("noise", 1e-31), Constant("real", 1e-6)], np.ones(2), 0.0, 1.0, rate=50.0)
    P = np.zeros((2, 1))
    scales = obj.renormalize(np.array([0.0, 1.0]), P)
    assert scales["noise"] == 1.0 and RENORMALIZE_FLOOR > 1e-31
    assert scales["real"] == pytest.approx(1e-6, rel=1e-12)
    assert pytest.approx(1.0 + 1e-31, rel=1e-12) == obj.evaluate(np.array([0.0, 1.0]), P, grad=False).E


def _piecewise_system(seed=0, n=12, n_other=20, n_hinge=30):
    """A linear least-squares system with hinge rows: rho_o + J_o h (other rows) and max(0, s + a h),
    as `NormalEquations` sees it (the rows on now, s > 0, in J^T J and J^T rho), and its exact model
    L(h) (the residuals are linear, so L is E itself)."""
    import scipy.sparse as sp

    from solver.active_set import HingeRows
    from solver.least_squares import NormalEquations

    rng = np.random.default_rng(seed)
    Jo, ro = rng.normal(size=(n_other, n)), rng.normal(size=n_other)
    A, s = rng.normal(size=(n_hinge, n)), rng.normal(size=n_hinge)

    def L(h):
        return np.sum((ro + Jo @ h) ** 2) + np.sum(np.maximum(0.0, s + A @ h) ** 2)

    def grad(h):
        return Jo.T @ (ro + Jo @ h) + A.T @ np.maximum(0.0, s + A @ h)

    on = s > 0
    H = Jo.T @ Jo + A[on].T @ A[on]
    ab = np.stack([np.r_[np.diag(H, -d), np.zeros(d)] for d in range(n)])
    ne = NormalEquations(ab, grad(np.zeros(n)), L(np.zeros(n)), HingeRows(sp.csr_matrix(A), s))
    return ne, L, grad, np.diag(H), (Jo, ro, A, s)


@pytest.mark.parametrize("mu", [1e-3, 0.3])
def test_active_set_step_minimizes_the_one_sided_model(mu, monkeypatch):
    # let the active set settle: the step minimizes L(h) + mu h^T D h, L keeping max(0, .) on the hinge
    # rows (checked with scipy's L-BFGS-B on the model written out), and its predicted decrease is
    # L(0) - L(h); with the default single change of the set (the step along the plain Gauss-Newton
    # direction, cut at the model's minimum) the damped model still decreases
    from scipy.optimize import minimize

    from solver import active_set

    ne, L, grad, D, _ = _piecewise_system()
    h1, pred1 = ne.step(mu)
    assert 0 < pred1 == pytest.approx(L(np.zeros(len(D))) - L(h1), rel=1e-10)
    assert L(h1) + mu * h1 @ (D * h1) < L(np.zeros(len(D)))
    ne.hinge.last = None
    monkeypatch.setattr(active_set, "MAX_SWITCHES", 50)
    h, pred = ne.step(mu)
    ref = minimize(lambda v: (L(v) + mu * v @ (D * v), 2 * grad(v) + 2 * mu * D * v), np.zeros(len(D)), jac=True,
                   method="L-BFGS-B", options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 10000})
    np.testing.assert_allclose(h, ref.x, atol=1e-6 * np.abs(ref.x).max())
    assert pred == pytest.approx(L(np.zeros(len(D))) - L(h), rel=1e-10)
    # the plain Gauss-Newton step (rows switched on or off by the step ignored) predicts a decrease that
    # the one-sided model does not have
    plain = ne.solve(mu)
    assert ne.model_decrease(plain) - (L(np.zeros(len(D))) - L(plain)) > 1e-3 * abs(pred)


def test_a_step_that_keeps_the_jacobian_is_exact_for_linear_residuals(monkeypatch):
    # the residuals are linear: J^T J kept and the exact gradient at the new point give the same step
    # and prediction as the normal equations built afresh there (a changed set of rows on included)
    import scipy.sparse as sp

    from solver import active_set
    from solver.active_set import HingeRows
    from solver.least_squares import NormalEquations

    ne, L, grad, D, (Jo, ro, A, s) = _piecewise_system(seed=4)
    h, _ = ne.step(1e-3)
    monkeypatch.setattr(active_set, "MAX_SWITCHES", 50)
    moved = ne.lagged(h, grad(h), L(h))
    s1 = s + A @ h
    assert np.any((s1 > 0) != (s > 0))
    on = s1 > 0
    H = Jo.T @ Jo + A[on].T @ A[on]
    ab = np.stack([np.r_[np.diag(H, -d), np.zeros(d)] for d in range(len(D))])
    fresh = NormalEquations(ab, grad(h), L(h), HingeRows(sp.csr_matrix(A), s1))
    # the same model, so the same minimizer under the same damping matrix
    fresh.scale = moved.scale = lambda: D
    h2, p2 = moved.step(0.1)
    h3, p3 = fresh.step(0.1)
    np.testing.assert_allclose(h2, h3, atol=1e-8 * np.abs(h3).max())
    assert p2 == pytest.approx(p3, rel=1e-8) and p2 == pytest.approx(L(h) - L(h + h2), rel=1e-8)


def test_signed_depths_extend_the_penetration_depth():
    # max(0, signed) is the penetration depth (`StaticSurfaces.penetration`), its gradient matches
    # central differences, and points beyond a box's edge have no linearization (-inf)
    from solver.surfaces import StaticSurfaces
    from solver.terms.penetration import signed_depths

    c, s = np.cos(0.3), np.sin(0.3)
    surfaces = StaticSurfaces(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.1]]),
                              np.array([[[c, -s, 0], [s, c, 0], [0, 0, 1]]]), np.array([[0.3, 0.2, 0.1]]),
                              ("floor", "box"))
    rng = np.random.default_rng(2)
    pts = np.array([1.0, 0.0, 0.1]) + rng.uniform(-0.5, 0.5, size=(400, 3))
    signed, grad = signed_depths(surfaces, pts, 0.005)
    depth, _ = surfaces.penetration(pts, 0.005)
    ok = np.isfinite(signed)
    np.testing.assert_allclose(np.maximum(0.0, signed[ok]), depth[ok], atol=1e-15)
    assert np.all(depth[~ok] == 0) and 50 < np.count_nonzero(~ok[:, 1]) < 350 and np.all(ok[:, 0])
    e = 1e-7
    with np.errstate(invalid="ignore"):  # -inf - -inf beyond the box's edges
        fd = np.stack([(signed_depths(surfaces, pts + e * d, 0.005)[0]
                        - signed_depths(surfaces, pts - e * d, 0.005)[0]) / (2 * e) for d in np.eye(3)], axis=-1)
    same = ok & np.isfinite(fd).all(-1) & (np.abs(fd - grad).max(-1) < 1.0)  # not across a face switch
    assert same.sum() > 0.9 * ok.sum()
    np.testing.assert_allclose(fd[same], grad[same], atol=1e-6)


def test_anatomy_hinge_rows_are_the_signed_angles_and_their_derivatives(toy):
    # the one-sided model's rows of the anatomy terms (`OneSided`): s = the weighted signed angle (its
    # positive part the weighted residual), rows a = d s / d xi against central differences of s
    from solver.active_set import ANGLE_BAND

    model, _, kf = toy
    problem = make_problem(model, kf, None, contacts=SCHEDULE, rate=40.0)
    objective, frames = moved(problem, seed=5)
    objective.weights[[t.name not in ("hinge", "rom") for t in objective.terms]] = 0.0
    rom = next(t for t in objective.terms if t.name == "rom")  # half the motions near their lower limit
    x = rom.angles_of(objective.basis(frames.times).evaluate(frames.values, (0,))[0])
    rom.lo, rom.hi = rom.lo.copy(), rom.hi.copy()
    rom.lo[::2], rom.hi[::2] = x[:, ::2].min(axis=0) + 0.02, np.pi
    local = LocalSpline(frames, objective.basis(frames.times).t)
    ne = normal_equations(objective, frames, local)

    def signed(fr, near=None):
        basis = objective.basis(fr.times)
        Y, Y1, Y2 = basis.evaluate(fr.values, objective.needs)
        q = np.full(len(basis.t), objective.h) if basis.weights is None else basis.weights
        out, masks = [], []
        for k, (_, c, res) in enumerate(term_residuals(objective, basis, Y, Y1, Y2)):
            w = np.sqrt(c * q)
            mask = (res.one_sided.signed > -ANGLE_BAND) & (w[:, None] > 0) if near is None else near[k]
            np.testing.assert_allclose(np.abs(res.r), np.maximum(0.0, res.one_sided.signed), atol=1e-14)
            out.append((w[:, None] * res.one_sided.signed)[mask]), masks.append(mask)
        return np.concatenate(out), masks

    s, near = signed(frames)
    assert ne.hinge is not None and len(s) > 20 and np.count_nonzero(s > 0) > 0
    np.testing.assert_allclose(ne.hinge.s, s, atol=1e-14)
    x, e, E = frames.x(), 1e-6, local.E.toarray()
    fd = np.stack([(signed(frames.with_x(x + e * d), near)[0] - signed(frames.with_x(x - e * d), near)[0]) / (2 * e)
                   for d in E.T], axis=1)
    P = ne.hinge.P.toarray()
    np.testing.assert_allclose(P, fd, atol=1e-5 * np.abs(fd).max())
