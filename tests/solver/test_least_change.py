"""The least-change problem (solver.least_change, docs/design.md): every constraint's and the measure of
change's gradient against central finite differences on the shipped clip's problem, the mass matrix
against MuJoCo, the measure of change on hand-built changes with known values, the preconditioner's
transpose, and solves whose answers are known (a figure standing still; the shipped clip's keyframes
met exactly and every constraint within its tolerance)."""
from dataclasses import replace

import mujoco
import numpy as np
import pytest

import solver
from solver.change import MeasureOfChange
from solver.kinematics import TangentMap
from solver.lagrangian import Preconditioner, _variable_dofs
from solver.layout import StateLayout
from solver.least_change import LeastChangeOptions, _start_frames, build_least_change, solve_least_change
from solver.manifold import FrameVariables
from solver.reference import ReferenceMotion, equal_mass_matrices
from solver.spline_basis import SplineBasis


@pytest.fixture(scope="module")
def shipped():
    model = solver.load_model(solver.shipped("run_and_step.xml"))
    keyframes, info = solver.read_keyframes(solver.shipped("run_and_step.keyframes.json"), model)
    return model, keyframes, info


@pytest.fixture(scope="module")
def problem(shipped):
    model, keyframes, info = shipped
    lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights, rate=200.0)
    frames = _start_frames(lc, LeastChangeOptions().min_gap)
    return lc, frames, SplineBasis(frames.times, lc.al.t)


def _perturbed(lc, frames, seed=1, size=1e-2):
    """Frame values moved off the plain spline (m or rad of `size`), so that every constraint has
    broken and met pairs."""
    var = FrameVariables(frames, lc.layout.quat_slots)
    return var.values(np.random.default_rng(seed).normal(size=var.size) * size)


def test_every_constraints_gradient_matches_finite_differences(problem):
    lc, frames, basis = problem
    al = lc.al
    P = _perturbed(lc, frames)
    rng = np.random.default_rng(2)
    free = ~frames.fixed
    for c in al.constraints:
        g = rng.normal(size=c.size)

        def f(Q, c=c, g=g):
            return float(g @ c.values(al.state(basis, Q)))

        st = al.state(basis, P)
        c.values(st)
        c.pull(st, g.copy())
        G = basis.pullback(*st.pullback())
        for trial in range(2):
            d = rng.normal(size=P.shape) * free
            eps = 1e-7
            num = (f(P + eps * d) - f(P - eps * d)) / (2 * eps)
            ana = float((G * d).sum())
            # central differences: truncation O(eps^2) and round-off ~1e-16 |f| / eps; a kink of a max()
            # inside an eps step is rare at random pairs
            assert ana == pytest.approx(num, rel=2e-4, abs=1e-6 * (1 + abs(f(P)))), (c.name, trial)


def test_measure_of_change_and_phi_gradients_match_finite_differences(problem):
    lc, frames, basis = problem
    al = lc.al
    saved = al.estimates()  # the module's problem is shared: its multipliers and rho go back as they were
    try:
        al.lam = [np.random.default_rng(3).uniform(0, 1, c.size) for c in al.constraints]
        al.rho = 3.0
        var = FrameVariables(frames, lc.layout.quat_slots)
        x = np.random.default_rng(4).normal(size=var.size) * 1e-3
        phi, G, _ = al.evaluate(basis, var.values(x))
        g = var.pullback(x, G)
        for seed in range(3):
            d = np.random.default_rng(10 + seed).normal(size=var.size)
            eps = 1e-6
            fp = al.evaluate(basis, var.values(x + eps * d), grad=False)[0]
            fm = al.evaluate(basis, var.values(x - eps * d), grad=False)[0]
            assert g @ d == pytest.approx((fp - fm) / (2 * eps), rel=1e-5)
    finally:
        al.lam, al.rho = saved


def test_phi_without_its_constant_part_is_never_negative(problem):
    """PHR's Phi is negative where multipliers stand on met constraints: at the plain spline (D = 0) every
    met pair with lam > 0 adds -lam^2/(2 rho) (the starting frames are the plain spline's, their inserted
    quaternions made unit: D/D0 ~ 1e-3). Phi + shift() is D/D0 plus the penalty's squares, here summed
    from the constraint values: what refinement's estimate is relative to."""
    lc, frames, basis = problem
    al = lc.al
    saved = al.estimates()
    try:
        al.rho = rho = 3.0
        scaled = al.scaled_values(basis, frames.values)
        al.lam = [np.where(ch < 0, 1e3, 0.0) for ch in scaled]  # large multipliers on the met pairs only
        phi, _, D = al.evaluate(basis, frames.values, grad=False)
        squares = sum(float(w @ np.maximum(0.0, lam + rho * ch) ** 2) for w, lam, ch in zip(al.w, al.lam, scaled))
        assert phi < 0
        assert phi + al.shift() == pytest.approx(D / al.d0 + squares / (2 * rho), rel=1e-9)
        assert phi + al.shift() >= 0
    finally:
        al.lam, al.rho = saved


def test_a_subproblem_does_not_depend_on_phis_constant_part(problem):
    """PHR's Phi is its nonnegative part minus shift() = sum (w/T) lam^2 / (2 rho), a constant of the
    subproblem (`test_phi_without_its_constant_part_is_never_negative`): the constant moves neither the
    minimizer nor the gradient, so a subproblem must end where it would without it, whatever it is. Here
    Phi is lowered by a constant K (and shift() raised by it) directly. L-BFGS's relative stopping test is
    on Phi + shift >= 0: on Phi itself, made large and negative by K, it would end the run after a few
    steps. The result reports Phi itself (its value at the returned path)."""
    import copy

    from solver.lagrangian import solve_subproblem

    lc, frames, basis = problem
    quat = lc.layout.quat_slots
    start = replace(frames, values=_perturbed(lc, frames, size=3e-3))
    runs = []
    for K in (0.0, 1e3):  # Phi + shift is ~1 near the subproblem's end: Phi ~ -1e3
        al = copy.copy(lc.al)
        al.evaluate = lambda basis, P, grad=True, al=al, K=K: (lambda phi, G, D: (phi - K, G, D))(
            *type(al).evaluate(al, basis, P, grad))
        al.shift = lambda al=al, K=K: type(al).shift(al) + K
        r = solve_subproblem(al, start, quat, ftol_rel=1e-5, basis=basis, max_evals=1000)
        runs.append((r, al.evaluate(basis, r.frames.values, grad=False)[0]))
    (a, phi_a), (b, phi_b) = runs
    # the same function, up to the round-off of Phi at 1e3 (~1e-13), which parts the two L-BFGS paths: run to 1e-5
    # they end at about the same Phi + shift (0.01-0.1 % apart under three BLAS kernels; at 1e-3, where a run
    # stops follows the round-off, up to 8 %), while a stopping test on Phi itself (~ -1e3) ends 86 % higher
    assert b.result.fun + 1e3 == pytest.approx(a.result.fun, rel=0.05)
    assert a.result.fun == pytest.approx(phi_a, rel=1e-12) and b.result.fun == pytest.approx(phi_b, rel=1e-12)


def test_reference_mass_matrix_is_mujocos(shipped):
    model, keyframes, _ = shipped
    plain = solver.FrameSet.from_keyframes(keyframes, StateLayout.from_model(model).quat_slots)
    t = np.linspace(plain.times[0], plain.times[-1], 7)
    ref = ReferenceMotion.from_frames(model, plain, t, np.full(7, 0.1))
    data = mujoco.MjData(model)
    for i in (0, 3, 6):
        data.qpos[:] = ref.qpos[i]
        mujoco.mj_forward(model, data)
        M = np.zeros((model.nv, model.nv))
        for j in range(model.nv):  # column by column: M e_j (mj_mulM), not the factor the code reads
            e = np.zeros(model.nv)
            e[j] = 1.0
            col = np.zeros(model.nv)
            mujoco.mj_mulM(model, data, col, e)
            M[:, j] = col
        np.testing.assert_allclose(ref.chol[i] @ ref.chol[i].T, M, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("pose", ["diagonal", "equal masses"])
def test_measure_of_change_of_a_known_change(shipped, pose):
    """D of the reference is 0; moving the root by x(t) = A sin(pi (t - t0) / T) along x changes the
    root's acceleration by a(t) = -A (pi/T)^2 sin(...) and its position by x(t): D = sum_i w_i (a_i^2 +
    omega^4 x_i^2) M_xx(t_i), M_xx the whole body's mass (a translation of the free root moves every body),
    with the pose part diagonal (a keyed path's) or a clean's (`equal_mass_matrices`: every body moved by x,
    the figure's mass again)."""
    model, keyframes, _ = shipped
    layout = StateLayout.from_model(model)
    tmap = TangentMap.from_layout(layout)
    plain = solver.FrameSet.from_keyframes(keyframes, layout.quat_slots)
    t0, t1 = plain.times[0], plain.times[-1]
    n = 400
    h = (t1 - t0) / n
    t = t0 + h * (np.arange(n) + 0.5)
    ref = ReferenceMotion.from_frames(model, plain, t, np.full(n, h))
    omega = 3.0
    metric = None if pose == "diagonal" else equal_mass_matrices(model, ref.qpos)
    change = MeasureOfChange(ref, tmap, omega=omega, pose=metric)
    from solver.path_state import PathState
    from solver.spline import interpolate

    Y, Y1, Y2 = interpolate(plain.times, plain.values, t, (0, 1, 2))
    assert change.evaluate(PathState(t, Y, Y1, Y2, tmap), grad=False) == pytest.approx(0.0, abs=1e-9)
    A, k = 0.01, np.pi / (t1 - t0)
    s = np.sin(k * (t - t0))
    Yc, Y1c, Y2c = Y.copy(), Y1.copy(), Y2.copy()
    Yc[:, 0] += A * s
    Y1c[:, 0] += A * k * np.cos(k * (t - t0))
    Y2c[:, 0] += -A * k * k * s
    mass = float(np.sum(model.body_mass))
    expected = float(np.sum(h * ((A * k * k * s) ** 2 + omega ** 4 * (A * s) ** 2) * mass))
    assert change.evaluate(PathState(t, Yc, Y1c, Y2c, tmap), grad=False) == pytest.approx(expected, rel=1e-9)


def _quat_mul(a, b):
    """Hamilton products a b of (n, 4) quaternions (w x y z)."""
    w1, v1, w2, v2 = a[:, :1], a[:, 1:], b[:, :1], b[:, 1:]
    return np.hstack([w1 * w2 - (v1 * v2).sum(1, keepdims=True), w1 * v2 + w2 * v1 + np.cross(v1, v2)])


@pytest.mark.parametrize("joint", ["l_ankle", "torso"])
def test_pose_part_prices_every_joint_angle_alike(shipped, joint):
    """A still figure, one joint turned by theta(t) = A sin(pi (t - t0) / T) about its child's x axis: the
    joint's angular acceleration is theta'' x (the reference is still) and its pose difference
    2 sin(theta / 2) x, so D = sum_i w_i (M_jj theta''_i^2 + omega^4 I (2 sin(theta_i / 2))^2), with M from
    MuJoCo's mj_fullM at the still pose and I the mean of diag(M) over the ball joints' 3 x 11 degrees of
    freedom: an ankle's pose costs what the torso's does, though its inertia about x is 1/270 of the torso's."""
    model, keyframes, _ = shipped
    layout = StateLayout.from_model(model)
    tmap = TangentMap.from_layout(layout)
    q = keyframes.values[0].copy()
    for slot in layout.quat_slots:
        q[slot] /= np.linalg.norm(q[slot])
    t0, t1, n = 0.0, 0.8, 400
    h = (t1 - t0) / n
    t = t0 + h * (np.arange(n) + 0.5)
    ref = ReferenceMotion.from_samples(model, np.array([t0, 0.4, t1]), np.tile(q, (3, 1)), t, np.full(n, h))
    omega = 4.0
    change = MeasureOfChange(ref, tmap, omega=omega, joints=layout.articulated_dofs)
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_forward(model, data)
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M)
    balls = [j for j in layout.joints if j.kind == "ball"]
    inertia = np.mean([M[d, d] for j in balls for d in range(j.dofadr, j.dofadr + 3)])
    jt = layout.joint(joint)
    A, k = 0.3, np.pi / (t1 - t0)
    th, th1, th2 = A * np.sin(k * t), A * k * np.cos(k * t), -A * k * k * np.sin(k * t)
    c, s_ = np.cos(th / 2)[:, None], np.sin(th / 2)[:, None]
    x = np.array([1.0, 0.0, 0.0])
    u0 = np.tile(q[jt.qposadr:jt.qposadr + 4], (n, 1))
    e = np.hstack([c, s_ * x])  # exp(theta x / 2) and its derivatives in t
    e1 = np.hstack([-s_, c * x]) * (th1 / 2)[:, None]
    e2 = np.hstack([-c, -s_ * x]) * ((th1 / 2) ** 2)[:, None] + np.hstack([-s_, c * x]) * (th2 / 2)[:, None]
    Y, Y1, Y2 = np.tile(q, (n, 1)), np.zeros((n, model.nq)), np.zeros((n, model.nq))
    sl = slice(jt.qposadr, jt.qposadr + 4)
    Y[:, sl], Y1[:, sl], Y2[:, sl] = _quat_mul(u0, e), _quat_mul(u0, e1), _quat_mul(u0, e2)
    from solver.path_state import PathState

    d = jt.dofadr
    expected = float(np.sum(h * (M[d, d] * th2 ** 2 + omega ** 4 * inertia * (2 * np.sin(th / 2)) ** 2)))
    assert change.evaluate(PathState(t, Y, Y1, Y2, tmap), grad=False) == pytest.approx(expected, rel=1e-6)


def test_preconditioner_transpose(problem):
    lc, frames, basis = problem
    var = FrameVariables(frames, lc.layout.quat_slots)
    pre = Preconditioner(var, basis, lc.al.change, lc.al.tmap, lc.al.d0)
    rng = np.random.default_rng(5)
    u, v = rng.normal(size=var.size), rng.normal(size=var.size)
    assert pre.apply(u) @ v == pytest.approx(u @ pre.apply_transpose(v), rel=1e-10)


def test_preconditioner_whitens_the_time_averaged_hessian(problem):
    """R^-T H R^-1 = I for each block of degrees of freedom free at the same frames, H built directly:
    (2 / D0) (W2^T diag(w) W2 (x) Mbar + omega^4 W^T diag(w) W (x) diag(Pbar)) on the block's frames F
    and degrees of freedom D, with W, W2 the spline's values and second derivatives at the quadrature
    points (`SplineBasis.gram`)."""
    lc, frames, basis = problem
    var = FrameVariables(frames, lc.layout.quat_slots)
    ch = lc.al.change
    pre = Preconditioner(var, basis, ch, lc.al.tmap, lc.al.d0)
    w = ch.ref.weights
    K2, K0 = basis.gram(2, w) * (2.0 / lc.al.d0), ch.omega ** 4 * basis.gram(0, w) * (2.0 / lc.al.d0)
    fr, dof = _variable_dofs(var, lc.al.tmap)
    index = max((g[0] for g in pre.groups), key=np.size)  # the variable frames' block
    F, D = fr[index[:, 0]], dof[index[0]]
    H = np.kron(K2[np.ix_(F, F)], ch.mbar[np.ix_(D, D)]) + np.kron(K0[np.ix_(F, F)], ch.pbar[np.ix_(D, D)])
    Rinv = np.zeros((index.size, index.size))
    for col in range(index.size):
        z = np.zeros(var.size)
        z[index.ravel()[col]] = 1.0
        Rinv[:, col] = pre.apply(z)[index.ravel()]
    assert len(F) > 10 and np.ptp(np.diag(ch.pbar)[D]) > 0  # many frames; a pose diagonal that is not M's
    np.testing.assert_allclose(Rinv.T @ H @ Rinv, np.eye(index.size), atol=1e-8)


def test_standing_still_is_left_alone():
    """Keyframes of a figure standing on the floor: the plain spline meets every constraint, so the least
    change is no change (D = 0)."""
    model = solver.load_model(solver.shipped("run_and_step.xml"))
    keyframes, info = solver.read_keyframes(solver.shipped("run_and_step.keyframes.json"), model)
    q = keyframes.values[0].copy()
    for slot in StateLayout.from_model(model).quat_slots:  # the file's 6 digits leave norms 1e-6 off
        q[slot] /= np.linalg.norm(q[slot])
    still = replace(keyframes, times=np.array([0.0, 0.4, 0.8]), values=np.tile(q, (3, 1)),
                    mask=np.ones((3, model.nq), bool))
    lc = build_least_change(model, still, rate=200.0)
    sol = solve_least_change(lc, LeastChangeOptions())
    assert sol.E_final == pytest.approx(0.0, abs=1e-12) and not sol.unmet
    np.testing.assert_allclose(sol.frames.path(np.linspace(0, 0.8, 9)), np.tile(q, (9, 1)), atol=1e-9)


@pytest.fixture(scope="module")
def solved(shipped):
    """(lc, sol, progress events): the shipped clip with its capture (the acceleration bounds are the
    capture's), solved as the command line solves it."""
    from runner.problem_file import find_reference

    model, keyframes, info = shipped
    ref = find_reference(info, model, quiet=True)
    lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights,
                            capture=(ref.times, ref.qpos))
    events = []
    sol = solve_least_change(lc, LeastChangeOptions(), progress=lambda e, i: events.append((e, i)))
    return lc, sol, events


@pytest.mark.slow
def test_shipped_clip_meets_keyframes_and_constraints(shipped, solved):
    """Each subproblem reports its worst constraint; the last report is the final path's worst c/tol
    (`Solution.integrals_final`); the keyframes are met exactly, nothing is raised (status converged)."""
    from solver.optimize import Status

    model, keyframes, info = shipped
    _, sol, events = solved
    reports = [i for e, i in events if e == "constraints"]
    assert len(reports) == len(sol.rounds)
    worst = max(sol.integrals_final.items(), key=lambda kv: kv[1])
    assert reports[-1]["worst"] == worst[0] and reports[-1]["value"] == pytest.approx(worst[1], rel=1e-9)
    at = np.flatnonzero(sol.frames.is_keyframe)
    fixed = keyframes.mask
    assert np.abs(sol.frames.values[at][fixed] - keyframes.values[fixed]).max() <= 1e-12
    assert not sol.unmet and all(v <= 1.0 for v in sol.integrals_final.values()), sol.integrals_final
    assert sol.status is Status.CONVERGED and sol.certificate == ()
    m = solver.path_metrics(model, sol.frames.times, sol.frames.values, keyframes)
    assert m["max_penetration_mm"] <= 1.0  # the penetration constraint's tolerance, at 1000 Hz


@pytest.mark.slow
def test_variable_frames_sit_on_quadrature_points(solved):
    """Every variable frame is on a quadrature point (`solver.feasibility.on_points`), where the acceleration
    bounds see the spline's hardest acceleration (linear in time on a segment, extreme at its frames)."""
    lc, sol, _ = solved
    free = sol.frames.times[~sol.frames.is_keyframe]
    assert free.size
    assert np.abs(free[:, None] - lc.al.t[None]).min(axis=1).max() <= 1e-12


def test_new_frame_times_go_to_the_nearest_quadrature_point_off_the_frames():
    from solver.feasibility import on_points
    from solver.frames import FrameSet

    points = 0.005 * (np.arange(200) + 0.5)  # the midpoint rule at 200 Hz on [0, 1] s
    frames = FrameSet(np.array([0.0, 0.5125, 1.0]), np.zeros((3, 1)), np.ones((3, 1), bool), np.ones(3, bool))
    got = on_points(np.array([0.0126, 0.0124, 0.5124, 0.999]), points, frames)
    np.testing.assert_allclose(got, [0.0125, 0.9975], rtol=0, atol=1e-15)  # 0.5125 is a frame already


@pytest.mark.slow
def test_no_jolt_bounds_hold_at_1000_hz_between_the_quadrature_points(shipped, solved):
    """The acceleration constraint holds at its 200 Hz quadrature points and at every frame (the keyframes
    and the variable frames are points: `solver.quadrature.quadrature_points`, `on_points`); between them
    the path's pelvis and ball-joint accelerations, by MuJoCo's differences of the path sampled every 1 ms
    (independent of the solver's derivatives), stay within the bound as posed (its limit and 5 %
    tolerance): a cubic's acceleration is linear between frames."""
    model = shipped[0]
    lc, sol, _ = solved
    (acc,) = [c for c in lc.al.constraints if c.name == "acceleration"]
    dt = 1e-3
    t = np.arange(sol.frames.times[0], sol.frames.times[-1] + 0.5 * dt, dt)
    q = sol.frames.path(t)
    v = np.zeros((len(t) - 1, model.nv))
    for k in range(len(t) - 1):
        mujoco.mj_differentiatePos(model, v[k], dt, q[k], q[k + 1])
    a = np.diff(v, axis=0) / dt  # (n - 2, nv) at the samples 1..n-2
    a[:, 0:3] = (q[2:, 0:3] - 2 * q[1:-1, 0:3] + q[:-2, 0:3]) / dt ** 2  # the pelvis: x'' in the world frame
    peaks = np.linalg.norm(a[:, acc.dofs], axis=2).max(axis=0)  # (j,)
    ratios = dict(zip(acc.labels[: len(acc.dofs)], peaks / acc.limits))
    assert np.all(peaks <= acc.limits + acc.tolerance[: len(acc.dofs)]), ratios  # the bound as posed, 5 %


@pytest.mark.slow
def test_the_contact_sites_stay_as_near_the_capture_as_the_plain_spline(shipped, solved):
    """The tracking bound as posed (`solver.constraints.tracking`: met within its tolerance, at most the plain
    spline's mean distance), measured between the quadrature points: the solved path, the plain spline and the
    capture sampled every 1 ms by scipy's natural cubic spline and placed by MuJoCo's kinematics (within 1 %:
    1 ms against the 200 Hz points)."""
    from scipy.interpolate import CubicSpline

    model = shipped[0]
    lc, sol, _ = solved
    times, qpos = lc.capture
    t = np.arange(sol.frames.times[0], sol.frames.times[-1], 1e-3)
    from solver.kinematics import mujoco_site_positions

    data = mujoco.MjData(model)
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s) for s in lc.figure.contact_sites]

    def sites(frames_t, frames_q):
        return mujoco_site_positions(model, data, ids, CubicSpline(frames_t, frames_q, bc_type="natural")(t))

    target = sites(times, qpos)
    mean = [float(np.linalg.norm(sites(f.times, f.values) - target, axis=2).mean()) for f in (lc.plain, sol.frames)]
    assert mean[1] <= 1.01 * mean[0], mean


def test_refinement_checks_are_recorded_where_they_chose_frames(shipped):
    """`Solution.segment_decreases`: each check's predicted decreases, one per segment of the frames it was
    made on; a refine round's scores are the check that chose its frames, on the frames before it; the
    last check is on the final frames (the solve stopped there), and its sum over Phi is the estimate."""
    from runner.problem_file import find_reference

    model, keyframes, info = shipped
    ref = find_reference(info, model, quiet=True)  # with its capture the problem is feasible on any BLAS kernel
    lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights,
                            capture=(ref.times, ref.qpos))
    o = LeastChangeOptions(tol=1e-3)  # a tight tol: the solve refines several times
    sol = solve_least_change(lc, o)
    checks = sol.segment_decreases
    assert len(checks) >= 2
    for times, dec in checks:
        assert dec.shape == (len(times) - 1,) and np.all(dec >= 0.0)
    refined = [r for r in sol.rounds if r.kind == "refine"]
    assert refined and all(r.scores is not None for r in refined)
    for r in refined:  # the check made on the frames just before the new ones were inserted
        before = next(times for times, dec in checks if dec is r.scores)
        assert set(before) < set(r.times)
    np.testing.assert_array_equal(checks[-1][0], sol.frames.times)
    assert sol.final_estimate <= o.tol


def _frames_at(times):
    from solver.frames import FrameSet

    times = np.asarray(times, float)
    return FrameSet(times, np.zeros((len(times), 1)), np.zeros((len(times), 1), bool), np.zeros(len(times), bool))


def test_a_segment_is_refined_when_it_predicts_more_than_its_share_by_length():
    """`equidistributed_times`: the midpoints of exactly the segments whose decrease exceeds allowed h / T (hand-built,
    and on random segments: within every share nothing is marked and the sum is within `allowed`, the solve's stop
    test; one segment over its share is marked alone)."""
    from solver.least_change_refine import equidistributed_times

    frames = _frames_at([0.0, 0.1, 0.4, 0.5, 1.0])  # segments 0.1, 0.3, 0.1, 0.5 s long on a 1 s path: shares 0.1, 0.3, ...
    marked = equidistributed_times(np.array([0.11, 0.29, 0.2, 0.5]), frames, allowed=1.0)
    np.testing.assert_allclose(marked, [0.05, 0.45])  # 0.11 > 0.1 and 0.2 > 0.1; 0.29 < 0.3, 0.5 = its share
    rng = np.random.default_rng(7)
    for _ in range(200):  # random segments, each decrease within its share: nothing marked, the sum within `allowed`
        times = np.cumsum(np.r_[0.0, rng.uniform(0.02, 0.3, 12)])
        share = 0.1 * np.diff(times) / times[-1]
        dec = share * rng.uniform(0.0, 1.0, 12)
        assert equidistributed_times(dec, _frames_at(times), allowed=0.1).size == 0
        assert dec.sum() <= 0.1 * (1 + 1e-12)
        j = int(rng.integers(12))  # one segment 1 % over its share: it alone is marked, at its midpoint
        dec[j] = 1.01 * share[j]
        np.testing.assert_allclose(equidistributed_times(dec, _frames_at(times), allowed=0.1), [0.5 * (times[j] + times[j + 1])])


def test_a_clip_twice_as_long_is_refined_in_the_same_segments():
    """Two copies of one path's segments end to end, the second's residual peaks of other heights (as where tiles
    join), with twice the allowance (Phi doubles with the path): the same segments of each copy are marked, each
    over its share. Ranked among all (Doerfler's bulk rule, half the total: 0.6 and 0.4), one peak of each copy
    would be."""
    from solver.least_change_refine import equidistributed_times

    times = np.array([0.0, 0.2, 0.3, 0.7, 1.0])  # shares of 0.5 on 1 s: 0.1, 0.05, 0.2, 0.15
    first, second = np.array([0.05, 0.3, 0.02, 0.4]), np.array([0.05, 0.6, 0.02, 0.16])
    one = equidistributed_times(first, _frames_at(times), allowed=0.5)
    np.testing.assert_allclose(one, [0.25, 0.85])
    two = equidistributed_times(np.r_[first, second], _frames_at(np.r_[times, 1.0 + times[1:]]), allowed=1.0)
    np.testing.assert_allclose(two, np.r_[one, 1.0 + one])


def test_the_evaluation_budget_is_for_the_whole_solve(shipped):
    """`max_evals` caps the solve's evaluations in all, not each subproblem's: a budget smaller than one
    subproblem's first run ends the solve with status MAX_EVALS, within the budget (plus the 3 of a
    refinement estimate at most), the keyframes met and the path so far kept."""
    from solver.optimize import Status

    model, keyframes, info = shipped
    lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights)
    budget = 25
    sol = solve_least_change(lc, LeastChangeOptions(max_evals=budget))
    assert sol.status is Status.MAX_EVALS and "evaluation budget of 25" in sol.message
    assert sum(r.result.n_evals for r in sol.rounds) <= budget
    assert sol.n_evals <= budget + 3
    at = np.flatnonzero(sol.frames.is_keyframe)
    assert np.abs(sol.frames.values[at][keyframes.mask] - keyframes.values[keyframes.mask]).max() <= 1e-12


def test_a_round_ends_at_its_own_evaluations_and_the_solve_goes_on(shipped):
    """`round_evals` caps each subproblem, not the solve: a round that spends it ends as an inexact subproblem
    (CONVERGED, its message naming the cap) and the solve goes on with the next round; the solve's own budget is
    not spent by it (no MAX_EVALS "evaluation budget"), and the keyframes stay met."""
    from solver.optimize import Status

    model, keyframes, info = shipped
    lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights)
    sol = solve_least_change(lc, LeastChangeOptions(round_evals=10, max_subproblems=4))
    capped = [r for r in sol.rounds if "round_evals" in r.result.message]
    assert capped and all(r.result.status is Status.CONVERGED for r in capped)
    assert all(r.result.n_evals <= 10 for r in sol.rounds)
    assert len(sol.rounds) == 4 and "evaluation budget" not in sol.message
    at = np.flatnonzero(sol.frames.is_keyframe)
    assert np.abs(sol.frames.values[at][keyframes.mask] - keyframes.values[keyframes.mask]).max() <= 1e-12


@pytest.mark.slow
def test_a_search_that_raises_nothing_is_judged_by_the_refinement_at_once(shipped):
    """One round a frame set (per_level=1) leaves a pair broken, so the least violation is sought after round 0; the
    run-and-step problem can be met, so it raises nothing, and the refinement judges the search's path next (its
    estimate), as it judges a round's, before any other round; the path returned meets every constraint."""
    model, keyframes, info = shipped
    lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights)
    events = []
    sol = solve_least_change(lc, LeastChangeOptions(per_level=1), progress=lambda e, i: events.append((e, i)))
    steps = [(e, i) for e, i in events if e in ("round", "certify", "estimate")]
    at = next(k for k, (e, _) in enumerate(steps) if e == "certify")
    assert steps[at][1]["raised"] == {} and steps[at + 1][0] == "estimate"
    assert all(v <= 1.0 for v in sol.integrals_final.values()), sol.integrals_final
