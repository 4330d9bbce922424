"""The near term (solver/terms/near.py): the departure from the plain spline, measured against MuJoCo's
own tangent-space difference and scipy's rotations, its gradient and residual Jacobian against central
differences, and a hand-built motion where no soft constraint is violated staying the plain spline."""
from dataclasses import replace

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from solver.animate import default_options, solve_problem
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.path_context import PathContext
from solver.problem import make_problem
from solver.terms.near import NearPlain, reference_length

from conftest import fd_gradient, random_qpos


def _wxyz(rot: Rotation) -> np.ndarray:
    x, y, z, w = rot.as_quat()
    return np.array([w, x, y, z])


def _constant(Y0):
    return lambda t: np.repeat(Y0[None], len(t), axis=0)


def test_value_is_the_mean_squared_tangent_distance(toy_model):
    """A path that holds the left knee 20 degrees (scipy) off the reference about a tilted axis, the
    root quaternion 10 degrees off, the root 6 cm away, over T = 2 s: the integral of f is
    (2 sin 10 deg)^2 + (2 sin 5 deg)^2 + (0.06 / L)^2 (constant in time, so its mean), and each
    quaternion's residual has the length of MuJoCo's `mj_differentiatePos` for that joint to 1 %."""
    layout = StateLayout.from_model(toy_model)
    ref = np.array(toy_model.qpos0, float)
    ref[layout.joint("l_hip").quat_index] = _wxyz(Rotation.from_euler("xyz", [10, -30, 5], degrees=True))
    Y0 = ref.copy()
    Y0[:3] += [0.03, -0.04, np.sqrt(0.06**2 - 0.05**2)]
    knee = layout.joint("l_knee").quat_index
    Y0[knee] = 1.7 * _wxyz(Rotation.from_rotvec(np.radians(20) * np.array([1, 2, 2]) / 3))  # not unit
    Y0[3:7] = -_wxyz(Rotation.from_rotvec(np.radians(10) * np.array([0, 0.6, 0.8])))  # the other hemisphere
    L = 0.7
    term = NearPlain(layout, _constant(ref), (1.0, 3.0), length=L)
    t = np.linspace(1.0, 3.0, 101)
    f = term.evaluate(t, np.repeat(Y0[None], len(t), axis=0), None, None, grad=False).f
    expected = (2 * np.sin(np.radians(10))) ** 2 + (2 * np.sin(np.radians(5))) ** 2 + (0.06 / L) ** 2
    np.testing.assert_allclose(f * 2.0, expected, rtol=1e-12)  # (1/T) f integrated over T = 2 s

    unit = Y0.copy()
    unit[knee] /= 1.7
    v = np.zeros(toy_model.nv)
    mujoco.mj_differentiatePos(toy_model, v, 1.0, ref, unit)
    r = term.residual(PathContext(t[:1], unit[None], None, None)).r[0] * np.sqrt(2.0)
    dof = toy_model.jnt_dofadr[toy_model.joint("l_knee").id]
    slot = list(map(tuple, layout.quat_slots)).index(tuple(knee))
    assert np.linalg.norm(r[3 + 3 * slot: 6 + 3 * slot]) == pytest.approx(np.linalg.norm(v[dof:dof + 3]), rel=0.01)
    np.testing.assert_allclose(r[:3] * L, v[:3], rtol=1e-12)  # root position: MuJoCo's world-frame difference


def test_zero_on_the_reference_and_without_one(toy_model):
    layout = StateLayout.from_model(toy_model)
    Y = random_qpos(np.random.default_rng(1), layout, 6)
    t = np.linspace(0, 1, 6)
    R = Y.copy()
    R[:, layout.quat_slots] *= -2.0  # a quaternion's scale and sign are not a departure
    on = NearPlain(layout, lambda s: R, (0.0, 1.0))
    np.testing.assert_allclose(on.evaluate(t, Y, None, None).f, 0.0, atol=1e-14)
    assert np.all(NearPlain(layout, None, (0.0, 1.0)).evaluate(t, Y, None, None).f == 0)


def test_gradient_and_residual_jacobian_match_central_differences(toy_model):
    """dY against central differences of sum f (to 1e-6 of the largest), f = |r|^2 (1e-12), and the
    compact residual blocks against central differences of r along a random direction (1e-6)."""
    layout = StateLayout.from_model(toy_model)
    rng = np.random.default_rng(7)
    Y, R = random_qpos(rng, layout, 7, spread=0.5), random_qpos(rng, layout, 7, spread=0.5)
    Y[3, layout.quat_slots[1]] *= -1.0  # a quaternion in the reference's other hemisphere
    t = np.linspace(0.0, 0.6, 7)
    term = NearPlain(layout, lambda s: R, (0.0, 0.6), length=0.8)
    ev = term.evaluate(t, Y, None, None)
    assert ev.f.min() > 0, "the term is zero on the test path: the check checks nothing"
    fd = fd_gradient(lambda Z: term.evaluate(t, Z, None, None, grad=False).f.sum(), Y)
    np.testing.assert_allclose(ev.dY, fd, atol=1e-6 * np.abs(fd).max())
    res = term.residual(PathContext(t, Y, None, None))
    np.testing.assert_allclose((res.r ** 2).sum(1), ev.f, rtol=1e-12)
    D = rng.normal(size=Y.shape)
    dr = (term.residual(PathContext(t, Y + 1e-6 * D)).r - term.residual(PathContext(t, Y - 1e-6 * D)).r) / 2e-6
    np.testing.assert_allclose(res.jvp(D), dr, atol=1e-6 * np.abs(dr).max())


def test_priced_like_another_term_a_rotation_costs_as_the_length_it_moves(toy_model):
    """With `renormalize_like`, f is not averaged over the clip: a knee 20 degrees off and the root 6 cm
    away give f = (L 2 sin 10 deg)^2 + 0.06^2 [m^2] at every instant, so that the integral is in the
    borrowed term's units (m^2 s); the gradient still matches central differences."""
    layout = StateLayout.from_model(toy_model)
    ref = np.array(toy_model.qpos0, float)
    Y0 = ref.copy()
    Y0[:3] += [0.0, 0.06, 0.0]
    Y0[layout.joint("l_knee").quat_index] = _wxyz(Rotation.from_euler("y", 20, degrees=True))
    L = 0.8
    term = NearPlain(layout, _constant(ref), (0.0, 2.0), length=L, renormalize_like="planted")
    assert term.renormalize_like == "planted"
    t = np.linspace(0.0, 2.0, 5)
    Y = np.repeat(Y0[None], len(t), axis=0)
    ev = term.evaluate(t, Y, None, None)
    np.testing.assert_allclose(ev.f, (L * 2 * np.sin(np.radians(10))) ** 2 + 0.06 ** 2, rtol=1e-12)
    fd = fd_gradient(lambda Z: term.evaluate(t, Z, None, None, grad=False).f.sum(), Y)
    np.testing.assert_allclose(ev.dY, fd, atol=1e-6 * np.abs(fd).max())


def test_reference_length_is_half_the_standing_height():
    class Fig:
        standing_height = 1.7

    assert reference_length(Fig()) == pytest.approx(0.85)
    assert reference_length(object()) == pytest.approx(0.85)


def _swing_keyframes(layout, nq):
    """A figure walking 1.2 m in the air (no surface near): legs swinging, pelvis turning; 5 keyframes."""
    times = np.linspace(0.0, 1.2, 5)
    V = np.zeros((5, nq))
    V[:, 0], V[:, 2] = np.linspace(0.0, 1.2, 5), 1.3
    for k, s in enumerate([0.0, 1.0, 0.0, -1.0, 0.0]):
        V[k, 3:7] = _wxyz(Rotation.from_euler("z", 30 * s, degrees=True))
        V[k, layout.joint("l_hip").quat_index] = _wxyz(Rotation.from_euler("y", 60 * s, degrees=True))
        V[k, layout.joint("r_hip").quat_index] = _wxyz(Rotation.from_euler("y", -60 * s, degrees=True))
        V[k, layout.joint("l_knee").quat_index] = _wxyz(Rotation.from_euler("y", 30 + 25 * s, degrees=True))
        V[k, layout.joint("r_knee").quat_index] = _wxyz(Rotation.from_euler("y", 30 - 25 * s, degrees=True))
    return Keyframes(times, V, np.ones_like(V, bool))


def _departure_deg(solution, layout):
    """[deg] the largest rotation of any quaternion of the optimized path from the plain spline's."""
    t = np.linspace(solution.initial.times[0], solution.initial.times[-1], 241)
    A, B = solution.frames.path(t), solution.initial.path(t)
    worst = 0.0
    for slot in layout.quat_slots:
        a = A[:, slot] / np.linalg.norm(A[:, slot], axis=1, keepdims=True)
        b = B[:, slot] / np.linalg.norm(B[:, slot], axis=1, keepdims=True)
        worst = max(worst, float(np.degrees(2 * np.arccos(np.clip(np.abs((a * b).sum(1)), 0, 1))).max()))
    return worst


@pytest.mark.slow
def test_a_motion_with_nothing_violated_stays_the_plain_spline(toy_model):
    """No surface near and every joint inside its limits: the only term that wants a change is the
    covariant acceleration (which is not the plain spline's Euclidean one), here at weight 1 (20x its
    default) so that it wants a visible one. With the near term at its default weight the optimized path
    stays within 1.5 degrees of the plain spline, and a heavier near term holds it closer than the
    solve without the term does (the check can fail)."""
    layout = StateLayout.from_model(toy_model)
    kf = _swing_keyframes(layout, toy_model.nq)
    got = {}
    for near in (None, 1.0, 100.0):
        terms = "penetration,unit,bending,smooth" + ("" if near is None else ",near")
        weights = {"smooth": 1.0, **({} if near is None else {"near": near})}
        problem = make_problem(toy_model, kf, terms, weights, rate=200.0)
        options = replace(default_options(dict(problem.weights)), max_evals=400)
        got[near] = _departure_deg(solve_problem(problem, options), layout)
    assert got[1.0] <= 1.5, f"with the near term the path left the plain spline by {got[1.0]:.2f} deg"
    assert got[100.0] < 0.5 * got[None], f"near at 100: {got[100.0]:.2f} deg, without it {got[None]:.2f}"
