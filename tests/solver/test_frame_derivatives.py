"""Central differences of sampled frames (solver.peak_bounds.frame_derivatives), the measure of the no-jolt
acceptance figures and of a clean's no-jolt bound, against scipy's cubic splines: for positions at uneven
times they are the weighted means of any interpolating cubic spline's second derivative at the frames
(de Boor, A Practical Guide to Splines, ch. IV), the property that makes a bound met at the frames hold by
this measure too."""
import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from solver.errors import InputError
from solver.peak_bounds import frame_derivatives


@pytest.fixture(scope="module")
def model(toy_model):
    return toy_model


def _frames(model, times, root):
    q = np.zeros((len(times), model.nq))
    q[:, :3] = root
    q[:, 3] = 1.0  # the root's quaternion
    for j in range(1, model.njnt):
        q[:, model.jnt_qposadr[j]] = 1.0  # every ball joint at rest
    return q


@pytest.mark.parametrize("bc", ["natural", "not-a-knot", "clamped"])
def test_a_position_s_central_differences_are_means_of_the_spline_s_accelerations(model, bc):
    rng = np.random.default_rng(7)
    times = np.cumsum(rng.uniform(1 / 150, 1 / 20, 40))  # uneven steps, 6.7-50 ms
    root = rng.normal(scale=0.1, size=(len(times), 3)) + [0, 0, 1]
    qvel, qacc = frame_derivatives(model, times, _frames(model, times, root))
    M = CubicSpline(times, root, bc_type=bc)(times, 2)  # the spline's acceleration at the frames
    h0, h1 = np.diff(times)[:-1, None], np.diff(times)[1:, None]
    mean = (h0 * M[:-2] + 2 * (h0 + h1) * M[1:-1] + h1 * M[2:]) / (3 * (h0 + h1))
    np.testing.assert_allclose(qacc[:, :3], mean, rtol=1e-9, atol=1e-9 * np.abs(M).max())
    assert np.all(np.linalg.norm(qacc[:, :3], axis=1) <= np.linalg.norm(M, axis=1).max() * (1 + 1e-12))
    slope = np.diff(root, axis=0) / np.diff(times)[:, None]
    np.testing.assert_allclose(qvel[:, :3], 0.5 * (slope[1:] + slope[:-1]), rtol=1e-12, atol=1e-12)


def test_a_still_joint_has_no_derivatives_and_bad_times_are_named(model):
    times = np.linspace(0, 1, 11)
    qvel, qacc = frame_derivatives(model, times, _frames(model, times, [0, 0, 1]))
    assert np.abs(qvel).max() == 0 and np.abs(qacc).max() == 0
    with pytest.raises(InputError, match="increasing"):
        frame_derivatives(model, times[::-1], _frames(model, times, [0, 0, 1]))
    with pytest.raises(InputError, match="n >= 3"):
        frame_derivatives(model, times[:2], _frames(model, times[:2], [0, 0, 1]))
