"""Each objective term's gradient against central finite differences, and its value against
hand-computed cases."""
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


def test_penetration_tree_and_mujoco_paths_agree(toy_model, layout):
    """The vectorized pass (`KinematicTree`) and MuJoCo point by point (the path for models the tree
    does not cover) give the same values and gradients; a hinge model takes the MuJoCo path."""
    import mujoco
    from tree_models import HINGE

    rng = np.random.default_rng(7)
    Y = random_qpos(rng, layout, 40, spread=0.3)
    Y[:, 2] = rng.uniform(0.85, 1.0, 40)  # most points with a site inside the floor, some clear
    Y[::3, 0] = 1.5  # over the step box
    tree, mj = Penetration(toy_model, margin=0.005), Penetration(toy_model, margin=0.005)
    mj._tree = None
    assert tree._tree is not None
    a, b = tree.evaluate(None, Y, None, None), mj.evaluate(None, Y, None, None)
    assert 0 < np.count_nonzero(a.f) < len(Y)
    np.testing.assert_allclose(a.f, b.f, rtol=0, atol=1e-15)
    np.testing.assert_allclose(a.dY, b.dY, rtol=0, atol=1e-11 * np.abs(b.dY).max())
    np.testing.assert_allclose(tree.depths(Y), mj.depths(Y), rtol=0, atol=1e-12)
    xml = HINGE.replace('pos="0 0 1"', 'pos="0 0 .1"').replace('size=".03"/>', 'size=".03"/><site name="tip" pos=".3 0 0"/>').replace(
        "</worldbody>", '<geom type="plane" size="5 5 .1"/></worldbody>')
    hinge = Penetration(mujoco.MjModel.from_xml_string(xml), sites=["tip"], margin=0.0)
    assert hinge._tree is None
    np.testing.assert_allclose(hinge.evaluate(None, np.array([[np.pi / 2], [0.0]]), None, None).f, [0.2**2, 0.0],
                               atol=1e-12)  # the tip swung 0.2 m below the floor, then level and clear


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
    assert not Penetration.pointwise  # keeps a MuJoCo scratch state; may defer its gradient to an engine
