"""Each objective term's gradient against central finite differences, and its value against
hand-computed cases."""
import mujoco
import numpy as np
import pytest

from solver.layout import StateLayout
from solver.terms import CovariantAcceleration, Hyperextension, Penetration, UnitQuaternion

from conftest import fd_gradient, random_qpos

HINGES = {"l_knee": (0, 1, 0), "r_knee": (0, -1, 0)}


def check_term_gradient(term, Y, Y1, Y2, rtol=1e-5, atol=1e-7):
    t = np.linspace(0, 1, len(Y))
    ev = term.evaluate(t, Y, Y1, Y2, grad=True)
    for k, (X, g) in enumerate(((Y, ev.dY), (Y1, ev.dY1), (Y2, ev.dY2))):
        if k not in term.needs:
            assert g is None
            continue
        if g is None:
            g = np.zeros_like(X)

        def f(Z, k=k):
            args = [Y, Y1, Y2]
            args[k] = Z
            return term.evaluate(t, *args, grad=False).f.sum()

        np.testing.assert_allclose(g, fd_gradient(f, X), rtol=rtol, atol=atol, err_msg=f"d/dY{k}")


@pytest.fixture()
def layout(toy_model):
    return StateLayout.from_model(toy_model)


def test_unit_quaternion_value_and_gradient(layout):
    rng = np.random.default_rng(0)
    Y = random_qpos(rng, layout, 5)
    term = UnitQuaternion(layout.quat_slots)
    n = np.linalg.norm(Y[:, layout.quat_slots], axis=-1)
    np.testing.assert_allclose(term.evaluate(None, Y, None, None).f, ((1 - n**2) ** 2).sum(1))
    check_term_gradient(term, Y, None, None)


def test_covariant_acceleration_value_and_gradient(layout):
    rng = np.random.default_rng(1)
    Y = random_qpos(rng, layout, 4)
    Y2 = rng.normal(size=Y.shape)
    term = CovariantAcceleration(layout.quat_slots, layout.linear_index)
    q, a = Y[:, layout.quat_slots], Y2[:, layout.quat_slots]
    radial = q * ((a * q).sum(-1) / (q * q).sum(-1))[..., None]
    expect = ((a - radial) ** 2).sum((1, 2)) + (Y2[:, layout.linear_index] ** 2).sum(1)
    np.testing.assert_allclose(term.evaluate(None, Y, None, Y2).f, expect)
    check_term_gradient(term, Y, None, Y2)


def test_covariant_acceleration_of_a_great_circle_is_zero():
    """Uniform rotation q(t) = (cos wt, sin wt, 0, 0): q'' = -w^2 q is purely radial."""
    from solver.layout import StateLayout

    lay = StateLayout.single_quaternion()
    t = np.linspace(0, 1, 9)
    w = 1.7
    Y = np.stack([np.cos(w * t), np.sin(w * t), 0 * t, 0 * t], 1)
    term = CovariantAcceleration(lay.quat_slots)
    np.testing.assert_allclose(term.evaluate(t, Y, None, -(w**2) * Y).f, 0, atol=1e-12)


def test_hyperextension_angle_and_gradient(layout):
    term = Hyperextension(layout, HINGES)
    Y = random_qpos(np.random.default_rng(0), layout, 1, spread=0.0, scale=(1, 1)).repeat(3, 0)
    knee = layout.joint("l_knee").quat_index
    for i, deg in enumerate([20.0, -5.0, -40.0]):  # flexion 20 deg, hyperextension 5 and 40 deg
        a = np.radians(deg)
        Y[i, knee] = 1.3 * np.array([np.cos(a / 2), 0, np.sin(a / 2), 0])  # about +y, scaled
    np.testing.assert_allclose(np.degrees(term.angles(Y)[:, 0]), [20, -5, -40], atol=1e-9)
    np.testing.assert_allclose(term.evaluate(None, Y, None, None).f, np.radians([0, 5, 40]) ** 2, atol=1e-12)
    Y[:, knee] *= -1  # the same rotation written as -q gives the same angle
    np.testing.assert_allclose(np.degrees(term.angles(Y)[:, 0]), [20, -5, -40], atol=1e-9)
    rng = np.random.default_rng(3)
    Yr = random_qpos(rng, layout, 6, spread=0.5)
    assert term.evaluate(None, Yr, None, None).f.sum() > 0  # some random samples hyperextend
    check_term_gradient(term, Yr, None, None)


def test_penetration_value_and_gradient(toy_model, layout):
    term = Penetration(toy_model, margin=0.0)
    Y = random_qpos(np.random.default_rng(0), layout, 1, spread=0.0, scale=(1, 1))
    # identity pose: soles 0.95 m below the pelvis; pelvis at z = 0.9 puts every site 5 cm deep
    Y[0, :3] = [0, 0, 0.9]
    np.testing.assert_allclose(term.evaluate(None, Y, None, None).f, [4 * 0.05**2], atol=1e-12)
    # over the step box (top at z = 0.2): pelvis at z = 1.12 -> sites 3 cm inside the box
    Y[0, :3] = [1.5, 0, 1.12]
    np.testing.assert_allclose(term.evaluate(None, Y, None, None).f, [4 * 0.03**2], atol=1e-12)
    rng = np.random.default_rng(5)
    Yr = random_qpos(rng, layout, 6, spread=0.25)
    Yr[:, 2] = 0.9
    Yr[:3, 0] = 1.5
    assert np.count_nonzero(term.evaluate(None, Yr, None, None).f) >= 3
    check_term_gradient(term, Yr, None, None, rtol=1e-5, atol=1e-8)


def mujoco_penetration(model, Y, sites, margin):
    """The reference: f = sum depth^2 and its gradient from MuJoCo point by point (`mj_kinematics`
    positions, `mj_jacSite` Jacobians, mapped to qpos by `TangentMap.pullback`)."""
    from solver.kinematics import TangentMap
    from solver.layout import site_ids
    from solver.surfaces import StaticSurfaces

    d = mujoco.MjData(model)
    ids = site_ids(model, sites)
    surfaces = StaticSurfaces.from_model(model, d)
    tmap = TangentMap.from_layout(StateLayout.from_model(model))
    f, dY = np.zeros(len(Y)), np.zeros(Y.shape)
    jac = np.zeros((3, model.nv))
    for i, y in enumerate(Y):
        d.qpos[:] = y
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        depth, ddepth = surfaces.penetration(d.site_xpos[ids][None], margin)
        f[i] = (depth * depth).sum()
        gv = np.zeros(model.nv)
        for k, sid in enumerate(ids):
            mujoco.mj_jacSite(model, d, jac, None, int(sid))
            gv += np.einsum("s,si->i", 2.0 * depth[0, k], ddepth[0, k]) @ jac
        dY[i] = tmap.pullback(y[None], gv[None])[0]
    return f, dY


def test_penetration_matches_mujoco_point_by_point(toy_model, layout):
    """The term's one path (its engine's vectorized forward and reverse pass through a `PathContext`)
    against MuJoCo point by point (`mujoco_penetration`): values to 1e-12 m^2, gradients to 1e-9 of
    their largest entry; a hinge model (which the vectorized tree does not cover) gets MuJoCo's engine."""
    from tree_models import HINGE

    from solver.path_context import MujocoSitePositions

    rng = np.random.default_rng(7)
    Y = random_qpos(rng, layout, 40, spread=0.3)
    Y[:, 2] = rng.uniform(0.85, 1.0, 40)  # most points with a site inside the floor, some clear
    Y[::3, 0] = 1.5  # over the step box
    term = Penetration(toy_model, margin=0.005)
    ev = term.evaluate(None, Y, None, None)
    f, dY = mujoco_penetration(toy_model, Y, term_sites(term), 0.005)
    assert 0 < np.count_nonzero(f) < len(Y)
    np.testing.assert_allclose(ev.f, f, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ev.dY, dY, rtol=0, atol=1e-9 * np.abs(dY).max())
    np.testing.assert_array_equal(term.depths(Y).max(axis=1) > 0, f > 0)  # the query reads the same engine
    xml = HINGE.replace('pos="0 0 1"', 'pos="0 0 .1"').replace('size=".03"/>', 'size=".03"/><site name="tip" pos=".3 0 0"/>').replace(
        "</worldbody>", '<geom type="plane" size="5 5 .1"/></worldbody>')
    hinge = Penetration(mujoco.MjModel.from_xml_string(xml), sites=["tip"], margin=0.0)
    assert isinstance(hinge.engine, MujocoSitePositions)
    np.testing.assert_allclose(hinge.evaluate(None, np.array([[np.pi / 2], [0.0]]), None, None).f, [0.2**2, 0.0],
                               atol=1e-12)  # the tip swung 0.2 m below the floor, then level and clear


def term_sites(term):
    """The names of the sites a penetration term reads (its engine's, in the term's order)."""
    ids = np.asarray(term.engine.site_ids)[term.site_index]
    return [mujoco.mj_id2name(term.model, mujoco.mjtObj.mjOBJ_SITE, int(i)) for i in np.atleast_1d(ids)]


def test_pointwise_terms_evaluate_the_same_on_any_split_of_the_points(layout):
    """`Term.pointwise` (the objective then evaluates the term on blocks of points): f and the
    gradients on each half of the points are the rows of the whole evaluation."""
    from solver.terms import NormalizedCovariantAcceleration

    rng = np.random.default_rng(6)
    Y = random_qpos(rng, layout, 9)
    Y1, Y2 = rng.normal(size=Y.shape), rng.normal(size=Y.shape)
    t = np.linspace(0, 1, 9)
    terms = [UnitQuaternion(layout.quat_slots), CovariantAcceleration(layout.quat_slots, layout.linear_index),
             NormalizedCovariantAcceleration(layout.quat_slots), Hyperextension(layout, HINGES, tolerance=-0.3)]
    for term in terms:
        assert term.pointwise, term.name
        whole = term.evaluate(t, Y, Y1, Y2, grad=True)
        parts = [term.evaluate(t[s], Y[s], Y1[s], Y2[s], grad=True) for s in (slice(0, 4), slice(4, 9))]
        for field in ("f", "dY", "dY1", "dY2"):
            w = getattr(whole, field)
            if w is None:
                assert all(getattr(p, field) is None for p in parts)
                continue
            np.testing.assert_allclose(np.concatenate([getattr(p, field) for p in parts]), w, rtol=1e-15, atol=0,
                                       err_msg=f"{term.name} {field}")
    assert not Penetration.pointwise  # reads its engine's pass and defers its gradient to it
