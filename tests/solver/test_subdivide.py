"""Frame sets, the objective's gradient through the spline, subdivision and the solve loop."""
import numpy as np
import pytest

from solver.frames import FrameSet
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.objective import Objective
from solver.optimize import Status
from solver.paper.solve import SolveOptions, solve
from solver.subdivide import global_times, weak_form_scores
from solver.terms import CovariantAcceleration, UnitQuaternion

from conftest import fd_gradient

LAYOUT = StateLayout.single_quaternion()


def quat(axis, deg):
    a = np.radians(deg) / 2
    return np.concatenate([[np.cos(a)], np.sin(a) * np.asarray(axis, float) / np.linalg.norm(axis)])


def orient_problem():
    times = np.array([0.0, 0.5, 1.2, 1.6, 2.5])
    qs = np.array([quat([1, 0, 0], 0), quat([1, 0, 0], 70), quat([0, 1, 0], 60), quat([1, 1, 0], -50),
                   quat([0, 0, 1], 90)])
    kf = Keyframes(times, qs, np.ones_like(qs, bool))
    terms = [UnitQuaternion(LAYOUT.quat_slots), CovariantAcceleration(LAYOUT.quat_slots)]
    return kf, Objective(terms, [1.0, 1.0], times[0], times[-1], rate=200)


def test_objective_gradient_matches_finite_differences():
    kf, obj = orient_problem()
    fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots).with_variable_frames([0.25, 1.0, 2.0])
    G = obj.evaluate(fs.times, fs.values).grad
    np.testing.assert_allclose(G, fd_gradient(lambda P: obj.evaluate(fs.times, P, grad=False).E, fs.values),
                               rtol=1e-6, atol=1e-8)


def test_inserting_frames_on_the_path_leaves_it_unchanged():
    kf, obj = orient_problem()
    fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots)
    finer = fs.with_variable_frames(global_times(fs, 3))
    assert finer.count == fs.count + 3 * (fs.count - 1) and finer.n_variable == 12
    t = np.linspace(0, 2.5, 1001)
    for nu in range(3):
        np.testing.assert_allclose(finer.path(t, nu), fs.path(t, nu), atol=1e-10 * 10**nu)
    assert np.isclose(obj.evaluate(finer.times, finer.values).E, obj.evaluate(fs.times, fs.values).E)


def test_weak_form_score_is_the_gradient_at_a_new_midpoint_frame():
    """Independent check: with every midpoint inserted (DESIGN.md: one evaluation scores all
    segments), perturb one candidate frame and difference E."""
    kf, obj = orient_problem()
    fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots)
    scores = weak_form_scores(obj, fs)
    assert scores.shape == (4,) and np.all(scores > 0)
    cand = fs.with_variable_frames(0.5 * (fs.times[1:] + fs.times[:-1]))
    for seg in (0, 3):
        i = np.flatnonzero(~cand.is_keyframe)[seg]

        def E(v, i=i):
            P = cand.values.copy()
            P[i] = v
            return obj.evaluate(cand.times, P, grad=False).E

        assert np.isclose(np.linalg.norm(fd_gradient(E, cand.values[i].copy())), scores[seg], rtol=1e-6)


def test_solve_meets_keyframes_exactly_and_lowers_the_objective():
    kf, obj = orient_problem()
    fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots)
    sol = solve(obj, fs, SolveOptions(subdivision="adaptive", per_segment=1, rounds=2, ftol_rel=1e-10))
    assert sol.E_final < 0.7 * sol.E_initial
    assert sol.frames.n_variable > 4 and len(sol.rounds) >= 2
    key = sol.frames.is_keyframe
    assert np.array_equal(sol.frames.values[key], fs.values)  # bit-exact: never variables
    np.testing.assert_allclose(sol.frames.path(kf.times), kf.values, atol=1e-12)
    assert np.all(np.diff(sol.trace) <= 0) or len(sol.rounds) > 1


def test_partial_keyframe_components_are_free_and_others_fixed():
    times = np.array([0.0, 1.0, 2.0])
    vals = np.array([quat([1, 0, 0], 0), quat([0, 1, 0], 80), quat([0, 0, 1], 80)])
    mask = np.ones_like(vals, bool)
    mask[1, 2:] = False  # the middle keyframe fixes only w and x
    kf = Keyframes(times, vals, mask)
    assert kf.is_partial.tolist() == [False, True, False] and np.isnan(kf.values[1, 2:]).all()
    fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots)
    assert fs.n_free == 2
    obj = Objective([UnitQuaternion(LAYOUT.quat_slots), CovariantAcceleration(LAYOUT.quat_slots)],
                    [1, 1], 0, 2, rate=100)
    sol = solve(obj, fs, SolveOptions(subdivision="none", ftol_rel=1e-10))
    assert sol.status is Status.CONVERGED
    assert np.array_equal(sol.frames.values[1, :2], vals[1, :2])
    assert not np.allclose(sol.frames.values[1, 2:], fs.values[1, 2:])


def test_grouped_preconditioner_equals_dense_cholesky_factor():
    """R^-1 applied per component group equals the dense inverse Cholesky factor of the free-component
    Hessian of integral |Y''|^2 (built here directly), and apply_transpose is its transpose."""
    from solver.paper.precondition import AccelerationPreconditioner

    times = np.array([0.0, 0.5, 1.2, 1.6])
    vals = np.array([quat([1, 0, 0], a) for a in (0, 40, 80, 120)])
    mask = np.ones_like(vals, bool)
    mask[1, 2:] = False  # a partial keyframe: a second free-row pattern
    fs = FrameSet.from_keyframes(Keyframes(times, vals, mask), LAYOUT.quat_slots).with_variable_frames([0.3, 1.4])
    obj = Objective([CovariantAcceleration(LAYOUT.quat_slots)], [1.0], 0.0, 1.6, rate=200)
    W2 = obj.basis(fs.times).W2
    rows, comps = np.nonzero(fs.free)
    H = 2 * obj.h * (W2.T @ W2)[np.ix_(rows, rows)] * (comps[:, None] == comps[None, :])
    H[np.diag_indices_from(H)] += 1e-10 * np.trace(H) / len(H)
    Rinv = np.linalg.inv(np.linalg.cholesky(H).T)
    pre = AccelerationPreconditioner(obj, fs)
    assert len(pre.groups) == 2
    z = np.random.default_rng(0).normal(size=fs.n_free)
    np.testing.assert_allclose(pre.apply(z), Rinv @ z, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(pre.apply_transpose(z), Rinv.T @ z, rtol=1e-6, atol=1e-9)


def test_gauss_quadrature_objective_gradient_and_integral():
    """Gauss-Legendre on every segment: gradient against finite differences; the unit term's integral
    (a polynomial of degree 12 in t on each segment, the spline's q.q squared) matches a fine uniform
    rule; terms with per-point state are refused."""
    from solver.errors import InputError
    from solver.terms.base import Term

    kf, uni = orient_problem()
    terms = [UnitQuaternion(LAYOUT.quat_slots), CovariantAcceleration(LAYOUT.quat_slots)]
    obj = Objective(terms, [1.0, 1.0], kf.times[0], kf.times[-1], quadrature="gauss", points=7)
    assert obj.t is None and obj.h is None
    fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots).with_variable_frames([0.25, 1.0, 2.0])
    G = obj.evaluate(fs.times, fs.values).grad
    np.testing.assert_allclose(G, fd_gradient(lambda P: obj.evaluate(fs.times, P, grad=False).E, fs.values),
                               rtol=1e-6, atol=1e-8)
    fine = Objective(terms, [1.0, 1.0], kf.times[0], kf.times[-1], rate=20000)
    a = obj.evaluate(fs.times, fs.values, grad=False).integrals
    b = fine.evaluate(fs.times, fs.values, grad=False).integrals
    assert abs(a["unit"] - b["unit"]) < 1e-6 * b["unit"]
    assert abs(a["covariant"] - b["covariant"]) < 1e-6 * b["covariant"]
    assert obj.basis(fs.times).weights.sum() == pytest.approx(kf.times[-1] - kf.times[0], rel=1e-14)

    class Lagged(Term):
        name = "lagged"

        def prepare(self, t, Y, Y1, Y2):
            pass

    with pytest.raises(InputError, match="'lagged' keeps per-point state"):
        Objective([Lagged()], [1.0], 0.0, 1.0, quadrature="gauss")
    with pytest.raises(InputError, match="unknown quadrature 'simpson'; choose one of: uniform, gauss"):
        Objective(terms, [1.0, 1.0], 0.0, 1.0, quadrature="simpson")
    with pytest.raises(InputError, match="points per segment"):
        Objective(terms, [1.0, 1.0], 0.0, 1.0, quadrature="gauss", points=0)


def test_preconditioner_folded_into_the_spline_matrices_gives_the_same_optimization():
    """Whole free frames (one preconditioner group): `solver.paper.round.optimize_round` folds R^-1 into the spline matrices;
    the objective it minimizes is the same function of z as the scatter/gather path."""
    from solver.paper.precondition import AccelerationPreconditioner

    kf, obj = orient_problem()
    fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots).with_variable_frames([0.25, 0.8, 1.4, 2.0])
    pre = AccelerationPreconditioner(obj, fs)
    rows = pre.whole_rows()
    assert rows is not None and np.array_equal(rows, np.flatnonzero(~fs.is_keyframe))
    z = 0.01 * np.random.default_rng(1).normal(size=fs.n_free)
    P = fs.values_from_x(fs.x() + pre.apply(z))
    basis = obj.basis(fs.times)
    Bz = basis.B[:, rows] @ pre.groups[0][2]
    Y = basis.B @ fs.values + Bz @ z.reshape(len(rows), 4)
    n = len(basis.t)
    E, _, acc = obj.evaluate_path(basis, Y[:n], Y[n:2 * n], Y[2 * n:])
    ev = obj.evaluate(fs.times, P)
    assert pytest.approx(ev.E, rel=1e-12) == E
    g = Bz.T @ np.concatenate([np.zeros((n, 4)) if a is None else a for a in acc])
    np.testing.assert_allclose(g.ravel(), pre.apply_transpose(ev.grad[fs.free]), rtol=1e-9, atol=1e-12)
    res = solve(obj, fs, SolveOptions(subdivision="none", precondition=True, ftol_rel=1e-10))
    plain = solve(obj, fs, SolveOptions(subdivision="none", precondition=False, ftol_rel=1e-12))
    assert res.E_final == pytest.approx(plain.E_final, rel=1e-6)


def test_project_sets_the_starting_values_of_the_first_variable_frames_only():
    kf, obj = orient_problem()
    fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots)
    unit = lambda v: v / np.linalg.norm(v, axis=1, keepdims=True)  # noqa: E731
    opts = SolveOptions(subdivision="global", per_segment=1, max_evals=1, renormalize=False)
    sol = solve(obj, fs, opts, project=unit)  # one evaluation: the result is the starting point
    var = ~sol.frames.is_keyframe
    np.testing.assert_allclose(np.linalg.norm(sol.frames.values[var], axis=1), 1.0, rtol=1e-14)
    np.testing.assert_array_equal(sol.frames.values[~var], fs.values)
    plain = solve(obj, fs, opts)
    assert np.abs(np.linalg.norm(plain.frames.values[var], axis=1) - 1).max() > 1e-3  # the spline dips
    np.testing.assert_allclose(unit(plain.frames.values[var]), sol.frames.values[var], rtol=1e-14)


def test_radial_stretch_of_the_preconditioner():
    """SolveOptions.radial_weight w: x = S^-1 R^-1 z with S^-1 = I + c u u^T per free quaternion,
    c = 1/sqrt(w) - 1, so the assumed Hessian S (H x I) S has curvature w H along each frame's radial
    direction u. apply_transpose is the transpose of apply; the whole-frames path of `optimize_round`
    (R^-1, then the stretch, folded next to the spline matrices) minimizes the same function."""
    from solver.paper.precondition import AccelerationPreconditioner

    kf, obj = orient_problem()
    fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots).with_variable_frames([0.25, 0.8, 1.4, 2.0])
    plain = AccelerationPreconditioner(obj, fs)
    pre = AccelerationPreconditioner(obj, fs, radial_weight=0.04, quat_slots=LAYOUT.quat_slots)
    assert pre.c == pytest.approx(4.0)
    rows = pre.whole_rows()
    U = fs.values[rows] / np.linalg.norm(fs.values[rows], axis=1, keepdims=True)
    Sinv = np.zeros((fs.n_free, fs.n_free))
    for i in range(len(rows)):
        Sinv[4 * i:4 * i + 4, 4 * i:4 * i + 4] = np.eye(4) + 4.0 * np.outer(U[i], U[i])
    eye = np.eye(fs.n_free)
    A = np.stack([pre.apply(e) for e in eye], axis=1)
    A0 = np.stack([plain.apply(e) for e in eye], axis=1)
    np.testing.assert_allclose(A, Sinv @ A0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.stack([pre.apply_transpose(e) for e in eye], axis=1), A.T, rtol=1e-12, atol=1e-12)
    Uw, c = pre.whole_radial()
    np.testing.assert_allclose(Uw, U, rtol=1e-14)
    opts = dict(subdivision="none", precondition=True, ftol_rel=1e-11)
    a = solve(obj, fs, SolveOptions(**opts, radial_weight=0.04, quat_slots=tuple(map(tuple, LAYOUT.quat_slots))))
    b = solve(obj, fs, SolveOptions(**opts))
    assert a.E_final == pytest.approx(b.E_final, rel=1e-6)
    # a partial keyframe (free w, x only): the stretch covers the variable frames only, general path
    vals = np.array([quat([1, 0, 0], 0), quat([0, 1, 0], 80), quat([0, 0, 1], 80)])
    mask = np.ones_like(vals, bool)
    mask[1, 2:] = False
    fs2 = FrameSet.from_keyframes(Keyframes(np.array([0.0, 1.0, 2.0]), vals, mask), LAYOUT.quat_slots)
    fs2 = fs2.with_variable_frames([0.5, 1.5])
    obj2 = Objective([UnitQuaternion(LAYOUT.quat_slots), CovariantAcceleration(LAYOUT.quat_slots)], [1, 1], 0, 2,
                     rate=100)
    pre2 = AccelerationPreconditioner(obj2, fs2, radial_weight=0.04, quat_slots=LAYOUT.quat_slots)
    assert pre2.whole_rows() is None and len(pre2.radial) == 1 and len(pre2.radial[0][0]) == 2
    r2 = solve(obj2, fs2, SolveOptions(**opts, radial_weight=0.04, quat_slots=((0, 1, 2, 3),)))
    assert r2.E_final == pytest.approx(solve(obj2, fs2, SolveOptions(**opts)).E_final, rel=1e-6)


def test_failed_preconditioned_round_is_retried_without_preconditioning(monkeypatch):
    """A round whose preconditioned optimization fails is re-run on the plain variables."""
    import importlib

    round_mod = importlib.import_module("solver.paper.round")  # where a round calls nlopt
    from solver.optimize import minimize as real_minimize

    calls = []

    def flaky(fun, x0, **kw):
        calls.append(len(calls))
        res = real_minimize(fun, x0, **kw)
        if len(calls) == 1:  # the first (preconditioned) run "fails" after some progress
            from dataclasses import replace

            return replace(res, status=Status.FAILED, message="nlopt failed: test")
        return res

    monkeypatch.setattr(round_mod, "minimize", flaky)
    kf, obj = orient_problem()
    fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots)
    sol = solve(obj, fs, SolveOptions(subdivision="global", per_segment=1, precondition=True, ftol_rel=1e-10))
    assert len(calls) == 2 and sol.status is Status.CONVERGED
    assert sol.E_final < sol.E_initial and sol.n_evals == len(sol.trace)
