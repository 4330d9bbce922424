"""The near_sites term (solver/terms/near_sites.py): the contact sites and the root near the plain
spline's, its value against MuJoCo's own site positions, its gradient and residual Jacobian against
central differences, and its scale borrowed from the planted term (eq. 7, `Objective.renormalize`)."""
import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from solver.layout import CONTACT_SITES, StateLayout
from solver.objective import Objective
from solver.path_context import PathContext
from solver.terms.contact import Planted
from solver.terms.near_sites import NearSites

from conftest import fd_gradient, random_qpos


def _constant(Y0):
    return lambda t: np.repeat(Y0[None], len(t), axis=0)


def _mujoco_sites(model, q):
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    return np.array([data.site(s).xpos for s in CONTACT_SITES])


def test_value_is_the_squared_distance_of_the_sites_and_the_root(toy_model):
    """A pose with the root 5 cm away and the left hip turned 25 degrees (scipy) from the reference:
    f = sum over the four contact sites of |p - p_ref|^2 (MuJoCo's `mj_kinematics`) + |root - root_ref|^2."""
    layout = StateLayout.from_model(toy_model)
    ref = np.array(toy_model.qpos0, float)
    q = ref.copy()
    q[:3] += [0.03, 0.0, -0.04]
    x, y, z, w = Rotation.from_euler("y", 25, degrees=True).as_quat()
    q[layout.joint("l_hip").quat_index] = [w, x, y, z]
    term = NearSites(toy_model, _constant(ref))
    t = np.linspace(0.0, 1.0, 5)
    f = term.evaluate(t, np.repeat(q[None], 5, axis=0), None, None, grad=False).f
    d = _mujoco_sites(toy_model, q) - _mujoco_sites(toy_model, ref)
    expected = (d ** 2).sum() + 0.05 ** 2
    assert np.linalg.norm(d[:2], axis=1).min() > 0.1, "the hip turn does not move the left foot: the check checks nothing"
    np.testing.assert_allclose(f, expected, rtol=1e-9)


def test_zero_on_the_reference_and_without_one(toy_model):
    layout = StateLayout.from_model(toy_model)
    Y = random_qpos(np.random.default_rng(3), layout, 5)
    t = np.linspace(0, 1, 5)
    np.testing.assert_allclose(NearSites(toy_model, lambda s: Y).evaluate(t, Y, None, None).f, 0.0, atol=1e-14)
    assert np.all(NearSites(toy_model, None).evaluate(t, Y, None, None).f == 0)


def test_gradient_and_residual_jacobian_match_central_differences(toy_model):
    """dY against central differences of sum f (1e-6 of the largest), f = |r|^2 (1e-12), and the
    residual's Jacobian (its compact blocks) along a random direction against central differences of r."""
    layout = StateLayout.from_model(toy_model)
    rng = np.random.default_rng(11)
    Y, R = random_qpos(rng, layout, 6, spread=0.5), random_qpos(rng, layout, 6, spread=0.5)
    t = np.linspace(0.0, 0.5, 6)
    term = NearSites(toy_model, lambda s: R)
    ev = term.evaluate(t, Y, None, None)
    assert ev.f.min() > 0
    fd = fd_gradient(lambda Z: term.evaluate(t, Z, None, None, grad=False).f.sum(), Y)
    np.testing.assert_allclose(ev.dY, fd, atol=1e-6 * np.abs(fd).max())
    res = term.residual(PathContext(t, Y, None, None))
    np.testing.assert_allclose((res.r ** 2).sum(1), ev.f, rtol=1e-12)
    D = rng.normal(size=Y.shape)
    dr = (term.residual(PathContext(t, Y + 1e-6 * D)).r - term.residual(PathContext(t, Y - 1e-6 * D)).r) / 2e-6
    np.testing.assert_allclose(res.jvp(D), dr, atol=1e-6 * np.abs(dr).max())
    gY = res.vjp(np.ones_like(res.r))[0]  # the product form agrees with the blocks
    np.testing.assert_allclose((gY * D).sum(), res.jvp(D).sum(), rtol=1e-9)


def test_its_scale_is_the_planted_terms(toy_model):
    """Eq. 7 cannot scale a term that is zero on the plain spline by its own value: near_sites takes
    planted's (the plain path here floats 3 cm over a contact: planted's integral (0.03 - h0)^2 x 0.5 s)."""
    layout = StateLayout.from_model(toy_model)
    Y = np.repeat(np.array(toy_model.qpos0, float)[None], 2, axis=0)
    Y[:, 2] = 0.95 + 0.03
    planted = Planted(toy_model, [type("C", (), {"site": "l_toe", "start": 0.25, "end": 0.75, "surface": ""})()],
                      rest_height=0.0)
    obj = Objective([planted, NearSites(toy_model, _constant(Y[0]))], np.array([10.0, 1.0]), 0.0, 1.0)
    scales = obj.renormalize(np.array([0.0, 1.0]), Y)
    assert scales["planted"] == pytest.approx(0.03 ** 2 * 0.5, rel=0.02)
    assert scales["near_sites"] == scales["planted"]
    assert layout.nq == Y.shape[1]
