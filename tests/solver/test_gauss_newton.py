"""The Gauss-Newton preconditioner of a clean's grid subproblems (solver.gauss_newton, solver.curvature):

* the clamped cubic B-spline with the natural end conditions is the natural spline (scipy's CubicSpline);
* a site's velocity Jacobians in qvel and in the pose are MuJoCo's (mj_jacSite, and its finite
  differences along the tangent by mj_integratePos);
* the no-jolt bound's curvature is the exact Hessian of psi(c) (finite differences of its own gradient);
* a clean solved with it on the toy dip keeps its feet out of the floor and its pins, and reaches a change
  no larger than D's preconditioner does (within the solve's tolerance);
* in the preconditioned variables Phi's Hessian (finite differences of its gradient) is about the
  identity with the slide and the no-jolt bound under the penalty (without a pair near its bound there is
  none: D's own preconditioner serves), where the old
  preconditioner (D's curvature alone) leaves it orders of magnitude away; with every constraint, about 1
  along the gradient and nowhere above it by more than 2 (a pair within a tolerance of its bound is priced
  before it acts, so a direction may be less curved than the model says, never much more).
"""
import mujoco
import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from solver.constraints.acceleration import AccelerationBound
from solver.constraints.sites import site_velocity_jacobians
from solver.contacts import Contact
from solver.displacement import build_displacement, clean_solution, solve_displacement
from solver.gauss_newton import GridModel
from solver.kinematic_tree import SiteKinematics
from solver.kinematics import TangentMap
from solver.lagrangian import Preconditioner, _variable_dofs
from solver.layout import StateLayout
from solver.least_change import LeastChangeOptions, _start_frames
from solver.manifold import FrameVariables
from solver.path_state import PathState
from solver.spline_basis import SplineBasis
from solver.spline_coefficients import SplineCoefficients
from tests.solver.test_displacement import DIP, _capture, _lowest_site


def test_the_coefficients_give_the_natural_spline():
    rng = np.random.default_rng(0)
    knots = np.cumsum(rng.uniform(0.05, 0.2, size=9))
    t = np.sort(np.r_[knots, rng.uniform(knots[0], knots[-1], size=40)])
    P = rng.normal(size=(9, 2))
    co = SplineCoefficients(knots, t)
    C = np.linalg.solve(np.vstack([co.at_frames.toarray(), co.ends]), np.vstack([P, np.zeros((2, 2))]))
    ref = CubicSpline(knots, P, bc_type="natural")
    for r in range(3):
        got = np.einsum("na,nak->nk", co.b[r], C[co.span[:, None] + np.arange(4)])
        assert np.allclose(got, ref(t, r), rtol=1e-9, atol=1e-9 * np.abs(ref(t, r)).max())


def test_site_velocity_jacobians_are_mujocos(toy_model):
    m, d = toy_model, mujoco.MjData(toy_model)
    layout = StateLayout.from_model(m)
    tmap = TangentMap.from_layout(layout)
    sites = ["l_heel", "r_toe"]
    engine = SiteKinematics(m, sites)
    rng = np.random.default_rng(1)
    n = 3
    Y = np.zeros((n, m.nq))
    for i in range(n):
        mujoco.mj_resetData(m, d)
        mujoco.mj_integratePos(m, d.qpos, rng.normal(scale=0.4, size=m.nv), 1.0)
        Y[i] = d.qpos
    Y1 = rng.normal(scale=0.5, size=Y.shape)
    st = PathState(np.arange(n) * 0.1, Y, Y1, np.zeros_like(Y), tmap, engine)
    qvel = st.motion.qvel
    points, cols = np.repeat(np.arange(n), 2), np.tile([0, 1], n)
    J = site_velocity_jacobians(st, points, cols)
    jac = np.zeros((3, m.nv))

    def velocity(qpos, i, k):
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_jacSite(m, d, jac, None, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, sites[k]))
        return jac.copy(), jac @ qvel[i]

    h = 1e-6  # [rad or m] central differences along the tangent: error ~1e-12 relative
    for q, (i, k) in enumerate(zip(points, cols)):
        jv, _ = velocity(Y[i] / np.r_[1.0, 1.0, 1.0, np.ones(m.nq - 3)], i, k)
        assert np.allclose(J[1, q], jv, atol=1e-9)
        for dof in range(m.nv):
            e = np.zeros(m.nv)
            e[dof] = h
            plus, minus = Y[i].copy(), Y[i].copy()
            mujoco.mj_integratePos(m, plus, e, 1.0)
            mujoco.mj_integratePos(m, minus, -e, 1.0)
            fd = (velocity(plus, i, k)[1] - velocity(minus, i, k)[1]) / (2 * h)
            assert np.allclose(J[0, q, :, dof], fd, atol=1e-6), (q, dof)


class _Accelerations:
    """A path's accelerations alone, for the no-jolt bound (its `motion.qacc` and adjoint)."""

    def __init__(self, qacc):
        self.motion = type("Motion", (), {"qacc": qacc})()
        self.g_acc = np.zeros_like(qacc)

    def add_acceleration(self, g):
        self.g_acc = self.g_acc + g


def test_the_no_jolt_curvature_is_the_exact_hessian():
    rng = np.random.default_rng(2)
    nv, n = 7, 2
    bound = AccelerationBound(n, [[1, 2, 3], [4, 5, 6]], [2.0, 5.0], [0.1, 0.25], ["a", "b"])
    a0 = rng.normal(scale=3.0, size=(n, nv))
    d1, d2 = rng.uniform(0.5, 2.0, size=bound.size), rng.uniform(0.5, 2.0, size=bound.size)
    c0 = bound.values(_Accelerations(a0))

    def grad(a):  # of psi(c) = d1 c + d2 (c - c0)^2 / 2: psi' = d1, psi'' = d2 at a0
        s = _Accelerations(a)
        bound.pull(s, d1 + d2 * (bound.values(s) - c0))
        return s.g_acc

    H = np.zeros((n, nv, nv))
    for t in bound.curvature(_Accelerations(a0), d1, d2):
        F = t.factors[2]
        sup = np.broadcast_to(t.support, F.shape[:1] + F.shape[2:])
        np.add.at(H, (t.points[:, None, None], sup[:, :, None], sup[:, None, :]), np.einsum("qki,qkl,qlj->qij", F, t.K, F))
    h = 1e-5  # c is quadratic in a: central differences are exact up to round-off
    for i in range(n):
        for j in range(nv):
            e = np.zeros((n, nv))
            e[i, j] = h
            col = (grad(a0 + e) - grad(a0 - e)) / (2 * h)
            assert np.allclose(H[:, :, j][i], col[i], atol=1e-7)
            assert np.allclose(np.delete(col, i, axis=0), 0.0)


@pytest.fixture(scope="module")
def dipped_problem(toy_model):
    t, q = _capture(toy_model, DIP)
    # planted around the legs' turning points (the hips swing at 1 Hz): each foot slides a few millimetres
    feet = (Contact("l_heel", 0.2, 0.3), Contact("r_toe", 0.7, 0.8), Contact("l_toe", 1.2, 1.3))
    disp = build_displacement(toy_model, t, q, contacts=feet)
    al = disp.lc.al.posed()
    return disp, al


def _curvatures(al, frames, basis, pre, quat, directions=3, seed=4):
    """Phi's curvature in the preconditioned variables, by central differences of its gradient, along its
    gradient and along random directions."""
    var = FrameVariables(frames, quat)

    def grad(z):
        x = pre.apply(z)
        _, G, _ = al.evaluate(basis, var.values(x), True)
        return pre.apply_transpose(var.pullback(x, G))

    g0 = grad(np.zeros(pre.size))
    rng = np.random.default_rng(seed)
    dirs = [-g0] + list(rng.normal(size=(directions, pre.size)))
    out = []
    for v in dirs:
        v = v / np.linalg.norm(v)
        h = 1e-6 / np.abs(pre.apply(v)).max()
        out.append(float(v @ (grad(h * v) - grad(-h * v))) / (2 * h))
    return np.array(out)


def _only(al, names):
    keep = [i for i, c in enumerate(al.constraints) if c.name in names]
    al.constraints = [al.constraints[i] for i in keep]
    al.w = [al.w[i] for i in keep]
    al.lam = [al.lam[i] for i in keep]


def test_the_preconditioned_hessian_is_about_the_identity(dipped_problem):
    disp, al0 = dipped_problem
    quat = disp.lc.layout.quat_slots
    frames = _start_frames(disp.lc, 0.0)  # a variable frame at every capture frame
    rng = np.random.default_rng(5)
    var = FrameVariables(frames, quat)
    fr, dof = _variable_dofs(var, al0.tmap)
    wave = np.sin(2 * np.pi * frames.times)[fr] * rng.normal(scale=0.02, size=al0.tmap.nv)[dof]
    frames = var.frame_set(wave)  # off d = 0 by a smooth 2 cm / 0.02 rad change: the feet slide
    basis = SplineBasis(frames.times, al0.t)
    al = al0.posed()
    _only(al, ())
    assert GridModel(basis, al, quat).preconditioner(al, frames) is None  # Phi = D/D0: D's preconditioner serves
    for rho, names in ((1.0, ("slide", "acceleration")), (1.0, None)):
        al = al0.posed()
        if names is not None:
            _only(al, names)
        al.rho = rho
        gn = GridModel(basis, al, quat).preconditioner(al, frames)
        curv = _curvatures(al, frames, basis, gn, quat)
        if names is None:  # every constraint: pairs within a tolerance of their bound are priced before they act,
            # so no more than about 1 along the gradient; Phi is not convex there (the flight pairs' heights alone
            # give -3.4 to 0.7 along these directions), so a direction's sign follows the constraints' mix, not the
            # model; along the random directions the hinge pairs alone curve 2.0-2.8 times as much as the band
            # prices them (its Gauss-Newton part leaves out the hinge angle's own second derivative)
            assert 0.5 < curv[0] < 2.0 and np.all(curv < 3.0), curv
        else:  # the band leaves out the site velocity's second derivative in the pose (Gauss-Newton), weighted
            # by psi' = s / tol: with a clean's slide tolerance of a tenth of a millimetre a frame step (0.6 mm
            # over these 0.1 s contacts) it prices one direction at twice its curvature (0.92 with 2 mm)
            assert np.all((curv > 0.4) & (curv < 2.0)), (names, curv)
        if names is not None:
            old = Preconditioner(FrameVariables(frames, quat), basis, al.change, al.tmap, al.d0)
            assert _curvatures(al, frames, basis, old, quat)[0] > 100.0  # D's curvature alone: far from it


def test_a_clean_preconditioned_by_gauss_newton_meets_the_dip_contract(toy_model):
    """The toy dip (tests/solver/test_displacement.py) cleaned with the Gauss-Newton preconditioner: its feet
    out of the floor within the 1 mm tolerance (MuJoCo's kinematics), the pins exact, and a change not
    larger than the one the same problem reaches with D's preconditioner (the problem solved another way) by
    more than GAP. Both are local answers of a nonconvex problem, each ended by a relative-progress test, not
    at a proven optimum: D's run stalls on this dip (rho grows over subproblems of a few evaluations) and keeps
    the least violation's path, so its change, and the two answers' order, move with the subproblems' stop."""
    t, q = _capture(toy_model, DIP)
    disp = build_displacement(toy_model, t, q, pins=(0.25, 1.75))
    sol = solve_displacement(disp, LeastChangeOptions(newton=True))
    clean = clean_solution(disp, sol)
    low = _lowest_site(toy_model, clean.frames.path(np.linspace(t[0], t[-1], 1001)))
    assert low.min() >= -1e-3 - 1e-4, low.min()
    np.testing.assert_allclose(clean.frames.values[disp.pins], q[disp.pins], rtol=0, atol=1e-15)  # c + 0, rounded
    other = solve_displacement(disp, LeastChangeOptions())
    # [1] the spread of such local answers: measured E 0.248-0.282 over both preconditioners and both stops of
    # a subproblem (relative to Phi or to Phi + shift); a preconditioner that lost its way would be far above
    GAP = 0.10
    assert sol.E_final <= other.E_final * (1.0 + GAP), (sol.E_final, other.E_final)


def test_an_indefinite_band_is_refused_and_the_subproblem_falls_back(dipped_problem, monkeypatch):
    """`_factor` raises on a band that is not positive semidefinite (a negative pivot no ridge below 1 lifts);
    where a factorization fails, the grid model gives no preconditioner, so the subproblem keeps D's."""
    import solver.gauss_newton as gn

    ab = np.zeros((2, 3))
    ab[0] = [1.0, -1.0, 1.0]
    with pytest.raises(np.linalg.LinAlgError):
        gn._factor(ab)
    disp, al0 = dipped_problem
    quat = disp.lc.layout.quat_slots
    frames = _start_frames(disp.lc, 0.0)
    al = al0.posed()
    al.rho = 1.0
    basis = SplineBasis(frames.times, al.t)
    var = FrameVariables(frames, quat)
    fr, dof = _variable_dofs(var, al.tmap)
    moved = var.frame_set(np.sin(2 * np.pi * frames.times)[fr] * 0.02)  # the feet slide: slide pairs act
    model = GridModel(basis, al, quat)
    assert model.preconditioner(al, moved) is not None

    def fail(ab):
        raise np.linalg.LinAlgError("not positive definite")

    monkeypatch.setattr(gn, "_factor", fail)
    assert model.preconditioner(al, moved) is None



def test_s_s_transpose_is_the_inverse_of_the_modelled_hessian(dipped_problem, monkeypatch):
    """x = S z inverts the band it factors, D's curvature and the slide's (its pointwise part; the contact-long
    rank-one terms left out here), along the slowest displacements too: S S^T H = I with H = T^T H_C T built
    densely, T the map from the free frame values to the B-spline coefficients (the natural spline through them).
    A ridge on the equilibrated band from the start (1e-10) left S S^T short along the slowest ones: here at 0.44 of
    the inverse, on 40 frames of a 120 fps capture 1000-fold."""
    import solver.gauss_newton as gn

    disp, al0 = dipped_problem
    quat = disp.lc.layout.quat_slots
    frames = _start_frames(disp.lc, 0.0)
    al = al0.posed()
    _only(al, ("slide",))
    al.rho = 1.0
    basis = SplineBasis(frames.times, al.t)
    var = FrameVariables(frames, quat)
    fr, dof = _variable_dofs(var, al.tmap)
    moved = var.frame_set(np.sin(2 * np.pi * frames.times)[fr] * 0.02)  # the feet slide: slide pairs act
    monkeypatch.setattr(gn, "_low_rank", lambda *a: (None, None))
    model = GridModel(basis, al, quat)
    pre = model.preconditioner(al, moved)
    var = FrameVariables(moved, quat)
    P = var.values(np.zeros(var.size))
    st = al.state(basis, P)
    c = al.constraints[0]
    ch = c.values(st) / c.tolerance
    s = np.maximum(0.0, al.lam[0] + al.rho * ch)
    near = al.lam[0] + al.rho * (ch + 1.0) > 0
    terms = [t for t in c.curvature(st, al.w[0] * s / c.tolerance, al.w[0] * al.rho / c.tolerance ** 2 * near)
             if isinstance(t, gn.Curvature)]
    M = gn._motion_maps(al.tmap, st, basis.evaluate(P, (0, 1, 2)))
    co, nv = model.coefs, al.tmap.nv
    Hb = model.change + gn._assemble(co, terms, M, nv)
    HC = np.zeros((co.size * nv, co.size * nv))
    for k in range(co.size):
        for d in range(min(4, co.size - k)):
            blk = Hb[k, d] if d else np.tril(Hb[k, 0]) + np.tril(Hb[k, 0], -1).T
            HC[(k + d) * nv:(k + d + 1) * nv, k * nv:(k + 1) * nv] = blk
            HC[k * nv:(k + 1) * nv, (k + d) * nv:(k + d + 1) * nv] = blk.T
    m = len(moved.times)
    T = np.linalg.solve(np.vstack([co.at_frames.toarray(), co.ends]), np.vstack([np.eye(m), np.zeros((2, m))]))
    free = fr * nv + dof
    H = (np.kron(T, np.eye(nv)).T @ HC @ np.kron(T, np.eye(nv)))[np.ix_(free, free)]
    SS = np.stack([pre.apply(pre.apply_transpose(e)) for e in np.eye(var.size)], axis=1)
    eig = np.linalg.eigvals(SS @ H).real
    assert eig.min() > 0.99 and eig.max() < 1.01, (eig.min(), eig.max())
