"""The kinematics-only engine (`SiteKinematics`): site positions and velocities against MuJoCo
(mj_kinematics, mj_objectVelocity), its reverse pass (and the inverse dynamics' without a torque
gradient) against central differences, the velocity-only
`PathMotion`, and the contact terms on it against the same terms on the full inverse dynamics."""
from pathlib import Path

import mujoco
import numpy as np
import pytest
from shipped_sites import SITES as CONTACT_SITES
from tree_models import HINGE, ODD, tangent_step

from solver.errors import InputError
from solver.inverse_dynamics import InverseDynamics
from solver.kinematic_tree import SiteKinematics
from solver.kinematics import TangentMap
from solver.layout import StateLayout

from conftest import random_qpos

SCENE = Path(__file__).resolve().parents[2] / "models" / "run_and_step.xml"


@pytest.fixture(scope="module", params=["scene", "odd"])
def model(request):
    if request.param == "odd":
        return mujoco.MjModel.from_xml_string(ODD)
    if SCENE.exists():
        return mujoco.MjModel.from_xml_path(str(SCENE))
    return request.getfixturevalue("toy_model")


def _state(model, rng, n):
    Y = random_qpos(rng, StateLayout.from_model(model), n)
    return Y, rng.normal(size=(n, model.nv))


def test_sites_match_mujoco(model):
    rng = np.random.default_rng(11)
    Y, V = _state(model, rng, 5)
    eng = SiteKinematics(model, CONTACT_SITES)
    res = eng.forward(Y, V)
    d = mujoco.MjData(model)
    vel = np.zeros(6)
    for i in range(len(Y)):
        d.qpos[:], d.qvel[:] = Y[i], V[i]
        mujoco.mj_forward(model, d)
        for j, sid in enumerate(eng.site_ids):
            np.testing.assert_allclose(res.sites[i, j], d.site_xpos[sid], atol=1e-12)
            mujoco.mj_objectVelocity(model, d, mujoco.mjtObj.mjOBJ_SITE, int(sid), vel, 0)
            np.testing.assert_allclose(eng.site_velocities(res)[i, j], vel[3:], atol=1e-10)
    assert not res.tau.any() and res.qacc.shape == (len(Y), 0)
    assert eng.forward(Y.copy(), V.copy()) is res  # cached by value


@pytest.mark.parametrize("engine", [SiteKinematics, InverseDynamics])
def test_vjp_matches_central_differences(model, engine):
    """The sites' reverse pass: SiteKinematics's, and InverseDynamics's without a torque gradient (g_tau
    None: its forces' reverse pass is skipped)."""
    rng = np.random.default_rng(12)
    n, nv = 3, model.nv
    Y, V = _state(model, rng, n)
    A = rng.normal(size=(n, nv))  # read by the inverse dynamics only
    eng = engine(model, CONTACT_SITES)
    gs, gv = rng.normal(size=(n, 4, 3)), rng.normal(size=(n, 4, 3))
    Gq, Gv, Ga = eng.vjp(eng.forward(Y, V, A), None, gs, gv)
    assert Ga is None

    def phi(Y_, V_):
        r = eng.forward(Y_, V_, A)
        return (r.sites * gs).sum((1, 2)) + (eng.site_velocities(r) * gv).sum((1, 2))

    h = 1e-6
    fq, fv = np.zeros((n, nv)), np.zeros((n, nv))
    for i in range(nv):
        e = np.zeros((n, nv))
        e[:, i] = h
        fq[:, i] = (phi(tangent_step(model, Y, e), V) - phi(tangent_step(model, Y, -e), V)) / (2 * h)
        fv[:, i] = (phi(Y, V + e) - phi(Y, V - e)) / (2 * h)
    np.testing.assert_allclose(Gq, fq, rtol=0, atol=1e-6 * (1 + np.abs(fq).max()))
    np.testing.assert_allclose(Gv, fv, rtol=0, atol=1e-6 * (1 + np.abs(fv).max()))


def test_pose_only_site_positions_and_their_reverse_pass(model):
    """`KinematicTree.site_positions` against MuJoCo's mj_kinematics, and `site_positions_vjp` on a subset
    of the rows against central differences of those positions (the penetration term's pass)."""
    rng = np.random.default_rng(14)
    n, nv = 5, model.nv
    Y, _ = _state(model, rng, n)
    tree = SiteKinematics(model, CONTACT_SITES)
    P, pose = tree.site_positions(Y)
    d = mujoco.MjData(model)
    for i in range(n):
        d.qpos[:] = Y[i]
        mujoco.mj_kinematics(model, d)
        np.testing.assert_allclose(P[i], d.site_xpos[tree.site_ids], rtol=0, atol=1e-12)
    rows = np.array([1, 3, 4])
    gs = rng.normal(size=(len(rows), 4, 3))
    G = tree.site_positions_vjp(pose, gs, rows)
    assert G.shape == (len(rows), nv)

    def phi(Y_):
        return (tree.site_positions(Y_)[0] * gs).sum((1, 2))

    h, fd = 1e-6, np.zeros((len(rows), nv))
    for i in range(nv):
        e = np.zeros((len(rows), nv))
        e[:, i] = h
        fd[:, i] = (phi(tangent_step(model, Y[rows], e)) - phi(tangent_step(model, Y[rows], -e))) / (2 * h)
    np.testing.assert_allclose(G, fd, rtol=0, atol=1e-6 * (1 + np.abs(fd).max()))
    np.testing.assert_array_equal(tree.site_positions_vjp(pose, np.zeros((n, 4, 3))), 0.0)  # all rows, no adjoint


def test_velocity_only_motion_matches_the_full_one():
    model = mujoco.MjModel.from_xml_string(ODD)
    layout = StateLayout.from_model(model)
    tm = TangentMap.from_layout(layout)
    rng = np.random.default_rng(13)
    Y = random_qpos(rng, layout, 4)
    Y1, Y2 = rng.normal(size=Y.shape), rng.normal(size=Y.shape)
    full, vel = tm.motion(Y, Y1, Y2), tm.motion(Y, Y1, None)
    assert vel.qacc is None
    np.testing.assert_array_equal(vel.qvel, full.qvel)
    g, gp = rng.normal(size=(4, tm.nv)), rng.normal(size=(4, tm.nv))
    for a, b in zip(vel.vjp(g, None, gp), full.vjp(g, None, gp), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13)
    with pytest.raises(ValueError, match="no qacc"):
        vel.vjp(g, g)


def test_the_engines_partial_tangent_map_gives_the_full_maps_bits(model):
    """`SiteKinematics.motion_map` (the joints the engine reads: the legs and the root) against the full
    map: qvel (and qacc) the same bits on those joints and 0 on the others, and the same pullback of
    adjoints that are 0 on the others (the engine's). A map of every joint is the full map itself."""
    layout = StateLayout.from_model(model)
    full = TangentMap.from_layout(layout)
    part = SiteKinematics(model, CONTACT_SITES).motion_map
    assert full.subset(np.arange(full.nv)) is full
    assert not full.partial
    kept = np.concatenate([part.quat_v.ravel(), part.lin_v.ravel()]).astype(int)
    other = np.setdiff1d(np.arange(full.nv), kept)
    rng = np.random.default_rng(14)
    Y = random_qpos(rng, layout, 5)
    Y1, Y2 = rng.normal(size=Y.shape), rng.normal(size=Y.shape)
    a, b = full.motion(Y, Y1, Y2), part.motion(Y, Y1, Y2)
    for x, y in ((a.qvel, b.qvel), (a.qacc, b.qacc)):
        assert np.array_equal(x[:, kept].view(np.int64), y[:, kept].view(np.int64))
        np.testing.assert_array_equal(y[:, other], 0.0)
    g, gp = rng.normal(size=(5, full.nv)), rng.normal(size=(5, full.nv))
    g[:, other] = gp[:, other] = 0.0
    for x, y in zip(a.vjp(g, None, gp), b.vjp(g, None, gp), strict=True):
        np.testing.assert_array_equal(x, y)  # values: a zero's sign may differ where the full map adds 0s
    if part.partial:  # the figure: 7 of its 12 quaternions
        assert len(other) and len(part.quat_q) < len(full.quat_q)


def test_unsupported_joints_are_named():
    with pytest.raises(InputError, match="elbow.*hinge"):
        SiteKinematics(mujoco.MjModel.from_xml_string(HINGE))


def test_forward_without_qvel_is_the_pose_pass(model):
    """`SiteKinematics.forward(qpos, None)`: the positions of the full pass (to 1e-14 m), no velocities,
    and a `vjp` of site-position adjoints (zero on some rows) equal to the full pass's pose gradient
    (to 1e-12 of its largest entry) with no qvel gradient."""
    rng = np.random.default_rng(21)
    n = 6
    Y, V = _state(model, rng, n)
    eng = SiteKinematics(model, CONTACT_SITES)
    full = eng.forward(Y, V)
    pose = eng.forward(Y, None)
    assert pose is not full and pose.qvel.size == 0
    np.testing.assert_allclose(pose.sites, full.sites, rtol=0, atol=1e-14)
    g = rng.normal(size=full.sites.shape)
    g[[0, 3]] = 0.0
    Gq_full, _, _ = eng.vjp(full, None, g)
    Gq, Gv, Ga = eng.vjp(pose, None, g)
    assert Gv is None and Ga is None
    np.testing.assert_allclose(Gq, Gq_full, rtol=0, atol=1e-12 * np.abs(Gq_full).max())
    assert not np.any(Gq[[0, 3]])
