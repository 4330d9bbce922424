"""The preconditioner's radial weight from the terms' curvatures (`auto_radial_weight`)."""
import numpy as np
import pytest
import scipy.linalg

from solver.errors import InputError
from solver.frames import FrameSet
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.objective import Objective
from solver.paper.precondition import AccelerationPreconditioner, auto_radial_weight
from solver.paper.solve import SolveOptions, solve
from solver.spline import spline_matrices
from solver.terms import CovariantAcceleration, UnitQuaternion

LAYOUT = StateLayout.single_quaternion()


def quat(axis, deg):
    a = np.radians(deg) / 2
    return np.concatenate([[np.cos(a)], np.sin(a) * np.asarray(axis, float) / np.linalg.norm(axis)])


def problem(unit_weight=1.0, rate=200):
    times = np.array([0.0, 0.5, 1.2, 1.6, 2.5])
    axes = [[1, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1]]
    qs = np.array([quat(a, d) for a, d in zip(axes, [0, 70, 60, -50, 90])])
    kf = Keyframes(times, qs, np.ones_like(qs, bool))
    obj = Objective([UnitQuaternion(LAYOUT.quat_slots), CovariantAcceleration(LAYOUT.quat_slots)],
                    [unit_weight, 0.05], times[0], times[-1], rate=rate)
    fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots).with_variable_frames([0.25, 0.8, 1.0, 1.4, 2.0, 2.2])
    return obj, fs


def test_auto_radial_weight_is_the_smallest_ratio_of_value_to_acceleration_curvature():
    """w = the smallest generalized eigenvalue of (G, A) over the free frames, with G = 8 lambda_unit
    h W^T W (the unit term's radial Gauss-Newton curvature) and A = 2 lambda_smooth h W2^T W2 (the
    acceleration curvature): w A <= G on every mode, and no larger multiple is. Reference: dense W, W2
    and scipy's generalized symmetric eigensolver."""
    obj, fs = problem()
    basis = obj.basis(fs.times)
    H = basis.gram(2, 2.0 * obj.h)
    w, slots = auto_radial_weight(obj, fs, H)
    np.testing.assert_array_equal(slots, LAYOUT.quat_slots)
    rows = np.flatnonzero(~fs.is_keyframe)
    W, _, W2 = spline_matrices(fs.times, obj.t)
    G = 8.0 * 1.0 * obj.h * (W.T @ W)[np.ix_(rows, rows)]
    A = 2.0 * 0.05 * obj.h * (W2.T @ W2)[np.ix_(rows, rows)]
    ref = scipy.linalg.eigh(G, A, eigvals_only=True)
    assert w == pytest.approx(ref[0], rel=1e-8)
    assert ref[-1] > 5 * ref[0]  # the ratio is far from one number: the weight must pick one end
    assert np.linalg.eigvalsh(G - w * A)[0] >= -1e-9 * np.abs(G).max()
    assert np.linalg.eigvalsh(G - 1.01 * w * A)[0] < 0


def test_auto_radial_weight_without_a_unit_term_is_one():
    obj, fs = problem(unit_weight=0.0)
    assert auto_radial_weight(obj, fs, obj.basis(fs.times).gram(2, 2.0 * obj.h)) == (1.0, ())
    pre = AccelerationPreconditioner(obj, fs, radial_weight="auto")
    assert pre.radial_weight == 1.0 and pre.radial == []


def test_auto_weight_uses_the_unit_terms_slots_and_is_scale_free():
    """The weight depends on the terms' weights over their scales: doubling both leaves it; the stretch
    acts on the unit term's quaternion (quat_slots in the options are not needed)."""
    obj, fs = problem()
    pre = AccelerationPreconditioner(obj, fs, radial_weight="auto")
    assert pre.radial_weight != 1.0 and len(pre.radial) == 1
    obj.weights = obj.weights * 2.0
    obj.scales = obj.scales * 2.0
    assert AccelerationPreconditioner(obj, fs, radial_weight="auto").radial_weight == pytest.approx(pre.radial_weight)


def test_solve_options_take_auto_and_reject_other_words():
    SolveOptions(precondition=True, radial_weight="auto")
    with pytest.raises(InputError, match="radial_weight must be a number > 0 or 'auto'"):
        SolveOptions(radial_weight="automatic")
    with pytest.raises(InputError, match="radial_weight"):
        SolveOptions(radial_weight=0.0)


def test_auto_weight_reaches_the_same_optimum_in_fewer_evaluations():
    """Only the metric changes: the same minimum (tight tolerance), and the unit term's stiff radial
    directions no longer slow L-BFGS down."""
    obj, fs = problem()
    opts = dict(subdivision="none", precondition=True, ftol_rel=1e-12, renormalize=True)
    auto = solve(obj, fs, SolveOptions(**opts, radial_weight="auto"))
    plain = solve(obj, fs, SolveOptions(**opts))
    assert auto.E_final == pytest.approx(plain.E_final, rel=1e-7)
    assert auto.n_evals < plain.n_evals


def test_factor_is_the_inverse_cholesky_factor_and_is_shared_on_the_same_knots():
    """R^-1 with R^T R = H (+ ridge), H the Hessian of integral |Y''|^2 (2 h W2^T W2 on the uniform
    rule); a second preconditioner on the same knots (the next round, the optimization check) reuses
    it, and frames on other knots get their own."""
    obj, fs = problem()
    a = AccelerationPreconditioner(obj, fs, 1.0)
    rows, comps, Rinv = a.groups[0]
    _, _, W2 = spline_matrices(fs.times, obj.t)
    H = 2.0 * obj.h * W2.T @ W2
    Hr = H[np.ix_(rows, rows)]
    R = np.linalg.inv(Rinv)
    np.testing.assert_allclose(R.T @ R, Hr, rtol=1e-8, atol=1e-8 * np.abs(Hr).max())
    assert np.allclose(np.tril(Rinv, -1), 0.0)
    b = AccelerationPreconditioner(obj, fs.with_x(fs.x() * 0.9), 0.3, LAYOUT.quat_slots)
    assert b.groups[0][2] is Rinv
    c = AccelerationPreconditioner(obj, fs.with_variable_frames([0.6]), 1.0)
    assert c.groups[0][2].shape[0] == Rinv.shape[0] + 1
