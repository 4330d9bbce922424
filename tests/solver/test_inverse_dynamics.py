"""Spline velocities/accelerations in MuJoCo's terms, the vectorized inverse dynamics, and the
joint-torque and root-residual terms: against MuJoCo (mj_differentiatePos, mj_inverse, mjd_inverseFD,
mj_mulM), against finite differences, and against physical expectations with units."""
from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.interpolate import make_interp_spline
from shipped_sites import SITES as CONTACT_SITES
from tree_models import HINGE, ODD, tangent_step

from solver.errors import InputError
from solver.inverse_dynamics import InverseDynamics, MujocoInverseDynamics, constraint_free_copy
from solver.kinematics import TangentMap
from solver.layout import StateLayout
from solver.surfaces import StaticSurfaces
from solver.terms.dynamics import JointTorque, RootResidual, make_engine

from conftest import fd_gradient, random_qpos

SCENE = Path(__file__).resolve().parents[2] / "models" / "run_and_step.xml"
G = 9.81

@pytest.fixture(scope="module")
def scene(request):
    """The real figure in its scene if it exists, else the inline toy figure of conftest."""
    if SCENE.exists():
        return mujoco.MjModel.from_xml_path(str(SCENE))
    return request.getfixturevalue("toy_model")


@pytest.fixture(scope="module")
def odd():
    return mujoco.MjModel.from_xml_string(ODD)


def state(model, rng, n=3, spread=0.6):
    layout = StateLayout.from_model(model)
    Y = random_qpos(rng, layout, n, spread=spread)
    return layout, Y, rng.normal(size=Y.shape), rng.normal(size=Y.shape)


def normalized(layout, Y):
    Y = np.array(Y, float)
    for slot in layout.quat_slots:
        Y[..., slot] /= np.linalg.norm(Y[..., slot], axis=-1, keepdims=True)
    return Y


# ------------------------------------------------------------------------------------------ item 1


def test_spline_qvel_and_qacc_match_mj_differentiate_pos(scene):
    """qvel = B(Y) Y' and qacc of a natural cubic spline through frames with non-unit quaternions
    against central differences of mj_differentiatePos (qacc: differences of such velocities)."""
    rng = np.random.default_rng(0)
    layout = StateLayout.from_model(scene)
    tm = TangentMap.from_layout(layout)
    times = np.array([0.0, 0.4, 0.9, 1.3, 2.0])
    frames = random_qpos(rng, layout, len(times), spread=0.5)
    spline = make_interp_spline(times, frames, k=3, bc_type="natural")
    d1, d2 = spline.derivative(1), spline.derivative(2)
    t = np.array([0.3, 0.77, 1.6])

    def diff_pos(a, b, dt):
        v = np.zeros(scene.nv)
        mujoco.mj_differentiatePos(scene, v, dt, normalized(layout, a), normalized(layout, b))
        return v

    def fd_vel(ti, h):
        return diff_pos(spline(ti - h), spline(ti + h), 2 * h)

    mo = tm.motion(spline(t), d1(t), d2(t))
    h = 1e-3
    for i, ti in enumerate(t):
        np.testing.assert_allclose(mo.qvel[i], fd_vel(ti, 1e-5), rtol=0, atol=1e-7)
        qacc = (fd_vel(ti + h, 1e-5) - fd_vel(ti - h, 1e-5)) / (2 * h)
        np.testing.assert_allclose(mo.qacc[i], qacc, rtol=0, atol=2e-5 * (1 + np.abs(qacc).max()))
    np.testing.assert_allclose(tm.acceleration(spline(t), d1(t), d2(t)), mo.qacc)
    np.testing.assert_allclose(tm.velocity(spline(t), d1(t)), mo.qvel)


def test_qvel_qacc_jacobians_match_finite_differences(scene):
    rng = np.random.default_rng(1)
    layout, Y, Y1, Y2 = state(scene, rng, n=3)
    tm = TangentMap.from_layout(layout)
    J = tm.motion(Y, Y1, Y2).jacobians()
    h = 1e-6

    def fd(fun, X):
        out = np.zeros((len(X), tm.nv, tm.nq))
        for k in range(tm.nq):
            Xp, Xm = X.copy(), X.copy()
            Xp[:, k] += h
            Xm[:, k] -= h
            out[:, :, k] = (fun(Xp) - fun(Xm)) / (2 * h)
        return out

    expect = {
        "dv_dY": fd(lambda X: tm.motion(X, Y1, Y2).qvel, Y),
        "dv_dY1": fd(lambda X: tm.motion(Y, X, Y2).qvel, Y1),
        "da_dY": fd(lambda X: tm.motion(X, Y1, Y2).qacc, Y),
        "da_dY1": fd(lambda X: tm.motion(Y, X, Y2).qacc, Y1),
        "da_dY2": fd(lambda X: tm.motion(Y, Y1, X).qacc, Y2),
    }
    for name, E in expect.items():
        np.testing.assert_allclose(J[name], E, rtol=0, atol=1e-7 * (1 + np.abs(E).max()), err_msg=name)


def test_motion_vjp_pose_part_is_the_tangent_pullback(scene):
    rng = np.random.default_rng(2)
    layout, Y, Y1, Y2 = state(scene, rng)
    tm = TangentMap.from_layout(layout)
    g = rng.normal(size=(len(Y), tm.nv))
    dY, dY1, dY2 = tm.motion(Y, Y1, Y2).vjp(None, None, g)
    np.testing.assert_allclose(dY, tm.pullback(Y, g), atol=1e-12)
    assert not dY1.any() and not dY2.any()


# ------------------------------------------------------------------------------ inverse dynamics


@pytest.mark.parametrize("which", ["scene", "odd"])
def test_inverse_dynamics_matches_mj_inverse(which, request):
    model = request.getfixturevalue(which)
    flags = int(model.opt.disableflags)
    rng = np.random.default_rng(3)
    layout, Y, _, _ = state(model, rng, n=4)
    V, A = rng.normal(size=(4, model.nv)), rng.normal(size=(4, model.nv))
    res = InverseDynamics(model, CONTACT_SITES).forward(Y, V, A)
    m = constraint_free_copy(model)
    d = mujoco.MjData(m)
    sites = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s) for s in CONTACT_SITES]
    for i in range(len(Y)):
        d.qpos[:], d.qvel[:], d.qacc[:] = Y[i], V[i], A[i]
        mujoco.mj_inverse(m, d)
        scale = 1 + np.abs(d.qfrc_inverse).max()
        np.testing.assert_allclose(res.tau[i], d.qfrc_inverse, rtol=0, atol=1e-10 * scale)
        np.testing.assert_allclose(res.sites[i], d.site_xpos[sites], atol=1e-12)
    assert int(model.opt.disableflags) == flags  # the caller's model is untouched (a copy was changed)


@pytest.mark.parametrize("which", ["scene", "odd"])
def test_inverse_dynamics_gradient(which, request):
    """vjp against central differences of forward (pose moved by mj_integratePos), against MuJoCo's
    mjd_inverseFD (forward differences: looser), and d/d qacc against the mass matrix (mj_mulM)."""
    model = request.getfixturevalue(which)
    rng = np.random.default_rng(4)
    n, nv = 2, model.nv
    layout, Y, _, _ = state(model, rng, n=n)
    V, A = rng.normal(size=(n, nv)), rng.normal(size=(n, nv))
    eng = InverseDynamics(model, CONTACT_SITES)
    g, gs = rng.normal(size=(n, nv)), rng.normal(size=(n, 4, 3))
    res = eng.forward(Y, V, A)
    Gq, Gv, Ga = eng.vjp(res, g, gs)

    def phi(Y_, V_, A_):
        r = eng.forward(Y_, V_, A_)
        return (r.tau * g).sum(1) + (r.sites * gs).sum((1, 2))

    h = 1e-6
    fq, fv, fa = (np.zeros((n, nv)) for _ in range(3))
    for i in range(nv):
        e = np.zeros((n, nv))
        e[:, i] = h
        fq[:, i] = (phi(tangent_step(model, Y, e), V, A) - phi(tangent_step(model, Y, -e), V, A)) / (2 * h)
        fv[:, i] = (phi(Y, V + e, A) - phi(Y, V - e, A)) / (2 * h)
        fa[:, i] = (phi(Y, V, A + e) - phi(Y, V, A - e)) / (2 * h)
    for got, want, name in ((Gq, fq, "pose"), (Gv, fv, "qvel"), (Ga, fa, "qacc")):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * (1 + np.abs(want).max()), err_msg=name)

    ref = MujocoInverseDynamics(model, CONTACT_SITES)
    rq, rv, ra = ref.vjp(ref.forward(Y, V, A), g, gs)
    for got, want in ((Gq, rq), (Gv, rv), (Ga, ra)):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-4 * (1 + np.abs(want).max()))

    d = mujoco.MjData(model)
    for i in range(n):
        d.qpos[:] = Y[i]
        mujoco.mj_forward(model, d)
        Mg = np.zeros(nv)
        mujoco.mj_mulM(model, d, Mg, g[i])
        np.testing.assert_allclose(Ga[i], Mg, rtol=1e-10, atol=1e-10)


def test_unsupported_model_raises_and_mujoco_backend_handles_it():
    model = mujoco.MjModel.from_xml_string(HINGE)
    with pytest.raises(InputError, match="hinge.*backend='mujoco'"):
        InverseDynamics(model)
    # the arm, rotated 0.3 rad down about +y, is held by a torque about -y: -m g r cos(0.3) [N m]
    res = MujocoInverseDynamics(model).forward(np.array([[0.3]]), np.zeros((1, 1)), np.zeros((1, 1)))
    m_g_r = model.body_mass[1] * G * model.body_ipos[1][0]
    assert res.tau[0, 0] == pytest.approx(-m_g_r * np.cos(0.3), rel=1e-9)


# ------------------------------------------------------------------------------------------ terms


def check_term_gradient(term, Y, Y1, Y2, rtol=1e-6):
    ev = term.evaluate(None, Y, Y1, Y2, grad=True)
    for k, (X, g) in enumerate(((Y, ev.dY), (Y1, ev.dY1), (Y2, ev.dY2))):

        def f(Z, k=k):
            args = [Y, Y1, Y2]
            args[k] = Z
            return term.evaluate(None, *args, grad=False).f.sum()

        want = fd_gradient(f, X)
        scale = np.abs(want).max()
        np.testing.assert_allclose(g, want, rtol=0, atol=rtol * scale, err_msg=f"{term.name} d/dY{k}")


def test_joint_torque_value_and_gradient(scene):
    rng = np.random.default_rng(5)
    layout, Y, Y1, Y2 = state(scene, rng, n=3)
    knee = "l_knee" if any(j.name == "l_knee" for j in layout.joints) else layout.joints[2].name
    term = JointTorque(scene, weights={knee: 3.0})
    tau = term.torques(Y, Y1, Y2)
    w = np.ones(scene.nv)
    w[:6] = 0.0
    j = layout.joint(knee)
    w[j.dofadr : j.dofadr + 3] = 3.0
    np.testing.assert_allclose(term.evaluate(None, Y, Y1, Y2, grad=False).f, (w * tau**2).sum(1))
    check_term_gradient(term, Y, Y1, Y2)


def test_root_residual_value_and_gradient_through_the_flight_indicator(scene):
    """Samples with the feet in the air, touching, and in between (0 < phi < 1): the indicator's
    gradient is part of the term's."""
    rng = np.random.default_rng(6)
    layout, Y, Y1, Y2 = state(scene, rng, n=4, spread=0.05)
    Y[:, 0] -= 3.0  # over the open floor, away from the step
    term = RootResidual(scene)
    mo = term.tmap.motion(Y, Y1, Y2)
    lowest = term.engine.forward(Y, mo.qvel, mo.qacc).sites[..., 2].min(1)
    Y[:, 2] += np.array([0.4, -0.01, 0.015, 0.03]) - lowest  # clearance of the lowest site
    mo = term.tmap.motion(Y, Y1, Y2)
    res = term.engine.forward(Y, mo.qvel, mo.qacc)
    phi, _ = term.flight(res.sites)
    assert phi[0] == 1.0 and phi[1] == 0.0 and 0.0 < phi[2] < phi[3] < 1.0
    wr = res.tau[:, :6]
    expect = phi * ((wr[:, :3] ** 2).sum(1) + (wr[:, 3:] ** 2).sum(1) / term.torque_arm**2)
    np.testing.assert_allclose(term.evaluate(None, Y, Y1, Y2, grad=False).f, expect)
    check_term_gradient(term, Y, Y1, Y2)


def test_terms_share_an_engine(scene):
    rng = np.random.default_rng(7)
    _, Y, Y1, Y2 = state(scene, rng, n=3)
    eng = make_engine(scene, CONTACT_SITES)
    shared = [JointTorque(scene, engine=eng), RootResidual(scene, engine=eng)]
    alone = [JointTorque(scene), RootResidual(scene)]
    for a, b in zip(shared, alone):
        ea, eb = a.evaluate(None, Y, Y1, Y2), b.evaluate(None, Y, Y1, Y2)
        for x, y in zip((ea.f, ea.dY, ea.dY1, ea.dY2), (eb.f, eb.dY, eb.dY1, eb.dY2)):
            np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("kind", ["inverse dynamics", "kinematics only"])
def test_a_path_context_runs_each_engine_once(scene, kind):
    """`PathContext.forward` computes an engine's pass on the first ask and returns the same objects
    after; a new context on the same path computes it again (equal values); a context without Y'
    gives the kinematics engine's positions alone (equal to the full pass's)."""
    from solver.kinematic_tree import SiteKinematics
    from solver.path_context import PathContext, PoseOnly

    layout, Y, Y1, Y2 = state(scene, np.random.default_rng(9))
    tm = TangentMap.from_layout(layout)
    eng = make_engine(scene, CONTACT_SITES) if kind == "inverse dynamics" else SiteKinematics(scene, CONTACT_SITES)
    ctx = PathContext(None, Y, Y1, Y2)
    mo, res = ctx.forward(eng, tm)
    again = ctx.forward(eng, tm)
    assert again[0] is mo and again[1] is res
    other = tm.motion(Y[::-1].copy(), Y1, Y2)
    eng.forward(Y[::-1].copy(), other.qvel, other.qacc)  # the engine now holds another pass
    mo2, res2 = PathContext(None, Y.copy(), Y1.copy(), Y2.copy()).forward(eng, tm)
    np.testing.assert_array_equal(res2.sites, res.sites)
    np.testing.assert_array_equal(res2.tau, res.tau)
    if kind == "kinematics only":
        mo3, res3 = PathContext(None, Y).forward(eng, tm)
        assert isinstance(mo3, PoseOnly) and res3.qvel.size == 0
        np.testing.assert_allclose(res3.sites, res.sites, rtol=0, atol=1e-14)
    else:
        with pytest.raises(ValueError, match="needs path derivative 1"):
            PathContext(None, Y).forward(eng, tm)


# ------------------------------------------------------------------------------ physical checks


def hip_joint(model, layout, site="l_toe"):
    """The ball joint of the root's child body on the way to `site` (the hip), by tree structure."""
    b = int(model.site_bodyid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site)])
    root_body = int(model.jnt_bodyid[0])
    while int(model.body_parentid[b]) != root_body:
        b = int(model.body_parentid[b])
    j = int(model.body_jntadr[b])
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
    return layout.joint(name), b


def test_static_pose_torques_are_gravity_compensation(scene):
    """Held still (Y' = Y'' = 0): the torques are mj_inverse at rest; a leg raised straight forward
    needs a hip torque of m g r [N m] about the hip's lateral axis, m the leg's mass, r its lever."""
    layout = StateLayout.from_model(scene)
    hip, thigh = hip_joint(scene, layout)
    Y = np.zeros((2, scene.nq))
    Y[:, :3] = [0.0, 0.0, 2.0]
    for slot in layout.quat_slots:
        Y[:, slot] = [1.3, 0.0, 0.0, 0.0]  # identity, not unit
    Y[1, hip.qpos_slice] = 0.9 * np.array([np.cos(-np.pi / 4), 0.0, np.sin(-np.pi / 4), 0.0])  # thigh to +x
    Z = np.zeros_like(Y)
    term = JointTorque(scene)
    tau = term.torques(Y, Z, Z)
    d = mujoco.MjData(scene)
    for i in range(2):
        d.qpos[:] = normalized(layout, Y[i])
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        mujoco.mj_inverse(scene, d)
        np.testing.assert_allclose(tau[i], d.qfrc_inverse, atol=1e-9)
    # leg raised forward: hip torque (0, -m g r, 0) in the thigh frame (a rotation about y keeps y)
    mujoco.mj_kinematics(scene, d)
    mujoco.mj_comPos(scene, d)
    m_leg = float(scene.body_subtreemass[thigh])
    r = float(d.subtree_com[thigh][0] - d.xanchor[int(scene.body_jntadr[thigh])][0])
    assert 0.1 < r < 0.6  # [m] the leg's centre of mass is well in front of the hip
    t_hip = tau[1, hip.dofadr : hip.dofadr + 3]
    np.testing.assert_allclose(t_hip, [0.0, -m_leg * G * r, 0.0], atol=1e-9 * m_leg * G)
    assert term.evaluate(None, Y, Z, Z, grad=False).f[1] >= (m_leg * G * r) ** 2


def test_root_residual_of_free_fall_is_zero_and_of_rest_in_the_air_is_the_weight(scene):
    layout = StateLayout.from_model(scene)
    Y = np.zeros((3, scene.nq))
    for slot in layout.quat_slots:
        Y[:, slot] = [0.8, 0.0, 0.0, 0.0]
    Y[:, :3] = [0.3, -0.2, 2.5]  # high in the air
    Y[2, :3] = [0.0, 0.0, 0.0]  # feet far below the floor: "in contact"
    Z = np.zeros_like(Y)
    fall = Z.copy()
    fall[0, :3] = scene.opt.gravity  # root accelerates with gravity [m/s^2], nothing else moves
    root = RootResidual(scene)
    torque = JointTorque(scene)
    np.testing.assert_allclose(root.wrench(Y[:1], Z[:1], fall[:1]), 0.0, atol=1e-9)
    assert root.evaluate(None, Y[:1], Z[:1], fall[:1]).f[0] == pytest.approx(0.0, abs=1e-12)
    assert torque.evaluate(None, Y[:1], Z[:1], fall[:1]).f[0] == pytest.approx(0.0, abs=1e-12)

    mass = float(scene.body_subtreemass[int(scene.jnt_bodyid[0])])
    wr = root.wrench(Y, Z, Z)
    np.testing.assert_allclose(wr[:, :3], [[0.0, 0.0, mass * G]] * 3, rtol=1e-12, atol=1e-9)  # [N]
    d = mujoco.MjData(scene)
    d.qpos[:] = normalized(layout, Y[1])
    mujoco.mj_kinematics(scene, d)
    mujoco.mj_comPos(scene, d)
    lever = d.subtree_com[int(scene.jnt_bodyid[0])] - Y[1, :3]
    np.testing.assert_allclose(wr[1, 3:], np.cross(lever, [0.0, 0.0, mass * G]), atol=1e-9)  # [N m]
    f = root.evaluate(None, Y, Z, Z, grad=False).f
    assert f[1] == pytest.approx((mass * G) ** 2 + (wr[1, 3:] ** 2).sum() / root.torque_arm**2, rel=1e-12)
    assert f[2] == 0.0  # in contact: the wrench is the ground's business
    assert 0.2 < root.torque_arm < 0.6  # [m] radius of gyration of a human-sized figure


def test_bad_arguments_name_the_fix(scene):
    with pytest.raises(InputError, match="unknown joint 'wrist'"):
        JointTorque(scene, weights={"wrist": 1.0})
    layout = StateLayout.from_model(scene)
    with pytest.raises(InputError, match=">= 0"):
        JointTorque(scene, weights={layout.joints[1].name: -1.0})
    with pytest.raises(InputError, match="free root"):
        JointTorque(scene, weights={layout.joints[0].name: 1.0})
    with pytest.raises(InputError, match="analytic, mujoco"):
        make_engine(scene, CONTACT_SITES, backend="magic")
    with pytest.raises(InputError, match="contact_distance"):
        RootResidual(scene, contact_distance=0.0)
    with pytest.raises(InputError, match="not tracked by the engine"):
        RootResidual(scene, engine=make_engine(scene, sites=()))
    with pytest.raises(InputError, match="no site 'nose'"):
        RootResidual(scene, sites=("nose",))
    assert RootResidual(scene, surfaces=StaticSurfaces.from_model(scene)).surfaces.count >= 1
