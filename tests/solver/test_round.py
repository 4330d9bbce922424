"""`solver.paper.round`: the functions of z that nlopt minimizes in one round, against the generic path.

The fast paths for whole free frames fold R^-1 (and the radial stretch) next to the spline matrices;
they must be the same function of z as x = x0 + `AccelerationPreconditioner.apply`(z) through
`Objective.evaluate`, with the gradient mapped by `apply_transpose`.
"""
import numpy as np
import pytest

from solver.frames import FrameSet
from solver.optimize import Status, Stop
from solver.paper.orient import LAYOUT, build_objective, check_keyframes
from solver.paper.precondition import AccelerationPreconditioner
from solver.paper.round import _orientation_fun, _whole_frames_fun


def quat(axis, deg):
    a = np.radians(deg) / 2
    return np.concatenate([[np.cos(a)], np.sin(a) * np.asarray(axis, float) / np.linalg.norm(axis)])


def orientation(radial_weight):
    times = np.array([0.0, 0.4, 1.3, 1.8, 3.0])
    axes = [[1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1], [1, 0, 1]]
    kf = check_keyframes(times, [quat(a, d) for a, d in zip(axes, [0, 100, -60, 140, 30])])
    obj, _, _ = build_objective(kf)  # normalized form, Gauss quadrature: the fused objective
    fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots).with_variable_frames([0.2, 0.9, 1.1, 1.55, 2.4])
    pre = AccelerationPreconditioner(obj, fs, radial_weight, LAYOUT.quat_slots)
    return obj, fs, pre


def reference(obj, fs, pre, z):
    ev = obj.evaluate(fs.times, fs.values_from_x(fs.x() + pre.apply(z)))
    return ev.E, pre.apply_transpose(ev.grad[fs.free])


@pytest.mark.parametrize("radial_weight", [0.1, 1.0])
@pytest.mark.parametrize("maker", [_orientation_fun, _whole_frames_fun])
def test_whole_frames_functions_are_the_generic_function_of_z(maker, radial_weight):
    obj, fs, pre = orientation(radial_weight)
    assert obj.fused_orientation
    rows, radial = pre.whole_rows(), pre.whole_radial()
    assert (radial[0] is None) == (radial_weight == 1.0)
    fun = maker(obj, obj.basis(fs.times), fs, rows, pre.groups[0][2], radial)
    rng = np.random.default_rng(3)
    for scale in (0.0, 0.05, 0.3):
        z = scale * rng.normal(size=fs.n_free)
        E, g = fun(z, True)
        E_ref, g_ref = reference(obj, fs, pre, z)
        assert pytest.approx(E_ref, rel=1e-12) == E
        np.testing.assert_allclose(g, g_ref, rtol=1e-9, atol=1e-12 * np.abs(g_ref).max())
        assert fun(z, False) == (pytest.approx(E, rel=1e-14), None)


def test_orientation_gradient_matches_central_differences():
    obj, fs, pre = orientation(0.1)
    fun = _orientation_fun(obj, obj.basis(fs.times), fs, pre.whole_rows(), pre.groups[0][2], pre.whole_radial())
    z = 0.2 * np.random.default_rng(7).normal(size=fs.n_free)
    _, g = fun(z, True)
    h = 1e-6
    fd = np.array([(fun(z + h * e, False)[0] - fun(z - h * e, False)[0]) / (2 * h) for e in np.eye(fs.n_free)])
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-7 * np.abs(fd).max())


def test_orientation_path_stops_on_a_non_finite_trial_point_and_names_the_term():
    """A trial point with NaN components (as a line search that overflowed would give) stops the round
    with Status.NONFINITE and names the first term whose integral is not finite, as the generic path
    does."""
    obj, fs, pre = orientation(1.0)
    rows, Rinv = pre.whole_rows(), pre.groups[0][2]
    fun = _orientation_fun(obj, obj.basis(fs.times), fs, rows, Rinv, pre.whole_radial())
    z = np.full(fs.n_free, np.nan)
    with pytest.raises(Stop) as err:
        fun(z, True)
    assert err.value.status is Status.NONFINITE and "objective term 'unit'" in err.value.message
