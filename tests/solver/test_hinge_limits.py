"""The hinge constraint's limits (solver.constraints.anatomy): each knee's and elbow's rotation off its hinge is
held to the largest swing of a known path through the keyframes: the capture they came from (with the
keyframes' own swing), else the plain spline. Checked on keyframes whose right elbow swings a known angle
off its hinge (built from an axis and an angle with scipy's rotations), where the plain spline overshoots
that angle between them; the swings are measured by scipy's rotations (the twist about the axis taken out)."""
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import solver
from solver.constraint_set import TOLERANCES
from solver.least_change import build_least_change
from solver.spline import interpolate
from solver.terms.anatomy_table import off_hinge_angles

SWING = 40.0  # [deg] the keyed right elbow's swing off its hinge
WIDER = 55.0  # [deg] the capture's largest swing there


def _swing(axis: np.ndarray, deg: float) -> np.ndarray:
    """(w, x, y, z) of a rotation by deg about a unit axis perpendicular to `axis` (a pure swing)."""
    perp = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    xyzw = Rotation.from_rotvec(np.radians(deg) * perp / np.linalg.norm(perp)).as_quat()
    return np.r_[xyzw[3], xyzw[:3]]


@pytest.fixture(scope="module")
def swung():
    """The shipped keyframes with the right elbow straight on the first half of them and swung SWING off its
    hinge on the second: a step the natural spline overshoots."""
    model = solver.load_model(solver.shipped("run_and_step.xml"))
    keyframes, _ = solver.read_keyframes(solver.shipped("run_and_step.keyframes.json"), model)
    layout = solver.StateLayout.from_model(model)
    axis = np.array(solver.Figure.from_model(model).flexion_axes["r_elbow"], float)
    axis = axis / np.linalg.norm(axis)
    qi = layout.joint("r_elbow").quat_index
    values = keyframes.values.copy()
    half = len(values) // 2
    values[:half, qi] = [1.0, 0.0, 0.0, 0.0]
    values[half:, qi] = _swing(axis, SWING)
    return model, replace(keyframes, values=values), qi, axis


def _swing_angle(q: np.ndarray, axis: np.ndarray) -> float:
    """[rad] the swing of the rotation (w, x, y, z) off `axis`: what is left of it once its twist about the
    axis (the quaternion's projection onto it) is taken out."""
    r = Rotation.from_quat(np.r_[q[1:], q[0]])
    twist = np.r_[(q[1:] @ axis) * axis, q[0]]
    return float((r * Rotation.from_quat(twist / np.linalg.norm(twist)).inv()).magnitude())


def _hinge(lc):
    return next(c for c in lc.al.constraints if c.name == "hinge")


def _limit(hinge, joint):
    return float(hinge.limit[list(hinge.labels).index(joint)])


def test_a_capture_holds_the_hinge_to_its_swing_not_the_plain_splines_overshoot(swung):
    """A capture through the keyframes that swings the right elbow SWING all along: the limit is SWING,
    where the plain spline through the keyframes overshoots it; the left elbow's is its largest swing at
    the keyframes that fix it or in the capture."""
    model, keyframes, qi, axis = swung
    plain = build_least_change(model, keyframes).plain
    t = np.linspace(plain.times[0], plain.times[-1], 2001)
    over = off_hinge_angles(interpolate(plain.times, plain.values, t), qi[None], axis[None])
    assert np.degrees(over.max()) > SWING + 1.0  # the plain spline overshoots the keyed swing
    times = np.linspace(plain.times[0], plain.times[-1], 241)
    qpos = interpolate(plain.times, plain.values, times)
    qpos[:, qi] = _swing(axis, SWING)
    lc = build_least_change(model, keyframes, capture=(times, qpos))
    assert np.degrees(_limit(_hinge(lc), "r_elbow")) == pytest.approx(SWING, abs=1e-9)
    layout = solver.StateLayout.from_model(model)
    left = np.array(solver.Figure.from_model(model).flexion_axes["l_elbow"], float)
    left = left / np.linalg.norm(left)
    li = layout.joint("l_elbow").quat_index
    fixed = keyframes.mask[:, li].all(axis=1)  # a partial keyframe that leaves the joint free forces nothing
    known = [_swing_angle(q, left) for q in np.r_[keyframes.values[fixed][:, li], qpos[:, li]]]
    assert _limit(_hinge(lc), "l_elbow") == pytest.approx(max(max(known), TOLERANCES["hinge"]), abs=1e-9)


def test_a_capture_through_the_keyframes_widens_the_hinge_to_its_own_swing(swung):
    """The capture the keyframes came from swings WIDER between them: a known path through them does, so the
    limit is its largest swing."""
    model, keyframes, qi, axis = swung
    plain = build_least_change(model, keyframes).plain
    times = np.linspace(plain.times[0], plain.times[-1], 241)
    qpos = interpolate(plain.times, plain.values, times)
    qpos[:, qi] = _swing(axis, SWING)
    qpos[120, qi] = _swing(axis, WIDER)
    lc = build_least_change(model, keyframes, capture=(times, qpos))
    assert np.degrees(_limit(_hinge(lc), "r_elbow")) == pytest.approx(WIDER, abs=1e-9)


def test_without_a_capture_the_plain_spline_is_the_known_path(swung):
    """Keyframes alone (an animator's): the plain spline is the only path known to pass through them, so the
    limit is its own largest swing at the quadrature points."""
    model, keyframes, qi, axis = swung
    lc = build_least_change(model, keyframes)
    Y = interpolate(lc.plain.times, lc.plain.values, lc.al.t)
    expected = max(_swing_angle(q, axis) for q in Y[:, qi])
    assert np.degrees(expected) > SWING + 1.0
    assert _limit(_hinge(lc), "r_elbow") == pytest.approx(expected, abs=1e-9)


def test_hyperextension_is_held_a_rotation_resolution_inside_its_bound(swung):
    """The acceptance bound is hyperextension <= the plain spline's + 0.5 degree, measured at 1000 Hz; the constraint
    holds at the quadrature points, so its tolerance is the bound's 0.5 degree less a capture's 0.1 degree rotation
    resolution (a keyed walk left at the edge of 0.5 degree measured 0.0007 degree beyond it between the points)."""
    model, keyframes, _, _ = swung
    lc = build_least_change(model, keyframes)
    bend = next(c for c in lc.al.constraints if c.name == "hyperextension")
    assert np.degrees(bend.tolerance) == pytest.approx(0.5 - 0.1, abs=1e-12)
